"""Echoes of a MIMO downward-looking array over a terrain of scatterers (docs/methods.md §4).

Terrain: a DEM (heights on a regular north/east grid) becomes scatterers with circular
complex Gaussian reflectivity, several per DEM cell at random positions inside it and on the
bilinear surface (:func:`terrain_scatterers`). :func:`peaks_dem` is the array paper's
synthetic surface of three peaks and two valleys (MATLAB's ``peaks`` over [-3, 3]², scaled
to -39.2977..48.6260 m).

Echo of channel c = m N + n (tx-major) at pulse p (stop-and-hop, exact distances):
a scatterer at ``q`` with reflectivity a contributes, for ``0 <= τ_n - τ_d < T_p``,

    a g exp(j π K_s (τ_n - τ_d - T_p/2)²) exp(-j 2π f_c τ_d),   τ_d = (|q - tx_m| + |q - rx_n|) / c

the bistatic form of :mod:`sarmoco.sim.echo`'s matched echo, so that range compression puts
it at ``(R_tx + R_rx)/2`` with phase ``exp(-j k (R_tx + R_rx))``. g is the two-way antenna
weight, evaluated in the body frame from the INS reference point: ``sinc²(D u_x / λ)`` along
track inside the main lobe ``|u_x| < λ/D`` (antenna length D) and 1 across track for look
angles within ``max_look_rad`` of the body z axis, 0 outside. Element positions and the
attitude come per pulse (``p + R(q) b``), so a constant roll and a roll series are the same
call.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.array.geometry import ArrayLayout, element_positions_ned, euler_to_quat
from sarmoco.processing.geometry import quat_to_matrix
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, RadarParams

PAPER_DEM_RANGE_M = (-39.2977, 48.6260)
"""Elevation range of the array paper's synthetic terrain, m."""


def peaks_dem(n_north: int, n_east: int) -> FloatArray:
    """The three-peak / two-valley surface on an (n_north, n_east) grid, heights in m.

    MATLAB's ``peaks`` over [-3, 3] on both axes (north along the first), mapped linearly so
    that its minimum and maximum on this grid are the paper's -39.2977 m and 48.6260 m.
    """
    if n_north < 3 or n_east < 3:
        raise ProcessingError(f"peaks_dem: grid {n_north}x{n_east} is smaller than 3x3")
    u = np.linspace(-3.0, 3.0, n_east)[None, :]
    v = np.linspace(-3.0, 3.0, n_north)[:, None]
    z = (
        3.0 * (1.0 - u) ** 2 * np.exp(-(u**2) - (v + 1.0) ** 2)
        - 10.0 * (u / 5.0 - u**3 - v**5) * np.exp(-(u**2) - v**2)
        - np.exp(-((u + 1.0) ** 2) - v**2) / 3.0
    )
    lo, hi = PAPER_DEM_RANGE_M
    return np.asarray(lo + (z - z.min()) * (hi - lo) / (z.max() - z.min()), dtype=np.float64)


def terrain_scatterers(
    height_m: FloatArray,
    spacing_m: float,
    origin_ne_m: tuple[float, float],
    per_cell: int,
    rng: np.random.Generator,
) -> tuple[FloatArray, ComplexArray]:
    """Scatterers on a DEM surface.

    Parameters
    ----------
    height_m : ndarray of float64, shape (n_north, n_east)
        Heights above the NED origin (up = -down), m, at ``origin + (i, j) * spacing``.
    spacing_m : float
        Grid spacing, m (> 0), equal along north and east.
    origin_ne_m : (float, float)
        North and east of sample (0, 0), m.
    per_cell : int
        Scatterers per grid cell (>= 1), uniformly placed in the cell.
    rng : numpy.random.Generator
        Source of positions and reflectivities.

    Returns
    -------
    targets_ned : ndarray of float64, shape (K, 3)
        Scatterer positions, NED, m (down = -height, bilinear between grid samples).
    amplitudes : ndarray of complex128, shape (K,)
        Circular complex Gaussian reflectivities, unit mean power.
    """
    h = np.asarray(height_m, dtype=np.float64)
    if h.ndim != 2 or min(h.shape) < 2 or not np.all(np.isfinite(h)):
        raise ProcessingError(
            f"terrain_scatterers: height shape {h.shape} is not a finite 2-D grid"
        )
    if not spacing_m > 0.0 or per_cell < 1:
        raise ProcessingError(
            f"terrain_scatterers: spacing_m {spacing_m!r} or per_cell {per_cell!r} is not > 0"
        )
    n0, n1 = h.shape
    k = (n0 - 1) * (n1 - 1) * per_cell
    i = np.repeat(np.arange(n0 - 1), (n1 - 1) * per_cell) + rng.random(k)
    j = np.tile(np.repeat(np.arange(n1 - 1), per_cell), n0 - 1) + rng.random(k)
    i0, j0 = np.floor(i).astype(np.int64), np.floor(j).astype(np.int64)
    fi, fj = i - i0, j - j0
    z = (
        h[i0, j0] * (1 - fi) * (1 - fj)
        + h[i0 + 1, j0] * fi * (1 - fj)
        + h[i0, j0 + 1] * (1 - fi) * fj
        + h[i0 + 1, j0 + 1] * fi * fj
    )
    targets = np.stack([origin_ne_m[0] + i * spacing_m, origin_ne_m[1] + j * spacing_m, -z], axis=1)
    amp = (rng.standard_normal(k) + 1j * rng.standard_normal(k)) / math.sqrt(2.0)
    return targets, amp


@numba.njit(cache=True, parallel=True)
def _array_kernel(
    out: np.ndarray,
    tx: np.ndarray,
    rx: np.ndarray,
    ref: np.ndarray,
    rot: np.ndarray,
    targets: np.ndarray,
    amps: np.ndarray,
    gate: float,
    fs: float,
    tp: float,
    chirp_rate: float,
    carrier_hz: float,
    wavelength: float,
    antenna_length: float,
    tan_max_look: float,
) -> None:
    n_p, n_tx = tx.shape[0], tx.shape[1]
    n_rx = rx.shape[1]
    n_s = out.shape[2]
    n_k = targets.shape[0]
    u_max = wavelength / antenna_length
    dt = 1.0 / fs
    step2 = complex(
        math.cos(2.0 * math.pi * chirp_rate * dt * dt),
        math.sin(2.0 * math.pi * chirp_rate * dt * dt),
    )
    for p in numba.prange(n_p):
        rt = np.empty(n_tx)
        rr = np.empty(n_rx)
        for k in range(n_k):
            d0 = targets[k, 0] - ref[p, 0]
            d1 = targets[k, 1] - ref[p, 1]
            d2 = targets[k, 2] - ref[p, 2]
            r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            # body-frame direction (R^T d)
            bx = (rot[p, 0, 0] * d0 + rot[p, 1, 0] * d1 + rot[p, 2, 0] * d2) / r
            if abs(bx) >= u_max:
                continue
            by = rot[p, 0, 1] * d0 + rot[p, 1, 1] * d1 + rot[p, 2, 1] * d2
            bz = rot[p, 0, 2] * d0 + rot[p, 1, 2] * d1 + rot[p, 2, 2] * d2
            if bz <= 0.0 or abs(by) > tan_max_look * bz:
                continue
            s = math.pi * antenna_length * bx / wavelength
            g = 1.0 if s == 0.0 else (math.sin(s) / s) ** 2
            w = amps[k] * g
            for m in range(n_tx):
                e0 = targets[k, 0] - tx[p, m, 0]
                e1 = targets[k, 1] - tx[p, m, 1]
                e2 = targets[k, 2] - tx[p, m, 2]
                rt[m] = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            for n in range(n_rx):
                e0 = targets[k, 0] - rx[p, n, 0]
                e1 = targets[k, 1] - rx[p, n, 1]
                e2 = targets[k, 2] - rx[p, n, 2]
                rr[n] = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
            for m in range(n_tx):
                for n in range(n_rx):
                    tau_d = (rt[m] + rr[n]) / C_MPS
                    n0 = max(0, math.ceil((tau_d - gate) * fs))
                    n1 = min(n_s, math.ceil((tau_d + tp - gate) * fs))
                    if n1 <= n0:
                        continue
                    u = gate + n0 * dt - tau_d - 0.5 * tp
                    ph = math.pi * chirp_rate * u * u - 2.0 * math.pi * carrier_hz * tau_d
                    z = w * complex(math.cos(ph), math.sin(ph))
                    ph1 = math.pi * chirp_rate * (2.0 * u * dt + dt * dt)
                    ratio = complex(math.cos(ph1), math.sin(ph1))
                    c = m * n_rx + n
                    for i in range(n0, n1):
                        out[p, c, i] += z
                        z *= ratio
                        ratio *= step2


def synthesize_array(
    radar: RadarParams,
    layout: ArrayLayout,
    pos_ned: FloatArray,
    quat: FloatArray,
    targets_ned: FloatArray,
    amplitudes: ComplexArray,
    antenna_length_m: float,
    max_look_rad: float,
    snr_db: float | None = None,
    rng: np.random.Generator | None = None,
) -> ComplexArray:
    """Raw matched-receive echoes of every Tx/Rx pair (module docstring).

    Parameters
    ----------
    radar : RadarParams
        Waveform and receive window (``receive`` must be ``"matched"``; chirp direction and
        ``iq_conjugate`` honoured).
    layout : ArrayLayout
        Transmitter and receiver positions in the body frame.
    pos_ned : ndarray of float64, shape (P, 3)
        True INS reference-point position at each pulse, NED, m.
    quat : ndarray of float64, shape (P, 4)
        True attitude at each pulse, scalar-first body-to-NED quaternion (a constant roll
        or a roll series alike).
    targets_ned : ndarray of float64, shape (K, 3)
        Scatterers, NED, m.
    amplitudes : ndarray of complex, shape (K,)
        Scatterer reflectivities.
    antenna_length_m : float
        Along-track length D of the elements, m: two-way pattern sinc²(D u_x / λ), main lobe.
    max_look_rad : float
        Largest look angle off the body z axis across track, rad (the paper: 20°).
    snr_db : float, optional
        Per-sample SNR of a unit scatterer; complex white Gaussian noise added. None: none.
    rng : numpy.random.Generator, optional
        Noise source (required with ``snr_db``).

    Returns
    -------
    ndarray of complex64, shape (P, M N, radar.n_samples)
        Echoes [pulse, channel, fast time], channel c = m N + n (tx-major).
    """
    if radar.receive != "matched":
        raise ProcessingError("synthesize_array: radar.receive must be 'matched'")
    if not antenna_length_m > 0.0 or not 0.0 < max_look_rad < math.pi / 2.0:
        raise ProcessingError(
            f"synthesize_array: antenna_length_m {antenna_length_m!r} or max_look_rad "
            f"{max_look_rad!r} out of range"
        )
    pos = np.ascontiguousarray(pos_ned, dtype=np.float64)
    q = np.ascontiguousarray(quat, dtype=np.float64)
    tgt = np.ascontiguousarray(targets_ned, dtype=np.float64).reshape(-1, 3)
    amp = np.ascontiguousarray(amplitudes, dtype=np.complex128).reshape(-1)
    if amp.shape != (tgt.shape[0],):
        raise ProcessingError(
            f"synthesize_array: amplitudes{amp.shape} and targets{tgt.shape} disagree"
        )
    tx = element_positions_ned(pos, q, layout.tx_body_m)
    rx = element_positions_ned(pos, q, layout.rx_body_m)
    rot = np.ascontiguousarray(quat_to_matrix(q))
    out = np.zeros((pos.shape[0], layout.n_channels, radar.n_samples), dtype=np.complex64)
    _array_kernel(
        out, tx, rx, pos, rot, tgt, amp,
        radar.range_gate_delay_s, radar.sample_rate_hz, radar.pulse_width_s,
        radar.signed_chirp_rate_hz_per_s, radar.carrier_hz, radar.wavelength_m,
        float(antenna_length_m), math.tan(max_look_rad),
    )  # fmt: skip
    if snr_db is not None:
        if rng is None:
            raise ProcessingError("synthesize_array: snr_db needs an rng")
        sigma = np.float32(10.0 ** (-snr_db / 20.0) / math.sqrt(2.0))
        noise = rng.standard_normal((*out.shape, 2), dtype=np.float32) * sigma
        out += noise.view(np.complex64)[..., 0]
    if radar.iq_conjugate:
        np.conjugate(out, out=out)
    return out


def level_strip(
    n_pulses: int,
    prf_hz: float,
    speed_mps: float,
    altitude_m: float,
    north0_m: float,
    roll_rad: FloatArray | float = 0.0,
    t0_ns: int = 1_000_000_000_000,
) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """A straight, level pass due north at constant speed, with a roll per pulse.

    Parameters
    ----------
    n_pulses : int
        Number of pulses P.
    prf_hz, speed_mps, altitude_m : float
        Pulse rate, Hz; ground speed, m/s; height above the NED origin, m.
    north0_m : float
        North of the first pulse, m (east is 0).
    roll_rad : float or ndarray of shape (P,)
        Roll at each pulse (right wing down positive), rad; pitch and yaw are 0.
    t0_ns : int
        GPS time of the first pulse, ns.

    Returns
    -------
    t_ns : ndarray of int64, shape (P,)
    pos_ned : ndarray of float64, shape (P, 3)
    quat : ndarray of float64, shape (P, 4)
        Scalar-first body-to-NED attitude.
    """
    if n_pulses < 2 or not prf_hz > 0.0:
        raise ProcessingError(f"level_strip: n_pulses {n_pulses!r} or prf_hz {prf_hz!r} invalid")
    k = np.arange(n_pulses)
    t_ns = t0_ns + np.round(k * 1e9 / prf_hz).astype(np.int64)
    pos = np.zeros((n_pulses, 3))
    pos[:, 0] = north0_m + speed_mps * (t_ns - t0_ns) * 1e-9
    pos[:, 2] = -altitude_m
    roll = np.broadcast_to(np.asarray(roll_rad, dtype=np.float64), (n_pulses,))
    return t_ns, pos, euler_to_quat(roll, 0.0, 0.0)


@dataclass(frozen=True)
class ArrayStrip:
    """A simulated pass of the array over a DEM.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    pos_ned : ndarray of float64, shape (P, 3)
        True INS reference-point positions, NED, m.
    quat : ndarray of float64, shape (P, 4)
        True attitude, scalar-first body-to-NED.
    echoes : ndarray of complex64, shape (P, M N, S)
        Raw echoes [pulse, channel (tx-major), fast time].
    """

    t_ns: np.ndarray
    pos_ned: FloatArray
    quat: FloatArray
    echoes: ComplexArray


def aperture_m(wavelength_m: float, antenna_length_m: float, far_range_m: float) -> float:
    """Along-track extent over which a point at ``far_range_m`` is in the main lobe, m."""
    return 2.0 * far_range_m * wavelength_m / antenna_length_m


def simulate_strip(
    radar: RadarParams,
    layout: ArrayLayout,
    antenna_length_m: float,
    max_look_rad: float,
    speed_mps: float,
    height_m: FloatArray,
    spacing_m: float,
    origin_ne_m: tuple[float, float],
    altitude_m: float,
    north_range_m: tuple[float, float],
    roll_rad: float | Callable[[np.ndarray], np.ndarray],
    per_cell: int = 2,
    seed: int = 0,
) -> ArrayStrip:
    """Echoes of a level pass due north (east 0) over a DEM, covering ``north_range_m``.

    The pass starts and ends half an aperture beyond ``north_range_m`` (so every point in
    it is seen over the whole main lobe); only scatterers within that reach are simulated.

    Parameters
    ----------
    radar, layout, antenna_length_m, max_look_rad
        As :func:`synthesize_array`.
    speed_mps : float
        Ground speed, m/s.
    height_m, spacing_m, origin_ne_m, per_cell
        The DEM and scatterer density, as :func:`terrain_scatterers`.
    altitude_m : float
        Platform height above the NED origin, m.
    north_range_m : (float, float)
        North extent of the strip to image, m.
    roll_rad : float or callable
        True roll, rad: constant, or a function of the time since the first pulse (s, array)
        returning one roll per pulse.
    seed : int
        Seed of the scatterers' positions and reflectivities.
    """
    rng = np.random.default_rng(seed)
    targets, amp = terrain_scatterers(height_m, spacing_m, origin_ne_m, per_cell, rng)
    far = (altitude_m - float(np.min(height_m))) / math.cos(max_look_rad) + 10.0
    half = 0.5 * aperture_m(radar.wavelength_m, antenna_length_m, far)
    lo, hi = north_range_m
    keep = (targets[:, 0] >= lo - half) & (targets[:, 0] <= hi + half)
    step = speed_mps / radar.prf_hz
    n_p = int((hi - lo + 2.0 * half) / step) + 1
    roll = roll_rad(np.arange(n_p) / radar.prf_hz) if callable(roll_rad) else roll_rad
    t, pos, quat = level_strip(n_p, radar.prf_hz, speed_mps, altitude_m, lo - half, roll)
    echoes = synthesize_array(
        radar, layout, pos, quat, targets[keep], amp[keep], antenna_length_m, max_look_rad
    )
    return ArrayStrip(t, pos, quat, echoes)
