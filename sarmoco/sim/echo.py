"""Raw echo synthesis for point scatterers: pulsed LFM and dechirped FMCW, complex baseband.

Every sample is evaluated in closed form from the exact stop-and-hop range
``R_pk = |apc_p - target_k|`` (no small-angle or far-field shortcut); the loop over pulses,
targets and the samples each echo occupies runs in a numba kernel.

Waveform (fast time ``tau`` from the pulse's transmit time stamp): the transmitted chirp is
``exp(j 2 pi f_c tau + j pi K_s (tau - T_p/2)**2)`` for ``0 <= tau < T_p``, with the signed
chirp rate ``K_s = +B / T_p`` (``radar.chirp_direction`` "up") or ``-B / T_p`` ("down")
(centred on the carrier). With the two-way delay ``tau_d = 2 R / c``:

- ``matched``: the demodulated echo sampled at ``tau_n = gate + n / f_s`` is
  ``a exp(j pi K_s (tau_n - tau_d - T_p/2)**2) exp(-j 4 pi R / lambda)`` while
  ``0 <= tau_n - tau_d < T_p``, else 0.
- ``dechirp``: the echo is mixed with the conjugate of a long reference chirp delayed by
  ``tau_ref = gate``; with ``Delta = tau_d - tau_ref`` and ``u_n = (n - N/2) / f_s`` (sample
  time relative to ``tau_ref + T_p/2``) the beat signal is
  ``a exp(-j 2 pi f_c Delta) exp(-j 2 pi K_s Delta u_n) exp(j pi K_s Delta**2)`` while
  ``Delta - T_p/2 <= u_n < Delta + T_p/2``, else 0 (the last factor is the residual video
  phase).

A receiver with ``radar.iq_conjugate`` (spectral inversion) delivers the complex conjugate of
these samples (noise included).

:func:`sarmoco.processing.rangecomp.compress` inverts both so that a target at range R peaks
at R with phase ``exp(-j 4 pi R / lambda)``.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, IntArray, RadarParams


@numba.njit(cache=True)
def _matched_kernel(
    out: np.ndarray,
    ranges: np.ndarray,
    weights: np.ndarray,
    gate: float,
    fs: float,
    tp: float,
    chirp_rate: float,
    wavelength: float,
) -> None:
    n_p, n_k = ranges.shape
    n_s = out.shape[1]
    for p in range(n_p):
        for k in range(n_k):
            w = weights[p, k]
            if w == 0:
                continue
            r = ranges[p, k]
            tau_d = 2.0 * r / C_MPS
            n0 = max(0, math.ceil((tau_d - gate) * fs))
            n1 = min(n_s, math.ceil((tau_d + tp - gate) * fs))
            carrier = -4.0 * math.pi * r / wavelength
            for n in range(n0, n1):
                u = gate + n / fs - tau_d - 0.5 * tp
                ph = math.pi * chirp_rate * u * u + carrier
                out[p, n] += w * complex(math.cos(ph), math.sin(ph))


@numba.njit(cache=True)
def _dechirp_kernel(
    out: np.ndarray,
    ranges: np.ndarray,
    weights: np.ndarray,
    gate: float,
    fs: float,
    tp: float,
    chirp_rate: float,
    carrier_hz: float,
) -> None:
    n_p, n_k = ranges.shape
    n_s = out.shape[1]
    half = n_s // 2
    for p in range(n_p):
        for k in range(n_k):
            w = weights[p, k]
            if w == 0:
                continue
            delta = 2.0 * ranges[p, k] / C_MPS - gate
            n0 = max(0, math.ceil((delta - 0.5 * tp) * fs) + half)
            n1 = min(n_s, math.ceil((delta + 0.5 * tp) * fs) + half)
            const = -2.0 * math.pi * carrier_hz * delta + math.pi * chirp_rate * delta * delta
            slope = -2.0 * math.pi * chirp_rate * delta
            for n in range(n0, n1):
                ph = const + slope * ((n - half) / fs)
                out[p, n] += w * complex(math.cos(ph), math.sin(ph))


def slant_ranges(apc_ned: FloatArray, targets_ned: FloatArray) -> FloatArray:
    """Exact APC-to-target distances, shape (P, K), m."""
    return np.asarray(
        np.linalg.norm(targets_ned[None, :, :] - apc_ned[:, None, :], axis=-1), dtype=np.float64
    )


def noise_sigma(snr_db: float) -> float:
    """Noise standard deviation per complex sample for a unit target at ``snr_db`` per sample."""
    return float(10.0 ** (-snr_db / 20.0))


def synthesize(
    radar: RadarParams,
    t_ns: IntArray,
    apc_ned: FloatArray,
    targets_ned: FloatArray,
    amplitudes: npt.ArrayLike,
    snr_db: float | None,
    rng: np.random.Generator,
    illumination: FloatArray | None = None,
) -> ComplexArray:
    """Raw complex-baseband echoes of point targets (see the module docstring).

    Parameters
    ----------
    radar : RadarParams
        Waveform and receive chain (``matched`` or ``dechirp``, chirp direction, I/Q
        conjugation).
    t_ns : ndarray of int64, shape (P,)
        Transmit time of each pulse, GPS ns (the echo depends on time only through ``apc_ned``).
    apc_ned : ndarray of float64, shape (P, 3)
        True APC at each pulse (stop-and-hop), NED, m.
    targets_ned : ndarray of float64, shape (K, 3)
        Scatterer positions, NED, m.
    amplitudes : ndarray of complex, shape (K,)
        Scatterer amplitudes (per sample, before compression).
    snr_db : float or None
        Per-sample SNR of a unit-amplitude target; complex white Gaussian noise of variance
        ``10**(-snr_db/10)`` is added. None: no noise.
    rng : numpy.random.Generator
        Noise source.
    illumination : ndarray of float64, shape (P, K), optional
        Two-way antenna weight per pulse and target (e.g. ``Scenario.illumination``);
        default 1.

    Returns
    -------
    ndarray of complex64, shape (P, radar.n_samples)
    """
    apc = np.ascontiguousarray(apc_ned, dtype=np.float64)
    tgt = np.ascontiguousarray(targets_ned, dtype=np.float64).reshape(-1, 3)
    amp = np.asarray(amplitudes, dtype=np.complex128).reshape(-1)
    n_p = apc.shape[0]
    if apc.shape != (n_p, 3) or np.shape(t_ns) != (n_p,) or amp.shape != (tgt.shape[0],):
        raise ProcessingError(
            f"synthesize: shapes t{np.shape(t_ns)} apc{apc.shape} targets{tgt.shape} "
            f"amplitudes{amp.shape} disagree (want (P,), (P,3), (K,3), (K,))"
        )
    weights = amp[None, :] * (1.0 if illumination is None else illumination)
    weights = np.ascontiguousarray(np.broadcast_to(weights, (n_p, tgt.shape[0])))
    ranges = slant_ranges(apc, tgt)
    echo = np.zeros((n_p, radar.n_samples), dtype=np.complex64)
    args = (radar.range_gate_delay_s, radar.sample_rate_hz, radar.pulse_width_s)
    k_s = radar.signed_chirp_rate_hz_per_s
    if radar.receive == "matched":
        _matched_kernel(echo, ranges, weights, *args, k_s, radar.wavelength_m)
    else:
        _dechirp_kernel(echo, ranges, weights, *args, k_s, radar.carrier_hz)
    if snr_db is not None:
        sigma = noise_sigma(snr_db) / math.sqrt(2.0)
        noise = rng.standard_normal((n_p, radar.n_samples, 2), dtype=np.float32) * np.float32(sigma)
        echo += noise.view(np.complex64)[..., 0]
    if radar.iq_conjugate:
        np.conjugate(echo, out=echo)
    return echo
