"""INS-only per-pulse motion compensation (docs/methods.md §2, THz paper eqs. 14-32).

The APC deviation from the reference track is the trapezoidal integral of the
INS velocity (imaging frame y, z) over the actual pulse times::

    ΔY(1) = 0,   ΔY(k) = ΔY(k-1) + ½ (v_y(k-1) + v_y(k)) (t_k - t_{k-1})      (same for Z)
    d_los(k) = ΔY(k) sin β + ΔZ(k) cos β          (positive toward the scene)

The echo of pulse k carries exp(+j 4π d_los(k) / λ); compensation multiplies
by exp(-j 4π d_los(k) / λ). Because d_los is linear in (sin β, cos β) the
running state is the pair (ΔY, ΔZ), which also serves every range bin.

- ``order=1``: one β, the scene centre's, for all range bins.
- ``order=2``: β per range bin, cos β = H / r (r the bin's slant range): the
  displacement as a broadside point at that range sees it, to second order (the
  deviation across the line of sight squared over 2r is subtracted). Points seen under
  squint at the same range see the cross-track part differently (eq. 29); that
  residual is azimuth-variant in a stripmap, so the image former removes it per
  pixel (``compensated_dy_m`` of
  :func:`~sarmoco.processing.imaging.backprojection.backproject_into`).
- Envelope: where |d_los| at the scene centre exceeds ``envelope_fraction``
  of the range resolution cell, the pulse is resampled in range (linear phase
  in range frequency, sub-sample, zero-padded: what leaves the window is lost,
  never wrapped onto its other end) so that the range error
  ΔR = -d_los is removed: its content moves by +d_los toward far range.

Inputs are range-compressed pulses (P, S) whose bin i lies at slant range
``range_axis_m[i]``; times are GPS ns (``int64``); velocities NED m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.geometry import (
    ReferenceTrack,
    look_angle,
    vector_to_imaging,
)
from sarmoco.processing.phasor import phasor
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray, RadarParams

DEFAULT_ENVELOPE_FRACTION = 0.05
"""Default envelope threshold, in range cells: a pulse whose scene-centre |d_los| is below it
is left unshifted. The compressed peak read that far off keeps sinc(0.05) = 99.6 % of its
amplitude; at 0.25 cell it keeps 90 %, and in 0.3 m rms turbulence that 10 % amplitude
ripple over the aperture cost 0.1-0.3 dB of azimuth PSLR and widened the range IRW by 0.6 %
(ku-vehicle ×0.1, tests/daemon/test_envelope.py)."""


@dataclass(frozen=True)
class LosGeometry:
    """Radar and scene constants of the line-of-sight correction.

    Build it with :meth:`build`.

    Parameters
    ----------
    wavelength_m : float
        Carrier wavelength, m.
    range_axis_m : ndarray of float64, shape (S,)
        Slant range of each range-compressed bin (uniform spacing), m.
    range_cell_m : float
        Range resolution cell c / 2B, m (unit of ``envelope_fraction``).
    beta_c_rad : float
        Look angle of the scene centre, rad.
    beta_bins_rad : ndarray of float64, shape (S,)
        Look angle of each range bin (``order=2``; NaN-free), rad.
    scene_range_m : float
        Slant range of the scene centre, m.
    order : {1, 2}
        Scene-centre β (1) or β per bin (2).
    envelope_fraction : float or None
        Fraction of a range cell above which a pulse is shifted in range;
        None never shifts.
    """

    wavelength_m: float
    range_axis_m: FloatArray
    range_cell_m: float
    beta_c_rad: float
    beta_bins_rad: FloatArray
    scene_range_m: float
    order: Literal[1, 2]
    envelope_fraction: float | None

    @classmethod
    def build(
        cls,
        radar: RadarParams,
        range_axis_m: FloatArray,
        ground_depth_m: float,
        scene_range_m: float,
        *,
        order: Literal[1, 2] = 1,
        envelope_fraction: float | None = DEFAULT_ENVELOPE_FRACTION,
    ) -> LosGeometry:
        """Derive the look angles from flat ground at ``ground_depth_m`` below the track.

        Parameters
        ----------
        radar : RadarParams
            Carrier and bandwidth.
        range_axis_m : ndarray, shape (S,)
            Slant range of each compressed bin, m (uniform spacing).
        ground_depth_m : float
            Depth H of the flat ground below the reference track, m.
        scene_range_m : float
            Slant range of the scene centre, m.
        order, envelope_fraction
            See the class parameters.
        """
        axis = np.asarray(range_axis_m, dtype=np.float64)
        if axis.ndim != 1 or axis.shape[0] < 2:
            raise ProcessingError("LosGeometry: range_axis_m must be 1-D with >= 2 bins")
        step = np.diff(axis)
        if not np.allclose(step, step[0], rtol=1e-6, atol=0.0) or not step[0] > 0:
            raise ProcessingError("LosGeometry: range_axis_m is not uniform and increasing")
        if order not in (1, 2):
            raise ProcessingError(f"LosGeometry: order {order!r} is not 1 or 2")
        if envelope_fraction is not None and not envelope_fraction >= 0.0:
            raise ProcessingError(f"LosGeometry: envelope_fraction {envelope_fraction!r} < 0")
        beta_bins = look_angle(axis, ground_depth_m) if order == 2 else np.zeros(0)
        return cls(
            wavelength_m=radar.wavelength_m,
            range_axis_m=axis,
            range_cell_m=radar.range_resolution_m,
            beta_c_rad=float(look_angle(scene_range_m, ground_depth_m)),
            beta_bins_rad=beta_bins,
            scene_range_m=float(scene_range_m),
            order=order,
            envelope_fraction=envelope_fraction,
        )

    @property
    def bin_spacing_m(self) -> float:
        """Slant-range spacing of the compressed bins, m."""
        return float(self.range_axis_m[1] - self.range_axis_m[0])


@dataclass(frozen=True)
class MocompSolution:
    """Per-pulse motion solution, as the recorder stores it.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    disp_yz_m : ndarray of float64, shape (P, 2)
        APC deviation (ΔY, ΔZ) from the reference track, imaging frame, m.
    d_los_m : ndarray of float64, shape (P,)
        Line-of-sight displacement at the scene-centre look angle, m
        (positive toward the scene).
    phase_rad : ndarray of float64, shape (P,)
        Compensation phase at the scene centre, rad (the pulse was multiplied
        by exp(-j phase_rad); with ``order=2`` other bins got their own value).
    range_shift_m : ndarray of float64, shape (P,)
        Envelope shift applied toward far range, m (0 where none).
    """

    t_ns: IntArray
    disp_yz_m: FloatArray
    d_los_m: FloatArray
    phase_rad: FloatArray
    range_shift_m: FloatArray


def apply_delay(spec: ComplexArray, shift_bins: FloatArray) -> None:
    """Multiply spectra in place by exp(-j 2π f s) on the ``fftfreq(n)`` grid, per row.

    For even n the exponential is separable: bin ``m = a·B + b`` (and the negative
    half offset by -n/2) gets the product of a per-row coarse and fine table, so
    the cost is three in-place complex multiplies per element and no temporary,
    instead of a complex exponential per element (several times the cost of the
    FFT it multiplies). Table phases are reduced in float64 (:func:`phasor`).

    Parameters
    ----------
    spec : ndarray of complex64, shape (P, n), C-contiguous
        Spectra along axis 1 (FFT order), modified in place.
    shift_bins : ndarray of float64, shape (P,)
        Delay of each row, bins.
    """
    rows, n = spec.shape
    s = np.asarray(shift_bins, dtype=np.float64)[:, None]
    half = n // 2
    block = _separable_block(n)
    if block is None or not spec.flags.c_contiguous:
        spec *= phasor(-2.0 * np.pi * s * np.fft.fftfreq(n))
        return
    count = half // block
    view = spec.reshape(rows, 2, count, block)
    view *= phasor(-2.0 * np.pi * s * (np.arange(count) * block / n))[:, None, :, None]
    view *= phasor(-2.0 * np.pi * s * (np.arange(block) / n))[:, None, None, :]
    spec[:, half:] *= phasor(2.0 * np.pi * s * (half / n))


def _separable_block(n: int) -> int | None:
    """Fine-table length of :func:`apply_delay` for spectra of length n; None: no separable form."""
    half = n // 2
    block = 1 << max(0, round(0.5 * np.log2(max(half, 1))))
    return None if n % 2 or half % block else block


def shift_range(echo: ComplexArray, shift_bins: FloatArray) -> ComplexArray:
    """Delay each row by a fractional number of bins (toward higher index), without wrap.

    Band-limited (FFT) interpolation on a zero-padded window: the FFT is at least
    ``S + max|shift| + SHIFT_GUARD_BINS`` long, so what a shift moves past either end
    of the range window lands in the padding and is cut off (energy leaves the
    window instead of wrapping onto the other end). A row shifted by the whole
    window or more comes back as zeros.

    Parameters
    ----------
    echo : ndarray of complex, shape (P, S)
        Range-compressed pulses.
    shift_bins : ndarray of float64, shape (P,)
        Shift of each pulse in bins (positive: toward far range).
    """
    n = echo.shape[1]
    shift = np.asarray(shift_bins, dtype=np.float64)
    inside = np.abs(shift) < n
    out = np.zeros(echo.shape, dtype=echo.dtype)
    if not inside.any():
        return out
    every = bool(inside.all())
    rows, shift = (echo, shift) if every else (echo[inside], shift[inside])
    reach = int(np.ceil(np.abs(shift).max()))
    n_fft = _padded_length(n + reach + SHIFT_GUARD_BINS)
    spec = np.ascontiguousarray(scipy.fft.fft(rows, n_fft, axis=1), dtype=np.complex64)
    apply_delay(spec, shift)
    moved = scipy.fft.ifft(spec, axis=1, overwrite_x=True)[:, :n]
    if every:
        out[:] = moved
    else:
        out[inside] = moved
    return out


SHIFT_GUARD_BINS = 16
"""Zero padding beyond the largest shift in :func:`shift_range`, bins: room for the
sinc tails of a peak moved off the window's edge."""


def _padded_length(n: int) -> int:
    """Smallest fast FFT length >= n that :func:`apply_delay` handles with its separable tables."""
    m = int(scipy.fft.next_fast_len(n))
    while _separable_block(m) is None:
        m = int(scipy.fft.next_fast_len(m + 1))
    return m


def _bin_rotation(geom: LosGeometry, dy: FloatArray, dz: FloatArray) -> ComplexArray:
    """exp(-j (φ(p, r) - φ_c(p))) per pulse and bin (second order), (P, S) complex64.

    φ(p, r) = k d(p, r) with d(p, r) = ΔY_p sin β(r) + ΔZ_p cos β(r) - a_p(r)² / (2 r),
    a_p(r) = ΔY_p cos β(r) - ΔZ_p sin β(r) the deviation across the line of sight: the
    range change of a broadside point at r to second order. Near grazing a is mostly the
    vertical deviation: 1 m at 900 m gives 0.56 mm (0.35 rad in Ku band), and its change
    over an aperture (turbulence about a level track, up to ±1 m within a survey leg's
    segment) is a phase error of a few tenths of a rad (up to 0.7 dB of azimuth PSLR
    without the term). For a vertical deviation it holds under any squint (every point at
    range r is ``r² - H²`` from the track's nadir). The scene-centre linear part φ_c is applied
    per pulse in float64, so the per-bin difference is small (hundreds of rad at most)
    and float32 keeps it to ~1e-5 rad at a fraction of the cost of a float64 complex
    exponential.
    """
    k = 4.0 * np.pi / geom.wavelength_m
    sin_b, cos_b = np.sin(geom.beta_bins_rad), np.cos(geom.beta_bins_rad)
    f32 = np.float32
    dy32, dz32 = dy.astype(f32)[:, None], dz.astype(f32)[:, None]
    dphi = dy32 * (k * (sin_b - np.sin(geom.beta_c_rad))).astype(f32)
    dphi += dz32 * (k * (cos_b - np.cos(geom.beta_c_rad))).astype(f32)
    across = dy32 * cos_b.astype(f32) - dz32 * sin_b.astype(f32)
    dphi -= (k / (2.0 * geom.range_axis_m)).astype(f32) * across * across
    rot = np.empty(dphi.shape, dtype=np.complex64)
    rot.real = np.cos(dphi)
    rot.imag = np.sin(dphi)
    return np.conj(rot, out=rot)


def los_solution(t_ns: IntArray, disp_yz_m: FloatArray, geom: LosGeometry) -> MocompSolution:
    """The scene-centre D_los, its phase and the envelope shift of known APC deviations.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    disp_yz_m : ndarray of float64, shape (P, 2)
        APC deviation (ΔY, ΔZ) from the reference track, imaging frame, m.
    geom : LosGeometry
        Radar and scene constants.

    Returns
    -------
    MocompSolution
        ``range_shift_m`` is D_los where |D_los| exceeds ``geom.envelope_fraction`` of a
        range cell (0 elsewhere, and everywhere when that is None).
    """
    dy, dz = disp_yz_m[:, 0], disp_yz_m[:, 1]
    d_c = dy * np.sin(geom.beta_c_rad) + dz * np.cos(geom.beta_c_rad)
    shift_m = np.zeros_like(d_c)
    if geom.envelope_fraction is not None:
        rows = np.abs(d_c) > geom.envelope_fraction * geom.range_cell_m
        shift_m[rows] = d_c[rows]
    return MocompSolution(
        t_ns=np.asarray(t_ns, dtype=np.int64),
        disp_yz_m=np.asarray(disp_yz_m, dtype=np.float64),
        d_los_m=d_c,
        phase_rad=4.0 * np.pi / geom.wavelength_m * d_c,
        range_shift_m=shift_m,
    )


def remove_centre_phase(
    echo: ComplexArray, phase_rad: FloatArray, conjugate: bool = False
) -> ComplexArray:
    """Multiply each pulse by exp(-j phase): the first-order D_los phase, one scalar a pulse.

    A scalar per pulse commutes with range compression (linear, pulse by pulse), so it
    can be removed from raw echoes before slow-time presumming.

    Parameters
    ----------
    echo : ndarray of complex, shape (P, S)
        Pulses, raw or range-compressed.
    phase_rad : ndarray of float64, shape (P,)
        ``MocompSolution.phase_rad``, rad (computed in float64, applied in complex64).
    conjugate : bool
        The pulses are the conjugate of the baseband (raw I/Q of a receiver with
        ``radar.iq_conjugate``, conjugated by range compression): exp(+j phase) then.

    Returns
    -------
    ndarray of complex64, shape (P, S)
    """
    rot = phasor(phase_rad if conjugate else -np.asarray(phase_rad, dtype=np.float64))
    return np.asarray(echo, dtype=np.complex64) * rot[:, None]


def correct_los(
    echo: ComplexArray,
    t_ns: IntArray,
    disp_yz_m: FloatArray,
    geom: LosGeometry,
    centre_phase: bool = True,
) -> tuple[ComplexArray, MocompSolution]:
    """Apply the envelope shift and the phase of a known APC deviation.

    Parameters
    ----------
    echo : ndarray of complex, shape (P, S)
        Range-compressed pulses (bins on ``geom.range_axis_m``).
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    disp_yz_m : ndarray of float64, shape (P, 2)
        APC deviation (ΔY, ΔZ) from the reference track, imaging frame, m.
    geom : LosGeometry
        Radar and scene constants.
    centre_phase : bool
        Remove the scene-centre phase too (False: it was removed before range
        compression, :func:`remove_centre_phase`; the envelope and, with ``order=2``,
        the per-bin remainder are applied).

    Returns
    -------
    out : ndarray of complex64, shape (P, S)
        Compensated pulses.
    solution : MocompSolution
        What was applied.
    """
    if echo.ndim != 2 or echo.shape[0] != t_ns.shape[0] or disp_yz_m.shape != (t_ns.shape[0], 2):
        raise ProcessingError(
            f"correct_los: echo {echo.shape}, t_ns {t_ns.shape}, disp {disp_yz_m.shape} disagree"
        )
    if echo.shape[1] != geom.range_axis_m.shape[0]:
        raise ProcessingError(
            f"correct_los: {echo.shape[1]} range bins but the axis has {geom.range_axis_m.shape[0]}"
        )
    solution = los_solution(t_ns, disp_yz_m, geom)
    out: ComplexArray = np.asarray(echo, dtype=np.complex64)
    rows = np.flatnonzero(solution.range_shift_m)
    if rows.size:
        out = out.copy() if out is echo else out  # never write into the caller's array
        out[rows] = shift_range(out[rows], solution.range_shift_m[rows] / geom.bin_spacing_m)
    if geom.order == 2:
        rot = _bin_rotation(geom, disp_yz_m[:, 0], disp_yz_m[:, 1])
        if centre_phase:
            rot *= np.exp(-1j * solution.phase_rad).astype(np.complex64)[:, None]
        out = out * rot
    elif centre_phase:
        out = remove_centre_phase(out, solution.phase_rad)
    return out, solution


def displacement_from_positions(
    t_ns: IntArray, pos_ned: FloatArray, track: ReferenceTrack
) -> FloatArray:
    """APC deviation (ΔY, ΔZ) from known positions (the GPS/position-based baseline), (P, 2), m."""
    return track.deviation(t_ns, pos_ned)[:, 1:3]


@dataclass(frozen=True)
class LosState:
    """What the streaming compensator carries from one block to the next.

    Parameters
    ----------
    last_t_ns : int or None
        Time of the last pulse seen, GPS ns (None before the first pulse).
    last_vel_yz : ndarray, shape (2,)
        Imaging-frame (v_y, v_z) at that pulse, m/s.
    disp_yz_m : ndarray, shape (2,)
        Running (ΔY, ΔZ) at that pulse, m.
    """

    last_t_ns: int | None = None
    last_vel_yz: FloatArray = field(default_factory=lambda: np.zeros(2))
    disp_yz_m: FloatArray = field(default_factory=lambda: np.zeros(2))


def integrate_los(
    t_ns: IntArray, vel_yz: FloatArray, state: LosState
) -> tuple[FloatArray, LosState]:
    """Trapezoidal running (ΔY, ΔZ) over the actual pulse times (eqs. 30-31).

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, strictly increasing and after ``state.last_t_ns``, GPS ns.
    vel_yz : ndarray of float64, shape (P, 2)
        Imaging-frame (v_y, v_z) at each pulse, m/s.
    state : LosState
        Carried state (a fresh one starts the aperture: ΔD(1) = 0).

    Returns
    -------
    disp : ndarray of float64, shape (P, 2)
        (ΔY, ΔZ) at each pulse, m (of whatever point ``vel_yz`` is the velocity of).
    state : LosState
        State after the last pulse.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    if t.shape[0] == 0:
        return np.zeros((0, 2)), state
    first = state.last_t_ns is None
    t_prev = np.concatenate([[t[0] if first else state.last_t_ns], t]).astype(np.int64)
    v_prev = np.concatenate([vel_yz[:1] if first else state.last_vel_yz[None, :], vel_yz])
    dt_ns = np.diff(t_prev)
    if np.any(dt_ns[int(first) :] <= 0):
        raise ProcessingError("integrate_los: pulse times are not strictly increasing")
    inc = 0.5 * (v_prev[1:] + v_prev[:-1]) * (dt_ns * 1e-9)[:, None]
    disp = np.cumsum(inc, axis=0) + state.disp_yz_m
    new = LosState(
        last_t_ns=int(t[-1]),
        last_vel_yz=np.array(vel_yz[-1], dtype=np.float64),
        disp_yz_m=disp[-1].copy(),
    )
    return disp, new


class InsMotionCompensator:
    """Streaming INS-only compensation with explicit carried state.

    Feeding an aperture block by block gives the same output as one call on
    the whole aperture (to float tolerance), because the only coupling between
    pulses is the running (ΔY, ΔZ) sum and the last pulse's time and velocity,
    all held in :attr:`state`.

    The velocities given are those of the antenna phase centre (APC). An
    IMU-to-APC lever arm is not handled here: whoever turns INS samples into
    per-pulse navigation adds the rotated arm's rate to the IMU velocity once
    (the daemon's aligner), so that integrating the APC velocity gives the APC
    displacement, ``R(q_k) l - R(q_1) l`` included.

    Parameters
    ----------
    track : ReferenceTrack
        Reference track (rotation NED → imaging frame).
    geometry : LosGeometry
        Radar and scene constants.
    state : LosState, optional
        Resume from a saved state.
    """

    def __init__(
        self,
        track: ReferenceTrack,
        geometry: LosGeometry,
        state: LosState | None = None,
    ) -> None:
        self.track = track
        self.geometry = geometry
        self.state = LosState() if state is None else state

    def displacement(self, t_ns: IntArray, vel_ned: FloatArray) -> FloatArray:
        """(ΔY, ΔZ) of the APC at each pulse and advance the state, (P, 2), m.

        Parameters
        ----------
        t_ns : ndarray of int64, shape (P,)
            Pulse times, GPS ns.
        vel_ned : ndarray of float64, shape (P, 3)
            APC velocity interpolated to the pulses, NED, m/s.
        """
        vel_img = vector_to_imaging(vel_ned, self.track)
        disp, self.state = integrate_los(t_ns, vel_img[:, 1:3], self.state)
        return disp

    def compensate(
        self, echo: ComplexArray, t_ns: IntArray, vel_ned: FloatArray
    ) -> tuple[ComplexArray, MocompSolution]:
        """Compensate one block of range-compressed pulses and advance the state.

        Parameters
        ----------
        echo : ndarray of complex, shape (P, S)
            Range-compressed pulses.
        t_ns, vel_ned
            As in :meth:`displacement`.

        Returns
        -------
        out : ndarray of complex64, shape (P, S)
        solution : MocompSolution
        """
        disp = self.displacement(np.asarray(t_ns, dtype=np.int64), vel_ned)
        return correct_los(echo, np.asarray(t_ns, dtype=np.int64), disp, self.geometry)


def compensate_aperture(
    echo: ComplexArray,
    t_ns: IntArray,
    vel_ned: FloatArray,
    track: ReferenceTrack,
    geometry: LosGeometry,
) -> tuple[ComplexArray, MocompSolution]:
    """One-call INS-only compensation of a whole aperture (see :class:`InsMotionCompensator`)."""
    return InsMotionCompensator(track, geometry).compensate(echo, t_ns, vel_ned)
