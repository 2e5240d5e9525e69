"""Range lines of one subaperture: selection, Doppler-rate measurement and the fits of the
two steps, and the contrast that decides whether a released block is corrected."""

from __future__ import annotations

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
    fit_accelerations,
    fit_range_polynomial,
    look_angle,
)
from sarmoco.processing.autofocus.settings import AutofocusConfig, AutofocusGeometry
from sarmoco.processing.mocomp import shift_range
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray


@dataclass(frozen=True)
class Bands:
    """The selected lines of one subaperture: bins (N,), bands (N, B, M) and the slant
    range of every band bin (N * B,), m."""

    bins: IntArray
    bands: ComplexArray
    band_range_m: FloatArray


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


def select_bands(sub: ComplexArray, range_m: FloatArray, config: AutofocusConfig) -> Bands:
    """Select the lines of a subaperture (pulses x bins) and gather their bands."""
    bins = select_lines(sub, config.n_lines, config.guard_bins)
    idx = np.clip(
        bins[:, None] + np.arange(-config.half_band, config.half_band + 1)[None, :],
        0,
        sub.shape[1] - 1,
    )
    return Bands(bins, gather_bands(sub, bins, config.half_band), range_m[idx].ravel())


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
    peak stands less than ``config.min_peak_db`` over its median; if fewer than
    ``config.min_lines`` lines are left, every weight is zero (no correction).
    """
    bins, bands = lines.bins, lines.bands
    if bins.size == 0:
        empty = np.zeros(0)
        return LineRates(empty, empty, empty, empty, empty)
    ref = nominal_rate(range_m[bins], geometry.rate_speed_mps, geometry.wavelength_m)
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
    if np.count_nonzero(good) < config.min_lines:
        good[:] = False
    weight = np.where(good, 10.0 ** (peak_db / 10.0) - 1.0, 0.0)
    return LineRates(range_m[bins], delta, weight, quality, peak_db)


def fit_accel(lines: LineRates, geometry: AutofocusGeometry) -> tuple[tuple[float, float], float]:
    if lines.n_used < 2:
        return (0.0, 0.0), float("nan")
    return fit_accelerations(
        lines.range_m, lines.rate_hz_per_s, lines.weight, geometry.depth_m, geometry.wavelength_m
    )


def fit_kappa(
    lines: LineRates, geometry: AutofocusGeometry, order: int
) -> tuple[FloatArray, float]:
    if lines.n_used < 1:
        return np.zeros(3), float("nan")
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
    bands = gather_bands(data, bins, 0)
    ref = nominal_rate(range_m[bins], geometry.rate_speed_mps, geometry.wavelength_m)
    return float(np.sum(line_contrast(bands, t_s, ref)))


def los_accel(accel_yz: FloatArray, geometry: AutofocusGeometry) -> FloatArray:
    """LOS acceleration at the scene-centre look angle from (a_y, a_z) rows, m/s²."""
    beta_c = float(look_angle(np.array([geometry.ref_range_m]), geometry.depth_m)[0])
    return np.asarray(accel_yz @ np.array([np.sin(beta_c), np.cos(beta_c)]), dtype=float)
