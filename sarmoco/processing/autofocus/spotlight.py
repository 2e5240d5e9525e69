"""Per-pulse autofocus of a deramped spotlight phase history (GOTCHA-like data).

A spotlight phase history is already deramped to a per-pulse reference range, so a motion
error along the line of sight d_p (m) multiplies pulse p by ``exp(-j 4π f d_p / c)`` at every
frequency f: a phase at the carrier and a range (envelope) shift. The estimator is the
backprojection form of PGA's maximum-likelihood step: at the Q brightest pixels q of the
current image, pulse p's contribution ``c_pq = Σ_f ph[p, f] exp(j 4π f (|x_q - apc_p| - r0_p) / c)``
is compared with the pixel value ``I_q = Σ_p c_pq``; the phase ``φ_p = arg Σ_q c_pq conj(I_q)``
maximises the energy of those pixels. Iterated with the correction applied, it converges
like PGA with a window shrunk to the resolution cell.

The estimator is phase only: an envelope error of a few range cells decorrelates a pulse's
contribution from the bright pixel. :func:`spotlight_two_step` therefore first aligns the range
profiles (:func:`~sarmoco.processing.autofocus.range_alignment.align_ranges`, envelope step),
then repeats the phase estimator on a fresh image, re-selecting the bright pixels each time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.autofocus.range_alignment import align_ranges
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray


@dataclass
class SpotlightResult:
    """What :func:`spotlight_autofocus` estimated.

    Parameters
    ----------
    los_m : ndarray, shape (P,)
        LOS displacement removed from each pulse over the whole band (envelope and phase), m.
    phase_rad : ndarray, shape (P,)
        Further carrier phase removed from each pulse, rad.
    rms_updates_rad : list of float
        RMS phase update of each iteration, rad.
    """

    los_m: FloatArray
    phase_rad: FloatArray
    rms_updates_rad: list[float] = field(default_factory=list)

    def apply(self, ph: ComplexArray, freq_hz: FloatArray) -> ComplexArray:
        """Remove the estimated error from a phase history (P, F)."""
        ramp = 4.0 * np.pi * freq_hz[None, :] * self.los_m[:, None] / C_MPS
        return (ph * np.exp(1j * ramp - 1j * self.phase_rad[:, None])).astype(ph.dtype)


def pulse_contributions(
    ph: ComplexArray, freq_hz: FloatArray, apc_m: FloatArray, r0_m: FloatArray, pix_m: FloatArray
) -> ComplexArray:
    """Contribution of every pulse to every pixel, shape (P, Q): exact float64 backprojection.

    The frequencies are taken as the uniform grid fitted to ``freq_hz`` (first value and mean
    step), so the sum over frequency is a polynomial in ``exp(j 4π df Δr / c)`` (Horner).
    """
    d_r = np.linalg.norm(pix_m[None, :, :] - apc_m[:, None, :], axis=2) - r0_m[:, None]
    n_f = freq_hz.size
    step = np.exp(4j * np.pi / C_MPS * d_r * (freq_hz[-1] - freq_hz[0]) / (n_f - 1))
    ph64 = ph.astype(np.complex128)
    out = np.zeros(d_r.shape, dtype=np.complex128)
    for k in range(n_f - 1, -1, -1):
        out = out * step + ph64[:, k, None]
    return out * np.exp(4j * np.pi / C_MPS * d_r * freq_hz[0])


def _detrend(y: FloatArray) -> FloatArray:
    k = np.arange(y.size, dtype=float)
    return np.asarray(y - np.polyval(np.polyfit(k, y, 1), k), dtype=float)


def spotlight_autofocus(
    ph: ComplexArray,
    freq_hz: FloatArray,
    apc_m: FloatArray,
    r0_m: FloatArray,
    pixels_m: FloatArray,
    image: ComplexArray,
    n_pixels: int = 200,
    max_iter: int = 8,
    tol_rad: float = 0.01,
) -> SpotlightResult:
    """Estimate a per-pulse carrier phase error of a deramped spotlight phase history.

    Parameters
    ----------
    ph : ndarray, shape (P, F)
        Phase history deramped to ``r0_m``.
    freq_hz : ndarray, shape (F,)
        Frequencies, Hz, ascending.
    apc_m, r0_m : ndarray, shapes (P, 3), (P,)
        Antenna phase centres (scene frame, m) and reference ranges, m.
    pixels_m : ndarray, shape (N, 3)
        Scene-frame positions of the pixels of ``image`` (flattened), m.
    image : ndarray, shape (N,)
        An image of the data on those pixels (the brightest ``n_pixels`` are used).
    max_iter, tol_rad
        At most ``max_iter`` iterations; stop when the RMS update is under ``tol_rad``, rad.

    Returns
    -------
    SpotlightResult
        ``phase_rad`` with zero mean and trend (a linear phase only moves the image);
        ``los_m`` is zero.
    """
    if ph.shape != (apc_m.shape[0], freq_hz.size) or pixels_m.shape[0] != image.size:
        raise ProcessingError(
            f"spotlight_autofocus: ph {ph.shape}, freq {freq_hz.shape}, apc {apc_m.shape}, "
            f"pixels {pixels_m.shape}, image {image.shape} disagree"
        )
    pix = pixels_m[np.argsort(np.abs(image))[::-1][:n_pixels]]
    contrib = pulse_contributions(ph, freq_hz, apc_m, r0_m, pix)
    phi = np.zeros(ph.shape[0])
    updates: list[float] = []
    for _ in range(max_iter):
        corrected = contrib * np.exp(-1j * phi)[:, None]
        img = corrected.sum(axis=0)
        upd = _detrend(np.angle(np.sum(corrected * np.conj(img)[None, :], axis=1)))
        phi += upd
        updates.append(float(np.sqrt(np.mean(upd**2))))
        if updates[-1] < tol_rad:
            break
    return SpotlightResult(np.zeros(ph.shape[0]), _detrend(phi), updates)


def spotlight_two_step(
    ph: ComplexArray,
    freq_hz: FloatArray,
    apc_m: FloatArray,
    r0_m: FloatArray,
    pixels_m: FloatArray,
    form_image: Callable[[ComplexArray], ComplexArray],
    n_pixels: int = 200,
    max_outer: int = 6,
    tol_rad: float = 0.03,
) -> SpotlightResult:
    """Envelope alignment, then the phase estimator repeated on fresh images.

    Parameters
    ----------
    ph, freq_hz, apc_m, r0_m, pixels_m
        As for :func:`spotlight_autofocus`.
    form_image : callable
        Phase history (P, F) to the complex image on ``pixels_m`` (any shape, N values).
    n_pixels : int
        Bright pixels used by each phase pass (re-selected on every new image).
    max_outer, tol_rad
        At most ``max_outer`` phase passes; stop when a pass removes less than ``tol_rad``
        RMS, rad.

    Returns
    -------
    SpotlightResult
        ``los_m`` from the envelope step (zero mean and trend); ``phase_rad`` the sum of the
        phase passes; ``rms_updates_rad`` the RMS phase removed by each pass.
    """
    res = SpotlightResult(align_ranges(ph, freq_hz), np.zeros(ph.shape[0]))
    for _ in range(max_outer):
        cur = res.apply(ph, freq_hz)
        step = spotlight_autofocus(
            cur, freq_hz, apc_m, r0_m, pixels_m, form_image(cur).ravel(), n_pixels
        )
        res.phase_rad = res.phase_rad + step.phase_rad
        res.rms_updates_rad.append(float(np.sqrt(np.mean(step.phase_rad**2))))
        if res.rms_updates_rad[-1] < tol_rad:
            break
    return res
