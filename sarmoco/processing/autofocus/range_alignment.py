"""Envelope (range) alignment of a deramped phase history from range-profile magnitudes.

A line-of-sight displacement d_p (m) of pulse p shifts its range profile by d_p. Each pulse's
range-compressed magnitude is cross-correlated with those of the next ``max_lag`` pulses
(upsampled, parabolic sub-bin peak): every pair (p, p + l) measures ``d_{p+l} - d_p`` plus the
slow migration of the scene itself. All pairs are solved together by least squares for d
(many lags average the per-pair noise instead of accumulating it as a single-lag chain does).
The scene's own migration over a short aperture is nearly linear in time (a scatterer off the
reference point walks in range at a constant rate), and so is the unobservable part of d (a
linear LOS displacement only moves the image): the estimate has zero mean and zero trend.
"""

from __future__ import annotations

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.phase_history import compressed_from_phase_history
from sarmoco.processing.types import ComplexArray, FloatArray


def _lag_shifts(spec: ComplexArray, lag: int) -> FloatArray:
    """Shift (bins, signed) of profile ``p + lag`` relative to profile p, for every p."""
    xc = np.fft.ifft(spec[lag:] * np.conj(spec[:-lag]), axis=1).real
    n = xc.shape[1]
    rows = np.arange(xc.shape[0])
    k = np.argmax(xc, axis=1)
    ym, y0, yp = xc[rows, (k - 1) % n], xc[rows, k], xc[rows, (k + 1) % n]
    den = ym - 2.0 * y0 + yp
    frac = np.where(den < 0.0, 0.5 * (ym - yp) / np.where(den < 0.0, den, -1.0), 0.0)
    return np.asarray(((k + n // 2) % n - n // 2) + frac, dtype=float)


def align_ranges(
    ph: ComplexArray, freq_hz: FloatArray, max_lag: int = 16, upsample: int = 8
) -> FloatArray:
    """Estimate each pulse's LOS displacement from the drift of its range profile.

    Parameters
    ----------
    ph : ndarray, shape (P, F)
        Phase history deramped to a per-pulse reference range (uniform ascending frequencies).
    freq_hz : ndarray, shape (F,)
        Frequencies, Hz.
    max_lag : int
        Each pulse is compared with the next ``max_lag`` pulses.
    upsample : int
        Range oversampling of the profiles before the correlation.

    Returns
    -------
    ndarray, shape (P,)
        LOS displacement d_p, m, positive away from the antenna (the profile moves to longer
        range), with zero mean and zero linear trend over the pulse index. Removing it is
        multiplying pulse p by ``exp(+j 4π f d_p / c)``.
    """
    n_p = ph.shape[0]
    if n_p < 3 or not 1 <= max_lag < n_p:
        raise ProcessingError(f"align_ranges: {n_p} pulses, max_lag {max_lag}")
    rc, range_m, _ = compressed_from_phase_history(ph, freq_hz, upsample)
    mag = np.abs(rc).astype(float)
    spec = np.fft.fft(mag - mag.mean(axis=1, keepdims=True), axis=1)
    bin_m = float(range_m[1] - range_m[0])
    # normal equations of the pair differences d_{p+l} - d_p = shift, plus sum(d) = 0
    normal = np.ones((n_p, n_p))
    rhs = np.zeros(n_p)
    for lag in range(1, max_lag + 1):
        shift_m = _lag_shifts(spec, lag) * bin_m
        first = np.arange(n_p - lag)
        np.add.at(normal, (first, first), 1.0)
        np.add.at(normal, (first + lag, first + lag), 1.0)
        np.add.at(normal, (first, first + lag), -1.0)
        np.add.at(normal, (first + lag, first), -1.0)
        np.add.at(rhs, first + lag, shift_m)
        np.add.at(rhs, first, -shift_m)
    d = np.linalg.solve(normal, rhs)
    k = np.arange(n_p, dtype=float)
    return np.asarray(d - np.polyval(np.polyfit(k, d, 1), k), dtype=float)
