"""``sarmoco sim --preset mimo-array``: the MIMO array scenario, as files or live links.

::

    sarmoco sim --preset mimo-array [--scale S] [--roll-deg 3 | --roll-series]
                [--dem FILE.npz] --out DIR

writes ``radar.vrt`` (one VITA 49.2 stream ID per Tx/Rx pair), ``nav.tlog`` (MAVLink, the
roll in the attitude), ``truth.json`` (with the true DEM) and a matching ``sarmoco.toml``
(``radar.mode = "array"``). With ``--serve --radar udp://127.0.0.1:PORT --ins
mavlink:udpout:127.0.0.1:PORT [--truth FILE]`` the same pulses and INS samples go to a live
daemon (``sarmoco run``) over the links instead, as the other presets' ``--serve`` does.
``--roll-deg`` sets the constant roll (default the paper's 3 deg);
``--roll-series`` makes the roll that mean plus a low-pass random series, which the
processor only knows from the INS stream. ``--dem`` replaces the synthetic terrain by a DEM
(``.npz`` with ``height_m`` and ``spacing_m``, :func:`~sarmoco.sim.array_scenario.read_dem`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

from sarmoco.app.simconfig import write_config
from sarmoco.errors import ConfigError
from sarmoco.sim.array_run import (
    NAV_PROTOCOL,
    ArrayRun,
    array_ins_feed,
    array_radar_emitter,
    simulate_array,
    truth_dict,
    wire_section,
    write_array_run,
)
from sarmoco.sim.array_scenario import ARRAY_PRESET, ArrayScenario, load_array_preset
from sarmoco.sim.emitter import Emitter
from sarmoco.sim.insemitters import INS_EMITTERS, InsEmitterOptions, live_ins_emitter
from sarmoco.sim.outfiles import RADAR_FILE, TRUTH_FILE, write_truth
from sarmoco.sim.player import Pacing, play_emitters
from sarmoco.sim.scenario import radar_table
from sarmoco.sim.transports import Link

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
    if args.preset == ARRAY_PRESET and args.serve and not args.radar:
        raise ConfigError(f"sim --serve: the {ARRAY_PRESET} preset needs --radar")
    if args.preset != ARRAY_PRESET:
        for name in ("roll_deg", "dem"):
            if getattr(args, name) is not None:
                flag = "--" + name.replace("_", "-")
                raise ConfigError(f"sim {flag}: only the {ARRAY_PRESET} preset takes it")
        if args.roll_series:
            raise ConfigError(f"sim --roll-series: only the {ARRAY_PRESET} preset takes it")


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


def _simulate(args: argparse.Namespace) -> ArrayRun:
    """The array run the arguments describe."""
    scn = load_array_preset(
        args.scale, roll_deg=args.roll_deg, roll_series=args.roll_series, dem=args.dem,
        seed=args.seed,
    )  # fmt: skip
    return simulate_array(scn, args.ins_grade, args.ins_rate, args.seed)


def serve_array(args: argparse.Namespace, radar: Link, pacing: Pacing) -> int:
    """Simulate the array preset and play it to a live daemon: every channel of each pulse
    on ``radar``, the INS on each ``--ins`` link; the truth record to ``--truth``.

    One JSON line ``{"event": "listening", ...}`` goes to stdout once the links are open
    (each with the ``connect`` the daemon opens), ``{"event": "done", ...}`` at the end.
    """
    run = _simulate(args)
    feed = array_ins_feed(run)
    emitters: dict[str, Emitter] = {}
    try:
        emitters["radar"] = array_radar_emitter(run, radar, args.payload, args.seed)
        for k, spec in enumerate(args.ins or [], start=1):
            options = InsEmitterOptions(None, args.seed * 16 + k, k)
            emitters[f"ins{k}"] = live_ins_emitter(spec, feed, options)
        _print_line({
            "event": "listening", "pid": os.getpid(), "preset": ARRAY_PRESET,
            "scale": args.scale, "n_pulses": int(run.t_ns.size),
            "radar": emitters["radar"].describe(),
            "ins": [e.describe() for name, e in emitters.items() if name != "radar"],
            "truth": None if args.truth is None else str(args.truth),
        })  # fmt: skip
        result = play_emitters(
            list(emitters.values()), pacing, wait_s=args.wait, linger_s=args.linger
        )
        if args.truth is not None:
            write_truth(args.truth, truth_dict(run) | {"wire": wire_section(result.wire, emitters)})
        _print_line({
            "event": "done", "wall_s": round(result.wall_s, 3), "shift_ns": result.wire.shift_ns,
            "links": {name: e.stats() for name, e in emitters.items()},
        })  # fmt: skip
    finally:
        for e in emitters.values():
            e.close()
    return 0


def _print_line(record: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(record) + "\n")
    sys.stdout.flush()


def run_array(args: argparse.Namespace) -> int:
    """Simulate the array preset and write its files and configuration into ``args.out``."""
    run = _simulate(args)
    scn = run.scenario
    out = Path(args.out)
    truth = write_array_run(run, out, payload=args.payload, seed=args.seed)
    write_config(out / CONFIG_FILE, array_config_table(scn, out, args.payload))
    files = [d.get("path") for d in truth["wire"]["links"].values()]
    record = {
        "event": "written",
        "dir": str(out),
        "files": [*files, str(out / TRUTH_FILE), str(out / CONFIG_FILE)],
    }
    _print_line(record)
    return 0
