"""Range lines of one subaperture: selection, Doppler-rate measurement and the fits of the
two steps, and the contrast that decides whether a released block is corrected."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from sarmoco.processing.autofocus.doppler_rate import (
    compressed_magnitude,
    contrast_optimisation,
    gather_bands,
    line_contrast,
    map_drift,
    nominal_rate,
    select_lines,
)
from sarmoco.processing.autofocus.report import LineRates
from sarmoco.processing.autofocus.separation import (
    acceleration_design,
    fit_accelerations,
    fit_range_polynomial,
    look_angle,
    weighted_lstsq,
)
from sarmoco.processing.autofocus.settings import AutofocusConfig, AutofocusGeometry
from sarmoco.processing.beam import squint_sine
from sarmoco.processing.mocomp import shift_range
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray


@dataclass(frozen=True)
class Bands:
    """The selected lines of one subaperture: bins (N,), bands (N, B, M), the slant
    range of every band bin (N * B,), m, how evenly each line is lit over the
    subaperture (N,), in [0, 1] (:func:`illumination_balance`), and over its two halves
    (N,), in [0, 1] (the weaker half's signal energy over the stronger's)."""

    bins: IntArray
    bands: ComplexArray
    band_range_m: FloatArray
    balance: FloatArray
    halves: FloatArray


WALK_FRACTION = 0.5
"""Range walk over a subaperture, in range bins, below which it is left in place."""


def unwalk(
    sub: ComplexArray, t_s: FloatArray, bin_m: float, geometry: AutofocusGeometry
) -> ComplexArray:
    """A subaperture (pulses x bins at times ``t_s``, s; bins ``bin_m`` apart, m) with the
    range walk of the beam centre removed about its mid time (a squinted beam,
    :attr:`AutofocusGeometry.walk_mps`): each target stays on its line while its phase
    history is kept. The subaperture itself when the walk over it is under
    :data:`WALK_FRACTION` of a bin (a beam within a few tenths of a degree of broadside:
    the band-limited shift would only perturb the lines)."""
    if sub.shape[0] == 0:
        return sub
    span = float(t_s[-1]) - float(t_s[0])
    if abs(geometry.walk_mps) * span < WALK_FRACTION * bin_m:
        return sub
    mid = 0.5 * (float(t_s[0]) + float(t_s[-1]))
    return shift_range(sub, -geometry.walk_mps * (np.asarray(t_s) - mid) / bin_m)


def demodulate(bands: ComplexArray, t_s: FloatArray, geometry: AutofocusGeometry) -> ComplexArray:
    """Lines (N, B, M) at pulse times ``t_s`` (s) moved from the beam's Doppler centroid
    (:attr:`AutofocusGeometry.centroid_hz`) to zero frequency, with the pulses' own times.

    The estimators dechirp the lines and take FFTs over the pulses as if these were evenly
    spaced in slow time. The pulses' times (along-track position over the reference speed)
    are not: PRT jitter, and the along-track speed wandering about the reference speed,
    move them by tens of microseconds. A target's phase advances by ``2 π f t``; sampled
    at uneven times and read as even, its tone is smeared by ``2 π f δt``, and a spacing
    error quadratic over a subaperture (an along-track acceleration a_x) reads as a rate
    error ``f a_x / v``. Broadside, f stays within half the Doppler bandwidth of zero and
    the errors of the targets on either side of the beam centre cancel; a squinted beam
    adds its centroid to every target's f (-106 Hz at 3.5° of squint on the Ku
    acceptance scene: 0.1 m/s² along track read as 0.6 Hz/s of rate error in every
    line). Removed with the pulses' own times, the centroid no longer counts.
    """
    f_dc = geometry.centroid_hz
    if f_dc == 0.0 or bands.shape[-1] == 0:
        return bands
    tc = np.asarray(t_s, dtype=np.float64) - 0.5 * (float(t_s[0]) + float(t_s[-1]))
    return np.asarray(bands * np.exp(-2j * np.pi * f_dc * tc).astype(np.complex64))


def line_rate_speeds(
    bands: ComplexArray, t_s: FloatArray, geometry: AutofocusGeometry
) -> FloatArray:
    """``v cos ψ`` of each line's scatterer (N,), m/s, for its nominal Doppler rate
    ``-2 (v cos ψ)² / (λ R)``: ψ its squint at the middle of the subaperture, from the line's
    Doppler (the beam's centroid plus the line's own offset from it, the phase of its
    pulse-to-pulse correlation over the demodulated band (N, B, M) at pulse times ``t_s``).

    Within a squinted beam the rate differs between its edges by ``2 tan ψ`` times the
    beamwidth (0.7 % at 8° of squint and a 2.9° beam): a scatterer crossing the beam reads
    a rate error that changes linearly through its aperture against the beam centre's
    rate, which a scene of targets side by side along track (all at the same place in the
    beam at once) turned into a steady drift of the estimated acceleration, a cubic phase
    error over the aperture (azimuth PSLR -12.2 dB, one sidelobe up and one down, on
    simulated echoes without any motion error). Broadside, ``2 tan ψ`` is zero at the
    beam centre and the correction second order.
    """
    v = geometry.speed_mps
    if bands.shape[-1] < 2:
        return np.full(bands.shape[0], geometry.rate_speed_mps)
    corr = np.einsum("nbm,nbm->n", bands[..., 1:], np.conj(bands[..., :-1]))
    step_s = (float(t_s[-1]) - float(t_s[0])) / (bands.shape[-1] - 1)
    f_hz = geometry.centroid_hz + np.angle(corr) / (2.0 * np.pi * step_s)
    sine = np.clip(squint_sine(f_hz, v, geometry.wavelength_m), -1.0, 1.0)
    return np.asarray(v * np.sqrt(1.0 - sine**2), dtype=float)


def select_bands(sub: ComplexArray, range_m: FloatArray, config: AutofocusConfig) -> Bands:
    """Select the lines of a subaperture (pulses x bins) and gather their bands."""
    bins = select_lines(sub, config.n_lines, config.guard_bins)
    idx = np.clip(
        bins[:, None] + np.arange(-config.half_band, config.half_band + 1)[None, :],
        0,
        sub.shape[1] - 1,
    )
    quarters = quarter_signal(sub, bins, max(config.half_band, config.guard_bins // 2))
    halves = quarters[:2].sum(axis=0), quarters[2:].sum(axis=0)
    return Bands(
        bins,
        gather_bands(sub, bins, config.half_band),
        range_m[idx].ravel(),
        _weaker_over_stronger(quarters),
        _weaker_over_stronger(np.stack(halves)),
    )


def _weaker_over_stronger(signal: FloatArray) -> FloatArray:
    """Smallest over largest of each column of ``signal`` (parts x lines), in [0, 1]."""
    return np.asarray(signal.min(axis=0) / np.maximum(signal.max(axis=0), 1e-300))


def quarter_signal(sub: ComplexArray, bins: IntArray, half_width: int) -> FloatArray:
    """Signal energy of each line (N,) in each quarter of the subaperture, shape (4, N):
    the power of the bins within ``half_width`` of the line summed, the noise (the median
    bin's power in that quarter) taken off; ones with fewer than 4 pulses or no line."""
    m = sub.shape[0]
    if m < 4 or bins.size == 0:
        return np.ones((4, bins.shape[0]))
    edges = np.linspace(0, m, 5).astype(np.int64)
    power = np.square(np.abs(sub), dtype=np.float64)
    quarters = np.stack([power[a:b].mean(axis=0) for a, b in itertools.pairwise(edges)])
    noise = np.median(quarters, axis=1, keepdims=True)
    idx = np.clip(bins[:, None] + np.arange(-half_width, half_width + 1), 0, sub.shape[1] - 1)
    return np.asarray(np.maximum(quarters - noise, 0.0)[:, idx].sum(axis=2))


def illumination_balance(sub: ComplexArray, bins: IntArray, half_width: int) -> FloatArray:
    """How evenly each line's scatterers are lit over the subaperture, in [0, 1] (N,).

    The signal energy of the bins within ``half_width`` of the line (wide enough that the
    range walk of a moving target stays inside) in each quarter of the subaperture, the
    noise (median bin) taken off, weakest quarter over strongest: 1 for scatterers lit
    throughout, near 0 for one that enters or leaves the beam inside the subaperture.

    Such a line is in one map-drift look and not (or only partly) in the other: the looks'
    correlation then measures where its echo starts or stops, and where it is lit for part
    of the subaperture its rate belongs to that part, not to the subaperture's centre. On
    the independent ku acceptance scene (seed 3) such lines gave 85 to 520 Hz/s against
    rate errors of 1 to 3 Hz/s and, at quality 0.32 to 0.43, passed the quality floor.
    Dropping every unbalanced line removes them, but at the ends of a short run (wide-swath
    ku case at 50 m altitude, 1.4 s) it leaves the end subapertures without lines or with a
    range model lowered to a constant; :func:`measure_line_rates` multiplies a line's weight
    by the square of its balance instead, which keeps what a partly lit line knows where
    nothing else is (the square: wide-swath case far target -12.80 dB azimuth PSLR, -12.32
    with the balance itself; the acceptance scene's seeds 1-7 alike).

    Parameters
    ----------
    sub : ndarray of complex, shape (M, S)
        Range-compressed subaperture, pulses x range bins.
    bins : ndarray of int, shape (N,)
        The lines' range bins.
    half_width : int
        Bins each side of a line counted in its energy.
    """
    return _weaker_over_stronger(quarter_signal(sub, bins, half_width))


def measure_line_rates(
    lines: Bands,
    t_s: FloatArray,
    range_m: FloatArray,
    geometry: AutofocusGeometry,
    config: AutofocusConfig,
) -> LineRates:
    """Measure the Doppler-rate errors of the selected lines of one subaperture.

    A line's weight is its peak-to-median power ratio minus one, an estimate of the signal
    to noise (and clutter) ratio of its dominant scatterer, to which the inverse variance of a
    rate estimate is proportional. The UAV paper's eq. 13 (docs/methods.md §3) weights by the
    mean compressed magnitude; measured on a few-target scene at 0 dB per-pulse SNR, that
    leaves noise and range-sidelobe lines (a fifth of a target's weight each) enough weight
    to defocus the image. A line gets
    zero weight if its estimator quality is under ``config.min_quality`` or its compressed
    peak stands less than ``config.min_peak_db`` over its median. The weight is lowered for
    a line whose scatterer is not lit throughout the subaperture (the square of its
    :func:`illumination_balance`). Map drift compares the spectra of the subaperture's two
    halves: a line whose scatterer is lit in one half only (the weaker half's signal under
    :data:`BOTH_HALVES` of the stronger's) compares a spectrum with noise and gets zero
    weight. If fewer than ``config.min_lines`` lines are left, none of them lit throughout
    the subaperture (:data:`LIT_THROUGHOUT`), every weight is zero (no estimate: the
    spliced series bridges the subaperture from its neighbours).
    """
    bins = lines.bins
    if bins.size == 0:
        empty = np.zeros(0)
        return LineRates(empty, empty, empty, empty, empty)
    bands = demodulate(lines.bands, t_s, geometry)
    ref = nominal_rate(range_m[bins], line_rate_speeds(bands, t_s, geometry), geometry.wavelength_m)
    if config.estimator == "map-drift":
        delta, quality = map_drift(bands, t_s, ref)
    else:
        delta, quality = contrast_optimisation(bands, t_s, ref, config.rate_span_hz_per_s)
    n_fft = 4 * int(2 ** np.ceil(np.log2(t_s.shape[0])))
    mag = compressed_magnitude(bands, t_s, ref + delta, n_fft)
    power = mag**2
    peak_db = 10.0 * np.log10(power.max(axis=1) / np.maximum(np.median(power, axis=1), 1e-30))
    peak = power.max(axis=1)
    # a line far weaker than the strongest is a range sidelobe of a bright target (the
    # target walks through the sidelobes' nulls as it migrates in range) or clutter
    strong = peak >= peak.max() * 10.0 ** (-config.max_below_strongest_db / 10.0)
    good = (quality >= config.min_quality) & (peak_db >= config.min_peak_db) & strong
    weight = np.where(good, 10.0 ** (peak_db / 10.0) - 1.0, 0.0)
    weight *= lines.balance**2
    if config.estimator == "map-drift":
        weight[lines.halves < BOTH_HALVES] = 0.0
    weight[weight < NEGLIGIBLE_WEIGHT * weight.max(initial=0.0)] = 0.0
    lit = np.any((weight > 0) & (lines.balance >= LIT_THROUGHOUT))
    if np.count_nonzero(weight) < config.min_lines and not lit:
        weight[:] = 0.0
    return LineRates(range_m[bins], delta, weight, quality, peak_db)


BOTH_HALVES = 0.1
"""A line whose weaker half of the subaperture holds less than this fraction of the signal
energy of its stronger half is not used by map drift (its scatterer is in one look only).
Where the beam first reached the scene of the independent acceptance case at -4° of crab
looking left (with a 4 s heading window), such a line (lit in the last quarter only:
halves 0.03) read 328 Hz/s beside a line lit over three quarters (halves 0.50, 0.78 Hz/s);
at 0.5 % of the weight it made the subaperture's estimate 2.48 Hz/s where the INS error's
rate was 1.11, and the worst azimuth PSLR -12.19 dB (-12.45 without it)."""


LIT_THROUGHOUT = 0.5
"""A usable line whose :func:`illumination_balance` reaches this holds a scatterer lit over
the whole subaperture: alone, it still gives the subaperture an estimate (fewer than
``min_lines`` usable lines guard against a fit through noise or through the edge of a
scatterer's echo, whose balance is near zero). At the end of a squinted run the last
target in the beam is often such a line alone: its subapertures bridged by the end fit
instead left it -12.43 dB azimuth PSLR on the independent acceptance scene at 4 deg crab
(its phase error 0.166 rad rms against 0.081 with its own line)."""


NEGLIGIBLE_WEIGHT = 1e-3
"""Lines weighing less than this fraction of the subaperture's heaviest are not used (so
they count neither in the fits nor toward the lines a range model needs)."""


SEPARATION_LINES = 4
"""Usable lines from which the envelope step separates a_y from a_z (two more than the two
unknowns, as :func:`~sarmoco.processing.autofocus.separation.fit_range_polynomial` asks of
its model); with fewer, the acceleration is taken along the scene-centre line of sight."""


def fit_accel(lines: LineRates, geometry: AutofocusGeometry) -> tuple[tuple[float, float], float]:
    """(a_y, a_z), m/s², and the fit's residual, Hz/s; NaN (no estimate) with fewer than two
    usable lines.

    The rows ``(2/λ)(sin β_i, cos β_i)`` of lines a few degrees of look angle apart are
    nearly parallel: solved exactly through two or three lines, the rate differences of
    noise, or of a target entering the beam, become accelerations of tens of m/s² (on the
    independent acceptance scene at 4° of crab: two lines gave a_y = 116,
    a_z = -184 m/s², 7.6 m/s² along the line of sight; the integrated envelope shift then
    had the never-worse check reject the corrections over the rest of the run, -9.4 dB
    azimuth PSLR). With fewer than :data:`SEPARATION_LINES` usable lines the lines measure
    one acceleration along the scene-centre line of sight (β_c), which is all the envelope
    correction takes of them (:func:`los_accel`).
    """
    if lines.n_used < 2:
        return (float("nan"), float("nan")), float("nan")
    if lines.n_used >= SEPARATION_LINES:
        return fit_accelerations(
            lines.range_m, lines.rate_hz_per_s, lines.weight, geometry.depth_m,
            geometry.wavelength_m,
        )  # fmt: skip
    beta_c = float(look_angle(np.array([geometry.ref_range_m]), geometry.depth_m)[0])
    los_c = np.array([np.sin(beta_c), np.cos(beta_c)])
    design = acceleration_design(lines.range_m, geometry.depth_m, geometry.wavelength_m) @ los_c
    (a_los,), res = weighted_lstsq(design[:, None], lines.rate_hz_per_s, lines.weight)
    return (float(a_los * los_c[0]), float(a_los * los_c[1])), res


def fit_kappa(
    lines: LineRates, geometry: AutofocusGeometry, order: int
) -> tuple[FloatArray, float]:
    """κ0..κ2 and the fit's residual, Hz/s; NaN (no estimate) without a usable line."""
    if lines.n_used < 1:
        return np.full(3, np.nan), float("nan")
    return fit_range_polynomial(
        lines.range_m, lines.rate_hz_per_s, lines.weight, geometry.ref_range_m, order
    )


CONTRAST_MARGIN = 0.97
"""A released block keeps its autofocus corrections unless they leave the contrast of its
strongest lines below this fraction of the contrast without them (estimation noise moves
the contrast of a block that the corrections focus by a percent or two)."""

GUARD_LINES = 8
"""Strongest range lines of a released block whose contrast decides whether it is corrected."""


def block_contrast(
    data: ComplexArray,
    t_s: FloatArray,
    bins: IntArray,
    range_m: FloatArray,
    geometry: AutofocusGeometry,
) -> float:
    """Summed azimuth-compressed contrast of the range lines ``bins`` of a block of pulses.

    Each line is compressed with the nominal Doppler rate of its range over the whole
    block (:func:`~sarmoco.processing.autofocus.doppler_rate.line_contrast`): the sharper
    the targets on those lines, the larger the contrast. Needs at least 8 pulses.
    """
    bands = demodulate(gather_bands(data, bins, 0), t_s, geometry)
    ref = nominal_rate(range_m[bins], geometry.rate_speed_mps, geometry.wavelength_m)
    return float(np.sum(line_contrast(bands, t_s, ref)))


def los_accel(accel_yz: FloatArray, geometry: AutofocusGeometry) -> FloatArray:
    """LOS acceleration at the scene-centre look angle from (a_y, a_z) rows, m/s²."""
    beta_c = float(look_angle(np.array([geometry.ref_range_m]), geometry.depth_m)[0])
    return np.asarray(accel_yz @ np.array([np.sin(beta_c), np.cos(beta_c)]), dtype=float)
