"""Phase gradient autofocus (docs/methods.md §3, PGA paragraph; THz paper refinement stage).

The core works on azimuth-compressed lines whose inverse FFT along azimuth is the phase
history on the pulse axis (dechirped lines). Per iteration: the brightest scatterer of each
line is circularly shifted to the centre, windowed (the window shrinks with the iterations),
the phase gradient is estimated with the maximum-likelihood (phase-difference) estimator
``Δφ(k) = arg Σ_i g_i*(k) g_i(k+1)``, integrated, its mean and linear trend removed, and
applied; the loop stops when the RMS update falls below a tolerance.

:func:`pga_stripmap` forms such lines from range-compressed data on a straight reference track
by removing the exact hyperbolic phase of a broadside target at the aperture centre for every
range bin, and returns one azimuth phase error per pulse (common to all range bins).
"""

from __future__ import annotations

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.autofocus.doppler_rate import select_lines
from sarmoco.processing.types import ComplexArray, FloatArray


def _window_width(shifted: ComplexArray, floor_db: float) -> int:
    """Width (bins) of the centred non-coherent average above ``floor_db`` of its peak."""
    power = np.mean(np.abs(shifted) ** 2, axis=0)
    c = power.shape[0] // 2
    above = power >= power[c] * 10.0 ** (floor_db / 10.0)
    left = c
    while left > 0 and above[left - 1]:
        left -= 1
    right = c
    while right < power.shape[0] - 1 and above[right + 1]:
        right += 1
    return int(2 * max(c - left, right - c) + 1)


def pga(
    lines: ComplexArray,
    max_iter: int = 8,
    tol_rad: float = 0.02,
    min_window: int = 16,
    floor_db: float = -20.0,
) -> tuple[FloatArray, list[float]]:
    """Estimate the common azimuth phase error of azimuth-compressed lines.

    Parameters
    ----------
    lines : ndarray, shape (N, P)
        N azimuth-compressed lines (each the FFT over P pulses of a dechirped range line).
    max_iter : int
        At most this many iterations.
    tol_rad : float
        Stop when the RMS phase update is below this, rad.
    min_window : int
        Smallest window, bins.
    floor_db : float
        The window is twice the width where the centred average is above this level of its
        peak, dB, never wider than the previous one.

    Returns
    -------
    phase : ndarray, shape (P,)
        Phase error per pulse, rad (zero mean, zero trend); remove it with exp(-j phase).
    rms_updates : list of float
        RMS update of each iteration, rad.
    """
    if lines.ndim != 2 or lines.shape[1] < 2 * min_window:
        raise ProcessingError(f"pga: lines of shape {lines.shape} are too few pulses")
    n_p = lines.shape[1]
    k = np.arange(n_p, dtype=float)
    history = np.fft.ifft(lines, axis=1)
    total = np.zeros(n_p)
    width = n_p
    updates: list[float] = []
    for _ in range(max_iter):
        img = np.fft.fft(history * np.exp(-1j * total)[None, :], axis=1)
        peaks = np.argmax(np.abs(img), axis=1)
        rows = np.arange(img.shape[0])[:, None]
        # Centre shift to bin 0 (not P/2, which would add a pi-per-pulse ramp at the wrap).
        shifted = img[rows, (np.arange(n_p)[None, :] + peaks[:, None]) % n_p]
        width = max(
            min_window, min(width, 2 * _window_width(np.fft.fftshift(shifted, 1), floor_db))
        )
        win = (np.abs(np.fft.fftfreq(n_p) * n_p) <= width // 2).astype(float)
        g = np.fft.ifft(shifted * win[None, :], axis=1)
        grad = np.angle(np.sum(np.conj(g[:, :-1]) * g[:, 1:], axis=0))
        phi = np.concatenate([[0.0], np.cumsum(grad)])
        trend = np.polyval(np.polyfit(k, phi, 1), k)
        phi -= trend
        total += phi
        updates.append(float(np.sqrt(np.mean(phi**2))))
        if updates[-1] < tol_rad:
            break
    return total - np.polyval(np.polyfit(k, total, 1), k), updates


def pga_stripmap(
    rc: ComplexArray,
    t_s: FloatArray,
    range_m: FloatArray,
    speed_mps: float,
    wavelength_m: float,
    n_lines: int = 32,
    guard_bins: int = 2,
    max_iter: int = 8,
    tol_rad: float = 0.02,
) -> tuple[FloatArray, list[float]]:
    """PGA on range-compressed data compensated to a straight reference track.

    Each range bin r is dechirped with ``exp(+j 4π (sqrt(r² + v² τ²) - r) / λ)``,
    ``τ = t - t_mid``, which turns a broadside target into a tone; the brightest
    ``n_lines`` bins (``guard_bins`` apart, so the neighbours of a migrating target also
    count) feed :func:`pga`.

    Parameters
    ----------
    rc : ndarray, shape (P, S)
        Range-compressed pulses, after the two-step corrections.
    t_s : ndarray, shape (P,)
        Pulse times, s.
    range_m : ndarray, shape (S,)
        Slant range of each bin, m.
    speed_mps, wavelength_m : float
        Reference-track speed (m/s) and wavelength (m).

    Returns
    -------
    phase : ndarray, shape (P,)
        Azimuth phase error per pulse, rad; correct with ``rc * exp(-j phase)[:, None]``.
    rms_updates : list of float
        RMS update of each iteration, rad.
    """
    bins = select_lines(rc, n_lines, guard_bins)
    if bins.size == 0:
        return np.zeros(rc.shape[0]), []
    tau = t_s - 0.5 * (t_s[0] + t_s[-1])
    r = range_m[bins][None, :]
    hyper = np.sqrt(r**2 + (speed_mps * tau[:, None]) ** 2) - r
    lines = (rc[:, bins] * np.exp(4j * np.pi * hyper / wavelength_m)).T
    return pga(np.fft.fft(lines, axis=1), max_iter=max_iter, tol_rad=tol_rad)
