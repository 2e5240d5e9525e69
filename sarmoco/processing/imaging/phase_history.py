"""Conversions between range-compressed pulses and a deramped phase history.

Sign convention (docs/methods.md §1): after range compression a point target at range
``R`` is a sinc at ``R`` with phase ``exp(-j 4 pi R / lambda)``; its phase
history (the range spectrum) is ``exp(-j 4 pi f R / c)`` over the transmitted
band ``f``. A phase history *deramped* to a reference range ``R_ref`` per pulse
(motion compensated to a reference point, as the AFRL GOTCHA data are) is
``exp(-j 4 pi f (R - R_ref) / c)``.
"""

from __future__ import annotations

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray


def phase_history_from_compressed(
    rc: ComplexArray,
    range_axis_m: FloatArray,
    carrier_hz: float,
    bandwidth_hz: float,
    ref_range_m: FloatArray,
) -> tuple[ComplexArray, FloatArray]:
    """Range-compressed pulses to a phase history deramped to ``ref_range_m``.

    Parameters
    ----------
    rc : ndarray of complex, shape (P, S)
        Range-compressed pulses, basebanded (range spectrum centred on zero).
    range_axis_m : ndarray of float64, shape (S,)
        Uniform slant range of each bin, m.
    carrier_hz : float
        Centre frequency, Hz (the ``lambda`` of the phase convention).
    bandwidth_hz : float
        Transmitted bandwidth, Hz; only frequencies within ``carrier +- B/2`` are kept.
    ref_range_m : ndarray of float64, shape (P,)
        Deramp (reference) range of each pulse, m, e.g. the range to the scene centre.

    Returns
    -------
    ph : ndarray of complex128, shape (P, F)
        Deramped phase history, frequency ascending.
    freq_hz : ndarray of float64, shape (F,)
        The frequency of each column, Hz.
    """
    p, s = rc.shape
    if range_axis_m.shape != (s,) or ref_range_m.shape != (p,):
        raise ProcessingError(
            f"phase_history_from_compressed: rc{rc.shape}, range axis {range_axis_m.shape}, "
            f"ref range {ref_range_m.shape} disagree"
        )
    dr = float(range_axis_m[1] - range_axis_m[0])
    nu = np.fft.fftshift(np.fft.fftfreq(s, dr))  # cycles per metre of range
    fb = nu * C_MPS / 2.0
    keep = np.abs(fb) <= bandwidth_hz / 2.0 * (1.0 + 1e-9)
    spec = np.fft.fftshift(np.fft.fft(rc.astype(np.complex128), axis=1), axes=1)[:, keep]
    nu, freq = nu[keep], carrier_hz + fb[keep]
    # remove the bin-0 offset, then the reference range
    ph = spec * np.exp(-2j * np.pi * nu * range_axis_m[0])[None, :]
    ph *= np.exp(4j * np.pi * freq[None, :] * ref_range_m[:, None] / C_MPS)
    return ph, freq


def compressed_from_phase_history(
    ph: ComplexArray, freq_hz: FloatArray, upsample: int = 1
) -> tuple[ComplexArray, FloatArray, float]:
    """A deramped phase history to range-compressed pulses (relative range).

    Parameters
    ----------
    ph : ndarray of complex, shape (P, F)
        Phase history deramped to a per-pulse reference range, uniform
        ascending frequencies.
    freq_hz : ndarray of float64, shape (F,)
        Frequency of each column, Hz.
    upsample : int
        Zero-padding factor of the inverse FFT (range oversampling).

    Returns
    -------
    rc : ndarray of complex64, shape (P, F * upsample)
        Range-compressed pulses: a target at ``R`` is a peak at ``R - R_ref``
        with phase ``exp(-j 4 pi fc (R - R_ref) / c)``; the lines are periodic
        over ``c / (2 df)``.
    range_axis_m : ndarray of float64, shape (F * upsample,)
        Range of each bin relative to the reference range, m, centred on zero.
    carrier_hz : float
        The centre frequency ``fc`` of that phase, Hz: ``f_0 + (F // 2) df`` with
        ``f_0`` and ``df`` fitted to ``freq_hz``.
    """
    p, f = ph.shape
    if freq_hz.shape != (f,) or f < 2:
        raise ProcessingError(f"compressed_from_phase_history: ph{ph.shape} freq{freq_hz.shape}")
    # fit the spacing over the whole band (files may store frequencies in float32)
    df = float(freq_hz[-1] - freq_hz[0]) / (f - 1)
    fit = freq_hz[0] + np.arange(f) * df
    if df <= 0 or np.max(np.abs(freq_hz - fit)) > 0.01 * df:
        raise ProcessingError("compressed_from_phase_history: frequencies not uniform ascending")
    n = f * upsample
    spec = np.zeros((p, n), dtype=np.complex128)
    spec[:, (np.arange(f) - f // 2) % n] = ph
    rc = np.fft.fftshift(np.fft.ifft(spec, axis=1) * n, axes=1)
    range_axis = (np.arange(n) - n // 2) * C_MPS / (2.0 * df * n)
    return rc.astype(np.complex64), range_axis, float(fit[f // 2])
