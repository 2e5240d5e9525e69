"""Segmentation of a strip into straight reference tracks, and the turns between them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.processing.segments import Segmenter, SegmentLimits, SegmentPlan

PRF_HZ = 100.0
SPEED_MPS = 17.5
TURN_RPS = np.radians(11.6)  # the real ArduPilot loiter's turn rate
LIMITS = SegmentLimits(deviation_m=3.0, turn_rad=np.radians(1.45), window_s=2.6)


def _racetrack(leg_s: float = 20.0) -> tuple[np.ndarray, np.ndarray, float, float]:
    """North leg, a 180° left turn, south leg: times (s), APC velocity NED, turn start, end."""
    t_turn = np.pi / TURN_RPS
    t = np.arange(0.0, 2 * leg_s + t_turn, 1.0 / PRF_HZ)
    psi = -np.clip(t - leg_s, 0.0, t_turn) * TURN_RPS
    vel = SPEED_MPS * np.stack([np.cos(psi), np.sin(psi), np.zeros_like(t)], axis=1)
    return t, vel, leg_s, leg_s + t_turn


def _plan(t: np.ndarray, vel: np.ndarray, block: int) -> tuple[SegmentPlan, list[ReferenceTrack]]:
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    first = ReferenceTrack.from_velocity(np.zeros(3), vel[0], int(t_ns[0]))
    seg = Segmenter(LIMITS, first, "right")
    turns: list[np.ndarray] = []
    starts: list[int] = []
    tracks: list[ReferenceTrack] = []
    cut_x: list[np.ndarray] = []
    offsets: list[np.ndarray] = []
    for a in range(0, t.size, block):
        p = seg.plan(t_ns[a : a + block], vel[a : a + block])
        turns.append(p.turn)
        starts += (p.starts + a).tolist()
        tracks += p.tracks
        cut_x.append(p.cut_x_m)
        offsets.append(p.offset_m)
    plan = SegmentPlan(
        np.concatenate(turns),
        np.asarray(starts),
        tuple(tracks),
        np.concatenate(cut_x),
        np.concatenate(offsets),
    )
    return plan, tracks


def test_a_turn_is_flagged_and_the_next_leg_gets_its_own_track() -> None:
    t, vel, t_in, t_out = _racetrack()
    plan, tracks = _plan(t, vel, 256)
    flagged = t[plan.turn]
    # flagged within an aperture of the turn's start, until the window is straight again
    assert t_in < flagged[0] < t_in + 1.0
    assert t_out < flagged[-1] < t_out + 2 * LIMITS.window_s
    assert np.all(np.diff(np.flatnonzero(plan.turn)) == 1)  # one run of turn pulses
    assert plan.starts.tolist() == [int(np.flatnonzero(plan.turn)[-1]) + 1]
    south = tracks[0]
    np.testing.assert_allclose(south.x_hat, [-1.0, 0.0, 0.0], atol=1e-9)
    # the new track starts where the APC is: 2 turn radii west of the first leg
    radius = SPEED_MPS / TURN_RPS
    assert south.origin_ned[1] == pytest.approx(-2 * radius, rel=1e-3)


def test_block_by_block_equals_one_call() -> None:
    t, vel, _, _ = _racetrack(8.0)
    whole, _ = _plan(t, vel, t.size)
    for block in (1000, 256, 97):
        cut, _ = _plan(t, vel, block)
        np.testing.assert_array_equal(cut.turn, whole.turn)
        np.testing.assert_array_equal(cut.starts, whole.starts)


def test_a_drift_away_from_the_track_starts_segments_that_keep_it_within_tolerance() -> None:
    """A 1° heading error never flagged as a turn: the deviation grows 0.3 m/s."""
    t = np.arange(0.0, 60.0, 1.0 / PRF_HZ)
    psi = np.radians(1.0)
    vel = SPEED_MPS * np.tile([np.cos(psi), np.sin(psi), 0.0], (t.size, 1))
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    north = ReferenceTrack.from_velocity(np.zeros(3), np.array([SPEED_MPS, 0.0, 0.0]), t_ns[0])
    plan = Segmenter(LIMITS, north, "right").plan(t_ns, vel)
    assert not plan.turn.any()
    # 3 m at 0.305 m/s: about 9.8 s after the start, then along the true heading
    assert plan.starts.size == 1
    assert t[plan.starts[0]] == pytest.approx(3.0 / (SPEED_MPS * np.sin(psi)), abs=0.02)
    np.testing.assert_allclose(plan.tracks[0].x_hat[:2], [np.cos(psi), np.sin(psi)], atol=1e-9)


def test_limits_must_be_positive() -> None:
    with pytest.raises(ProcessingError, match="deviation_m"):
        SegmentLimits(deviation_m=0.0, turn_rad=0.1, window_s=1.0)


def test_a_restart_takes_the_whole_segment_s_mean_heading() -> None:
    """Turbulent cross-track velocity (0.1 m/s rms at 0.1-0.5 Hz) on a 1° heading, the first
    track due north: one restart at 3 m, then a track along the segment's mean velocity
    that stays within tolerance for the rest of 180 s (the window-mean velocity at the
    restart, 2.6 s of gusts, is up to ~0.5° off and drifts out again)."""
    t = np.arange(0.0, 180.0, 1.0 / PRF_HZ)
    rng = np.random.default_rng(3)
    f = rng.uniform(0.1, 0.5, 8)
    gust = 0.05 * np.sin(2 * np.pi * f[None, :] * t[:, None] + rng.uniform(0, 7, 8)).sum(1)
    psi = np.radians(1.0)
    c, s = np.cos(psi), np.sin(psi)
    vel = np.stack([SPEED_MPS * c - gust * s, SPEED_MPS * s + gust * c, 0 * t], axis=1)
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    north = ReferenceTrack.from_velocity(np.zeros(3), np.array([SPEED_MPS, 0.0, 0.0]), t_ns[0])
    plan = Segmenter(LIMITS, north, "right").plan(t_ns, vel)
    assert not plan.turn.any()
    assert plan.starts.size == 1
    heading = np.arctan2(plan.tracks[0].x_hat[1], plan.tracks[0].x_hat[0])
    assert abs(np.degrees(heading) - 1.0) < 0.1


def test_after_a_navigation_gap_the_track_follows_the_flight_after_it() -> None:
    """A 10 s INS silence: before it the APC flies at -16 mrad,
    sinking 0.16 m/s; during it the daemon holds that last velocity as a placeholder
    (``known`` false); after it the APC flies level at -6.5 mrad. The placeholders drift
    3 m off the first track (due north) 8.3 s into the silence: no segment starts there.
    The segment that starts at the first pulse with navigation after the silence takes the
    heading flown after it, whatever the block cut, not the heading of the placeholders or
    of the flight before it (the daemon's track was -14.2 mrad, and the targets after the
    silence focused at 1.2 x the azimuth IRW)."""
    t = np.arange(0.0, 20.0, 1.0 / PRF_HZ)
    before, after = -16e-3, -6.5e-3
    v_before = [SPEED_MPS * np.cos(before), SPEED_MPS * np.sin(before), 0.16]
    v_after = [SPEED_MPS * np.cos(after), SPEED_MPS * np.sin(after), 0.0]
    vel = np.where((t < 11.0)[:, None], v_before, v_after)
    known = (t < 1.0) | (t >= 11.0)
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    north = ReferenceTrack.from_velocity(np.zeros(3), np.array([SPEED_MPS, 0.0, 0.0]), t_ns[0])
    for block in (t.size, 256, 97):
        seg = Segmenter(LIMITS, north, "right")
        starts: list[int] = []
        tracks: list[ReferenceTrack] = []
        for a in range(0, t.size, block):
            p = seg.plan(t_ns[a : a + block], vel[a : a + block], known[a : a + block])
            assert not p.turn.any()
            starts += (p.starts + a).tolist()
            tracks += p.tracks
        assert starts == [int(np.flatnonzero(t >= 11.0)[0])], (block, t[starts])
        heading = np.arctan2(tracks[0].x_hat[1], tracks[0].x_hat[0])
        assert abs(heading - after) < 0.5e-3, (block, heading)


def test_a_skip_does_not_start_a_segment_and_a_turn_after_it_still_does() -> None:
    """Straight flight with 4 s of pulses left out (longer than the window): a hole with
    nothing said about it starts a segment at the first pulse after it (as after a
    navigation gap); marked ``after_skip`` it does not, whatever the block cut. A turn
    flown after a skip is still flagged and the leg after it gets its own track."""
    t, vel, turn_start, _ = _racetrack(leg_s=20.0)
    keep = (t < 8.0) | (t >= 12.0)
    t, vel = t[keep], vel[keep]
    after = np.diff(np.flatnonzero(keep), prepend=-1) > 1
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    north = ReferenceTrack.from_velocity(np.zeros(3), vel[0], int(t_ns[0]))
    first_after = int(np.flatnonzero(after)[0])
    for block in (t.size, 256, 97):
        for tell, expect_skip_start in ((False, True), (True, False)):
            seg = Segmenter(LIMITS, north, "right")
            starts: list[int] = []
            turn: list[np.ndarray] = []
            for a in range(0, t.size, block):
                mark = after[a : a + block] if tell else None
                p = seg.plan(t_ns[a : a + block], vel[a : a + block], after_skip=mark)
                starts += (p.starts + a).tolist()
                turn.append(p.turn)
            assert (first_after in starts) == expect_skip_start, (block, tell, starts)
            turned = np.concatenate(turn)
            assert turned.any() and t[np.argmax(turned)] > turn_start
            assert any(t[s] > turn_start for s in starts)


def test_known_must_match_the_pulses() -> None:
    north = ReferenceTrack.from_velocity(np.zeros(3), np.array([SPEED_MPS, 0.0, 0.0]), 10**18)
    t_ns = 10**18 + np.arange(4, dtype=np.int64) * 10**7
    with pytest.raises(ProcessingError, match="known"):
        Segmenter(LIMITS, north, "right").plan(t_ns, np.ones((4, 3)), np.ones(3, dtype=bool))


def test_a_deviation_cut_reaches_back_by_the_overlap_and_not_after_a_turn() -> None:
    """With ``overlap_s``, the segment of a drift cut starts 1.5 s before it, on the line
    through the APC at the cut (its deviation 0 there), whatever the blocks; the one
    after a turn does not reach back."""
    t = np.arange(0.0, 20.0, 1.0 / PRF_HZ)
    psi = np.radians(1.0)
    vel = SPEED_MPS * np.tile([np.cos(psi), np.sin(psi), 0.0], (t.size, 1))
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    north = ReferenceTrack.from_velocity(np.zeros(3), np.array([SPEED_MPS, 0.0, 0.0]), t_ns[0])
    limits = replace(LIMITS, overlap_s=1.5)
    for block in (t.size, 256, 97):
        seg = Segmenter(limits, north, "right")
        plans = [seg.plan(t_ns[a : a + block], vel[a : a + block]) for a in range(0, t.size, block)]
        plan = next(p for p in plans if p.starts.size)
        track = plan.tracks[0]
        t_cut = 3.0 / (SPEED_MPS * np.sin(psi))
        assert (track.t0_ns - t_ns[0]) * 1e-9 == pytest.approx(t_cut - 1.5, abs=0.02)
        assert plan.cut_x_m[0] == pytest.approx(1.5 * track.v0_mps, abs=0.5)
        cut = int(np.argmin(np.abs(t - t_cut)))
        dev = track.deviation(t_ns[cut : cut + 1], (vel[0] * t[cut])[None, :])[0]
        assert abs(dev[1]) < 1e-6 and abs(dev[0]) < 0.05
        np.testing.assert_allclose(plan.offset_m[0, 1:], 0.0, atol=1e-6)
    t, vel, _, _ = _racetrack(8.0)
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    first = ReferenceTrack.from_velocity(np.zeros(3), vel[0], int(t_ns[0]))
    plan = Segmenter(limits, first, "right").plan(t_ns, vel)
    assert plan.starts.size == 1 and np.isnan(plan.cut_x_m).all()
    assert plan.tracks[0].t0_ns == t_ns[plan.starts[0]]


def test_a_course_swing_the_body_does_not_make_is_no_turn() -> None:
    """Gusts swing the course by 2.5° between aperture windows (a 0.29 Hz cross-track
    velocity of 0.6 m/s at 17.5 m/s, 0.66 m peak to peak: about the acceptance flight's
    with twice its motion)
    while the body holds its heading: without the body's heading the course alone flags
    it a turn; with it, no pulse is. A turn the body makes with the course (the racetrack,
    the body's heading along the velocity) is flagged as before, block by block alike."""
    t = np.arange(0.0, 20.0, 1.0 / PRF_HZ)
    gust = 0.6 * np.sin(2 * np.pi * 0.29 * t)
    vel = np.stack([np.full(t.size, SPEED_MPS), gust, 0 * t], axis=1)
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    north = ReferenceTrack.from_velocity(np.zeros(3), np.array([SPEED_MPS, 0.0, 0.0]), t_ns[0])
    limits = replace(LIMITS, turn_rad=np.radians(1.91), window_s=1.71)
    assert Segmenter(limits, north, "right").plan(t_ns, vel).turn.any()
    held = np.radians(6.0) + np.zeros(t.size)  # crabbed 6°, the body's heading held
    held[::7] = np.nan  # pulses without attitude leave the rest to decide
    for block in (t.size, 256, 97):
        seg = Segmenter(limits, north, "right")
        for a in range(0, t.size, block):
            s = slice(a, a + block)
            assert not seg.plan(t_ns[s], vel[s], body_heading_rad=held[s]).turn.any()
    t, vel, t_in, _ = _racetrack()
    t_ns = (10**18 + np.round(t * 1e9)).astype(np.int64)
    first = ReferenceTrack.from_velocity(np.zeros(3), vel[0], int(t_ns[0]))
    body = np.arctan2(vel[:, 1], vel[:, 0]) + np.radians(6.0)
    with_body = Segmenter(LIMITS, first, "right").plan(t_ns, vel, body_heading_rad=body).turn
    np.testing.assert_array_equal(with_body, Segmenter(LIMITS, first, "right").plan(t_ns, vel).turn)
    assert t_in < t[np.argmax(with_body)] < t_in + 1.0
