"""Navigation samples to pulse times: Hermite position, consistent velocity, SLERP, gaps."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from sarmoco.errors import NavigationError
from sarmoco.processing.navinterp import (
    bracket,
    bridge_gap,
    integrate_velocity,
    interpolate_nav,
    slerp,
)
from sarmoco.processing.types import NavSamples
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.turbulence import TurbulenceDeviation

MS = 1_000_000  # ns


def _cubic(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cubic trajectory (Hermite reproduces it exactly) and its derivative."""
    c = np.array([[1.0, -2.0, 0.5], [60.0, 3.0, -0.2], [0.3, -1.5, 0.1], [-0.4, 0.2, 0.05]])
    tt = t_s[:, None]
    pos = c[0] + c[1] * tt + c[2] * tt**2 + c[3] * tt**3
    vel = c[1] + 2 * c[2] * tt + 3 * c[3] * tt**2
    return pos, vel


def _nav(t_ns: np.ndarray, with_pos: bool = True) -> NavSamples:
    pos, vel = _cubic((t_ns - t_ns[0]) * 1e-9)
    yaw = np.linspace(0.0, 0.6, t_ns.shape[0])
    quat = Rotation.from_euler("ZYX", np.stack([yaw, 0.1 * yaw, -0.2 * yaw], 1)).as_quat(
        scalar_first=True
    )
    return NavSamples(t_ns=t_ns, vel_ned=vel, quat=quat, pos_ned=pos if with_pos else None)


def test_hermite_reproduces_a_cubic_track_on_non_uniform_samples() -> None:
    rng = np.random.default_rng(4)
    nav_t = np.cumsum(rng.integers(3 * MS, 8 * MS, size=100)).astype(np.int64)
    pulses = np.sort(rng.integers(nav_t[0], nav_t[-1], size=1000)).astype(np.int64)
    out = interpolate_nav(_nav(nav_t), pulses, max_gap_ns=10 * MS)
    pos, vel = _cubic((pulses - nav_t[0]) * 1e-9)
    assert out.valid.all()
    np.testing.assert_allclose(out.pos_ned, pos, atol=1e-9)
    np.testing.assert_allclose(out.vel_ned, vel, atol=1e-9)
    exact = interpolate_nav(_nav(nav_t), nav_t, max_gap_ns=10 * MS)  # on the samples themselves
    np.testing.assert_allclose(exact.vel_ned, _nav(nav_t).vel_ned, atol=1e-12)


def test_without_position_velocity_is_integrated_and_interpolated_linearly() -> None:
    nav_t = np.arange(0, 500 * MS, 5 * MS, dtype=np.int64) + 7 * MS
    nav = _nav(nav_t, with_pos=False)
    start = np.array([5.0, 6.0, -700.0])
    integ = integrate_velocity(nav, start)
    assert integ.pos_ned is not None
    np.testing.assert_array_equal(integ.pos_ned[0], start)
    step = integ.pos_ned[1] - integ.pos_ned[0]
    np.testing.assert_allclose(step, 0.5 * (nav.vel_ned[0] + nav.vel_ned[1]) * 5e-3, atol=1e-12)
    pulses = np.arange(nav_t[0], nav_t[-1], 50_000, dtype=np.int64)  # 20 kHz
    out = interpolate_nav(nav, pulses, max_gap_ns=10 * MS, pos0_ned=start)
    for k in range(3):
        lin = np.interp(pulses, nav_t, nav.vel_ned[:, k])
        np.testing.assert_allclose(out.vel_ned[:, k], lin, atol=1e-10)
    # the velocity is the derivative of the interpolated position
    fd = np.diff(out.pos_ned, axis=0) / 50e-6
    mid = 0.5 * (out.vel_ned[1:] + out.vel_ned[:-1])
    np.testing.assert_allclose(fd, mid, atol=1e-6)


def test_slerp_halfway_and_shorter_arc() -> None:
    rots = Rotation.from_euler("ZYX", [[0.0, 0.1, 0.0], [1.2, -0.3, 0.4]])
    q = rots.as_quat(scalar_first=True)
    s = np.linspace(0.0, 1.0, 7)
    ref = Slerp([0.0, 1.0], rots)(s)
    for sign in (1.0, -1.0):  # q and -q are the same attitude
        got = Rotation.from_quat(
            slerp(np.tile(q[0], (7, 1)), np.tile(sign * q[1], (7, 1)), s), scalar_first=True
        )
        assert np.all((got * ref.inv()).magnitude() < 1e-12)
    same = slerp(q[:1], q[:1], np.array([0.3]))
    np.testing.assert_allclose(np.abs(np.sum(same * q[:1])), 1.0, atol=1e-15)


def test_gaps_and_unbracketed_pulses_are_flagged_or_raised() -> None:
    nav_t = np.arange(0, 200 * MS, 5 * MS, dtype=np.int64)
    keep = np.ones(nav_t.shape[0], dtype=bool)
    keep[20:24] = False  # a 25 ms gap from 95 to 120 ms
    nav_t = nav_t[keep]
    nav = _nav(nav_t)
    pulses = np.array([-1, 0, 50 * MS, 96 * MS, 119 * MS, 120 * MS, 195 * MS, 196 * MS])
    idx, valid = bracket(nav_t, pulses, 10 * MS)
    np.testing.assert_array_equal(valid, [False, True, True, False, False, True, True, False])
    assert nav_t[idx[3]] == 95 * MS
    out = interpolate_nav(nav, pulses, 10 * MS, strict=False)
    np.testing.assert_array_equal(out.valid, valid)
    assert np.isnan(out.pos_ned[~valid]).all() and np.isfinite(out.pos_ned[valid]).all()
    with pytest.raises(NavigationError, match="4 of 8 pulses"):
        interpolate_nav(nav, pulses, 10 * MS)
    ok = interpolate_nav(nav, pulses[1:3], 10 * MS)  # covered pulses pass strict mode
    assert ok.valid.all()
    wide = interpolate_nav(nav, pulses[1:-1], 30 * MS)  # a looser max gap bridges it
    assert wide.valid.all()
    one = interpolate_nav(
        NavSamples(nav_t[:1], nav.vel_ned[:1], nav.quat[:1]), pulses, 1, strict=False
    )
    assert not one.valid.any()
    with pytest.raises(NavigationError):
        bracket(nav_t[::-1], pulses, 10 * MS)


LAMBDA_KU_M = 0.02
BETA_RAD = np.arccos(100.0 / 900.0)  # ku-vehicle: 100 m height, 900 m slant range
LOS_NED = np.array([0.0, np.sin(BETA_RAD), np.cos(BETA_RAD)])


def _bridge_errors(gap_s: float, seed: int, start_s: float) -> tuple[float, float]:
    """Largest LOS error of the displacement integrated across a silence of ``gap_s`` in the
    simulator's turbulence (ku-vehicle: 0.3 m rms sway, corner 0.2 Hz; 200 Hz INS), m:
    from :func:`bridge_gap`, and from the chord of the two end velocities."""
    turbulence = TurbulenceDeviation(MotionSpec(kind="turbulence", seed=seed))
    t_ns = np.arange(0, round((start_s + gap_s + 1.0) * 1e9), 5 * MS, dtype=np.int64)
    a, b = round(start_s * 1e9), round((start_s + gap_s) * 1e9)
    t_ns = t_ns[(t_ns < a) | (t_ns >= b)]
    vel = turbulence(t_ns * 1e-9)[1] + [17.5, 0.0, 0.0]
    nav = NavSamples(t_ns, vel, np.tile([1.0, 0, 0, 0], (t_ns.size, 1)))
    i = int(np.searchsorted(t_ns, a)) - 1
    q = np.arange(t_ns[i], t_ns[i + 1], MS, dtype=np.int64)
    true_vel = turbulence(q * 1e-9)[1] + [17.5, 0.0, 0.0]
    got = bridge_gap(nav, i, q, 100 * MS)[0]
    chord = vel[i] + (vel[i + 1] - vel[i]) * ((q - t_ns[i]) / (t_ns[i + 1] - t_ns[i]))[:, None]
    err = [np.abs(np.cumsum((v - true_vel) @ LOS_NED) * 1e-3).max() for v in (got, chord)]
    return err[0], err[1]


def test_a_silence_is_bridged_from_both_ends_accelerations() -> None:
    """Across a 0.3 s INS silence in the simulator's turbulence the bridged velocity's LOS
    integral (what D_los becomes) stays within lambda/8 at Ku band (2.5 mm) in the median of
    12 silences, and the chord of the end velocities (linear interpolation) misses by more
    than 4x that. Prints the sweep over silence lengths behind ``ins.bridge_gap_s``."""
    for gap_s in (0.1, 0.2, 0.3, 0.4, 0.5, 1.0):
        errs = np.array([_bridge_errors(gap_s, seed, start) for seed in (1, 2, 3)
                         for start in (0.7, 1.9, 3.3, 4.6)])  # fmt: skip
        med = np.median(errs, axis=0) * 1e3
        print(f"silence {gap_s} s: median max |LOS error| bridged {med[0]:.2f} mm, "
              f"chord {med[1]:.2f} mm (lambda/8 = {LAMBDA_KU_M / 8 * 1e3:.2f} mm)")  # fmt: skip
        if gap_s == 0.3:
            assert med[0] < LAMBDA_KU_M / 8 * 1e3
            assert med[1] > 4 * med[0]


def test_a_bridge_meets_both_ends_positions() -> None:
    """With positions: the bridge starts at p0 and ends at p1 even where the velocities'
    integral does not reach p1 (the mismatch is spread over the silence)."""
    t_ns = np.array([0, 5, 10, 310, 315, 320], dtype=np.int64) * MS
    vel = np.tile([17.5, 0.0, 0.0], (6, 1))
    step = np.array([[0, 0, 0]] * 3 + [[0, 0.01, 0]] * 3)  # p1 1 cm east of the integral
    pos = np.outer(t_ns * 1e-9, [17.5, 0.0, 0.0]) + step
    nav = NavSamples(t_ns, vel, np.tile([1.0, 0, 0, 0], (6, 1)), pos)
    q = np.array([10, 160, 310], dtype=np.int64) * MS
    got_vel, got_pos = bridge_gap(nav, 2, q, 100 * MS)
    assert got_pos is not None
    np.testing.assert_allclose(got_pos, [[0.175, 0, 0], [2.8, 0.005, 0], [5.425, 0.01, 0]],
                               atol=1e-9)  # fmt: skip
    np.testing.assert_allclose(got_vel, vel[:3], atol=1e-9)
