"""Fast factorised backprojection (FFBP) onto a plane grid, its factorisation set by a phase budget.

The form of Ulander, Hellsten & Stenström (IEEE TAES 39(3), 2003): the pulses are merged
``m`` at a time into subapertures, stage after stage; each subaperture ``A`` (centre
``c_A``: mid along-track position, mean cross-track position and height of its pulses) holds
a polar subimage ``V_A(r, α)`` of the grid's region, ``r`` the slant range from ``c_A`` and
``α`` the direction cosine along the grid's axis 0. A polar sample stands for the point
``p`` on the grid's plane with ``|p - c_A| = r`` and ``(p - c_A)·e0 = r α`` on the grid's
side of ``c_A``. The subimages are kept with the phase of their centre's range removed:

    V_A(r, α) = sum_{s in A} rc_s(R_s(p) - R_ref,s) exp(+j k (R_s(p) - R_ref,s - r)),
    k = 4 pi / lambda,

so that ``V_A`` is basebanded in ``r`` (sampled at the range step of the lines, then FFT
upsampled) and band-limited in ``α`` by the subaperture length ``L_A``. A merge reads each
child at the point of the parent's sample, ``V_B(r, α) = sum_A V_A(r_A, α_A)
exp(+j k (r_A - r))``, and the last stage is projected onto the pixels,
``I(x) = sum_A V_A(r_A(x), α_A(x)) exp(+j k r_A(x))``: with no approximation this is the
direct backprojection (:mod:`~sarmoco.processing.imaging.backprojection`) term for term.
The per-pulse parts of the direct path (range-axis limits, beam culling, the eq. 29 squint
residual) are applied in the first stage at the polar sample's point.

Error budget. Reading a child at the nearest angle sample, ``|δα| <= Δα / 2``, misplaces the
point by a path length ``s δα`` for a pulse at along-track offset ``s`` from the child's
centre, ``|s| <= L / 2``: a two-way phase error of at most ``k L Δα / 4 = pi L Δα / lambda``.
Every stage is read once (by its parent or by the pixels), so with ``n`` stages and a total
budget ``φ`` the angle step of a stage of (largest) length ``L`` is

    Δα = (φ / n) lambda / (pi L),

an angular oversampling of ``pi / (φ / n)`` over the Nyquist step ``lambda / (2 L)`` (a
coarse factorisation at UAV ranges, where the tile spans many such steps, loses sidelobe
level quickly). Linear interpolation in angle (``angle_order`` 1) keeps within the same
bound. The number of stages and the merge factor are then the cheapest (operation count of
the stages, the range upsampling and the projection) among those the pulses allow
(:func:`plan_factorisation`); when none beats the direct sum, the direct kernel runs.

Kernels: numba, one per stage shape (pulses to polar, polar to polar, polar to pixels),
parallel over output rows, geometry and phase in float64, samples complex64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.backprojection import (
    RangeLines,
    WarmUpScene,
    _sincos,
    backproject_into,
    pulse_geometry,
    thread_scratch,
)
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.interp import fft_upsample
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray

GRID_SCRATCH_TYPES = (np.float64, np.float64, np.float32, np.float32)
"""The last stage's scratch per column: range and angle position, cosine and sine."""

MERGE_FACTORS = (2, 3, 4)
"""Subapertures merged per stage that the planner considers."""

RANGE_PAD = 8
"""Range samples added on each side of a polar subimage (FFT wrap and interpolation reach)."""

ANGLE_PAD = 3
"""Angle samples added on each side of a polar subimage (the parent's points near the edge)."""

RANGE_UPSAMPLE = 8
"""FFT upsampling of the polar subimages in range before linear interpolation."""

FFT_COST = 2.0
"""Cost of one upsampled sample of the range FFTs, in units of one interpolated sample."""


@dataclass(frozen=True)
class Factorisation:
    """How the pulses are merged.

    Parameters
    ----------
    merge : int
        Subapertures merged per stage (>= 2).
    stages : int
        Number of merge stages (0: direct backprojection).
    stage_phase_rad : float
        Bound on the two-way phase error of reading one stage's subimages, rad.
    angle_order : int
        Interpolation in angle: 0 nearest sample, 1 linear.
    """

    merge: int
    stages: int
    stage_phase_rad: float
    angle_order: int = 1

    def __post_init__(self) -> None:
        if self.merge < 2 or self.stages < 0 or self.angle_order not in (0, 1):
            raise ProcessingError(f"Factorisation: {self} (merge >= 2, stages >= 0, order 0/1)")
        if not 0.0 < self.stage_phase_rad < math.pi:
            raise ProcessingError(
                f"Factorisation.stage_phase_rad: {self.stage_phase_rad!r} is not in (0, pi)"
            )


@dataclass(frozen=True)
class _Level:
    """Polar subimages of one stage: centres, sampling, and their samples.

    ``geo[A] = (u, w, h^2)`` of the centre in grid coordinates; sample ``(a, i)`` of
    subimage ``A`` is at ``α = alpha0[A] + a d_alpha``, ``r = r0[A] + i dr`` (m).
    ``data`` has shape (n_sub, n_alpha, n_r) complex64; ``length_m`` is the largest
    along-track extent of a subimage's pulses.
    """

    geo: FloatArray
    alpha0: FloatArray
    d_alpha: float
    r0: FloatArray
    dr: float
    data: ComplexArray
    length_m: float


@numba.njit(cache=True, inline="always")
def _ground_point(
    cu: float, cw: float, ch2: float, side: float, r: float, alpha: float
) -> tuple[float, float, bool]:  # pragma: no cover - compiled
    """Grid coordinates (u, w) of the polar sample (r, α) of a centre, and whether it exists."""
    g2 = r * r * (1.0 - alpha * alpha) - ch2
    if g2 < 0.0:
        return 0.0, 0.0, False
    return cu + r * alpha, cw + side * np.sqrt(g2), True


@numba.njit(cache=True, inline="always")
def _read(
    v: ComplexArray,
    a_pos: float,
    r_pos: float,
    order: int,
) -> tuple[float, float, bool]:  # pragma: no cover - compiled
    """Sample a polar subimage ``v[a, i]`` at fractional (angle, range) indices.

    Linear in range; nearest (``order`` 0) or linear (1) in angle. Outside: not found.
    """
    n_a, n_r = v.shape
    if r_pos < 0.0 or r_pos > n_r - 1.0 or a_pos < 0.0 or a_pos > n_a - 1.0:
        return 0.0, 0.0, False
    i = min(int(r_pos), n_r - 2)
    f = r_pos - i
    if order == 0:
        a = int(a_pos + 0.5)
        lo, hi = v[a, i], v[a, i + 1]
        return lo.real + f * (hi.real - lo.real), lo.imag + f * (hi.imag - lo.imag), True
    a = min(int(a_pos), n_a - 2)
    g = a_pos - a
    p, q = v[a, i], v[a, i + 1]
    s, t = v[a + 1, i], v[a + 1, i + 1]
    re0, im0 = p.real + f * (q.real - p.real), p.imag + f * (q.imag - p.imag)
    re1, im1 = s.real + f * (t.real - s.real), s.imag + f * (t.imag - s.imag)
    return re0 + g * (re1 - re0), im0 + g * (im1 - im0), True


@numba.njit(parallel=True, nogil=True, cache=True, fastmath=True)
def _pulses_to_polar(
    line: ComplexArray,
    r_first: float,
    dr_line: float,
    geo: FloatArray,
    first: IntArray,
    cgeo: FloatArray,
    alpha0: FloatArray,
    d_alpha: float,
    r0: FloatArray,
    dr: float,
    side: float,
    k: float,
    cull: bool,
    squint: bool,
    out: ComplexArray,
) -> None:  # pragma: no cover - compiled
    """First stage: pulses ``first[B] .. first[B + 1] - 1`` into the polar subimage ``B``.

    ``geo[s] = (u, w, h^2, R_ref, k ΔY, t_lo, t_hi)`` of pulse ``s`` (rows of ``line``), as
    in the direct kernel; a pulse adds to a sample only when its range is on the range axis
    and (when ``cull``) the point is within its beam (``t_lo rho <= dx <= t_hi rho``,
    ``rho^2 = dy^2 + h^2``).
    """
    n_sub, n_a, n_r = out.shape
    n_bins = line.shape[1]
    for flat in numba.prange(n_sub * n_a):
        b, a = flat // n_a, flat % n_a
        alpha = alpha0[b] + a * d_alpha
        for i in range(n_r):
            r = r0[b] + i * dr
            pu, pw, ok = _ground_point(cgeo[b, 0], cgeo[b, 1], cgeo[b, 2], side, r, alpha)
            if not ok:
                continue
            acc_re = 0.0
            acc_im = 0.0
            for s in range(first[b], first[b + 1]):
                dx = pu - geo[s, 0]
                dy = pw - geo[s, 1]
                g2 = dy * dy + geo[s, 2]
                if cull:
                    rho = np.sqrt(g2)
                    if dx < geo[s, 5] * rho or dx > geo[s, 6] * rho:
                        continue
                rs = np.sqrt(dx * dx + g2)
                d_rel = rs - geo[s, 3]
                u = (d_rel - r_first) / dr_line
                if u < 0.0 or u > n_bins - 1.0:
                    continue
                j = min(int(u), n_bins - 2)
                f = u - j
                lo, hi = line[s, j], line[s, j + 1]
                v_re = lo.real + f * (hi.real - lo.real)
                v_im = lo.imag + f * (hi.imag - lo.imag)
                ph = k * (d_rel - r)
                if squint:
                    ph += geo[s, 4] * (np.sqrt(dx * dx + dy * dy) - dy) / rs
                c, sn = _sincos(ph)
                acc_re += v_re * c - v_im * sn
                acc_im += v_re * sn + v_im * c
            out[b, a, i] = complex(acc_re, acc_im)


@numba.njit(parallel=True, nogil=True, cache=True, fastmath=True)
def _merge(
    child: ComplexArray,
    c_geo: FloatArray,
    c_alpha0: FloatArray,
    c_d_alpha: float,
    c_r0: FloatArray,
    c_dr: float,
    first: IntArray,
    geo: FloatArray,
    alpha0: FloatArray,
    d_alpha: float,
    r0: FloatArray,
    dr: float,
    side: float,
    k: float,
    order: int,
    out: ComplexArray,
) -> None:  # pragma: no cover - compiled
    """Merge stage: children ``first[B] .. first[B + 1] - 1`` into the polar subimage ``B``.

    ``child`` has shape (n_children, n_alpha, n_r_upsampled), sampled at
    ``c_alpha0[A] + a c_d_alpha``, ``c_r0[A] + i c_dr``.
    """
    n_sub, n_a, n_r = out.shape
    for flat in numba.prange(n_sub * n_a):
        b, a = flat // n_a, flat % n_a
        alpha = alpha0[b] + a * d_alpha
        for i in range(n_r):
            r = r0[b] + i * dr
            pu, pw, ok = _ground_point(geo[b, 0], geo[b, 1], geo[b, 2], side, r, alpha)
            if not ok:
                continue
            acc_re = 0.0
            acc_im = 0.0
            for c in range(first[b], first[b + 1]):
                du = pu - c_geo[c, 0]
                dw = pw - c_geo[c, 1]
                rc = np.sqrt(du * du + dw * dw + c_geo[c, 2])
                a_pos = (du / rc - c_alpha0[c]) / c_d_alpha
                v_re, v_im, hit = _read(child[c], a_pos, (rc - c_r0[c]) / c_dr, order)
                if not hit:
                    continue
                ph = k * (rc - r)
                cs, sn = _sincos(ph)
                acc_re += float(v_re * cs - v_im * sn)
                acc_im += float(v_re * sn + v_im * cs)
            out[b, a, i] = complex(acc_re, acc_im)


@numba.njit(parallel=True, nogil=True, cache=True, fastmath=True)
def _polar_to_grid(
    child: ComplexArray,
    c_geo: FloatArray,
    c_alpha0: FloatArray,
    c_d_alpha: float,
    c_r0: FloatArray,
    c_dr: float,
    ax0: FloatArray,
    ax1: FloatArray,
    k: float,
    order: int,
    r_rows: FloatArray,
    a_rows: FloatArray,
    cosines: FloatArray,
    sines: FloatArray,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled
    """Last stage: add every polar subimage, read at each pixel, into ``out`` (in place).

    ``out`` is the float32 view (re/im interleaved) of the complex64 pixels. Per row and
    subimage a first loop computes the polar position and phase of every column
    (vectorised) into the calling thread's rows of ``r_rows``, ``a_rows``, ``cosines`` and
    ``sines`` (:func:`~sarmoco.processing.imaging.backprojection.thread_scratch`), a second
    one reads and accumulates.
    """
    n1 = ax1.shape[0]
    for i in numba.prange(ax0.shape[0]):
        thread = numba.get_thread_id()
        r_pos, a_pos = r_rows[thread], a_rows[thread]
        cos_ph, sin_ph = cosines[thread], sines[thread]
        for c in range(child.shape[0]):
            du = ax0[i] - c_geo[c, 0]
            base = du * du + c_geo[c, 2]
            for j in range(n1):
                dw = ax1[j] - c_geo[c, 1]
                rc = np.sqrt(base + dw * dw)
                a_pos[j] = (du / rc - c_alpha0[c]) / c_d_alpha
                r_pos[j] = (rc - c_r0[c]) / c_dr
                cs, sn = _sincos(k * rc)
                cos_ph[j] = cs
                sin_ph[j] = sn
            for j in range(n1):
                v_re, v_im, hit = _read(child[c], a_pos[j], r_pos[j], order)
                if hit:
                    out[i, 2 * j] += v_re * cos_ph[j] - v_im * sin_ph[j]
                    out[i, 2 * j + 1] += v_re * sin_ph[j] + v_im * cos_ph[j]


def _groups(n: int, merge: int) -> IntArray:
    """Boundaries ``first`` of consecutive groups of ``merge`` out of ``n`` (last one shorter)."""
    return np.append(np.arange(0, n, merge), n).astype(np.int64)


def _centres(geo: FloatArray, first: IntArray) -> tuple[FloatArray, float]:
    """Centres ``(u, w, h^2)`` of groups of points ``geo[:, :3]`` and their largest length in u.

    The centre's u is the middle of the group's u span, w and height are the group means.
    A group of ``n`` members spanning ``D`` stands for an aperture of length ``D n / (n - 1)``
    (each member covers one spacing: a pulse its pulse interval, a subaperture its length).
    """
    start, count = first[:-1], np.diff(first)
    lo = np.minimum.reduceat(geo[:, 0], start)
    hi = np.maximum.reduceat(geo[:, 0], start)
    w = np.add.reduceat(geo[:, 1], start) / count
    h = np.add.reduceat(np.sqrt(geo[:, 2]), start) / count
    length = (hi - lo) * count / np.maximum(count - 1, 1)
    return np.column_stack([(lo + hi) / 2.0, w, h**2]), float(np.max(length))


def _polar_extent(
    cgeo: FloatArray, box: tuple[float, float, float, float]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Smallest and largest (α, r) of the rectangle ``box = (u0, u1, w0, w1)`` seen from centres.

    On a rectangle beside the centre both are extreme at corners, except the nearest range
    (the rectangle's point nearest the centre).
    """
    u0, u1, w0, w1 = box
    cu, cw, ch2 = cgeo[:, 0:1], cgeo[:, 1:2], cgeo[:, 2:3]
    du = np.array([u0, u0, u1, u1])[None, :] - cu
    dw = np.array([w0, w1, w0, w1])[None, :] - cw
    r = np.sqrt(du**2 + dw**2 + ch2)
    alpha = du / r
    nu = np.clip(cu[:, 0], u0, u1) - cu[:, 0]
    nw = np.clip(cw[:, 0], w0, w1) - cw[:, 0]
    r_min = np.sqrt(nu**2 + nw**2 + ch2[:, 0])
    return alpha.min(axis=1), alpha.max(axis=1), r_min, r.max(axis=1)


def _sampling(
    cgeo: FloatArray,
    box: tuple[float, float, float, float],
    d_alpha: float,
    dr: float,
) -> tuple[FloatArray, FloatArray, int, int]:
    """Per-subimage first angle and range, and the common numbers of samples, of a stage."""
    a_lo, a_hi, r_lo, r_hi = _polar_extent(cgeo, box)
    alpha0 = a_lo - ANGLE_PAD * d_alpha
    r0 = r_lo - RANGE_PAD * dr
    n_a = int(np.ceil(np.max(a_hi - a_lo) / d_alpha)) + 2 * ANGLE_PAD + 1
    n_r = int(np.ceil(np.max(r_hi - r_lo) / dr)) + 2 * RANGE_PAD + 1
    return alpha0, r0, n_a, n_r


def _stage_d_alpha(stage_phase_rad: float, wavelength_m: float, length_m: float) -> float:
    """Angle step whose nearest-sample phase error is ``stage_phase_rad`` (module docstring)."""
    return stage_phase_rad * wavelength_m / (math.pi * max(length_m, 1e-6))


def _stage_costs(
    geo: FloatArray,
    box: tuple[float, float, float, float],
    n_pixels: int,
    dr: float,
    wavelength_m: float,
    merge: int,
    stages: int,
    budget_rad: float,
) -> float:
    """Operation count of FFBP with these stages (interpolated samples; FFTs weighted)."""
    if stages == 0:
        return float("inf")
    cost = 0.0
    level_geo, n_children = geo, geo.shape[0]
    for stage in range(stages):
        first = _groups(n_children, merge)
        level_geo, length = _centres(level_geo, first)
        d_alpha = _stage_d_alpha(budget_rad / stages, wavelength_m, length)
        _, _, n_a, n_r = _sampling(level_geo, box, d_alpha, dr)
        n_sub = first.size - 1
        cost += n_children * n_a * n_r  # each child (or pulse) read once per sample
        cost += FFT_COST * n_sub * n_a * n_r * RANGE_UPSAMPLE
        n_children = n_sub
        if stage < stages - 1 and n_sub < 2:
            return float("inf")
    return cost + n_children * n_pixels


def _direct_cost(geo: FloatArray, grid: PlaneGrid, cull: bool) -> float:
    """Pulse-pixel pairs the direct kernel visits (beam culling at the grid's mid range)."""
    ax0, ax1 = np.asarray(grid.axis0_m), np.asarray(grid.axis1_m)
    if not cull:
        return float(geo.shape[0] * ax0.size * ax1.size)
    dw = float(np.mean(ax1)) - geo[:, 1]
    rho = np.sqrt(dw**2 + geo[:, 2])
    lo = np.maximum(geo[:, 0] + rho * geo[:, 5], ax0[0])
    hi = np.minimum(geo[:, 0] + rho * geo[:, 6], ax0[-1])
    rows = np.clip(hi - lo, 0.0, None) / abs(ax0[1] - ax0[0])
    return float(np.sum(rows) * ax1.size)


def plan_factorisation(
    geo: FloatArray,
    grid: PlaneGrid,
    dr_m: float,
    wavelength_m: float,
    budget_rad: float,
    cull: bool = False,
    angle_order: int = 1,
) -> Factorisation:
    """The cheapest factorisation whose phase error stays within ``budget_rad``.

    Parameters
    ----------
    geo : ndarray of float64, shape (P, 7)
        Pulses' APC in grid coordinates ``(u, w, h^2, R_ref, k ΔY, t_lo, t_hi)``
        (:class:`~sarmoco.processing.imaging.backprojection.PulseGeometry`), along-track order.
    grid : PlaneGrid
        Output pixels.
    dr_m : float
        Range step of the polar subimages (that of the range-compressed lines), m.
    wavelength_m : float
        Carrier wavelength, m.
    budget_rad : float
        Bound on the two-way phase error summed over the stages, rad (0 < budget < pi).
    cull : bool
        Beam culling of the direct kernel (columns 5 and 6 of ``geo``), for its cost.
    angle_order : int
        Interpolation order in angle (0 or 1).

    Returns
    -------
    Factorisation
        ``stages`` 0 when no factorisation is cheaper than the direct kernel.
    """
    if not 0.0 < budget_rad < math.pi:
        raise ProcessingError(f"plan_factorisation: budget {budget_rad!r} rad is not in (0, pi)")
    box = _box(grid)
    n_pixels = grid.axis0_m.size * grid.axis1_m.size
    best = Factorisation(2, 0, budget_rad, angle_order)
    best_cost = _direct_cost(geo, grid, cull)
    for merge in MERGE_FACTORS:
        stages = 1
        while merge**stages <= geo.shape[0] * merge:
            cost = _stage_costs(geo, box, n_pixels, dr_m, wavelength_m, merge, stages, budget_rad)
            if cost < best_cost:
                best, best_cost = (
                    Factorisation(merge, stages, budget_rad / stages, angle_order),
                    cost,
                )
            stages += 1
    return best


def _box(grid: PlaneGrid) -> tuple[float, float, float, float]:
    """The grid's pixels as a rectangle (u0, u1, w0, w1) in grid coordinates, m."""
    a0, a1 = np.asarray(grid.axis0_m), np.asarray(grid.axis1_m)
    return float(a0.min()), float(a0.max()), float(a1.min()), float(a1.max())


def _upsampled(level: _Level) -> _Level:
    """The level with its subimages FFT-upsampled in range by :data:`RANGE_UPSAMPLE`."""
    n_sub, n_a, n_r = level.data.shape
    up = fft_upsample(level.data.reshape(n_sub * n_a, n_r), RANGE_UPSAMPLE)
    return _Level(
        level.geo,
        level.alpha0,
        level.d_alpha,
        level.r0,
        level.dr / RANGE_UPSAMPLE,
        np.ascontiguousarray(up.reshape(n_sub, n_a, n_r * RANGE_UPSAMPLE), dtype=np.complex64),
        level.length_m,
    )


def ffbp_into(
    out: ComplexArray,
    lines: RangeLines,
    dr_m: float,
    apc_m: FloatArray,
    wavelength_m: float,
    grid: PlaneGrid,
    budget_rad: float,
    ref_range_m: FloatArray | None = None,
    pulses: IntArray | None = None,
    beam_half_angle_rad: float | None = None,
    compensated_dy_m: FloatArray | None = None,
    factorisation: Factorisation | None = None,
    beam_squint_rad: FloatArray | None = None,
) -> Factorisation:
    """Add the FFBP image of upsampled pulses to ``out`` in place.

    Arguments as :func:`~sarmoco.processing.imaging.backprojection.backproject_into`, plus:

    Parameters
    ----------
    dr_m : float
        Range step of the polar subimages, m: that of the range-compressed lines before
        upsampling (their samples are band-limited at this step).
    budget_rad : float
        Bound on the two-way phase error of the factorisation, rad (module docstring).
    factorisation : Factorisation, optional
        Force this factorisation instead of the one planned from ``budget_rad``.

    Returns
    -------
    Factorisation
        The one used (``stages`` 0: the direct kernel ran).
    """
    pg = pulse_geometry(
        "ffbp", out, lines, apc_m, wavelength_m, grid,
        ref_range_m, pulses, beam_half_angle_rad, compensated_dy_m, beam_squint_rad,
    )  # fmt: skip
    rows, k, cull = pg.rows, pg.k, pg.cull
    if rows.size == 0:
        return Factorisation(2, 0, budget_rad)
    order = np.argsort(pg.geo[rows, 0], kind="stable")
    geo = pg.geo[rows[order]]
    plan = factorisation or plan_factorisation(geo, grid, dr_m, wavelength_m, budget_rad, cull)
    if plan.stages == 0:
        backproject_into(
            out,
            lines,
            apc_m,
            wavelength_m,
            grid,
            ref_range_m,
            pulses=rows,
            beam_half_angle_rad=beam_half_angle_rad,
            compensated_dy_m=compensated_dy_m,
            beam_squint_rad=beam_squint_rad,
        )
        return plan
    box = _box(grid)
    side = 1.0 if (box[2] + box[3]) / 2.0 >= float(np.mean(geo[:, 1])) else -1.0
    if np.any((geo[:, 1] - box[2]) * (geo[:, 1] - box[3]) <= 0.0):
        raise ProcessingError("ffbp: an APC is above the grid's cross-track extent")
    line = np.ascontiguousarray(lines.data[rows[order]], dtype=np.complex64)
    first = _groups(rows.size, plan.merge)
    cgeo, length = _centres(geo, first)
    d_alpha = _stage_d_alpha(plan.stage_phase_rad, wavelength_m, length)
    alpha0, r0, n_a, n_r = _sampling(cgeo, box, d_alpha, dr_m)
    data = np.zeros((first.size - 1, n_a, n_r), np.complex64)
    _pulses_to_polar(
        line, lines.r_first_m, lines.dr_m, geo, first, cgeo, alpha0, d_alpha, r0, dr_m,
        side, k, cull, pg.squint, data,
    )  # fmt: skip
    level = _upsampled(_Level(cgeo, alpha0, d_alpha, r0, dr_m, data, length))
    for _ in range(plan.stages - 1):
        first = _groups(level.data.shape[0], plan.merge)
        cgeo, length = _centres(level.geo, first)
        d_alpha = _stage_d_alpha(plan.stage_phase_rad, wavelength_m, length)
        alpha0, r0, n_a, n_r = _sampling(cgeo, box, d_alpha, dr_m)
        data = np.zeros((first.size - 1, n_a, n_r), np.complex64)
        _merge(
            level.data, level.geo, level.alpha0, level.d_alpha, level.r0, level.dr,
            first, cgeo, alpha0, d_alpha, r0, dr_m, side, k, plan.angle_order, data,
        )  # fmt: skip
        level = _upsampled(_Level(cgeo, alpha0, d_alpha, r0, dr_m, data, length))
    _to_grid(level, grid, k, plan.angle_order, out)
    return plan


def _to_grid(level: _Level, grid: PlaneGrid, k: float, order: int, out: ComplexArray) -> None:
    """Add the last level's polar subimages to the pixels ``out`` of ``grid``
    (:func:`_polar_to_grid`, with each thread's scratch rows)."""
    r_rows, a_rows, cosines, sines = (
        thread_scratch(grid.axis1_m.size, t) for t in GRID_SCRATCH_TYPES
    )
    _polar_to_grid(
        level.data, level.geo, level.alpha0, level.d_alpha, level.r0, level.dr,
        np.asarray(grid.axis0_m, dtype=np.float64), np.asarray(grid.axis1_m, dtype=np.float64),
        k, order, r_rows, a_rows, cosines, sines, out.view(np.float32),
    )  # fmt: skip


def warm_up() -> None:
    """Compile :func:`ffbp_into`'s three kernels (or load them from numba's cache) by
    focusing :class:`~sarmoco.processing.imaging.backprojection.WarmUpScene` once in two
    stages, so that each kernel runs (the planner would pick the direct kernel for so few
    pulses; that one is :func:`~sarmoco.processing.imaging.backprojection.warm_up`'s).
    """
    s = WarmUpScene.make()
    ffbp_into(
        s.out, s.lines, 2.0 * s.lines.dr_m, s.apc_m, s.wavelength_m, s.grid, 0.3,
        pulses=np.flatnonzero(s.apc_m[:, 0] >= 0), beam_half_angle_rad=0.1,
        compensated_dy_m=np.zeros(4), factorisation=Factorisation(2, 2, 0.15),
    )  # fmt: skip
