"""Targets at the start of a run focus like the rest, through the daemon's pipeline.

ku-vehicle ×0.1 with the simulator's turbulence (``sarmoco sim --motion turbulence``:
0.3 m rms cross-track and vertical sway, 0.2 Hz corner), tactical INS, the autofocus on:
the run is one synthetic aperture (2.66 s), so the three targets' apertures begin at the
first pulse. Two defects cut those apertures (the second one is open):

- the turn test compared the heading averaged over the flight so far with the first
  pulse's heading alone: at seed 3 it flagged 1.01-1.95 s (165 pulses) as a turn, the
  pulses after it went to a second track, the targets were imaged in both (2.66 x the
  azimuth IRW in the first);
- the first reference track followed the mean INS velocity of one processing block
  (256 pulses, 1.46 s), e.g. 11.8 mrad off the run's course at seed 4; the pixels took
  the pulses within half the beam plus the 5.2 mrad squint tolerance of the track's
  broadside, so 6.6 of the 50 mrad the beam illuminates were cut (1.18 x IRW).

The image grid is laid along the first reference track, so the same 11.8 mrad turned it
against the course: the targets, 12 m apart in ground range, sat 0.13 m apart along track
from where they are. With ``mocomp.heading_window_s = 4`` the track follows 4 s of flight,
here the whole run: 0.017 m (the default, 0, keeps one block's heading).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.blocks import HOLD_MAX_BYTES, course_window_ns
from sarmoco.processing.geometry import fit_reference_track
from sarmoco.processing.metrics import PointTargetMetrics
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.store.flags import PulseFlag
from sarmoco.store.reader import open_store
from tests.daemon.test_pipeline import _target_metrics, feed

MAX_RELATIVE_POSITION_M = 0.1
"""Largest error of a target's place in the image relative to the others', m (a third of
the azimuth resolution)."""

HEADING_WINDOW_S = 4.0
"""``mocomp.heading_window_s`` of these runs (longer than the run: its whole flight), s."""

Focused = tuple[SimRun, list[PointTargetMetrics]]


def _run(seed: int) -> SimRun:
    """The ``sarmoco sim --preset ku-vehicle --scale 0.1 --motion turbulence
    --motion-seed SEED --ins-grade tactical`` run."""
    scn = load_preset("ku-vehicle", 0.1)
    return simulate(scn, MotionSpec("turbulence", seed=seed), "tactical")


def test_no_turn_and_one_segment_at_the_start_of_a_straight_run(tmp_path: Path) -> None:
    """Seed 3: no pulse is a turn and the strip has one reference track (before: 165
    pulses, 1.01-1.95 s, flagged as a turn, a second track from 1.95 s)."""
    run = _run(3)
    cfg = scenario_config(run.scenario, radar={"sample_format": "float32"})
    store_path = tmp_path / "run.zarr"
    feed(run, cfg, store_path)
    store = open_store(store_path)
    flags = store.read("pulses", ["flags"])["flags"]
    assert int(np.count_nonzero(flags & PulseFlag.TURN)) == 0
    tracks = {store.image(i)[1]["reference_track"]["t0_ns"] for i in range(store.n_images)}
    assert tracks == {int(run.t_ns[0])}, tracks


@pytest.fixture(scope="module")
def focused(tmp_path_factory: pytest.TempPathFactory) -> Callable[[int, float], Focused]:
    """The seed's run and its targets' metrics through the pipeline with that
    ``mocomp.heading_window_s`` (each pair once)."""
    done: dict[tuple[int, float], Focused] = {}

    def get(seed: int, heading_window_s: float = 0.0) -> Focused:
        key = (seed, heading_window_s)
        if key not in done:
            run = _run(seed)
            cfg = scenario_config(
                run.scenario,
                radar={"sample_format": "float32"},
                mocomp={"heading_window_s": heading_window_s},
            )
            store = tmp_path_factory.mktemp(f"seed{seed}") / "run.zarr"
            metrics = _target_metrics(run, cfg, store, replay=True)
            done[key] = (run, [m for m, _ in metrics])
        return done[key]

    return get


@pytest.mark.parametrize("seed", [4, 10])
def test_start_targets_keep_their_whole_aperture(
    seed: int, focused: Callable[[int, float], Focused]
) -> None:
    """Every target's azimuth PSLR is at most -12.5 dB and its IRW at most 1.1 x theory
    (0.886 x the preset's azimuth resolution).

    One processing block of flight can head off the flight's course by more than the
    squint tolerance; the pixels take the pulses of the beam where the attitude and the
    echoes' Doppler centroid put it, not of the track's broadside, so the targets keep
    their whole aperture.
    """
    run, metrics = focused(seed, 0.0)
    theory = 0.886 * run.scenario.azimuth_resolution_m
    az = [(m.axis0.pslr_db, m.axis0.irw_m / theory) for m in metrics]
    print(f"seed {seed}: azimuth PSLR dB / IRW x theory {az}")
    for pslr, irw in az:
        assert pslr <= -12.5 and irw <= 1.1, az


def test_the_image_grid_follows_the_course_not_the_first_block(
    focused: Callable[[int, float], Focused],
) -> None:
    """Seed 4, whose first processing block heads 11.8 mrad off the run's course: each
    target's place in the image grid (along track, ground range) less the median over the
    targets is within :data:`MAX_RELATIVE_POSITION_M` of its place on the course (the line
    fitted to the true antenna positions), so the grid is not turned against the ground."""
    run, metrics = focused(4, HEADING_WINDOW_S)
    course = fit_reference_track(run.t_ns, run.apc_ned, run.scenario.look_side)
    rel = run.targets_ned - run.apc_ned[0]
    truth = np.stack([rel @ course.x_hat, rel @ course.y_hat], axis=1)
    peaks = np.array([(m.axis0.peak_m, m.axis1.peak_m) for m in metrics])
    error = peaks - truth
    error -= np.median(error, axis=0)
    print(f"relative position errors (along, range), m: {error.round(3).tolist()}")
    assert np.hypot(*error.T).max() <= MAX_RELATIVE_POSITION_M, error


def test_a_replay_holds_no_more_than_its_bound_for_the_course() -> None:
    """The pulses a replay holds for the first track's course fit :data:`HOLD_MAX_BYTES`:
    the whole 4 s at ku-vehicle's 1 kHz, a shorter window at thz-spotlight's 20 kHz."""
    for preset, window_s in (("ku-vehicle", HEADING_WINDOW_S), ("thz-spotlight", None)):
        cfg = scenario_config(load_preset(preset, 1.0))
        held_ns = course_window_ns(cfg)
        pulse_bytes = cfg.radar.n_samples * np.dtype(np.complex64).itemsize
        assert held_ns * 1e-9 * cfg.radar.prf_hz * pulse_bytes <= HOLD_MAX_BYTES
        if window_s is not None:
            assert held_ns == round(window_s * 1e9)
        else:
            assert 0.5e9 < held_ns < round(cfg.mocomp.heading_window_s * 1e9)
