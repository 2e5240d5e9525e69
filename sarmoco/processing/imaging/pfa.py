"""Polar format algorithm (spotlight) onto a plane grid.

Input is a phase history deramped to the grid origin (the scene centre):
``ph[p, n] = sum_t a_t exp(-j 4 pi f_n (R_t,p - R_c,p) / c)``. In the far field,
``R_t - R_c ~ -u_p . (t - c)`` with ``u_p`` the unit vector from the centre to
the APC, so a sample is a point ``K = 4 pi f / c (u . e0, u . e1)`` of the
ground-plane spatial spectrum. With ``kr = -K . e1`` (range, axis 1 must be the
look direction: see :func:`~sarmoco.processing.imaging.grid.facing_heading`)
and ``kc = K . e0`` the samples lie on a polar raster. They are resampled to a
rectangle inscribed in it in two separable steps (keystone style): along
frequency to a uniform ``kr`` per pulse, then along the pulses to a uniform
``kc`` per ``kr`` row, both with the Kaiser-windowed sinc of
:mod:`~sarmoco.processing.imaging.interp`. The image is the 2-D DFT evaluated on
the grid's own pixels (two matrix products), so it lands on the same grid as
backprojection.

Validity: the planar-wavefront approximation leaves a quadratic phase error
that grows with the distance from the scene centre; it stays below pi/2 within
the radius ``r_max = 2 rho_c sqrt(R_c / lambda)`` (Carrara, Goodman, Majewski,
*Spotlight SAR*, eq. 3.64; ``rho_c`` the cross-range resolution, ``R_c`` the
range to the centre). Outside it targets defocus and are displaced.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.interp import sinc_interp
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, Image

IRW_SINC = 0.886
"""-3 dB width of an unweighted sinc, in resolution cells."""


@dataclass(frozen=True)
class PfaSupport:
    """The rectangle of the spatial spectrum that the polar format keeps, rad/m.

    Parameters
    ----------
    kc_lo, kc_hi : float
        Cross-range (axis 0) spatial frequency extent.
    kr_lo, kr_hi : float
        Range (axis 1) spatial frequency extent.
    """

    kc_lo: float
    kc_hi: float
    kr_lo: float
    kr_hi: float

    @property
    def irw_m(self) -> tuple[float, float]:
        """Theoretical unweighted IRW along axis 0 and axis 1, m (0.886 * 2 pi / extent)."""
        return (
            IRW_SINC * 2.0 * np.pi / (self.kc_hi - self.kc_lo),
            IRW_SINC * 2.0 * np.pi / (self.kr_hi - self.kr_lo),
        )


def _ground_los(apc_m: FloatArray, grid: PlaneGrid) -> tuple[FloatArray, FloatArray]:
    """Range and cross-range components (g_r, g_c) of the unit vectors centre->APC."""
    u = apc_m - np.asarray(grid.origin_m, dtype=np.float64)[None, :]
    u /= np.linalg.norm(u, axis=1)[:, None]
    e0, e1 = grid.unit_vectors
    g_r, g_c = -(u @ e1), u @ e0
    if np.any(g_r <= 0) or np.any(np.abs(g_c) >= g_r):
        raise ProcessingError(
            "pfa: the look direction must stay within 45° of the grid's axis 1 "
            "(build the grid with facing_heading)"
        )
    t = g_c / g_r
    if not (np.all(np.diff(t) > 0) or np.all(np.diff(t) < 0)):
        raise ProcessingError("pfa: the aspect angle is not monotonic over the pulses")
    return g_r, g_c


def pfa_support(freq_hz: FloatArray, apc_m: FloatArray, grid: PlaneGrid) -> PfaSupport:
    """The inscribed spectral rectangle used by :func:`polar_format` for these pulses."""
    g_r, g_c = _ground_los(apc_m, grid)
    k_lo, k_hi = 4.0 * np.pi * freq_hz[0] / C_MPS, 4.0 * np.pi * freq_hz[-1] / C_MPS
    kr_lo, kr_hi = float(np.max(k_lo * g_r)), float(np.min(k_hi * g_r))
    t = g_c / g_r
    t_min, t_max = float(np.min(t)), float(np.max(t))
    kc_lo = max(kr_lo * t_min, kr_hi * t_min)
    kc_hi = min(kr_lo * t_max, kr_hi * t_max)
    if not (kr_hi > kr_lo and kc_hi > kc_lo):
        raise ProcessingError("pfa: the polar raster has no inscribed rectangle")
    return PfaSupport(kc_lo, kc_hi, kr_lo, kr_hi)


def validity_radius_m(freq_hz: FloatArray, apc_m: FloatArray, grid: PlaneGrid) -> float:
    """Radius around the grid origin where the planar-wavefront error stays < pi/2, m."""
    sup = pfa_support(freq_hz, apc_m, grid)
    rho_c = 2.0 * np.pi / (sup.kc_hi - sup.kc_lo)
    r_c = float(np.mean(np.linalg.norm(apc_m - np.asarray(grid.origin_m)[None, :], axis=1)))
    lam = C_MPS / float(np.mean(freq_hz))
    return float(2.0 * rho_c * np.sqrt(r_c / lam))


def polar_to_rect(
    ph: ComplexArray,
    freq_hz: FloatArray,
    apc_m: FloatArray,
    grid: PlaneGrid,
    kr: FloatArray,
    kc: FloatArray,
    taps: int = 16,
) -> ComplexArray:
    """Resample a deramped phase history from its polar raster onto a rectangle.

    Parameters
    ----------
    ph, freq_hz, apc_m, grid, taps
        As for :func:`polar_format`.
    kr, kc : ndarray of float64
        Range (axis 1) and cross-range (axis 0) spatial frequencies of the rectangle,
        rad/m, each uniform and ascending (within :func:`pfa_support` for samples that
        are not to be zero).

    Returns
    -------
    ndarray of complex, shape (kr.size, kc.size)
        The spectrum ``G(kr, kc)``; the image is ``sum G exp(-j (kc a0 - kr a1))``.
    """
    p, f = ph.shape
    if freq_hz.shape != (f,) or apc_m.shape != (p, 3):
        raise ProcessingError(f"pfa: ph{ph.shape} freq{freq_hz.shape} apc{apc_m.shape}")
    df = float(freq_hz[-1] - freq_hz[0]) / (f - 1)  # uniform; fitted over the band
    g_r, g_c = _ground_los(apc_m, grid)
    # step 1: per pulse, frequency -> uniform kr
    f_at = kr[None, :] * C_MPS / (4.0 * np.pi * g_r[:, None])
    a = sinc_interp(np.asarray(ph), (f_at - freq_hz[0]) / df, taps)
    # step 2: per kr row, pulses -> uniform kc
    t = g_c / g_r
    order = np.argsort(t)
    ts = t[order]
    at = kc[None, :] / kr[:, None]
    pulse_at = np.interp(at, ts, order.astype(np.float64))
    slack = 1e-9 * (ts[-1] - ts[0])
    pulse_at[(at < ts[0] - slack) | (at > ts[-1] + slack)] = -1.0  # beyond the aperture: zeros
    return sinc_interp(np.ascontiguousarray(a.T), pulse_at, taps)  # (kr rows, kc columns)


def polar_format(
    ph: ComplexArray, freq_hz: FloatArray, apc_m: FloatArray, grid: PlaneGrid, taps: int = 16
) -> Image:
    """Form a spotlight image with the polar format algorithm.

    Parameters
    ----------
    ph : ndarray of complex, shape (P, F)
        Phase history deramped to ``grid.origin_m`` (see module docstring),
        frequencies uniform and ascending.
    freq_hz : ndarray of float64, shape (F,)
        Frequency of each column, Hz.
    apc_m : ndarray of float64, shape (P, 3)
        APC of each pulse in the grid's frame, m.
    grid : PlaneGrid
        Output pixels; its origin is the scene centre that ``ph`` is deramped
        to and its axis 1 the look direction.
    taps : int
        Length of the interpolation kernel.

    Returns
    -------
    Image
        complex64 pixels on ``grid``. The amplitude scale is that of ``ph``
        summed over the kept samples.
    """
    p, f = ph.shape
    if freq_hz.shape != (f,) or apc_m.shape != (p, 3):
        raise ProcessingError(f"pfa: ph{ph.shape} freq{freq_hz.shape} apc{apc_m.shape}")
    sup = pfa_support(freq_hz, apc_m, grid)
    kr = np.linspace(sup.kr_lo, sup.kr_hi, f)
    kc = np.linspace(sup.kc_lo, sup.kc_hi, p)
    g = polar_to_rect(np.asarray(ph, dtype=np.complex128), freq_hz, apc_m, grid, kr, kc, taps)
    # image: I(a0, a1) = sum G(kr, kc) exp(-j (kc a0 - kr a1))
    e0 = np.exp(-1j * np.outer(grid.axis0_m, kc))
    e1 = np.exp(1j * np.outer(kr, grid.axis1_m))
    img = e0 @ (g.T @ e1)
    return Image(
        img.astype(np.complex64),
        np.asarray(grid.axis0_m, dtype=np.float64),
        np.asarray(grid.axis1_m, dtype=np.float64),
        grid.frame,
    )
