"""Band-limited interpolation of uniformly sampled complex signals.

Used for range cell migration correction (range-Doppler) and for the
polar-to-rectangular resampling (polar format). The kernel is a sinc truncated
to ``taps`` samples and tapered with a Kaiser window (beta 2 pi). With the
default 16 taps the error on a complex tone stays below 0.4 % up to 0.38
cycles per sample (oversampling 1.3) and below 0.1 % up to 0.35; the signals
must be basebanded (spectrum centred on zero). The kernel is tabulated at
``TABLE_STEPS`` fractional offsets per sample (nearest entry: a position error of
at most 1/16384 sample) and applied by a compiled loop.
"""

from __future__ import annotations

import functools

import numba
import numpy as np
import numpy.typing as npt
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import ComplexArray, FloatArray

KAISER_BETA = 2.0 * np.pi
"""Kaiser window shape parameter of the interpolation kernel."""

TABLE_STEPS = 8192
"""Fractional offsets per sample at which the kernel is tabulated."""


@functools.lru_cache(maxsize=8)
def _kernel_table(taps: int) -> npt.NDArray[np.float64]:
    """Weights of the ``taps`` samples ``floor(pos) - taps/2 + 1 ...`` for ``frac(pos) = q /
    TABLE_STEPS``, shape (TABLE_STEPS + 1, taps)."""
    half = taps // 2
    frac = np.arange(TABLE_STEPS + 1)[:, None] / TABLE_STEPS
    d = np.arange(-half + 1, half + 1)[None, :] - frac
    w = np.sinc(d) * np.i0(KAISER_BETA * np.sqrt(np.clip(1.0 - (d / half) ** 2, 0.0, None)))
    table: npt.NDArray[np.float64] = w / np.i0(KAISER_BETA)
    return table


def _checked_table(caller: str, taps: int) -> npt.NDArray[np.float64]:
    """:func:`_kernel_table` of ``taps``, refused unless it is even and at least 2."""
    if taps < 2 or taps % 2:
        raise ProcessingError(f"{caller}: taps {taps!r} must be even and >= 2")
    return _kernel_table(taps)


@numba.njit(parallel=True, nogil=True, cache=True)
def _interp_rows(
    x: ComplexArray, pos: FloatArray, table: npt.NDArray[np.float64], out: ComplexArray
) -> None:  # pragma: no cover - compiled
    """``out[i, j]``: row ``i`` of ``x`` at ``pos[i, j]`` (``pos[0, j]`` when ``pos`` has
    one row: the same positions for every row) with the tabulated kernel."""
    n = x.shape[1]
    steps = table.shape[0] - 1
    taps = table.shape[1]
    half = taps // 2
    stride = 0 if pos.shape[0] == 1 else 1  # one row of positions: shared by every row
    for i in numba.prange(x.shape[0]):
        row = i * stride
        for j in range(pos.shape[1]):
            p = pos[row, j]
            if not (p >= 0.0 and p <= n - 1):
                out[i, j] = 0.0
                continue
            base = int(np.floor(p))
            w = table[int((p - base) * steps + 0.5)]
            re = 0.0
            im = 0.0
            for t in range(taps):
                idx = base - half + 1 + t
                if 0 <= idx < n:
                    v = x[i, idx]
                    re += v.real * w[t]
                    im += v.imag * w[t]
            out[i, j] = re + 1j * im


@numba.njit(parallel=True, nogil=True, cache=True)
def _interp_columns(
    x: ComplexArray, pos: FloatArray, table: npt.NDArray[np.float64], out: ComplexArray
) -> None:  # pragma: no cover - compiled
    """``out[j, k]``: column ``k`` of ``x`` at row position ``pos[j]`` with the tabulated
    kernel (the sums of :func:`_interp_rows`, term by term, over contiguous rows)."""
    n = x.shape[0]
    cols = x.shape[1]
    steps = table.shape[0] - 1
    taps = table.shape[1]
    half = taps // 2
    for j in numba.prange(pos.shape[0]):
        p = pos[j]
        if not (p >= 0.0 and p <= n - 1):
            out[j, :] = 0.0
            continue
        base = int(np.floor(p))
        w = table[int((p - base) * steps + 0.5)]
        re = np.zeros(cols)
        im = np.zeros(cols)
        for t in range(taps):
            idx = base - half + 1 + t
            if 0 <= idx < n:
                wt = w[t]
                for k in range(cols):
                    v = x[idx, k]
                    re[k] += v.real * wt
                    im[k] += v.imag * wt
        for k in range(cols):
            out[j, k] = re[k] + 1j * im[k]


def sinc_interp(x: ComplexArray, pos: FloatArray, taps: int = 16) -> ComplexArray:
    """Interpolate rows of ``x`` at fractional sample positions.

    Parameters
    ----------
    x : ndarray of complex, shape (M, N)
        M independent rows of N uniform samples.
    pos : ndarray of float64, shape (M, K) or (1, K)
        Positions to evaluate in each row, in samples (0 = first sample); one row: the
        same positions in every row of ``x``.
        Taps that fall outside ``[0, N)`` count as zero; an output outside
        ``[0, N - 1]`` is set to zero.
    taps : int
        Kernel length, even.

    Returns
    -------
    ndarray of complex, shape (M, K)
        Same precision as ``x`` (complex64 stays complex64).
    """
    table = _checked_table("sinc_interp", taps)
    if x.ndim != 2 or pos.ndim != 2 or pos.shape[0] not in (1, x.shape[0]):
        raise ProcessingError(f"sinc_interp: shapes x{x.shape} pos{pos.shape} disagree")
    dtype = np.result_type(x.dtype, np.complex64)
    out = np.empty((x.shape[0], pos.shape[1]), dtype=dtype)
    _interp_rows(
        np.ascontiguousarray(x, dtype=dtype),
        np.ascontiguousarray(pos, dtype=np.float64),
        table,
        out,
    )
    return out


def sinc_interp_columns(x: ComplexArray, pos: FloatArray, taps: int = 16) -> ComplexArray:
    """Interpolate every column of ``x`` at the same fractional row positions.

    The result equals ``sinc_interp(x.T, pos[None, :], taps).T`` (the same kernel and
    sums), computed over contiguous rows without transposing.

    Parameters
    ----------
    x : ndarray of complex, shape (N, M)
        N uniform samples (rows) of M independent columns.
    pos : ndarray of float64, shape (K,)
        Row positions to evaluate, in samples (0 = first row). Taps that fall outside
        ``[0, N)`` count as zero; an output row outside ``[0, N - 1]`` is set to zero.
    taps : int
        Kernel length, even.

    Returns
    -------
    ndarray of complex, shape (K, M)
        Same precision as ``x`` (complex64 stays complex64).
    """
    table = _checked_table("sinc_interp_columns", taps)
    if x.ndim != 2 or pos.ndim != 1:
        raise ProcessingError(f"sinc_interp_columns: shapes x{x.shape} pos{pos.shape}")
    dtype = np.result_type(x.dtype, np.complex64)
    out = np.empty((pos.shape[0], x.shape[1]), dtype=dtype)
    _interp_columns(
        np.ascontiguousarray(x, dtype=dtype),
        np.ascontiguousarray(pos, dtype=np.float64),
        table,
        out,
    )
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


def warm_up() -> None:
    """Compile the kernels of :func:`sinc_interp` and :func:`sinc_interp_columns` (or load
    them from numba's cache) for complex64 and complex128 samples."""
    for dtype in (np.complex64, np.complex128):
        sinc_interp(np.ones((2, 8), dtype), np.full((2, 3), 2.5))
        sinc_interp_columns(np.ones((8, 2), dtype), np.full(3, 2.5))
