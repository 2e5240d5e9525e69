"""The daemon pipeline in process: ring → aligner → focuser → recorder → report.

A scaled ku-vehicle run with turbulent cross-track motion and a tactical INS is fed
pulse by pulse (with INS samples arriving ahead of the pulses, as live), then the
store is reopened and its tiles measured: every point target must focus to the
unweighted-sinc limit within the autofocus issue's thresholds (PSLR ≤ -12.5 dB,
IRW ≤ 1.1 × theory) at the right place.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sarmoco.daemon.config import Config
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.report import write_report
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.simconfig import scenario_config
from sarmoco.daemon.status import Counters
from sarmoco.daemon.store import open_store
from sarmoco.drivers.samples import AttitudeSample, Validity, VelocitySample
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import MotionSpec

MOTION = MotionSpec(
    kind="turbulence",
    cross_track_rms_m=0.3,
    vertical_rms_m=0.15,
    along_speed_rms_mps=0.02,
    attitude_rms_rad=0.0,
    corner_hz=0.1,
    seed=1,
)
"""0.3 m rms cross-track sway: 30 wavelengths at Ku, far beyond any focusing tolerance."""

NAV_LEAD_NS = 50_000_000
"""INS samples reach the daemon up to this far ahead of the pulses, ns."""


@pytest.fixture(scope="module")
def run() -> SimRun:
    return simulate(load_preset("ku-vehicle", 0.1), MOTION, "tactical", seed=0)


def feed(run: SimRun, cfg: Config, store: Path) -> Pipeline:
    """Play a simulated run into a pipeline on the radar's virtual clock."""
    nav = run.ins.nav
    with open_recorder(cfg, store) as rec:
        pipe = Pipeline(cfg, rec, Counters())
        k = 0
        for i, t in enumerate(run.t_ns.tolist()):
            slot = pipe.ring.reserve()
            assert slot is not None
            slot.samples[...] = run.echo[i]
            pipe.ring.commit(slot, t, i)
            while k < nav.t_ns.size and nav.t_ns[k] < t + NAV_LEAD_NS:
                tk = int(nav.t_ns[k])
                vel = (float(nav.vel_ned[k, 0]), float(nav.vel_ned[k, 1]), float(nav.vel_ned[k, 2]))
                q = nav.quat[k]
                quat = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
                pipe.add_nav(
                    [
                        VelocitySample(tk, vel, Validity.VELOCITY, "sim", tk),
                        AttitudeSample(tk, quat, Validity.ATTITUDE, "sim", tk),
                    ],
                    None,
                )
                k += 1
            if i % 64 == 63:
                pipe.process(t)
        pipe.finish()
    return pipe


@pytest.mark.parametrize("autofocus", [False, True], ids=["ins-only", "ins+autofocus"])
def test_pipeline_focuses_and_records(run: SimRun, tmp_path: Path, autofocus: bool) -> None:
    scn = run.scenario
    cfg = scenario_config(scn, radar={"sample_format": "float32"}, autofocus={"enabled": autofocus})
    pipe = feed(run, cfg, tmp_path / "run.zarr")
    assert pipe.focuser is not None
    summary = write_report(tmp_path / "run.zarr", tmp_path / "report")
    assert summary["complete"]
    assert summary["run"]["pulses_processed"] == run.t_ns.size
    assert summary["run"]["pulses_nav_flagged"] == 0
    for name in ("image.png", "motion.png", "report.json", "report.txt"):
        assert (tmp_path / "report" / name).stat().st_size > 0
    store = open_store(tmp_path / "run.zarr")
    assert store.committed("pulses") == run.t_ns.size
    assert store.committed("motion") == run.t_ns.size
    points = summary["image"]["points"]
    track = pipe.focuser.track
    truth = [track.rotation @ (tg - run.apc_ned[0]) for tg in run.targets_ned]
    irw_az = 0.886 * scn.azimuth_resolution_m
    for tgt in truth:
        near = [p for p in points if math.hypot(p["x_m"] - tgt[0], p["y_m"] - tgt[1]) < 0.5]
        assert near, f"no focused point near {tgt[:2]}: {points}"
        p = near[0]
        irw_rg = 0.886 * scn.radar.range_resolution_m * np.hypot(tgt[1], tgt[2]) / tgt[1]
        assert p["pslr_az_db"] <= -12.5 and p["pslr_rg_db"] <= -12.5, p
        assert p["irw_az_m"] <= 1.1 * irw_az and p["irw_rg_m"] <= 1.1 * irw_rg, p
