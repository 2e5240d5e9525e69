"""Time-domain backprojection onto a plane grid (exact for any track).

For every pulse ``p`` and pixel ``x`` the range ``R = |apc_p - x|`` is computed
in float64, the range-compressed line is read at ``R - R_ref,p`` (FFT
upsampled, then linear interpolation) and the echo phase
``exp(-j 4 pi (R - R_ref,p) / lambda)`` (docs/methods.md §1) is removed:

    I(x) = sum_p  rc_p(R - R_ref,p) * exp(+j 4 pi (R - R_ref,p) / lambda)

``R_ref`` is zero for absolute range axes (the simulator's range compression)
and the per-pulse deramp range for data motion compensated to a reference
point (AFRL GOTCHA). Pixels whose range falls outside the range axis get no
contribution from that pulse. Optionally a pulse contributes only to the pixels
it sees within its beam (beam culling): within a half-angle of broadside, or within a
per-pulse interval of squint ``[psi_lo, psi_hi]`` (a squinted beam, e.g. an antenna fixed
to a crabbed body), the squint ``psi`` of a pixel being the angle between the APC-to-pixel
line and the plane normal to the grid's axis 0 (``tan psi = dx / sqrt(dy^2 + h^2)``).

Squint residual of the per-bin motion compensation (eq. 29, docs/methods.md §2):
when the pulses were compensated per range bin for an APC displacement ``ΔY_p``
along the grid's axis 1 as a broadside point at that range sees it (projection
``ΔY_p sqrt(R^2 - h^2) / R``, ``h`` the APC's height over the plane), a pixel seen
under squint at ``(dx, dy)`` from the APC sees ``ΔY_p dy / R`` instead, so its echo
keeps ``exp(-j 4 pi ΔY_p (sqrt(dx^2 + dy^2) - dy) / (lambda R))`` after the compensation.
Given ``ΔY_p``, that phase is removed with the echo phase:

    I(x) = sum_p  rc_p(R - R_ref,p) * exp(+j 4 pi (R - R_ref,p + e_p) / lambda),
    e_p = ΔY_p (sqrt(dx^2 + dy^2) - dy) / R

(``4 pi ΔY_p psi^2 / (2 lambda sin beta)`` to second order in the squint ``psi``, beta the
look angle). A displacement normal to the plane needs no such term: its projection
``h / R`` is the same for every point at range ``R``.

Kernel: numba-compiled, parallel over blocks of rows (axis 0) of the grid, GIL
released; each block takes the pulses a few at a time (cache blocking,
``PULSE_BLOCK``). The grid is separable (``R^2 = dx^2 + dy^2 + h^2`` in the grid's
own axes), so for each row and pulse the pixels that the range axis and the beam
admit form at most two contiguous runs of columns, found in closed form; only
those are visited. Geometry and phase are float64 (the phase is reduced to a
quarter turn in float64 and then evaluated by float32 polynomials, error below
4e-7), interpolation and accumulation float32; output complex64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.interp import fft_upsample
from sarmoco.processing.types import ComplexArray, FloatArray, Image, IntArray

DEFAULT_UPSAMPLE = 8
"""Default range upsampling before linear interpolation (error ~0.3 % rms)."""

ROW_BLOCK = 8
PULSE_BLOCK = 4
"""The kernel's loop blocking: a parallel task takes ``ROW_BLOCK`` rows of the grid, and
gives them ``PULSE_BLOCK`` pulses at a time.

numba's threading layers split a ``prange`` into one contiguous run of tasks per thread,
whatever ``numba.set_parallel_chunksize`` says; a block of pulses lights only the rows
its beam covers (often one half of a tile), so the tasks take the row blocks
interleaved (:func:`task_order`): each thread gets every ``T``-th block.

A row reads the part of each pulse's upsampled line that its ranges span
(ku-vehicle: 130 kB of a 416 kB line); so the parts of a few pulses stay in a core's L2
cache while the task's rows all use them (and the rows' pixels stay there too), instead
of every pulse's line streaming from memory once per row.
"""


@dataclass(frozen=True)
class RangeLines:
    """Range-compressed pulses upsampled in range, ready for backprojection.

    Parameters
    ----------
    data : ndarray of complex64, shape (P, S * upsample)
        Upsampled lines, C-contiguous.
    r_first_m : float
        Range of sample 0, m (relative to the per-pulse reference range when one is used).
    dr_m : float
        Range step of the upsampled samples, m.
    """

    data: ComplexArray
    r_first_m: float
    dr_m: float

    @classmethod
    def upsample(
        cls, rc: ComplexArray, range_axis_m: FloatArray, factor: int = DEFAULT_UPSAMPLE
    ) -> RangeLines:
        """FFT-upsample range-compressed pulses by ``factor``.

        Parameters
        ----------
        rc : ndarray of complex, shape (P, S)
            Range-compressed, basebanded pulses; bin ``i`` at ``range_axis_m[i]``.
        range_axis_m : ndarray of float64, shape (S,)
            Uniformly spaced range of each bin, m.
        factor : int
            Upsampling factor (>= 1).
        """
        s = rc.shape[1]
        if range_axis_m.shape != (s,) or s < 2:
            raise ProcessingError(f"RangeLines: rc{rc.shape}, range axis {range_axis_m.shape}")
        up = fft_upsample(np.asarray(rc, dtype=np.complex64), factor)
        return cls(
            np.ascontiguousarray(up, dtype=np.complex64),
            float(range_axis_m[0]),
            float(range_axis_m[1] - range_axis_m[0]) / factor,
        )


@numba.njit(cache=True, fastmath=True, inline="always")
def _sincos(ph: float) -> tuple[np.float32, np.float32]:  # pragma: no cover - compiled
    """(cos ph, sin ph) in float32 for a float64 phase of any size, error < 4e-7.

    The phase is reduced in float64 to ``r`` in [-pi/4, pi/4] plus a quadrant,
    then Taylor polynomials of degree 7 (sin) and 8 (cos) in float32 are
    rotated by the quadrant. The quadrant stays a float and is applied by
    compare-and-select (no float-to-integer conversion, which AVX without
    AVX-512 cannot do on vectors), so a loop over phases vectorises.
    """
    t = ph * (2.0 / np.pi)
    n = np.floor(t + 0.5)
    r = np.float32((t - n) * (np.pi / 2.0))
    q = n - 4.0 * np.floor(n * 0.25)  # quadrant 0, 1, 2 or 3, as a float
    r2 = r * r
    s = r * (
        np.float32(1.0)
        + r2
        * (np.float32(-1.0 / 6.0) + r2 * (np.float32(1.0 / 120.0) + r2 * np.float32(-1.0 / 5040.0)))
    )
    c = np.float32(1.0) + r2 * (
        np.float32(-0.5)
        + r2
        * (
            np.float32(1.0 / 24.0)
            + r2 * (np.float32(-1.0 / 720.0) + r2 * np.float32(1.0 / 40320.0))
        )
    )
    swap = (q == 1.0) | (q == 3.0)
    cc = s if swap else c
    ss = c if swap else s
    cc = -cc if (q == 1.0) | (q == 2.0) else cc
    ss = -ss if q >= 2.0 else ss
    return cc, ss


@numba.njit(cache=True, inline="always")
def _span(
    lo: float, hi: float, a0: float, da: float, n: int
) -> tuple[int, int]:  # pragma: no cover - compiled
    """Half-open index range ``[j0, j1)`` of the samples ``a0 + j da`` within ``[lo, hi]``."""
    if da > 0:
        f0, f1 = np.ceil((lo - a0) / da), np.floor((hi - a0) / da) + 1.0
    else:
        f0, f1 = np.ceil((hi - a0) / da), np.floor((lo - a0) / da) + 1.0
    j0 = int(min(max(f0, 0.0), float(n)))
    j1 = int(min(max(f1, 0.0), float(n)))
    return j0, max(j0, j1)


@numba.njit(cache=True, fastmath=True, inline="always")
def _beam_dy2(
    dx: float, h2: float, t_lo: float, t_hi: float, cull: bool
) -> tuple[float, float, bool]:  # pragma: no cover - compiled
    """Bounds ``(lo2, hi2)`` on ``dy^2`` of the points at ``dx`` along axis 0 inside the beam
    ``t_lo rho <= dx <= t_hi rho`` (``rho^2 = dy^2 + h^2``, ``t_lo < t_hi`` tangents of the
    squint interval), and whether any is (no culling: every point)."""
    if not cull:
        return -h2, np.inf, True
    rho_lo, rho_hi = 0.0, np.inf
    if dx > 0.0:
        if t_hi <= 0.0:
            return 0.0, 0.0, False
        rho_lo = dx / t_hi
        if t_lo > 0.0:
            rho_hi = dx / t_lo
    elif dx < 0.0:
        if t_lo >= 0.0:
            return 0.0, 0.0, False
        rho_lo = dx / t_lo
        if t_hi < 0.0:
            rho_hi = dx / t_hi
    elif t_lo > 0.0 or t_hi < 0.0:
        return 0.0, 0.0, False
    return rho_lo * rho_lo - h2, rho_hi * rho_hi - h2, True


def task_order(n_rows: int, block: int) -> IntArray:
    """The row blocks of ``n_rows`` rows (``block`` rows each) in the order a ``prange``
    over them takes them: every ``T``-th block in turn (``T``: numba's threads), so that
    each thread's contiguous share of the tasks spans the whole grid.

    Parameters
    ----------
    n_rows : int
        Rows of the grid.
    block : int
        Rows per task.

    Returns
    -------
    ndarray of int64, shape (ceil(n_rows / block),)
        Task ``t`` takes the rows ``[order[t] * block, (order[t] + 1) * block)``.
    """
    n_blocks = -(-n_rows // block)
    threads = numba.get_num_threads()
    return np.concatenate([np.arange(k, n_blocks, threads) for k in range(threads)])


def thread_scratch(n: int, dtype: type[np.generic]) -> np.ndarray:
    """One scratch row of ``n`` elements for each thread of the coming ``prange``, for a
    parallel kernel's per-row intermediate results (``numba.get_thread_id()`` picks the
    row); each row padded to whole 64-byte cache lines so that no two threads write one.

    A kernel takes one such array per intermediate quantity, as its own argument: scratch
    allocated inside the ``prange`` body (which numba hoists out of the loop), or rows of
    one array shared by the quantities, left the direct kernel as slow on two threads as
    on one (docs/measurements/realtime.md, "Each thread's scratch in its own arrays").

    Parameters
    ----------
    n : int
        Elements the row needs.
    dtype : numpy scalar type
        Element type.

    Returns
    -------
    ndarray, shape (numba.get_num_threads(), n rounded up to 64 bytes), uninitialised
    """
    per_line = max(1, 64 // np.dtype(dtype).itemsize)
    padded = -(-max(n, 1) // per_line) * per_line
    return np.empty((numba.get_num_threads(), padded), dtype)


SCRATCH_TYPES = (np.int32, np.float32, np.float32, np.float32)
"""The direct kernel's scratch per column: range bin, its fraction, cosine and sine."""


@numba.njit(parallel=True, nogil=True, cache=True, fastmath=True)
def _bp_kernel(
    line: ComplexArray,
    rows: IntArray,
    order: IntArray,
    r_first: float,
    dr: float,
    geo: FloatArray,
    ax0: FloatArray,
    ax1: FloatArray,
    k: float,
    cull: bool,
    squint: bool,
    bins: IntArray,
    fracs: FloatArray,
    cosines: FloatArray,
    sines: FloatArray,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled
    """Accumulate the pulses ``rows`` of ``line`` into ``out`` (float32 view, re/im interleaved).

    ``geo[p]``: pulse ``p``'s ``(u, w, h^2, R_ref, k ΔY, t_lo, t_hi)`` (:class:`PulseGeometry`;
    ``k ΔY`` used when ``squint``, loop-invariant, so the compiler keeps a loop without it).
    A pixel takes the pulse when its range is on the range axis and (when ``cull``)
    ``t_lo rho <= dx <= t_hi rho``, ``rho = sqrt(dy^2 + h^2)``: bounds on ``dy^2``. Per row
    and pulse a first loop puts range bin, fraction and phase of the admitted columns in
    the thread's rows of ``bins``, ``fracs``, ``cosines``, ``sines`` (:func:`thread_scratch`;
    vectorised, :func:`_sincos`), a second one interpolates and accumulates. Task ``t`` owns
    the ``ROW_BLOCK`` rows of block ``order[t]``, given ``PULSE_BLOCK`` pulses at a time.
    """
    n_bins = line.shape[1]
    n0, n1 = ax0.shape[0], ax1.shape[0]
    a1_0 = ax1[0]
    da1 = (ax1[n1 - 1] - a1_0) / (n1 - 1)
    top = n_bins - 1.0 - 1e-6
    r_last = r_first + (n_bins - 1) * dr
    inv_dr = 1.0 / dr
    n_pulses = rows.shape[0]
    for task in numba.prange(order.shape[0]):
        first = order[task] * ROW_BLOCK
        thread = numba.get_thread_id()
        bin_, frac = bins[thread], fracs[thread]
        cos_ph, sin_ph = cosines[thread], sines[thread]
        for q0 in range(0, n_pulses, PULSE_BLOCK):
            for i in range(first, min(n0, first + ROW_BLOCK)):
                for q in range(q0, min(q0 + PULSE_BLOCK, n_pulses)):
                    p = rows[q]
                    w, h2, rref, k_dy = geo[p, 1], geo[p, 2], geo[p, 3], geo[p, 4]
                    dx = ax0[i] - geo[p, 0]
                    dx2 = dx * dx
                    base = dx2 + h2
                    lo2, hi2, seen = _beam_dy2(dx, h2, geo[p, 5], geo[p, 6], cull)
                    r_min = rref + r_first
                    if r_min > 0.0:
                        lo2 = max(lo2, r_min * r_min - base)
                    r_max = rref + r_last
                    hi2 = min(hi2, r_max * r_max - base)
                    if not seen or r_max <= 0.0 or hi2 < 0.0 or hi2 < lo2:
                        continue
                    d_max = np.sqrt(hi2)
                    d_min = np.sqrt(max(lo2, 0.0))
                    s0, e0 = _span(w - d_max, w - d_min, a1_0, da1, n1)
                    s1, e1 = _span(w + d_min, w + d_max, a1_0, da1, n1)
                    if s1 < s0:
                        s0, e0, s1, e1 = s1, e1, s0, e0
                    s1 = max(s1, e0)  # the runs meet at dy = 0 when d_min = 0
                    e1 = max(e1, s1)
                    for seg in range(2):
                        js, je = (s0, e0) if seg == 0 else (s1, e1)
                        for j in range(js, je):
                            dy = ax1[j] - w
                            r = np.sqrt(base + dy * dy)
                            d_rel = r - rref
                            u = min(max((d_rel - r_first) * inv_dr, 0.0), top)
                            b = np.floor(u)
                            bin_[j] = np.int32(b)
                            frac[j] = np.float32(u - b)
                            ph = k * d_rel
                            if squint:
                                ph += k_dy * (np.sqrt(dx2 + dy * dy) - dy) / r
                            c, s = _sincos(ph)
                            cos_ph[j] = c
                            sin_ph[j] = s
                        for j in range(js, je):
                            b = bin_[j]
                            f = frac[j]
                            lo, hi = line[p, b], line[p, b + 1]
                            v_re = lo.real + f * (hi.real - lo.real)
                            v_im = lo.imag + f * (hi.imag - lo.imag)
                            out[i, 2 * j] += v_re * cos_ph[j] - v_im * sin_ph[j]
                            out[i, 2 * j + 1] += v_re * sin_ph[j] + v_im * cos_ph[j]


@dataclass(frozen=True)
class PulseGeometry:
    """The checked arguments of a backprojection, as its kernels take them.

    Attributes
    ----------
    rows : ndarray of int64, shape (Q,)
        Rows of the lines (pulses) to use.
    geo : ndarray of float64, shape (P, 7)
        Per pulse (every row of the lines), in the grid's coordinates: the APC's offset
        from the grid origin along axis 0 ``u`` and axis 1 ``w`` (m), its squared height
        above the grid plane ``h^2`` (m²), the reference range ``R_ref`` (m),
        ``k ΔY`` (rad/m · m: the compensated displacement of eq. 29 times ``k``; 0 without)
        and the tangents of the beam's squint interval ``tan psi_lo``, ``tan psi_hi``.
    k : float
        Two-way wavenumber 4 pi / lambda, rad/m.
    cull : bool
        Beam culling (columns 5 and 6 of ``geo`` are used).
    squint : bool
        The eq. 29 squint residual is removed (``compensated_dy_m`` given).
    """

    rows: IntArray
    geo: FloatArray
    k: float
    cull: bool
    squint: bool


def pulse_geometry(
    caller: str,
    out: ComplexArray,
    lines: RangeLines,
    apc_m: FloatArray,
    wavelength_m: float,
    grid: PlaneGrid,
    ref_range_m: FloatArray | None,
    pulses: IntArray | None,
    beam_half_angle_rad: float | None,
    compensated_dy_m: FloatArray | None,
    beam_squint_rad: FloatArray | None = None,
) -> PulseGeometry:
    """Check the arguments of :func:`backproject_into` (or of a kernel that takes the
    same, e.g. :func:`~sarmoco.processing.imaging.ffbp.ffbp_into`) and turn them into
    the per-pulse geometry its kernels read.

    Raises
    ------
    ProcessingError
        Named after ``caller``: shapes that disagree with the lines, an accumulator that
        is not C-contiguous complex64 of the grid's shape, pulse indices out of range, a
        beam half-angle outside (0, pi/2), squint intervals not inside (-pi/2, pi/2) and
        increasing, both kinds of beam given, a ΔY that is not finite.
    """
    n_p = lines.data.shape[0]
    shape = (grid.axis0_m.size, grid.axis1_m.size)
    if apc_m.shape != (n_p, 3):
        raise ProcessingError(f"{caller}: {n_p} lines, apc {apc_m.shape}")
    if out.shape != shape or out.dtype != np.complex64 or not out.flags.c_contiguous:
        raise ProcessingError(f"{caller}: out {out.shape} {out.dtype}, not C {shape} complex64")
    ref = np.zeros(n_p) if ref_range_m is None else np.asarray(ref_range_m, dtype=np.float64)
    if ref.shape != (n_p,):
        raise ProcessingError(f"{caller}: ref_range_m shape {ref.shape} is not ({n_p},)")
    rows = np.arange(n_p) if pulses is None else np.asarray(pulses, dtype=np.int64)
    if rows.size and (rows.min() < 0 or rows.max() >= n_p):
        raise ProcessingError(f"{caller}: pulse indices outside 0..{n_p - 1}")
    tan_beam = np.zeros((n_p, 2))
    if beam_half_angle_rad is not None:
        if beam_squint_rad is not None:
            raise ProcessingError(f"{caller}: a beam half-angle and squint intervals both given")
        if not 0.0 < beam_half_angle_rad < np.pi / 2:
            raise ProcessingError(f"{caller}: beam half-angle {beam_half_angle_rad!r} rad")
        tan_beam[:] = np.tan(beam_half_angle_rad) * np.array([-1.0, 1.0])
    if beam_squint_rad is not None:
        squint = np.asarray(beam_squint_rad, dtype=np.float64)
        if squint.shape != (n_p, 2) or not (
            np.all(squint[:, 0] < squint[:, 1]) and np.all(np.abs(squint) < np.pi / 2)
        ):
            raise ProcessingError(
                f"{caller}: beam squint intervals {squint.shape} not ({n_p}, 2) increasing "
                "within (-pi/2, pi/2)"
            )
        tan_beam = np.tan(squint)
    k = 4.0 * np.pi / wavelength_m
    k_dy = np.zeros(n_p)
    if compensated_dy_m is not None:
        k_dy = k * np.asarray(compensated_dy_m, dtype=np.float64)
        if k_dy.shape != (n_p,) or not np.all(np.isfinite(k_dy)):
            raise ProcessingError(
                f"{caller}: compensated_dy_m shape {k_dy.shape} is not ({n_p},) or not finite"
            )
    e0, e1 = grid.unit_vectors
    d = np.asarray(apc_m, dtype=np.float64) - np.asarray(grid.origin_m, dtype=np.float64)
    geo = np.column_stack([d @ e0, d @ e1, d[:, 2] ** 2, ref, k_dy, tan_beam])
    cull = beam_half_angle_rad is not None or beam_squint_rad is not None
    return PulseGeometry(rows, geo, k, cull, compensated_dy_m is not None)


def backproject_into(
    out: ComplexArray,
    lines: RangeLines,
    apc_m: FloatArray,
    wavelength_m: float,
    grid: PlaneGrid,
    ref_range_m: FloatArray | None = None,
    pulses: IntArray | None = None,
    beam_half_angle_rad: float | None = None,
    compensated_dy_m: FloatArray | None = None,
    beam_squint_rad: FloatArray | None = None,
) -> None:
    """Add the backprojection of upsampled pulses to ``out`` in place.

    Parameters
    ----------
    out : ndarray of complex64, shape (grid.axis0_m.size, grid.axis1_m.size)
        C-contiguous accumulator, updated in place.
    lines : RangeLines
        Upsampled range-compressed pulses, P rows.
    apc_m : ndarray of float64, shape (P, 3)
        Antenna phase centre of each pulse, in the grid's frame, m.
    wavelength_m : float
        The ``lambda`` of the echo phase ``exp(-j 4 pi R / lambda)``, m.
    grid : PlaneGrid
        Output pixels.
    ref_range_m : ndarray of float64, shape (P,), optional
        Per-pulse reference range that the range axis and phase are relative to, m.
    pulses : ndarray of int64, optional
        Rows of ``lines`` and ``apc_m`` to use (default all).
    beam_half_angle_rad : float, optional
        Beam culling: a pixel takes a pulse only when its squint, the angle
        between the APC-to-pixel line and the plane normal to the grid's axis 0,
        is at most this, rad (axis 0 is then the direction of flight). None: no culling.
    compensated_dy_m : ndarray of float64, shape (P,), optional
        APC displacement along the grid's axis 1 that each pulse was compensated for
        per range bin, as a broadside point sees it (docs/methods.md §2, second order),
        m. Given, every pixel gets its squint residual removed (eq. 29, module
        docstring); None: no such term.
    beam_squint_rad : ndarray of float64, shape (P, 2), optional
        Beam culling about a squinted beam: a pixel takes pulse ``p`` only when its
        squint (as for ``beam_half_angle_rad``) is within ``[lo_p, hi_p]``, rad (positive:
        ahead along axis 0). Not with ``beam_half_angle_rad``.
    """
    pg = pulse_geometry(
        "backproject", out, lines, apc_m, wavelength_m, grid,
        ref_range_m, pulses, beam_half_angle_rad, compensated_dy_m, beam_squint_rad,
    )  # fmt: skip
    bins, fracs, cosines, sines = (thread_scratch(len(grid.axis1_m), t) for t in SCRATCH_TYPES)
    _bp_kernel(
        lines.data,
        pg.rows,
        task_order(len(grid.axis0_m), ROW_BLOCK),
        lines.r_first_m,
        lines.dr_m,
        pg.geo,
        np.asarray(grid.axis0_m, dtype=np.float64),
        np.asarray(grid.axis1_m, dtype=np.float64),
        pg.k,
        pg.cull,
        pg.squint,
        bins,
        fracs,
        cosines,
        sines,
        out.view(np.float32),
    )


def backproject(
    rc: ComplexArray,
    range_axis_m: FloatArray,
    apc_m: FloatArray,
    wavelength_m: float,
    grid: PlaneGrid,
    ref_range_m: FloatArray | None = None,
    upsample: int = DEFAULT_UPSAMPLE,
) -> Image:
    """Backproject range-compressed pulses onto ``grid``.

    Parameters
    ----------
    rc : ndarray of complex, shape (P, S)
        Range-compressed pulses, basebanded; bin ``i`` is at range
        ``range_axis_m[i]`` (relative to ``ref_range_m`` when given).
    range_axis_m : ndarray of float64, shape (S,)
        Uniformly spaced range of each bin, m.
    apc_m : ndarray of float64, shape (P, 3)
        Antenna phase centre of each pulse, in the grid's frame, m.
    wavelength_m : float
        The ``lambda`` of the echo phase ``exp(-j 4 pi R / lambda)``, m.
    grid : PlaneGrid
        Output pixels.
    ref_range_m : ndarray of float64, shape (P,), optional
        Per-pulse reference range that the range axis and phase are relative to, m.
    upsample : int
        FFT upsampling of each line before linear interpolation.

    Returns
    -------
    Image
        complex64 pixels, axes and frame from ``grid``.
    """
    if apc_m.shape != (rc.shape[0], 3):
        raise ProcessingError(f"backproject: rc{rc.shape}, apc {apc_m.shape}")
    lines = RangeLines.upsample(rc, np.asarray(range_axis_m, dtype=np.float64), upsample)
    out = np.zeros((grid.axis0_m.size, grid.axis1_m.size), dtype=np.complex64)
    backproject_into(out, lines, apc_m, wavelength_m, grid, ref_range_m)
    return Image(
        out,
        np.asarray(grid.axis0_m, dtype=np.float64),
        np.asarray(grid.axis1_m, dtype=np.float64),
        grid.frame,
    )


@dataclass(frozen=True)
class WarmUpScene:
    """A tiny image (4 pulses, 4 x 4 pixels) that the kernels' warm-ups focus.

    Its arrays have the dtypes, dimensions and layouts the real calls pass
    (:meth:`TileImager <sarmoco.processing.imaging.tiles.TileImager>`'s), so numba
    compiles, or loads from its cache, the one specialisation those calls use.
    """

    out: ComplexArray
    lines: RangeLines
    apc_m: FloatArray
    grid: PlaneGrid
    wavelength_m: float = 0.02

    @classmethod
    def make(cls) -> WarmUpScene:
        """The scene: a 4 x 4 grid of 0.1 m pixels 10 m to the side of 4 pulses 5 m up."""
        grid = PlaneGrid(0.1 * np.arange(4.0), 10.0 + 0.1 * np.arange(4.0))
        apc = np.column_stack([0.1 * np.arange(4.0), np.zeros(4), np.full(4, 5.0)])
        rc = np.ones((4, 8), np.complex64)
        lines = RangeLines.upsample(rc, 10.0 + 0.05 * np.arange(8.0), 2)
        return cls(np.zeros((4, 4), np.complex64), lines, apc, grid)


def warm_up() -> None:
    """Compile :func:`backproject_into`'s kernel (or load it from numba's cache) by
    focusing :class:`WarmUpScene` once with every option a real call uses.

    numba compiles at a kernel's first call: seconds on an idle board, tens of seconds
    under load. The daemon calls this before it reads its links (``sarmoco run``).
    """
    s = WarmUpScene.make()
    backproject_into(
        s.out, s.lines, s.apc_m, s.wavelength_m, s.grid, pulses=np.flatnonzero(s.apc_m[:, 0] >= 0),
        beam_half_angle_rad=0.1, compensated_dy_m=np.zeros(4),
    )  # fmt: skip
