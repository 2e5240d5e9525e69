"""Navigation samples interpolated to pulse times (docs/design.md §4, time base).

Position: cubic Hermite between the two bracketing samples using the INS
velocity as the end-point derivatives (local, so it streams: a pulse needs
only the sample before and the sample after it). Velocity: the derivative of
that same Hermite cubic, so position and velocity stay consistent, or (for an
INS's own positions, whose updates and stamp quantisation the derivative would
amplify) the samples' velocity interpolated linearly; when the positions are
the trapezoidal integral of the velocities (an INS-only stream, see
:func:`integrate_velocity`) the two are the same. Attitude: SLERP between the
bracketing quaternions.

A pulse is valid only when samples bracket it and the bracketing interval is
not longer than ``max_gap_ns``; gaps are flagged, never bridged silently (a caller bridges
a short silence with :func:`bridge_gap` and flags what it bridged).
All times are GPS ns (``int64``); positions NED m, velocities NED m/s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from sarmoco.errors import NavigationError
from sarmoco.processing.types import BoolArray, FloatArray, IntArray, NavSamples


@dataclass(frozen=True)
class PulseNav:
    """Navigation state at each pulse.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    pos_ned : ndarray of float64, shape (P, 3)
        Position, NED, m (NaN where not valid).
    vel_ned : ndarray of float64, shape (P, 3)
        Velocity, NED, m/s (NaN where not valid).
    quat : ndarray of float64, shape (P, 4)
        Attitude, scalar-first body-to-NED (NaN where not valid).
    valid : ndarray of bool, shape (P,)
        True where samples bracket the pulse within the allowed gap.
    """

    t_ns: IntArray
    pos_ned: FloatArray
    vel_ned: FloatArray
    quat: FloatArray
    valid: BoolArray


def integrate_velocity(nav: NavSamples, pos0_ned: FloatArray | None = None) -> NavSamples:
    """Positions from velocities by the trapezoid rule, starting at ``pos0_ned``.

    Parameters
    ----------
    nav : NavSamples
        Samples; their ``pos_ned`` (if any) is ignored.
    pos0_ned : ndarray, shape (3,), optional
        Position at ``nav.t_ns[0]``, NED, m (default zero: positions relative
        to the first sample).

    Returns
    -------
    NavSamples
        The same samples with ``pos_ned`` filled in.
    """
    start = np.zeros(3) if pos0_ned is None else np.asarray(pos0_ned, dtype=np.float64)
    dt = np.diff(nav.t_ns.astype(np.int64)) * 1e-9
    steps = 0.5 * (nav.vel_ned[1:] + nav.vel_ned[:-1]) * dt[:, None]
    pos = np.empty_like(nav.vel_ned, dtype=np.float64)
    pos[0] = start
    np.cumsum(steps, axis=0, out=pos[1:])
    pos[1:] += start
    return NavSamples(t_ns=nav.t_ns, vel_ned=nav.vel_ned, quat=nav.quat, pos_ned=pos)


def bracket(nav_t_ns: IntArray, t_ns: IntArray, max_gap_ns: int) -> tuple[IntArray, BoolArray]:
    """Index of the sample before each pulse, and whether the pulse is covered.

    Parameters
    ----------
    nav_t_ns : ndarray of int64, shape (N,)
        Sample times, strictly increasing, GPS ns.
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    max_gap_ns : int
        Longest sample interval that may be interpolated across, ns.

    Returns
    -------
    idx : ndarray of int64, shape (P,)
        ``i`` with ``nav_t_ns[i] <= t < nav_t_ns[i + 1]`` (clipped to ``[0, N - 2]``).
    valid : ndarray of bool, shape (P,)
        Bracketed and the interval is at most ``max_gap_ns``.
    """
    nt = np.asarray(nav_t_ns, dtype=np.int64)
    t = np.asarray(t_ns, dtype=np.int64)
    if nt.shape[0] < 2:
        return np.zeros(t.shape[0], dtype=np.int64), np.zeros(t.shape[0], dtype=bool)
    if np.any(np.diff(nt) <= 0):
        raise NavigationError("navigation sample times are not strictly increasing")
    idx = np.clip(np.searchsorted(nt, t, side="right") - 1, 0, nt.shape[0] - 2).astype(np.int64)
    valid = (t >= nt[0]) & (t <= nt[-1]) & (nt[idx + 1] - nt[idx] <= max_gap_ns)
    return idx, valid


def slerp(q0: FloatArray, q1: FloatArray, s: FloatArray) -> FloatArray:
    """Spherical linear interpolation of unit quaternions, row by row.

    Parameters
    ----------
    q0, q1 : ndarray, shape (P, 4)
        End quaternions (scalar first); the shorter arc is taken.
    s : ndarray, shape (P,)
        Fraction from q0 (0) to q1 (1).
    """
    a = q0 / np.linalg.norm(q0, axis=1, keepdims=True)
    b = q1 / np.linalg.norm(q1, axis=1, keepdims=True)
    dot = np.sum(a * b, axis=1)
    b = np.where((dot < 0.0)[:, None], -b, b)
    dot = np.clip(np.abs(dot), -1.0, 1.0)
    theta = np.arccos(dot)
    sin_t = np.sin(theta)
    small = sin_t < 1e-9
    safe = np.where(small, 1.0, sin_t)
    w0 = np.where(small, 1.0 - s, np.sin((1.0 - s) * theta) / safe)
    w1 = np.where(small, s, np.sin(s * theta) / safe)
    q = w0[:, None] * a + w1[:, None] * b
    return np.asarray(q / np.linalg.norm(q, axis=1, keepdims=True), dtype=np.float64)


def interpolate_nav(
    nav: NavSamples,
    t_ns: IntArray,
    max_gap_ns: int,
    *,
    strict: bool = True,
    pos0_ned: FloatArray | None = None,
    velocity: Literal["positions", "samples"] = "positions",
) -> PulseNav:
    """Navigation state at pulse times.

    Parameters
    ----------
    nav : NavSamples
        Samples on the GPS time base. Without ``pos_ned`` the velocity is
        integrated first (:func:`integrate_velocity` from ``pos0_ned``).
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns (any order).
    max_gap_ns : int
        Longest sample interval that may be interpolated across, ns.
    strict : bool
        Raise on any uncovered pulse (True), or return NaN there with
        ``valid`` False (False).
    pos0_ned : ndarray, shape (3,), optional
        Start position for the integration when ``nav`` has no position, NED, m.
    velocity : {"positions", "samples"}
        ``"positions"``: the derivative of the position cubic (consistent with the
        position; right for exact tracks such as the rotated lever arm). ``"samples"``: the
        samples' own velocity, interpolated linearly: an aided INS's positions carry its
        position updates and stamps quantised to its clock (MAVLink: 1 ms, 17 mm along
        track at 17 m/s), which the cubic's derivative over a 10 ms interval turns into
        m/s; its velocity carries neither. The same when the positions are the velocity's
        trapezoidal integral.

    Raises
    ------
    NavigationError
        ``strict`` and some pulse is not bracketed or falls in a gap longer
        than ``max_gap_ns``.
    """
    src = nav if nav.pos_ned is not None else integrate_velocity(nav, pos0_ned)
    assert src.pos_ned is not None
    t = np.asarray(t_ns, dtype=np.int64)
    idx, valid = bracket(src.t_ns, t, max_gap_ns)
    if strict and not np.all(valid):
        uncovered = t[~valid]
        raise NavigationError(
            f"{uncovered.shape[0]} of {t.shape[0]} pulses not covered by navigation "
            f"(first at {int(uncovered[0])} ns; samples span {int(src.t_ns[0])}.."
            f"{int(src.t_ns[-1])} ns, max gap {max_gap_ns} ns)"
        )
    n = src.t_ns.shape[0]
    if n < 2:
        nan3 = np.full((t.shape[0], 3), np.nan)
        return PulseNav(t, nan3, nan3.copy(), np.full((t.shape[0], 4), np.nan), valid)
    t_a = src.t_ns[idx].astype(np.int64)
    h_ns = src.t_ns[idx + 1].astype(np.int64) - t_a
    h = (h_ns * 1e-9)[:, None]
    s = ((t - t_a) / h_ns)[:, None]
    p0, p1 = src.pos_ned[idx], src.pos_ned[idx + 1]
    v0, v1 = src.vel_ned[idx], src.vel_ned[idx + 1]
    s2, s3 = s * s, s * s * s
    pos = (
        (2 * s3 - 3 * s2 + 1) * p0
        + (s3 - 2 * s2 + s) * h * v0
        + (-2 * s3 + 3 * s2) * p1
        + (s3 - s2) * h * v1
    )
    if velocity == "samples":
        vel = (1.0 - s) * v0 + s * v1
    else:
        vel = (
            (6 * s2 - 6 * s) * p0 / h
            + (3 * s2 - 4 * s + 1) * v0
            + (-6 * s2 + 6 * s) * p1 / h
            + (3 * s2 - 2 * s) * v1
        )
    quat = slerp(src.quat[idx], src.quat[idx + 1], s[:, 0])
    pos[~valid] = np.nan
    vel[~valid] = np.nan
    quat[~valid] = np.nan
    return PulseNav(t_ns=t, pos_ned=pos, vel_ned=vel, quat=quat, valid=valid)


def end_acceleration(t_ns: IntArray, vel: FloatArray, k: int, side: int, fit_ns: int) -> FloatArray:
    """Acceleration at sample ``k`` from a least-squares quadratic through the velocities
    within ``fit_ns`` on one side of it (the edge of a gap: the samples beyond are missing).

    Parameters
    ----------
    t_ns : ndarray of int64, shape (N,)
        Sample times, GPS ns, increasing.
    vel : ndarray, shape (N, 3)
        Velocities, NED, m/s.
    k : int
        The sample at the gap's edge.
    side : int
        -1: fit the samples at and before ``k`` (the gap follows); +1: at and after it.
    fit_ns : int
        Span of the fit, ns.

    Returns
    -------
    ndarray, shape (3,)
        d vel / dt at ``t_ns[k]``, NED, m/s²; NaN with fewer than three samples in the span.
    """
    t0 = int(t_ns[k])
    if side < 0:
        lo, hi = int(np.searchsorted(t_ns, t0 - fit_ns, side="left")), k + 1
    else:
        lo, hi = k, int(np.searchsorted(t_ns, t0 + fit_ns, side="right"))
    if hi - lo < 3:
        return np.full(3, np.nan)
    x = (t_ns[lo:hi].astype(np.int64) - t0) * 1e-9
    design = np.stack([np.ones_like(x), x, x * x], axis=1)
    coef = np.linalg.lstsq(design, vel[lo:hi], rcond=None)[0]
    return np.asarray(coef[1], dtype=np.float64)


def bridge_gap(
    nav: NavSamples, i: int, t_ns: IntArray, fit_ns: int
) -> tuple[FloatArray, FloatArray | None]:
    """Velocity (and position) across the gap between samples ``i`` and ``i + 1``.

    Over a gap of many sample periods the linear velocity of :func:`interpolate_nav`
    misses the motion's curvature (its error is ``v'' T² / 8``). Here the velocity is
    the cubic Hermite through both ends' velocities and accelerations
    (:func:`end_acceleration` over ``fit_ns`` of samples beyond each end): error of
    order ``v'''' T⁴ / 384``. Where an end has fewer than three samples to fit, its
    acceleration is the chord ``(v1 - v0) / T``.

    Parameters
    ----------
    nav : NavSamples
        Samples, GPS ns, NED.
    i : int
        Index of the sample before the gap.
    t_ns : ndarray of int64, shape (P,)
        Query times inside the gap, GPS ns.
    fit_ns : int
        Span of the acceleration fits, ns.

    Returns
    -------
    vel : ndarray, shape (P, 3)
        Velocity, NED, m/s.
    pos : ndarray, shape (P, 3), or None
        Without ``nav.pos_ned`` None. Else ``p0`` plus the integral of ``vel``, plus the
        share ``s = (t - t0) / T`` of what that integral misses of ``p1 - p0`` (so both
        ends' positions are met), NED, m.
    """
    t0, t1 = int(nav.t_ns[i]), int(nav.t_ns[i + 1])
    h = (t1 - t0) * 1e-9
    v0, v1 = nav.vel_ned[i], nav.vel_ned[i + 1]
    chord = (v1 - v0) / h
    a0 = end_acceleration(nav.t_ns, nav.vel_ned, i, -1, fit_ns)
    a1 = end_acceleration(nav.t_ns, nav.vel_ned, i + 1, +1, fit_ns)
    a0 = np.where(np.isnan(a0), chord, a0)
    a1 = np.where(np.isnan(a1), chord, a1)
    s = ((np.asarray(t_ns, dtype=np.int64) - t0) / (t1 - t0))[:, None]
    s2, s3 = s * s, s**3
    vel = (2 * s3 - 3 * s2 + 1) * v0 + (s3 - 2 * s2 + s) * h * a0
    vel += (-2 * s3 + 3 * s2) * v1 + (s3 - s2) * h * a1
    if nav.pos_ned is None:
        return vel, None

    def displacement(s: FloatArray) -> FloatArray:
        return h * (
            (s**4 / 2 - s**3 + s) * v0
            + (s**4 / 4 - 2 * s**3 / 3 + s**2 / 2) * h * a0
            + (-(s**4) / 2 + s**3) * v1
            + (s**4 / 4 - s**3 / 3) * h * a1
        )

    p0, p1 = nav.pos_ned[i], nav.pos_ned[i + 1]
    pos = p0 + displacement(s) + (p1 - p0 - displacement(np.ones((1, 1)))) * s
    return vel, pos
