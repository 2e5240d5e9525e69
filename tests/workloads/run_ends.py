"""Ends of runs with the autofocus on.

Run as ``.venv/bin/python -m bench.run_ends [--seeds 0 1 2] [--uniform] [--no-autofocus]``.

ku-vehicle ×0.1 flown with the motion of a real ArduPilot flight log (18.5 → 19.5 m/s),
tactical INS, 9 targets (3 along track 15 m apart × 3 ranges; the start group is lit from
the run's first pulses, the end group leaves the beam 0.4 s, one subaperture, before the
last: the log flies faster than the preset's 17.5 m/s), simulated, written as ``.vrt`` and
``.tlog`` and replayed (``mocomp.along_track`` on unless ``--uniform``). Prints the azimuth
PSLR of the start, middle and end targets (each three ranges): the strip's nine brightest
points, as the report measures them.
"""

from __future__ import annotations

import math
from pathlib import Path

from sarmoco.app.simconfig import config_table, write_config
from sarmoco.daemon.config import load_config
from sarmoco.daemon.runner import replay_files
from sarmoco.products.report import bright_points, strip
from sarmoco.sim.faults import Faults
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.outfiles import NAV_FILES, RADAR_FILE, write_run
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import Target, load_preset
from sarmoco.store.reader import open_store

LOG = Path(__file__).resolve().parents[3] / "shared/data/mavlink/arduplane_quadplane_sitl.tlog"
"""The real ArduPilot flight log whose motion the run flies."""


def one(seed: int, along_track: bool, autofocus: bool, out: Path) -> list[list[float]]:
    """Simulate, replay and measure one seed; azimuth PSLR (dB) of start, middle, end."""
    ground = math.sqrt(900.0**2 - 100.0**2)
    targets = [Target((n, ground + e, 0.0)) for n in (-15.0, 0.0, 15.0) for e in (-10.0, 0, 10)]
    scn = load_preset("ku-vehicle", 0.1, targets=targets)
    run = simulate(scn, MotionSpec("flightlog", seed=seed, log_path=LOG), "tactical", seed=seed)
    write_run(run, Faults(), out, nav=["mavlink"], seed=seed)
    table = config_table(
        scn,
        radar={"link": str(out / RADAR_FILE)},
        ins={"protocol": "mavlink", "link": str(out / NAV_FILES["mavlink"])},
        recorder={"directory": str(out)},
    )
    table["autofocus"]["enabled"] = autofocus
    table.setdefault("mocomp", {})["along_track"] = along_track
    write_config(out / "sarmoco.toml", table)
    cfg = load_config(out / "sarmoco.toml")
    replay_files(cfg, out / RADAR_FILE, out / NAV_FILES["mavlink"], out / "run.zarr", False)
    # the nine brightest points of the strip (the report lists fewer), by along-track place
    image = strip(open_store(out / "run.zarr"))
    if image is None:
        raise RuntimeError(f"seed {seed}: the run made no image")
    points = bright_points(image, 9)
    ordered = sorted(points, key=lambda q: (round(q["x_m"]), q["y_m"]))
    values = [round(q["pslr_az_db"], 2) for q in ordered]
    return [values[0:3], values[3:6], values[6:9]]
