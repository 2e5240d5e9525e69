"""Range compression: matched filter (pulsed LFM) and dechirp FFT with residual video phase removal.

The waveform conventions are those of :mod:`sarmoco.sim.echo` (a centred chirp
``exp(j pi K_s (tau - T_p/2)**2)`` with the signed rate ``K_s = +B / T_p`` for an up-chirp and
``-B / T_p`` for a down-chirp, ``radar.chirp_direction``). A receiver that delivers the
conjugate of that baseband (``radar.iq_conjugate``, spectral inversion) has its samples
conjugated first. After :func:`compress`, a point target at slant range R peaks at
``range_axis_m(radar) == R`` (between bins when R is) and the peak carries the phase
``exp(-j 4 pi R / lambda)`` (docs/methods.md §1). Output bins are in increasing slant range for both
receive chains and both chirp directions. Pulses are independent, so any block of pulses can
be compressed on its own.

Matched filter: correlation with the reference chirp by FFT (length >= S + L - 1, no wrap);
output bin i is the lag ``gate + i / f_s``; bins beyond ``S - L`` hold echoes cut by the end of
the receive window. A window weights the reference spectrum over the band ``|f| <= B/2``.

Dechirp: a centred DFT of each pulse (sample time ``u_n = (n - N/2) / f_s`` about the reference
chirp's centre) evaluated at beat frequencies ``f_i = (i - N/2) f_s / N`` maps bin i to the delay
offset ``f_i / K``. An up-chirp's beat tone ``exp(-j 2 pi K Delta u)`` takes the DFT kernel
``exp(+j 2 pi f_i u_n)``, a down-chirp's ``exp(+j 2 pi K Delta u)`` the kernel
``exp(-j 2 pi f_i u_n)`` (the first kernel applied to the pulse reversed in time), so bin i is
the delay ``f_i / K`` for both. Multiplying by ``exp(-j pi f_i**2 / K_s)`` removes the
residual video phase and deskews every tone to the same time support, which leaves a flat
phase across each peak; the constant ``exp(-j 4 pi R_ref / lambda)`` restores the absolute
phase. With a window the deskewed signal is taken back to time, weighted over the common tone
support ``|u| < T_p/2`` and transformed again.
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, RadarParams

Window = str | tuple[str, float] | None
"""A window name (or name and parameter) accepted by ``scipy.signal.get_window``; None: rect."""


def range_axis_m(radar: RadarParams) -> FloatArray:
    """Slant range of each output bin of :func:`compress`, m, increasing."""
    i = np.arange(radar.n_samples, dtype=np.float64)
    if radar.receive == "matched":
        return C_MPS / 2.0 * (radar.range_gate_delay_s + i / radar.sample_rate_hz)
    beat_hz = (i - radar.n_samples // 2) * radar.sample_rate_hz / radar.n_samples
    return C_MPS / 2.0 * (radar.range_gate_delay_s + beat_hz / radar.chirp_rate_hz_per_s)


def reference_chirp(radar: RadarParams) -> ComplexArray:
    """Sampled transmit chirp ``exp(j pi K_s (m/f_s - T_p/2)**2)``, ``0 <= m/f_s < T_p``."""
    t = np.arange(int(np.ceil(radar.pulse_width_s * radar.sample_rate_hz))) / radar.sample_rate_hz
    k_s = radar.signed_chirp_rate_hz_per_s
    return np.exp(1j * np.pi * k_s * (t - radar.pulse_width_s / 2.0) ** 2)


def _window_values(window: Window, m: int) -> FloatArray:
    # scipy.signal here, not at the module's top: a daemon that weights no range spectrum
    # starts without it (its import is the largest part of a daemon process's start)
    from scipy.signal import get_window

    try:
        return np.asarray(get_window(window, m, fftbins=False), dtype=np.float64)
    except (ValueError, TypeError) as exc:
        raise ProcessingError(
            f"rangecomp.window: {window!r} is not a scipy window ({exc})"
        ) from exc


def _matched(radar: RadarParams, echo: ComplexArray, window: Window) -> ComplexArray:
    s = echo.shape[1]
    ref = reference_chirp(radar)
    nfft = scipy.fft.next_fast_len(s + ref.size - 1)
    filt = np.conj(scipy.fft.fft(ref, nfft))
    if window is not None:
        f = scipy.fft.fftfreq(nfft, 1.0 / radar.sample_rate_hz)
        band = np.flatnonzero(np.abs(f) <= radar.bandwidth_hz / 2.0)
        band = band[np.argsort(f[band])]
        weights = np.zeros(nfft)
        weights[band] = _window_values(window, band.size)
        filt = filt * weights
    spec = scipy.fft.fft(echo, nfft, axis=1) * filt.astype(np.complex64)
    return scipy.fft.ifft(spec, axis=1)[:, :s].astype(np.complex64)


def _alternating_sign(n: int) -> FloatArray:
    """``(-1)**(n' + N/2)`` for n' = 0..N-1, float32 so complex64 data stay single precision."""
    return (np.where(np.arange(n) % 2 == 0, 1.0, -1.0) * (-1.0) ** (n // 2)).astype(np.float32)


def _centred_dft(x: ComplexArray) -> ComplexArray:
    """``X_i = sum_n x_n exp(+j 2 pi (i - N/2)(n - N/2) / N)`` along axis 1 (N even)."""
    sign = _alternating_sign(x.shape[1])
    return scipy.fft.fftshift(scipy.fft.ifft(x, axis=1, norm="forward"), axes=1) * sign


def _centred_idft(spec: ComplexArray) -> ComplexArray:
    """Inverse of :func:`_centred_dft`."""
    sign = _alternating_sign(spec.shape[1])
    return scipy.fft.fft(scipy.fft.ifftshift(spec * sign, axes=1), axis=1, norm="forward")


def _dechirp(radar: RadarParams, echo: ComplexArray, window: Window) -> ComplexArray:
    n = echo.shape[1]
    if n % 2:
        raise ProcessingError(f"rangecomp: dechirp needs an even n_samples, got {n}")
    k_s = radar.signed_chirp_rate_hz_per_s
    beat_hz = (np.arange(n) - n // 2) * radar.sample_rate_hz / n
    r_ref = C_MPS * radar.range_gate_delay_s / 2.0
    rvp = np.exp(-1j * np.pi * beat_hz**2 / k_s - 4j * np.pi * r_ref / radar.wavelength_m)
    # unnormalised DFT with the kernel exp(+j..) (up-chirp) or exp(-j..) (down-chirp); the
    # centred DFT's sign and the RVP factor in one complex64 pass over the data
    if radar.chirp_direction == "up":
        spec = scipy.fft.ifft(echo, axis=1, norm="forward")
    else:
        spec = scipy.fft.fft(echo, axis=1)
    spec = scipy.fft.fftshift(spec, axes=1)
    spec *= (_alternating_sign(n) * rvp).astype(np.complex64)
    if window is not None:
        u = (np.arange(n) - n // 2) / radar.sample_rate_hz
        support = np.flatnonzero(np.abs(u) < radar.pulse_width_s / 2.0)
        weights = np.zeros(n)
        weights[support] = _window_values(window, support.size)
        spec = _centred_dft(_centred_idft(spec) * weights.astype(np.float32))
    return spec.astype(np.complex64, copy=False)


def compress(radar: RadarParams, echo: ComplexArray, window: Window = None) -> ComplexArray:
    """Range-compress a block of raw pulses.

    Parameters
    ----------
    radar : RadarParams
        The waveform and receive chain that produced ``echo`` (receive mode, chirp
        direction, I/Q conjugation).
    echo : ndarray of complex, shape (P, S)
        Raw samples as the receiver delivers them, S = ``radar.n_samples``.
    window : str or tuple, optional
        Range weighting (``"hann"``, ``"taylor"``, ``("kaiser", 6.0)``...); None: unweighted.

    Returns
    -------
    ndarray of complex64, shape (P, S)
        Bin i at slant range ``range_axis_m(radar)[i]``.
    """
    x = np.atleast_2d(np.asarray(echo))
    if x.ndim != 2 or x.shape[1] != radar.n_samples:
        raise ProcessingError(
            f"rangecomp.compress: echo shape {np.shape(echo)} is not (P, {radar.n_samples})"
        )
    x = x.astype(np.complex64, copy=False)
    if radar.iq_conjugate:
        x = np.conj(x)
    if radar.receive == "matched":
        return _matched(radar, x, window)
    return _dechirp(radar, x, window)
