"""``sarmoco sim --preset mimo-array``: the MIMO array scenario written as files.

::

    sarmoco sim --preset mimo-array [--scale S] [--roll-deg 3 | --roll-series]
                [--dem FILE.npz] --out DIR

writes ``radar.vrt`` (one VITA 49.2 stream ID per Tx/Rx pair), ``nav.tlog`` (MAVLink, the
roll in the attitude), ``truth.json`` (with the true DEM) and a matching ``sarmoco.toml``
(``radar.mode = "array"``). ``--roll-deg`` sets the constant roll (default the paper's 3 deg);
``--roll-series`` makes the roll that mean plus a low-pass random series, which the
processor only knows from the INS stream. ``--dem`` replaces the synthetic terrain by a DEM
(``.npz`` with ``height_m`` and ``spacing_m``, :func:`~sarmoco.sim.array_scenario.read_dem`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from sarmoco.app.simconfig import write_config
from sarmoco.errors import ConfigError
from sarmoco.sim.array_run import NAV_PROTOCOL, simulate_array, write_array_run
from sarmoco.sim.array_scenario import ARRAY_PRESET, ArrayScenario, load_array_preset
from sarmoco.sim.insemitters import INS_EMITTERS
from sarmoco.sim.outfiles import RADAR_FILE, TRUTH_FILE
from sarmoco.sim.scenario import radar_table

CONFIG_FILE = "sarmoco.toml"
"""The daemon configuration written beside the files."""


def add_array_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments only the ``mimo-array`` preset takes."""
    roll = p.add_argument_group("mimo-array preset")
    roll.add_argument(
        "--roll-deg", type=float, default=None, help="constant roll (or the series' mean), deg "
        "(default: the preset's 3)",
    )  # fmt: skip
    roll.add_argument(
        "--roll-series", action="store_true",
        help="roll = that mean plus a low-pass random series (0.5 deg rms, 2 Hz corner)",
    )  # fmt: skip
    roll.add_argument("--dem", type=Path, metavar="FILE.npz", help="terrain: height_m, spacing_m")


def check_array_arguments(args: argparse.Namespace) -> None:
    """Refuse the array arguments with another preset, and live links with the array.

    Raises
    ------
    ConfigError
        Naming the argument.
    """
    if args.preset != ARRAY_PRESET:
        for name in ("roll_deg", "dem"):
            if getattr(args, name) is not None:
                flag = "--" + name.replace("_", "-")
                raise ConfigError(f"sim {flag}: only the {ARRAY_PRESET} preset takes it")
        if args.roll_series:
            raise ConfigError(f"sim --roll-series: only the {ARRAY_PRESET} preset takes it")
    elif args.serve:
        raise ConfigError(f"sim --serve: the {ARRAY_PRESET} preset writes files only (--out DIR)")


def array_config_table(scn: ArrayScenario, out: Path, payload: str) -> dict[str, Any]:
    """The daemon configuration (a TOML table) for the files of ``scn`` written in ``out``."""
    return {
        "radar": radar_table(scn.radar)
        | {
            "mode": "array",
            "channels": scn.layout.n_channels,
            "link": str(out / RADAR_FILE),
            "sample_format": payload,
        },
        "geometry": {"height_m": scn.altitude_m - scn.mean_ground_m},
        "ins": {
            "protocol": NAV_PROTOCOL,
            "link": str(out / INS_EMITTERS[NAV_PROTOCOL].file),
            "lever_arm_m": [0.0, 0.0, 0.0],
        },
        "array": {
            "n_tx": scn.layout.n_tx,
            "n_rx": scn.layout.n_rx,
            "epc_spacing_m": scn.epc_spacing_m,
            "antenna_length_m": scn.antenna_length_m,
            "max_look_deg": math.degrees(scn.max_look_rad),
        },
        "recorder": {"directory": str(out)},
    }


def run_array(args: argparse.Namespace) -> int:
    """Simulate the array preset and write its files and configuration into ``args.out``."""
    scn = load_array_preset(
        args.scale, roll_deg=args.roll_deg, roll_series=args.roll_series, dem=args.dem,
        seed=args.seed,
    )  # fmt: skip
    run = simulate_array(scn, args.ins_grade, args.ins_rate, args.seed)
    out = Path(args.out)
    truth = write_array_run(run, out, payload=args.payload, seed=args.seed)
    write_config(out / CONFIG_FILE, array_config_table(scn, out, args.payload))
    files = [d.get("path") for d in truth["wire"]["links"].values()]
    record = {
        "event": "written",
        "dir": str(out),
        "files": [*files, str(out / TRUTH_FILE), str(out / CONFIG_FILE)],
    }
    sys.stdout.write(json.dumps(record) + "\n")
    return 0
