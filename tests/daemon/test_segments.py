"""A survey flight through the daemon's Focuser: straight legs joined by a banked turn.

ku-vehicle x0.1 flown as two 14 s legs joined by a 180° coordinated turn at the real
log's 11.6 °/s (19.9° bank, 86 m radius, 15.5 s), with the log's turbulence along the
legs and the 0.39 m lever arm (exact APC velocities, no noise, autofocus off, pulses at
their INS along-track position), two point targets at broadside of each leg. With
segments the south leg gets its own reference track: every target focuses, the turn's
pulses are flagged, D_los stays within the segment tolerance. With one track for the
whole run (``mocomp.segments = false``) the south leg's D_los reaches hundreds of metres
and its targets, on the other side of the first leg's track, are not imaged at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser, segment_limits
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.processing.imaging.tiles import Tile
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.segments import Segmenter
from sarmoco.processing.types import Image
from sarmoco.products.report import bright_points, strip
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.survey import SurveyPattern, survey_scenario, survey_spec
from sarmoco.store.flags import PulseFlag
from sarmoco.store.reader import open_store
from tests.daemon.test_pipeline import feed

SPEC = survey_spec(legs=2, leg_s=14.0, seed=1)
TOLERANCE_M = 3.0


@pytest.fixture(scope="module")
def run() -> SimRun:
    scn = survey_scenario(load_preset("ku-vehicle", 0.1, snr_db=None), SPEC)
    return simulate(scn, SPEC, "ideal")


@dataclass
class Focused:
    tiles: list[tuple[Tile, ReferenceTrack]]
    turn: np.ndarray
    d_los_m: np.ndarray
    segments: int


def _focus(run: SimRun, segments: bool, tolerance_m: float = TOLERANCE_M) -> Focused:
    cfg = scenario_config(
        run.scenario,
        autofocus={"enabled": False},
        imaging={"swath_m": 8.0},  # the targets lie at the scene-centre range
        mocomp={"along_track": True, "segments": segments, "segment_tolerance_m": tolerance_m},
    )
    n0 = cfg.imaging.block_pulses
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:n0].mean(axis=0))
    tiles: list[tuple[Tile, ReferenceTrack]] = []
    turn, d_los = [], []
    for a in range(0, run.t_ns.size, n0):
        b = slice(a, a + n0)
        out = focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b])
        assert out.motion is not None
        tiles += zip(out.tiles, out.tracks, strict=True)
        turn.append(out.turn)
        d_los.append(out.motion.d_los_m)
    end = focuser.finish()
    tiles += zip(end.tiles, end.tracks, strict=True)
    return Focused(tiles, np.concatenate(turn), np.concatenate(d_los), focuser.segments)


def _target_images(f: Focused, run: SimRun, target: np.ndarray) -> list[Image]:
    """The 3 m x 3 m around ``target`` in the frame of each track whose tiles reach it."""
    images = []
    for track in {id(tr): tr for _, tr in f.tiles}.values():
        tiles = sorted((t for t, tr in f.tiles if tr is track), key=lambda t: t.index)
        d = target - run.apc_ned[0] - track.origin_ned
        x, y = float(d @ track.x_hat), float(d @ track.y_hat)
        a0 = np.concatenate([t.grid.axis0_m for t in tiles])
        data = np.concatenate([t.data for t in tiles])
        a1 = tiles[0].grid.axis1_m
        i = np.flatnonzero(np.abs(a0 - x) <= 1.5)
        j = np.flatnonzero(np.abs(a1 - y) <= 1.5)
        if i.size < 10 or j.size < 10:
            continue
        images.append(Image(data[i[0] : i[-1] + 1, j[0] : j[-1] + 1], a0[i], a1[j], "ground"))
    return images


def _target_image(f: Focused, run: SimRun, target: np.ndarray) -> Image | None:
    """The 3 m x 3 m around ``target`` in the frame of the track whose tiles hold it best
    (None: no tile holds it)."""
    images = _target_images(f, run, target)
    return max(images, key=lambda img: float(np.abs(img.data).max())) if images else None


def _azimuth(f: Focused, run: SimRun) -> list[tuple[float, float] | None]:
    """Azimuth (PSLR dB, IRW m) of every target (None: not imaged)."""
    out: list[tuple[float, float] | None] = []
    for tgt in run.targets_ned:
        img = _target_image(f, run, tgt)
        m = None if img is None else point_target_metrics(img).axis0
        out.append(None if m is None else (m.pslr_db, m.irw_m))
    return out


def test_every_leg_focuses_turn_flagged_d_los_bounded(run: SimRun) -> None:
    f = _focus(run, segments=True)
    scn = run.scenario
    pattern = SurveyPattern.of(scn, SPEC)
    t = (run.t_ns - run.t_ns[0]) * 1e-9
    in_turn = (t > pattern.leg_s) & (t < pattern.leg_s + pattern.turn_s)
    # the turn is flagged (from within 1 s of its start), the legs' targets are not
    assert f.turn[in_turn & (t > pattern.leg_s + 1.0)].all()
    assert not f.turn[t < pattern.leg_s].any()
    assert f.segments == 2
    assert np.all(np.isnan(f.d_los_m[f.turn]))
    # bounded: at most the tolerance plus one pulse's growth
    assert np.nanmax(np.abs(f.d_los_m)) < TOLERANCE_M + 0.1
    irw_theory = 0.886 * scn.radar.wavelength_m / (4 * math.sin(scn.integration_angle_rad / 2))
    for az in _azimuth(f, run):
        assert az is not None
        assert az[0] <= -12.5
        assert az[1] <= 1.1 * irw_theory


def test_one_track_for_the_whole_survey_does_not_focus_the_second_leg(run: SimRun) -> None:
    f = _focus(run, segments=False)
    assert not f.turn.any() and f.segments == 1
    assert np.nanmax(np.abs(f.d_los_m)) > 100.0
    az = _azimuth(f, run)
    first, second = az[:2], az[2:]
    assert all(az is not None and az[0] <= -12.5 for az in first)  # the one track's leg
    # the second leg's targets are on the far side of the first leg's track: not imaged
    assert all(az is None or az[0] > -10.0 for az in second)


def test_the_store_flags_the_turn_and_names_each_tiles_track(tmp_path: Path) -> None:
    """Through the pipeline: the recorded flags carry TURN on the focuser's turn pulses
    only, and every tile names its segment's track (two tracks, legs 2 turn radii apart)."""
    spec = survey_spec(legs=2, leg_s=8.0, seed=2)
    base = load_preset("ku-vehicle", 0.1, snr_db=None)
    run = simulate(survey_scenario(base, spec, per_leg=1, margin_s=3.0), spec, "ideal")
    cfg = scenario_config(
        run.scenario,
        radar={"sample_format": "float32"},
        autofocus={"enabled": False},
        imaging={"swath_m": 8.0},
    )
    feed(run, cfg, tmp_path / "run.zarr")
    store = open_store(tmp_path / "run.zarr")
    pulses = store.read("pulses", ["t_ns", "flags"])
    turn = (pulses["flags"] & PulseFlag.TURN) != 0
    pattern = SurveyPattern.of(run.scenario, spec)
    t = (pulses["t_ns"] - run.t_ns[0]) * 1e-9
    # a turn at rate w from t = 0 moves the window mean over the last W against the one
    # before by w t^2 / (2 W) (t <= W): it crosses the beamwidth at sqrt(2 W beam / w)
    limits = segment_limits(cfg, run.scenario.speed_mps)
    onset_s = math.sqrt(2.0 * limits.window_s * limits.turn_rad / pattern.turn_rate_rps)
    assert onset_s < 1.5
    assert turn[(t > pattern.leg_s + onset_s + 0.1) & (t < pattern.leg_s + pattern.turn_s)].all()
    assert not turn[t < pattern.leg_s].any()
    assert not turn[t > pattern.leg_s + pattern.turn_s + 2 * 2.6].any()
    motion = store.read("motion", ["t_ns", "d_los_m"])
    assert np.array_equal(np.isnan(motion["d_los_m"]), turn)
    tracks = {}
    for i in range(store.n_images):
        track = store.image(i)[1]["reference_track"]
        tracks[track["t0_ns"]] = track
    assert len(tracks) == 2
    first, second = (tracks[k] for k in sorted(tracks))
    assert np.dot(first["x_hat_ned"], second["x_hat_ned"]) == pytest.approx(-1.0, abs=1e-3)
    apart = np.subtract(second["origin_ned"], first["origin_ned"]) @ first["y_hat_ned"]
    assert apart == pytest.approx(-2 * pattern.radius_m, rel=0.01)
    # the report's strip puts the second segment after the first: both targets, apart
    image = strip(store)
    assert image is not None and np.all(np.diff(image.axis0_m) > 0)
    points = sorted(bright_points(image, n=2), key=lambda p: p["x_m"])
    assert len(points) == 2 and points[1]["x_m"] - points[0]["x_m"] > 20.0


def test_a_deviation_cut_inside_an_aperture_leaves_the_target_whole() -> None:
    """One 16 s leg, 8 targets 1.25 s apart (the aperture is 2.6 s), a 0.3 m tolerance:
    the track drifts out twice, the first cut (at 11.8 s) inside the last two targets'
    apertures. Segments overlap at the cut, so every target is imaged once, from one
    track with its whole aperture (without the overlap, the last two targets' apertures
    were split: azimuth IRW 1.26 and 1.41 x theory)."""
    spec = survey_spec(legs=1, leg_s=16.0, seed=1)
    base = load_preset("ku-vehicle", 0.1, snr_db=None)
    run = simulate(survey_scenario(base, spec, per_leg=8, margin_s=3.0), spec, "ideal")
    f = _focus(run, segments=True, tolerance_m=0.3)
    assert f.segments == 3
    scn = run.scenario
    irw_theory = 0.886 * scn.radar.wavelength_m / (4 * math.sin(scn.integration_angle_rad / 2))
    for target in run.targets_ned:
        images = sorted(_target_images(f, run, target), key=lambda i: -np.abs(i.data).max())
        az = point_target_metrics(images[0]).axis0
        assert az is not None and az.irw_m <= 1.1 * irw_theory
        # once: no other segment's tiles show it (its sidelobes across the cut at most)
        peak = float(np.abs(images[0].data).max())
        assert all(np.abs(other.data).max() < 0.1 * peak for other in images[1:])
    image = _target_image(f, run, run.targets_ned[-1])
    assert image is not None
    last = point_target_metrics(image).axis0
    assert last is not None and last.pslr_db <= -12.5


def test_turbulence_of_a_straight_flight_is_not_a_turn() -> None:
    """The daemon's turn limit on a straight leg whose ground track swings as a real
    flight's does: the heading averaged over one aperture moves by 0.71 of the azimuth
    beamwidth from one aperture to the next (1.35° on a 1.91° beam in a real ArduPilot
    flight; here a cross-track velocity of period two apertures, 0.8 m peak to peak). No
    pulse is a turn (with half the beam as the limit, some are)."""
    cfg = scenario_config(load_preset("ku-vehicle", 0.1, snr_db=None))
    v0 = 17.5
    limits = segment_limits(cfg, v0)
    beam = math.radians(cfg.imaging.azimuth_beamwidth_deg)
    period = 2.0 * limits.window_s
    # consecutive half-period means of A sin differ by 4 A / pi: a heading step of 0.71 beam
    amp = 0.71 * beam * v0 * math.pi / 4.0
    t = np.arange(0.0, 20.0, 1.0 / 175.0)
    cross = amp * np.sin(2.0 * math.pi * t / period)
    psi = math.radians(62.0)
    vel = np.stack(
        [v0 * math.cos(psi) - cross * math.sin(psi), v0 * math.sin(psi) + cross * math.cos(psi),
         np.zeros_like(t)], axis=1,
    )  # fmt: skip
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
    n = round(limits.window_s * 175.0)
    means = np.convolve(heading, np.ones(n) / n, "valid")
    assert np.abs(means[n:] - means[:-n]).max() == pytest.approx(0.71 * beam, rel=0.05)
    track = ReferenceTrack.from_velocity(np.zeros(3), vel[0], int(t_ns[0]))
    plan = Segmenter(limits, track, "right").plan(t_ns, vel)
    assert not plan.turn.any()
