"""Attitude (roll) error of the virtual array: ΔR in wavenumbers, ΔR1 and ΔR2 compensation.

Imaging frame (docs/methods.md §1): x along track, y cross-track (right), z down. The ideal
virtual array at pulse p is the line ``(x_p, y_n, 0)``; INS position and attitude put EPC n at
``(x_p, y_n, 0) + δ_pn`` (:func:`epc_deviation`). For a target in the unit direction u from
the element (u_z > 0 toward the ground) the range changes, to first order in |δ|/R, by

    ΔR = -u · δ.

For a pure roll α the EPC moves to ``(x, y_n cos α, y_n sin α)``, δ = (0, y_n (cos α - 1),
y_n sin α), and this is the paper's ``ΔR = y_n [(y0/R)(1 - cos α) - (z0/R) sin α]`` with
y0/R = u_y, z0/R = u_z. The direction is fixed by the echo's wavenumbers, not by the target:
the echo of EPC n carries ``exp(-j k_r R)`` (k_r = 4π f/c, the two-way range wavenumber),
whose local along-track and cross-track wavenumbers are ``k_x = k_r (x0 - x)/R`` and
``k_y = k_r (y0 - y_n)/R`` (numpy's FFT sign), so

    u = (k_x / k_r, k_y / k_r, sqrt(1 - (k_x/k_r)² - (k_y/k_r)²))

(:func:`direction_from_wavenumbers`; the paper's y_n/R term is dropped: after the near-field
correction of the imager the array is phased as seen from infinity). The split:

- ΔR1 = -δ_z, ΔR at nadir (u = (0, 0, 1)), independent of wavenumber: removed per pulse and
  element with ``exp(+j k_r ΔR1)`` ("first compensation");
- ΔR2 = ΔR - ΔR1 = -(u_x δ_x + u_y δ_y + (u_z - 1) δ_z): the (k_x, k_y) plane is cut into
  M × N sub-blocks, each block taken back to (x, y_n) alone and multiplied by
  ``exp(+j k_r ΔR2(block centre))`` per pulse and element, the blocks summed ("second
  compensation"). Applying the phase in space after the block's inverse transform lets δ
  vary from pulse to pulse (a roll series), as long as it is slow over one aperture.

Both are applied in the range-frequency domain with each bin's own k_r (the paper applies
ΔR1 at the carrier; with k_r the envelope moves too).
"""

from __future__ import annotations

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.array.geometry import ArrayLayout, element_positions_ned
from sarmoco.processing.geometry import ReferenceTrack, ned_to_imaging
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray


def epc_deviation(
    t_ns: IntArray,
    pos_ned: FloatArray,
    quat: FloatArray,
    layout: ArrayLayout,
    track: ReferenceTrack,
) -> FloatArray:
    """Actual minus ideal EPC per pulse and channel, imaging frame, (P, C, 3), m.

    The ideal EPC of channel c at pulse p is ``(x_ref(t_p), y_c, 0)``: the reference track's
    along-track position at the pulse time and the EPC's body y, level and on track. The
    actual one is ``pos + R(q) epc_body`` (exterior orientation, R = R_κ R_ω R_α) in the
    imaging frame, so δ holds the linear errors (the INS point off the reference track) and
    the angular ones (roll, pitch, yaw moving each element differently).
    """
    epc_body = layout.epc_body_m
    actual = ned_to_imaging(element_positions_ned(pos_ned, quat, epc_body), track)
    ideal = np.zeros_like(actual)
    ideal[..., 0] = track.position_imaging(np.asarray(t_ns, dtype=np.int64))[:, 0][:, None]
    ideal[..., 1] = epc_body[None, :, 1]
    return np.asarray(actual - ideal, dtype=np.float64)


def direction_from_wavenumbers(
    kx: FloatArray | float, ky: FloatArray | float, kr: FloatArray | float
) -> FloatArray:
    """Unit direction element -> target from the echo's wavenumbers, (..., 3).

    Parameters
    ----------
    kx, ky : float or ndarray
        Along-track and cross-track wavenumbers, rad/m (numpy FFT sign).
    kr : float or ndarray
        Two-way range wavenumber 4π f / c, rad/m.

    Returns
    -------
    ndarray
        (u_x, u_y, u_z) with u_z = sqrt(1 - u_x² - u_y²) >= 0 (clipped at 0 beyond the
        visible region).
    """
    ux = np.asarray(kx, dtype=np.float64) / np.asarray(kr, dtype=np.float64)
    uy = np.asarray(ky, dtype=np.float64) / np.asarray(kr, dtype=np.float64)
    ux, uy = np.broadcast_arrays(ux, uy)
    uz = np.sqrt(np.clip(1.0 - ux * ux - uy * uy, 0.0, None))
    return np.stack([ux, uy, uz], axis=-1)


def range_error_m(deviation_m: FloatArray, direction: FloatArray) -> FloatArray:
    """First-order range change ``ΔR = -u · δ`` of an element moved by δ, m.

    Parameters
    ----------
    deviation_m : ndarray, shape (..., 3)
        Element displacement δ, imaging frame, m.
    direction : ndarray, shape (..., 3)
        Unit direction u from the element to the target (broadcast against δ).
    """
    return np.asarray(-np.sum(np.asarray(deviation_m) * np.asarray(direction), axis=-1))


def mean_roll_sine(deviation_m: FloatArray, y_m: FloatArray) -> float:
    """Least-squares slope of δ_z against the EPCs' y over all pulses: ≈ sin(mean roll)."""
    y = np.asarray(y_m, dtype=np.float64) - float(np.mean(y_m))
    dz = np.asarray(deviation_m, dtype=np.float64)[..., 2]
    return float(np.mean(dz @ y) / float(y @ y))


def _block_edges(n_bins: int, n_blocks: int, what: str) -> IntArray:
    if not 1 <= n_blocks <= n_bins:
        raise ProcessingError(f"roll compensation: {what} blocks {n_blocks!r} not in 1..{n_bins}")
    return np.round(np.linspace(0, n_bins, n_blocks + 1)).astype(np.int64)


def compensate(
    spec: ComplexArray,
    deviation_m: FloatArray,
    y_order: IntArray,
    kr: FloatArray,
    dx_m: float,
    dy_m: float,
    blocks: tuple[int, int] = (1, 8),
    ky_centre: float = 0.0,
) -> ComplexArray:
    """Remove ΔR1 and ΔR2 (module docstring) from range-frequency echoes, in place.

    Parameters
    ----------
    spec : ndarray of complex64, shape (P, C, F)
        Echoes of the virtual array (EPC phase corrected) in the range-frequency domain,
        pulses uniformly spaced along track.
    deviation_m : ndarray, shape (P, C, 3)
        EPC deviations δ (:func:`epc_deviation`), imaging frame, m.
    y_order : ndarray of int, shape (C,)
        Channel indices sorting the EPCs by increasing y (the virtual array order).
    kr : ndarray, shape (F,)
        Two-way range wavenumber of each frequency bin, 4π (f_c + f)/c, rad/m.
    dx_m, dy_m : float
        Pulse spacing along track and virtual-array spacing, m.
    blocks : (int, int)
        Sub-block counts (M along k_x, N along k_y); (1, 1) applies ΔR2 at the centre
        wavenumber only.
    ky_centre : float
        Centre of the k_y interval the FFT bins are unwrapped to, rad/m (a roll α turns the
        elements' boresight to sin θ = -sin α, the echo's k_y band to -k_r sin α; centring
        on it keeps the band unwrapped).

    Returns
    -------
    ndarray of complex64, shape (P, C, F)
        The compensated echoes (``spec`` itself, overwritten).
    """
    n_p, n_c, n_f = spec.shape
    if deviation_m.shape != (n_p, n_c, 3) or kr.shape != (n_f,) or y_order.shape != (n_c,):
        raise ProcessingError(
            f"roll compensation: shapes spec{spec.shape} deviation{deviation_m.shape} "
            f"kr{kr.shape} y_order{y_order.shape} disagree"
        )
    m_blocks, n_blocks = blocks
    kr32 = kr.astype(np.float32)
    dev = deviation_m[:, y_order, :]
    data = spec[:, y_order, :]
    # first compensation: ΔR1 = -δ_z per pulse and element, exp(+j k_r ΔR1)
    data *= np.exp(1j * (-dev[..., 2]).astype(np.float32)[..., None] * kr32).astype(np.complex64)
    # second compensation on (k_x, k_y) sub-blocks
    axes = (0, 1) if m_blocks > 1 else (1,)
    wspec = scipy.fft.fftn(data, axes=axes, workers=-1)
    kx = 2.0 * np.pi * scipy.fft.fftfreq(n_p, dx_m)
    ky = 2.0 * np.pi * scipy.fft.fftfreq(n_c, dy_m)
    period = 2.0 * np.pi / dy_m
    ky = ky_centre + np.mod(ky - ky_centre + period / 2.0, period) - period / 2.0
    kc = float(np.mean(kr))
    order_x = np.argsort(kx)
    order_y = np.argsort(ky)
    out = np.zeros_like(data)
    ex = _block_edges(n_p, m_blocks, "along-track")
    ey = _block_edges(n_c, n_blocks, "cross-track")
    for i in range(m_blocks):
        sel_x = order_x[ex[i] : ex[i + 1]]
        kx_c = float(np.mean(kx[sel_x])) if m_blocks > 1 else 0.0
        for j in range(n_blocks):
            sel_y = order_y[ey[j] : ey[j + 1]]
            ky_c = float(np.mean(ky[sel_y]))
            u = direction_from_wavenumbers(kx_c, ky_c, kc)
            block = np.zeros_like(wspec)
            if m_blocks > 1:
                block[np.ix_(sel_x, sel_y)] = wspec[np.ix_(sel_x, sel_y)]
            else:
                block[:, sel_y] = wspec[:, sel_y]
            back = scipy.fft.ifftn(block, axes=axes, workers=-1)
            dr2 = -(u[0] * dev[..., 0] + u[1] * dev[..., 1] + (u[2] - 1.0) * dev[..., 2])
            back *= np.exp(1j * dr2.astype(np.float32)[..., None] * kr32).astype(np.complex64)
            out += back
    spec[:, y_order, :] = out
    return spec
