"""Band-limited interpolation of uniformly sampled complex signals.

Used for range cell migration correction (range-Doppler) and for the
polar-to-rectangular resampling (polar format). The kernel is a sinc truncated
to ``taps`` samples and tapered with a Kaiser window (beta 2 pi). With the
default 16 taps the error on a complex tone stays below 0.4 % up to 0.38
cycles per sample (oversampling 1.3) and below 0.1 % up to 0.35; the signals
must be basebanded (spectrum centred on zero).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import ComplexArray, FloatArray

KAISER_BETA = 2.0 * np.pi
"""Kaiser window shape parameter of the interpolation kernel."""


def sinc_interp(x: ComplexArray, pos: FloatArray, taps: int = 16) -> ComplexArray:
    """Interpolate rows of ``x`` at fractional sample positions.

    Parameters
    ----------
    x : ndarray of complex, shape (M, N)
        M independent rows of N uniform samples.
    pos : ndarray of float64, shape (M, K)
        Positions to evaluate in each row, in samples (0 = first sample).
        Taps that fall outside ``[0, N)`` count as zero; an output outside
        ``[0, N - 1]`` is set to zero.
    taps : int
        Kernel length, even.

    Returns
    -------
    ndarray of complex, shape (M, K)
        Same precision as ``x`` (complex64 stays complex64).
    """
    if taps < 2 or taps % 2:
        raise ProcessingError(f"sinc_interp: taps {taps!r} must be even and >= 2")
    if x.ndim != 2 or pos.ndim != 2 or pos.shape[0] != x.shape[0]:
        raise ProcessingError(f"sinc_interp: shapes x{x.shape} pos{pos.shape} disagree")
    n = x.shape[1]
    half = taps // 2
    base = np.floor(pos).astype(np.int64)
    frac = pos - base
    out = np.zeros(pos.shape, dtype=np.result_type(x.dtype, np.complex64))
    norm = np.i0(KAISER_BETA)
    rows = np.arange(x.shape[0])[:, None]
    for k in range(-half + 1, half + 1):
        idx = base + k
        d = k - frac
        w = np.sinc(d) * np.i0(KAISER_BETA * np.sqrt(np.clip(1.0 - (d / half) ** 2, 0.0, None)))
        valid = (idx >= 0) & (idx < n)
        vals = x[rows, np.clip(idx, 0, n - 1)]
        out += np.where(valid, vals * (w / norm).astype(out.real.dtype), 0)
    out[(pos < 0) | (pos > n - 1)] = 0
    return out


def fft_upsample(x: ComplexArray, factor: int) -> ComplexArray:
    """Upsample each row of a basebanded complex signal by FFT zero-padding.

    Parameters
    ----------
    x : ndarray of complex, shape (M, N)
        Rows of N samples; the spectrum must be centred on zero frequency.
    factor : int
        Upsampling factor (>= 1).

    Returns
    -------
    ndarray of complex, shape (M, N * factor)
        Sample ``i * factor`` of a row equals sample ``i`` of the input; the
        precision of ``x`` is kept (complex64 is transformed in single precision).
    """
    if factor < 1:
        raise ProcessingError(f"fft_upsample: factor {factor!r} is not >= 1")
    if factor == 1:
        return x
    n = x.shape[1]
    m = n * factor
    spec = scipy.fft.fft(x, axis=1)
    lo = (n + 1) // 2  # bins 0 .. lo-1 are the non-negative frequencies
    padded = np.zeros((x.shape[0], m), dtype=spec.dtype)
    padded[:, :lo] = spec[:, :lo]
    padded[:, m - (n - lo) :] = spec[:, lo:]
    if n % 2 == 0:
        # the Nyquist bin -n/2 is split between -n/2 and +n/2
        padded[:, m - n // 2] *= 0.5
        padded[:, n // 2] = padded[:, m - n // 2]
    out = scipy.fft.ifft(padded, axis=1, overwrite_x=True)
    out *= factor
    return np.asarray(out).astype(x.dtype, copy=False)
