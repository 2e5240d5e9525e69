"""Block range-Doppler algorithm (stripmap) with RCMC and secondary range compression.

The block holds range-compressed pulses taken at uniform spacing ``dx`` along
a straight reference track; axis 1 is the slant range ``r0`` of closest
approach. Azimuth is processed in spatial frequency ``kx`` (cycles/m; the
Doppler frequency is ``v kx``), with ``sin(theta) = lambda kx / 2`` the squint
of a Doppler bin and ``D = cos(theta)``. A point target at ``(x0, r0)`` (echo
phase ``exp(-j 4 pi R / lambda)``, docs/methods.md §1) has, in the range-Doppler
domain, its range at ``r0 / D`` and azimuth phase
``exp(-j 4 pi r0 D / lambda - j 2 pi kx x0)`` (stationary phase, exact for a
straight track). The steps:

1. azimuth FFT, zero-padded to ``>= 2P - 1`` so compression is linear, not circular;
2. secondary range compression: the range-frequency terms beyond the linear
   one of ``sqrt((fc + fr)^2 - (c kx / 2)^2)`` are removed at the reference
   (mid-swath) range in the 2-D frequency domain;
3. RCMC: each Doppler row is resampled from ``r0 / D`` to ``r0`` with a 16-tap
   Kaiser-windowed sinc;
4. azimuth compression ``exp(+j 4 pi r0 D / lambda)`` within the processed
   Doppler band, then inverse azimuth FFT.

The processed band is ``|sin theta - sin theta_c| <= sin(alpha / 2)`` with ``alpha``
the processed angle: given, or by default ``BAND_MARGIN`` times the angle the
block subtends at each range, ``2 atan(P dx / (2 r0))``, and ``theta_c`` the squint
of the Doppler centroid (0 for a beam at broadside; a crabbed platform squints the
beam, Doppler centroid ``f_dc = 2 v sin(theta_c) / lambda``). The Doppler bins are
unwrapped around the centroid, so a centroid beyond the sampled band (aliased)
is processed at its true squint. The margin keeps the
Fresnel edges of a short aperture's spectrum (small time-bandwidth product)
inside the band, so the band edge does not weight them. The theoretical
azimuth IRW of an unweighted target seen over an aperture of length ``L`` at
range ``r0`` is ``0.886 / B_kx`` with ``B_kx = (4 / lambda) sin(atan(L / (2 r0)))``,
i.e. ``0.886 v / B_doppler``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.interp import sinc_interp
from sarmoco.processing.phasor import phasor
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, Image, IntArray

BAND_MARGIN = 1.5
"""Default processed angle over the angle the block subtends."""


@dataclass(frozen=True)
class RdaFilters:
    """The range-Doppler filters of one block shape (see the module's steps).

    The filters hold only the ``M`` Doppler rows with a bin in the processed band: the
    others are zero after azimuth compression, so their range steps are left out.

    Attributes
    ----------
    n_az : int
        Azimuth FFT length.
    src : ndarray of complex, shape (M, N) or None
        Secondary range compression, a range-frequency phase per Doppler row over a range
        FFT of ``N = next_fast_len(S)`` bins (the bins zero-padded; None: off).
    rcmc_bins : ndarray of float64, shape (M, S)
        Where each Doppler row takes the range bin of ``r0``: ``(r0 / D - r_first) / dr``.
    azimuth : ndarray of complex, shape (M, S)
        Azimuth compression ``exp(+j 4 pi r0 D / lambda)`` in the processed band, 0 outside.
    rows : ndarray of int, shape (M,)
        The bins of the ``n_az``-point azimuth FFT the rows take.
    n_out : int
        Inverse azimuth FFT length: ``n_az``, or fewer for a band narrower than the pulses'
        grid holds (a presum in the Doppler domain: the image comes out on an along-track
        grid ``n_az / n_out`` times coarser).
    out_rows : ndarray of int, shape (M,)
        The bins of the inverse FFT the rows go to (the others are zero).
    """

    n_az: int
    src: ComplexArray | None
    rcmc_bins: FloatArray
    azimuth: ComplexArray
    rows: IntArray
    n_out: int
    out_rows: IntArray


def rda_filters(
    n_az: int,
    dx_m: float,
    range_axis_m: FloatArray,
    wavelength_m: float,
    sin_max: FloatArray,
    src: bool = True,
    centroid_squint_rad: float = 0.0,
    dtype: type[np.complexfloating] = np.complex128,
) -> RdaFilters:
    """The filters of :func:`focus_block` for blocks of ``n_az`` (padded) rows.

    Parameters
    ----------
    n_az : int
        Azimuth FFT length.
    dx_m : float
        Pulse spacing along the track, m.
    range_axis_m : ndarray of float64, shape (S,)
        Uniform slant range of each bin, m.
    wavelength_m : float
        Carrier wavelength, m.
    sin_max : ndarray of float64, shape (S,)
        Half the processed band at each range, as ``sin`` of the angle from the centroid.
    src : bool
        Secondary range compression.
    centroid_squint_rad : float
        Squint of the Doppler centroid (forward positive), rad.
    dtype : complex dtype
        Precision of the complex filters.
    """
    s = range_axis_m.shape[0]
    dr = float(range_axis_m[1] - range_axis_m[0])
    # Doppler bins as spatial frequency kx (cycles/m), unwrapped around the centroid's
    kx_c = 2.0 * np.sin(centroid_squint_rad) / wavelength_m
    kx = np.fft.fftfreq(n_az, dx_m)
    kx = kx_c + (kx - kx_c + 0.5 / dx_m) % (1.0 / dx_m) - 0.5 / dx_m
    sin_sq = wavelength_m * kx / 2.0  # (n_az,)
    if np.any(np.abs(sin_sq) >= 1.0):
        raise ProcessingError("rda: pulse spacing below lambda/2 gives evanescent Doppler bins")
    band = np.abs(sin_sq - np.sin(centroid_squint_rad))[:, None] <= sin_max[None, :]
    d = np.sqrt(1.0 - sin_sq**2)
    src_filter = None
    if src:
        fc = C_MPS / wavelength_m
        fr = np.fft.fftfreq(scipy.fft.next_fast_len(s), dr) * C_MPS / 2.0
        a2 = (fc * sin_sq[:, None]) ** 2
        resid = np.sqrt((fc + fr[None, :]) ** 2 - a2) - fc * d[:, None] - fr[None, :] / d[:, None]
        r_ref = float(range_axis_m[s // 2])
        # shift to the bin-0 origin does not matter: the filter is a pure range-frequency phase
        src_filter = phasor(4.0 * np.pi * r_ref / C_MPS * resid, dtype)
    rcmc = (range_axis_m[None, :] / d[:, None] - range_axis_m[0]) / dr
    azimuth = phasor((4.0 * np.pi / wavelength_m) * d[:, None] * range_axis_m[None, :], dtype)
    azimuth[~band] = 0.0
    rows = np.flatnonzero(band.any(axis=1))
    return RdaFilters(
        n_az,
        None if src_filter is None else src_filter[rows],
        rcmc[rows],
        azimuth[rows],
        rows,
        n_az,
        rows,
    )


def focus_block(rc: ComplexArray, filters: RdaFilters, taps: int = 16) -> ComplexArray:
    """Range-Doppler focus of ``rc`` (P × S, P <= ``filters.n_az``) with ``filters``.

    Returns the image in the filters' precision (complex64 filters and pulses are
    transformed in single precision): P × S, or ``ceil(P n_out / n_az)`` rows of a
    coarser grid (``filters.n_out``).
    """
    p, s = rc.shape
    rd = scipy.fft.fft(np.asarray(rc, dtype=filters.azimuth.dtype), n=filters.n_az, axis=0)
    rd = rd[filters.rows]  # the rows in the band
    if filters.src is not None:
        spectrum = scipy.fft.fft(rd, n=filters.src.shape[1], axis=1, overwrite_x=True)
        spectrum *= filters.src
        rd = scipy.fft.ifft(spectrum, axis=1, overwrite_x=True)[:, :s]
    rd = sinc_interp(rd, filters.rcmc_bins, taps)
    rd *= filters.azimuth
    spectrum = np.zeros((filters.n_out, s), dtype=rd.dtype)
    spectrum[filters.out_rows] = rd
    out: ComplexArray = scipy.fft.ifft(spectrum, axis=0, overwrite_x=True)
    return out[: -(-p * filters.n_out // filters.n_az)]


def range_doppler(
    rc: ComplexArray,
    range_axis_m: FloatArray,
    along_track_m: FloatArray,
    wavelength_m: float,
    integration_angle_rad: float | None = None,
    src: bool = True,
    taps: int = 16,
    pad: bool = True,
    centroid_squint_rad: float = 0.0,
) -> Image:
    """Focus a stripmap block with the range-Doppler algorithm.

    Parameters
    ----------
    rc : ndarray of complex, shape (P, S)
        Range-compressed, basebanded pulses (motion compensated to the
        reference track if the platform deviated from it).
    range_axis_m : ndarray of float64, shape (S,)
        Uniform slant range of each bin from the reference track, m.
    along_track_m : ndarray of float64, shape (P,)
        Position of each pulse along the reference track, m, uniformly spaced.
    wavelength_m : float
        Carrier wavelength (the ``lambda`` of the echo phase), m.
    integration_angle_rad : float, optional
        Processed angle (Doppler band); default: ``BAND_MARGIN`` times what the
        block subtends.
    src : bool
        Apply secondary range compression.
    taps : int
        RCMC interpolation kernel length.
    pad : bool
        Zero-pad the azimuth FFT to ``>= 2P - 1`` (linear compression over the
        whole block). False: the FFT is ``P`` long and compression is circular, so
        only the outputs at least a half aperture from both ends of the block are
        exact.
    centroid_squint_rad : float
        Squint of the Doppler centroid ``theta_c`` (positive: the beam looks
        forward, toward +x), rad; 0 for a beam at broadside.

    Returns
    -------
    Image
        complex64, frame ``"slant"``: axis 0 along-track (the pulse positions),
        axis 1 slant range of closest approach. Computed in single precision when
        ``rc`` is complex64, else in double.
    """
    p, s = rc.shape
    if range_axis_m.shape != (s,) or along_track_m.shape != (p,) or p < 2 or s < 2:
        raise ProcessingError(
            f"rda: rc{rc.shape}, range axis {range_axis_m.shape}, track {along_track_m.shape}"
        )
    dx = float(along_track_m[-1] - along_track_m[0]) / (p - 1)
    if not np.allclose(np.diff(along_track_m), dx, rtol=1e-3, atol=0.0) or dx <= 0:
        raise ProcessingError("rda: pulses are not uniformly spaced along the track (resample)")
    if integration_angle_rad is None:
        sin_max = np.sin(BAND_MARGIN * np.arctan(p * dx / (2.0 * range_axis_m)))  # (S,)
    else:
        sin_max = np.full(s, np.sin(integration_angle_rad / 2.0))
    n_az = scipy.fft.next_fast_len(2 * p - 1 if pad else p)
    dtype = np.complex64 if rc.dtype == np.complex64 else np.complex128
    filters = rda_filters(
        n_az, dx, range_axis_m, wavelength_m, sin_max, src, centroid_squint_rad, dtype
    )
    img = focus_block(rc, filters, taps)
    axis0 = along_track_m[0] + np.arange(p) * dx
    return Image(
        img.astype(np.complex64), axis0, np.asarray(range_axis_m, dtype=np.float64), "slant"
    )
