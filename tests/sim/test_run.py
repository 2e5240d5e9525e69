"""simulate(): a scaled run is complete, follows the true APC pulse by pulse, and records its
truth (its speed is measured by ``bench/bench_sim.py``, not asserted here)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sarmoco.processing.rangecomp import compress, range_axis_m
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import load_preset
from tests.conftest import SHARED_DATA

TLOG = SHARED_DATA / "mavlink" / "arduplane_quadplane_sitl.tlog"


@pytest.mark.parametrize("name", ["thz-spotlight", "ku-vehicle", "ku-microuav"])
def test_scaled_run_is_complete(name: str) -> None:
    scn = load_preset(name, scale=0.1)
    run = simulate(scn, MotionSpec(kind="turbulence", seed=1), "tactical", seed=4)
    p = scn.n_pulses
    assert run.echo.shape == (p, scn.radar.n_samples) and run.echo.dtype == np.complex64
    assert run.t_ns.dtype == np.int64 and run.t_ns[0] == run.t0_ns == scn.t0_ns
    assert np.all(np.diff(run.t_ns) > 0)
    assert run.apc_ned.shape == run.vel_ned.shape == (p, 3)
    nav = run.ins.nav
    assert nav.t_ns[0] < run.t_ns[0] and nav.t_ns[-1] > run.t_ns[-1]
    truth = json.loads(json.dumps(run.truth_dict()))
    assert truth["scenario"]["name"] == name and len(truth["pulses"]["t_ns"]) == p
    assert truth["pulses"]["t_ns"][0] == scn.t0_ns and len(truth["targets"]) == 3
    assert truth["ins"]["grade"] == "tactical"


@pytest.mark.parametrize(
    ("name", "motion"),
    [
        ("thz-spotlight", MotionSpec(kind="turbulence", seed=3)),
        ("ku-vehicle", MotionSpec(kind="flightlog", log_path=TLOG, log_start_s=30.0)),
    ],
)
def test_echo_follows_true_apc_pulse_by_pulse(name: str, motion: MotionSpec) -> None:
    scn = load_preset(name, scale=0.1, snr_db=None)
    run = simulate(scn, motion, "ideal")
    rc = compress(scn.radar, run.echo)
    axis = range_axis_m(scn.radar)
    lit = scn.illumination(run.apc_ned, run.targets_ned)
    k = 1  # scene centre target
    r = np.linalg.norm(run.targets_ned[k] - run.apc_ned, axis=1)
    pulses = np.flatnonzero(lit[:, k] > 0)
    # the motion moves the target through many range bins and many wavelengths
    assert np.ptp(r) > 2 * scn.radar.wavelength_m
    bins = np.argmin(np.abs(axis[None, :] - r[pulses, None]), axis=1)
    phase = np.angle(rc[pulses, bins] * np.exp(4j * np.pi * r[pulses] / scn.radar.wavelength_m))
    assert np.abs(phase).max() < 0.05
    near = bins[:, None] + np.arange(-8, 9)[None, :]
    peak = near[np.arange(pulses.size), np.argmax(np.abs(rc[pulses[:, None], near]), axis=1)]
    assert np.all(np.abs(peak - bins) <= 1)
