"""Where the antenna's azimuth beam points, and the Doppler centroid it gives.

The antenna is fixed to the body. Its azimuth beam is a cone about the antenna's array
axis ``a`` (the direction of its along-track aperture): the beam centre is the set of
directions ``u`` with ``u · a = 0`` and a rectangular beam of two-way width θ holds those
with ``|asin(u · a)| <= θ/2``. Mounted broadside, ``a`` is body x; an antenna turned about
body z by a squint ψm (positive: the beam turns forward) has
``a = (cos ψm, -s sin ψm, 0)`` in body axes (x forward, y right, z down), ``s = +1``
looking right and ``-1`` looking left. Tilting the antenna down (its depression) turns it
about ``a`` and leaves the cone unchanged.

In the imaging frame of a straight reference track (x along track, y toward the
illuminated side, z down; docs/methods.md §1) a ground point at look angle β from the
vertical and squint ψ from the plane normal to the track is seen along
``u = (sin ψ, cos ψ sin β, cos ψ cos β)``. With ``a = (a_x, a_y, a_z)`` in that frame and
``G = a_y sin β + a_z cos β``, ``u · a = A sin(ψ + φ)`` (``A = sqrt(a_x² + G²)``,
``φ = atan2(G, a_x)``), so the beam centre is seen at squint ``ψc = -φ`` and the beam edges
at ``±asin(sin(θ/2) / A) - φ``. A body yawed by a crab ``c`` against the track (toward the
illuminated side) squints the beam backward by about ``asin(sin β tan c)``.

A point target at squint ψ has the Doppler frequency ``f = 2 v sin ψ / λ`` (echo phase
``exp(-j 4 π R / λ)``, R decreasing ahead of broadside): the beam centre gives the
Doppler centroid ``f_dc``, which a pulse rate below ``2 |f_dc|`` aliases.

The centroid is also measured from the echoes (:func:`accc_centroid_hz`): the
average cross-correlation coefficient of consecutive pulses (Madsen 1989) gives
``f_dc`` modulo the pulse rate; the ambiguity is the one that lands closest to the
centroid from the attitude (:func:`resolve_ambiguity`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.geometry import ReferenceTrack, quat_to_matrix, vector_to_imaging
from sarmoco.processing.types import ComplexArray, FloatArray


@dataclass(frozen=True)
class DopplerCentroid:
    """The Doppler centroid of one block of pulses, from the attitude and from the echoes.

    Attributes
    ----------
    t_ns : int
        Time of the block's first pulse, GPS ns.
    squint_rad : float
        Squint of the beam centre from the plane normal to the reference track at the
        reference look angle, from the attitude and the antenna mount, rad (positive: ahead).
    attitude_hz : float
        Doppler centroid from the attitude and the antenna mount, ``2 v0 sin ψ / λ``, Hz.
    echo_hz : float
        Doppler centroid measured from the block's motion-compensated echoes (ACCC), its
        ambiguity resolved with ``attitude_hz``, Hz (NaN: not measured).
    """

    t_ns: int
    squint_rad: float
    attitude_hz: float
    echo_hz: float


def array_axis_body(squint_rad: float, look_side: str) -> FloatArray:
    """Array axis of an antenna turned about body z by ``squint_rad`` (positive: the beam
    turns forward), body axes (x forward, y right, z down), unit vector (3,)."""
    s = 1.0 if look_side == "right" else -1.0
    return np.array([math.cos(squint_rad), -s * math.sin(squint_rad), 0.0])


def array_axis_imaging(
    quat: FloatArray, axis_body: FloatArray, track: ReferenceTrack
) -> FloatArray:
    """Mean array axis of pulses in the imaging frame of ``track``, levelled, unit vector (3,).

    The axis is taken horizontal (its NED down component dropped): the azimuth pointing
    comes from the heading of the array axis, as for an antenna levelled in pitch and
    roll. A body-fixed antenna pitched by θp also moves its ground squint by about
    ``-θp cos β``; that, and the attitude's motion, is what the squint tolerance covers.

    Parameters
    ----------
    quat : ndarray, shape (P, 4)
        Attitude of each pulse, scalar-first body-to-NED quaternions (non-finite rows are
        left out).
    axis_body : ndarray, shape (3,)
        Array axis in body axes (:func:`array_axis_body`).
    track : ReferenceTrack
        The reference track whose imaging frame the axis is given in.

    Raises
    ------
    ProcessingError
        If no pulse has a finite, non-zero attitude.
    """
    q = np.asarray(quat, dtype=np.float64).reshape(-1, 4)
    q = q[np.all(np.isfinite(q), axis=1) & (np.linalg.norm(q, axis=1) > 0)]
    if q.shape[0] == 0:
        raise ProcessingError("array_axis_imaging: no pulse with an attitude")
    axis_ned = quat_to_matrix(q) @ np.asarray(axis_body, dtype=np.float64)
    level = axis_ned.mean(axis=0) * np.array([1.0, 1.0, 0.0])
    mean = vector_to_imaging(level[None, :], track)[0]
    return np.asarray(mean / np.linalg.norm(mean), dtype=np.float64)


def _phase(axis_img: FloatArray, look_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(A, φ) of the module docstring for the look angles ``look_rad``."""
    ax, ay, az = (float(v) for v in axis_img)
    g = ay * np.sin(look_rad) + az * np.cos(look_rad)
    return np.hypot(ax, g), np.arctan2(g, ax)


def centre_squint_rad(axis_img: FloatArray, look_rad: FloatArray | float) -> FloatArray:
    """Squint from the plane normal to the track at which the beam centre sees the ground
    at look angles ``look_rad`` (rad, from the vertical), rad (positive: ahead)."""
    _, phi = _phase(axis_img, np.asarray(look_rad, dtype=np.float64))
    return np.asarray(-phi, dtype=np.float64)


def squint_interval_rad(
    axis_img: FloatArray, half_rad: float, look_rad: FloatArray
) -> tuple[float, float]:
    """Squint interval (from the plane normal to the track) that the beam of half-width
    ``half_rad`` covers at every look angle of ``look_rad`` (rad), rad: (lo, hi).

    Raises
    ------
    ProcessingError
        If the beam does not meet the ground at a look angle (the array axis lies within
        ``half_rad`` of the line of sight).
    """
    amp, phi = _phase(axis_img, np.asarray(look_rad, dtype=np.float64))
    ratio = math.sin(half_rad) / amp
    if np.any(ratio >= 1.0):
        raise ProcessingError("squint_interval_rad: the beam is along the line of sight")
    edge = np.arcsin(ratio)
    return float(np.min(-edge - phi)), float(np.max(edge - phi))


PER_METRE = 1.0
"""The speed, m/s, at which a Doppler frequency in Hz (:func:`doppler_hz`,
:func:`squint_sine`) is an image's along-track spatial frequency in cycles/m."""


def doppler_hz(speed_mps: float, wavelength_m: float, squint_rad: FloatArray | float) -> FloatArray:
    """Doppler frequency ``2 v sin ψ / λ`` of a point seen at squint ``squint_rad``, Hz."""
    return np.asarray(
        2.0 * speed_mps * np.sin(np.asarray(squint_rad, dtype=np.float64)) / wavelength_m,
        dtype=np.float64,
    )


def squint_sine(
    doppler_hz: FloatArray | float, speed_mps: float, wavelength_m: float
) -> FloatArray:
    """``sin ψ = f λ / (2 v)``: the sine of the squint at which a point has Doppler
    ``doppler_hz`` (the inverse of :func:`doppler_hz`), unclipped; beyond ±1 no squint has
    that Doppler.

    Parameters
    ----------
    doppler_hz : float or ndarray of float64
        Doppler frequency, Hz.
    speed_mps, wavelength_m : float
        Along-track speed ``v`` (m/s) and wavelength ``λ`` (m).

    Returns
    -------
    ndarray of float64
        ``sin ψ``, ψ from the plane normal to the track (positive ahead), same shape.
    """
    return np.asarray(doppler_hz, dtype=np.float64) * (wavelength_m / (2.0 * speed_mps))


def within_band(
    intervals_rad: FloatArray, band_hz: FloatArray, speed_mps: float, wavelength_m: float
) -> FloatArray:
    """Squint intervals cut to the squints whose Doppler lies in a band.

    Parameters
    ----------
    intervals_rad : ndarray of float64, shape (P, 2)
        Squint intervals (low, high) from the plane normal to the track, rad.
    band_hz : ndarray of float64, shape (P, 2)
        Doppler band (low, high) of each, Hz: squint ``asin(f λ / (2 v))``.
    speed_mps, wavelength_m : float
        Along-track speed ``v`` (m/s) and wavelength ``λ`` (m).

    Returns
    -------
    ndarray of float64, shape (P, 2)
        Each interval's part inside its band, rad; the band's own squints where the two
        do not overlap.
    """
    band = np.arcsin(np.clip(squint_sine(band_hz, speed_mps, wavelength_m), -1.0, 1.0))
    cut = np.column_stack(
        [np.maximum(intervals_rad[:, 0], band[:, 0]), np.minimum(intervals_rad[:, 1], band[:, 1])]
    )
    return np.where((cut[:, 0] < cut[:, 1])[:, None], cut, band)


def accc_centroid_hz(rc: ComplexArray, prf_hz: float) -> float:
    """Doppler centroid of range-compressed pulses modulo the pulse rate (ACCC), Hz.

    ``f = PRF / (2 π) · arg Σ_n Σ_r s[n + 1, r] conj(s[n, r])`` over consecutive pulses
    and all range bins (Madsen's average cross-correlation coefficient): the phase
    advance per pulse of the echoes' mean Doppler, in ``(-PRF/2, PRF/2]``. The pulses must
    be uniformly spaced and compensated for the platform's line-of-sight motion.

    Parameters
    ----------
    rc : ndarray of complex, shape (P, S)
        Range-compressed, motion-compensated pulses (P >= 2).
    prf_hz : float
        Pulse rate, Hz.

    Returns
    -------
    float
        The centroid, Hz; NaN when the pulses carry no energy.
    """
    return correlation_centroid_hz(accc_correlation(rc), prf_hz)


def accc_correlation(rc: ComplexArray) -> complex:
    """``Σ_n Σ_r s[n + 1, r] conj(s[n, r])`` of pulses (P, S), P >= 2: the sum whose phase
    :func:`accc_centroid_hz` turns into a centroid (sums of several blocks add up)."""
    if rc.shape[0] < 2:
        raise ProcessingError(f"accc_correlation: {rc.shape[0]} pulses (need 2)")
    return complex(np.vdot(rc[:-1], rc[1:]))


def accc_coherence(rc: ComplexArray, correlation: complex) -> float:
    """Magnitude of the correlation coefficient of consecutive pulses, ``|correlation|``
    over the pulses' energy (0..1): near 1 for echoes of the beam's scene, about
    ``1 / sqrt(P S)`` for noise alone (whose centroid means nothing)."""
    energy = float(np.vdot(rc, rc).real)
    return abs(correlation) / energy if energy > 0 else 0.0


def echoes_stand_out(rc: ComplexArray, ratio: float) -> bool:
    """Whether some range bin of pulses (P, S) holds more than ``ratio`` times the median
    bin's power summed over the pulses: a scatterer's echoes, where noise alone (P pulses)
    spreads by about ``1 / sqrt(P)`` about the median. All-zero pulses hold nothing."""
    power = np.einsum("pr,pr->r", rc, rc.conj()).real
    median = float(np.median(power))
    return bool(power.max() > ratio * median) if median > 0 else bool(power.max() > 0)


def correlation_centroid_hz(correlation: complex, prf_hz: float) -> float:
    """Doppler centroid of a pulse-to-pulse correlation (:func:`accc_correlation`) at pulse
    rate ``prf_hz``, in ``(-PRF/2, PRF/2]``, Hz; NaN for a zero correlation."""
    if correlation == 0:
        return math.nan
    return prf_hz * math.atan2(correlation.imag, correlation.real) / (2.0 * math.pi)


def resolve_ambiguity(measured_hz: float, expected_hz: float, prf_hz: float) -> float:
    """``measured_hz`` plus the multiple of ``prf_hz`` that lands nearest ``expected_hz``, Hz."""
    return measured_hz + prf_hz * round((expected_hz - measured_hz) / prf_hz)
