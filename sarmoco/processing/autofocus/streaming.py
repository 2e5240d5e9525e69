"""Sliding-subaperture two-step autofocus (METHODS §3), streaming and offline.

Input: range-compressed pulses already compensated with the navigation solution, on a uniform
slant-range axis, with the nominal geometry (straight reference track at speed v0, flat ground
at depth H below it). Step 1 (envelope): per subaperture, Doppler-rate errors of the strongest
lines give (a_y, a_z); spliced and integrated twice they give the LOS displacement at the
scene-centre look angle, which is removed by a range shift. Step 2 (phase): on the
envelope-corrected subaperture the rates are measured again and fitted with κ0 + κ1 Δd + κ2 Δd²;
κ spliced and integrated twice give the phase error of every range bin.

Streaming: subaperture j is estimated (step 1) as soon as its last pulse is in; step 2 of j
runs when step 1 of j + 1 is known (its envelope is then interpolated, not extrapolated);
pulses up to the centre of the latest step-2 subaperture are corrected and released. The
latency is at most subaperture + hop (the first pulses of a run); later pulses wait
2 hop + subaperture/2, which is no more for overlaps of 50 % or more.
The constant and linear terms are pinned at the start (zero value and slope); the offline
form pins zero mean and trend over the aperture instead, otherwise it uses the same
subaperture grid and estimators, so both agree up to a line in time (and the envelope
extrapolation at the end of a subaperture in streaming).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.autofocus.doppler_rate import (
    compressed_magnitude,
    contrast_optimisation,
    gather_bands,
    map_drift,
    nominal_rate,
    select_lines,
)
from sarmoco.processing.autofocus.report import AutofocusReport, LineRates, SubapertureReport
from sarmoco.processing.autofocus.separation import (
    fit_accelerations,
    fit_range_polynomial,
    look_angle,
)
from sarmoco.processing.autofocus.splice import (
    double_integrate,
    integrate_twice,
    phase_screen,
    shift_range,
    splice,
)
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray


@dataclass(frozen=True)
class AutofocusGeometry:
    """Nominal geometry the data were compensated to.

    Parameters
    ----------
    wavelength_m : float
        Carrier wavelength, m.
    speed_mps : float
        Speed v0 of the straight reference track, m/s.
    depth_m : float
        Height H of the reference track above the flat ground, m (cos β = H / r).
    ref_range_m : float
        Scene-centre slant range R_c, m (envelope look angle β_c and Δd = R - R_c).
    """

    wavelength_m: float
    speed_mps: float
    depth_m: float
    ref_range_m: float


@dataclass(frozen=True)
class AutofocusConfig:
    """Settings of the two-step autofocus.

    Parameters
    ----------
    subaperture_s, hop_s : float
        Subaperture length and hop, s (overlap 1 - hop/subaperture, at least 50 % advised).
    n_lines : int
        Range lines used per subaperture.
    guard_bins : int
        Minimum spacing of two lines, bins.
    half_band : int
        Each line is a band of 2 half_band + 1 bins (magnitudes summed for map drift).
    estimator : {"map_drift", "contrast"}
        Doppler-rate estimator.
    envelope_step : bool
        Run step 1 (False: the paper's phase-only baseline).
    range_order : int
        Order of the κ range model of step 2 (0, 1, 2).
    min_quality : float
        Lines of lower estimator quality get zero weight.
    min_peak_db : float
        Lines whose azimuth-compressed peak stands less than this above the line's median
        power get zero weight (noise-only lines: the peak of ~M exponential samples is about
        8 dB over their median, so 15 dB rejects them with a margin), dB.
    min_lines : int
        A subaperture with fewer usable lines makes no correction (rate error 0) rather than
        a fit through noise.
    rate_span_hz_per_s : float
        Search half-width of contrast optimisation, Hz/s.
    phase_passes : int
        The phase step is repeated on its own output this many times in all (the residual
        rates shrink, so the looks are sharper and the rate change inside a subaperture no
        longer biases them); κ of the passes add up. Offline a pass covers the whole
        aperture; streaming, a subaperture's passes use the rates known so far (the later
        ones extrapolated).
    """

    subaperture_s: float = 0.4
    hop_s: float = 0.1
    n_lines: int = 16
    guard_bins: int = 6
    half_band: int = 1
    estimator: Literal["map_drift", "contrast"] = "map_drift"
    envelope_step: bool = True
    range_order: int = 2
    min_quality: float = 0.3
    min_peak_db: float = 15.0
    min_lines: int = 2
    rate_span_hz_per_s: float = 150.0
    phase_passes: int = 3

    def __post_init__(self) -> None:
        if not 0 < self.hop_s <= self.subaperture_s:
            raise ProcessingError(
                f"AutofocusConfig: hop_s {self.hop_s} must be in (0, subaperture_s "
                f"{self.subaperture_s}]"
            )
        if self.min_lines < 1 or self.phase_passes < 1:
            raise ProcessingError(
                f"AutofocusConfig: min_lines {self.min_lines} and phase_passes "
                f"{self.phase_passes} must be at least 1"
            )
        if self.estimator not in ("map_drift", "contrast"):
            raise ProcessingError(f"AutofocusConfig.estimator: {self.estimator!r} is unknown")


@dataclass(frozen=True)
class Corrections:
    """Autofocus corrections of a run of pulses.

    Parameters
    ----------
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    los_m : ndarray, shape (P,)
        Estimated LOS displacement at the scene-centre look angle (toward the scene), m;
        the envelope is shifted by this much (a peak at R - d_los goes back to R).
    phase_cycles : ndarray, shape (P, 3)
        Double integrals of κ0, κ1, κ2 (cycles, cycles/m, cycles/m²).
    ref_range_m : float
        R_c of the κ model, m.
    """

    t_ns: IntArray
    los_m: FloatArray
    phase_cycles: FloatArray
    ref_range_m: float

    def phase_rad(self, range_m: FloatArray) -> FloatArray:
        """Phase error of every pulse and range bin, rad, shape (P, S)."""
        return phase_screen(self.phase_cycles, np.asarray(range_m) - self.ref_range_m)

    def apply(self, rc: ComplexArray, range_m: FloatArray) -> ComplexArray:
        """Shift the envelopes and remove the phase error: returns corrected (P, S) data."""
        bin_m = float(range_m[1] - range_m[0])
        shifted = shift_range(rc, self.los_m, bin_m)
        return (shifted * np.exp(-1j * self.phase_rad(range_m))).astype(rc.dtype)


def _seconds(t_ns: IntArray, t0_ns: int) -> FloatArray:
    return np.asarray(t_ns - t0_ns, dtype=float) * 1e-9


def _line_rates(
    sub: ComplexArray,
    t_s: FloatArray,
    range_m: FloatArray,
    geometry: AutofocusGeometry,
    config: AutofocusConfig,
) -> LineRates:
    """Select lines and measure their Doppler-rate errors on one subaperture.

    A line's weight is its peak-to-median power ratio minus one, an estimate of the signal
    to noise (and clutter) ratio of its dominant scatterer, to which the inverse variance of a
    rate estimate is proportional. METHODS eq. 13 weights by the mean compressed magnitude;
    measured on a few-target scene at 0 dB per-pulse SNR, that leaves noise and range-sidelobe
    lines (a fifth of a target's weight each) enough weight to defocus the image. A line gets
    zero weight if its estimator quality is under ``config.min_quality`` or its compressed
    peak stands less than ``config.min_peak_db`` over its median; if fewer than
    ``config.min_lines`` lines are left, every weight is zero (no correction).
    """
    bins = select_lines(sub, config.n_lines, config.guard_bins)
    if bins.size == 0:
        empty = np.zeros(0)
        return LineRates(empty, empty, empty, empty, empty)
    bands = gather_bands(sub, bins, config.half_band)
    ref = nominal_rate(range_m[bins], geometry.speed_mps, geometry.wavelength_m)
    if config.estimator == "map_drift":
        delta, quality = map_drift(bands, t_s, ref)
    else:
        delta, quality = contrast_optimisation(bands, t_s, ref, config.rate_span_hz_per_s)
    n_fft = int(2 ** np.ceil(np.log2(t_s.shape[0])))
    mag = compressed_magnitude(bands, t_s, ref + delta, n_fft)
    power = mag**2
    peak_db = 10.0 * np.log10(power.max(axis=1) / np.maximum(np.median(power, axis=1), 1e-30))
    good = (quality >= config.min_quality) & (peak_db >= config.min_peak_db)
    if np.count_nonzero(good) < config.min_lines:
        good[:] = False
    weight = np.where(good, 10.0 ** (peak_db / 10.0) - 1.0, 0.0)
    return LineRates(range_m[bins], delta, weight, quality, peak_db)


def _fit_accel(lines: LineRates, geometry: AutofocusGeometry) -> tuple[tuple[float, float], float]:
    if lines.n_used < 2:
        return (0.0, 0.0), float("nan")
    return fit_accelerations(
        lines.range_m, lines.rate_hz_per_s, lines.weight, geometry.depth_m, geometry.wavelength_m
    )


def _fit_kappa(
    lines: LineRates, geometry: AutofocusGeometry, order: int
) -> tuple[FloatArray, float]:
    if lines.n_used < 1:
        return np.zeros(3), float("nan")
    return fit_range_polynomial(
        lines.range_m, lines.rate_hz_per_s, lines.weight, geometry.ref_range_m, order
    )


def _los_accel(accel_yz: FloatArray, geometry: AutofocusGeometry) -> FloatArray:
    """LOS acceleration at the scene-centre look angle from (a_y, a_z) rows, m/s²."""
    beta_c = float(look_angle(np.array([geometry.ref_range_m]), geometry.depth_m)[0])
    return np.asarray(accel_yz @ np.array([np.sin(beta_c), np.cos(beta_c)]), dtype=float)


def subaperture_starts(t_s: FloatArray, config: AutofocusConfig) -> FloatArray:
    """Start times of the complete subapertures that fit in ``t_s`` (first pulse at 0), s."""
    span = float(t_s[-1] - t_s[0])
    n = int(np.floor((span - config.subaperture_s) / config.hop_s + 1e-9)) + 1
    return np.asarray(float(t_s[0]) + config.hop_s * np.arange(max(n, 0)), dtype=float)


def _members(t_s: FloatArray, start_s: float, config: AutofocusConfig) -> slice:
    i0 = int(np.searchsorted(t_s, start_s - 1e-9))
    i1 = int(np.searchsorted(t_s, start_s + config.subaperture_s - 1e-9))
    return slice(i0, i1)


def autofocus_offline(
    rc: ComplexArray,
    t_ns: IntArray,
    range_m: FloatArray,
    geometry: AutofocusGeometry,
    config: AutofocusConfig,
) -> tuple[Corrections, AutofocusReport]:
    """Two-step autofocus of a whole aperture (constant and linear terms pinned to zero mean
    and zero trend).

    Parameters
    ----------
    rc : ndarray, shape (P, S)
        Navigation-compensated range-compressed pulses.
    t_ns : ndarray of int64, shape (P,)
        Pulse times, GPS ns.
    range_m : ndarray, shape (S,)
        Uniform slant-range axis, m.
    geometry, config
        See :class:`AutofocusGeometry`, :class:`AutofocusConfig`.

    Returns
    -------
    Corrections, AutofocusReport
    """
    t = _seconds(t_ns, int(t_ns[0]))
    starts = subaperture_starts(t, config)
    if starts.size == 0:
        raise ProcessingError(
            f"autofocus_offline: {t[-1]:.3f} s of data is shorter than a subaperture"
        )
    centres = starts + 0.5 * config.subaperture_s
    members = [_members(t, s, config) for s in starts]
    env_lines: list[LineRates | None] = [None] * starts.size
    accel = np.zeros((starts.size, 2))
    accel_res = np.full(starts.size, np.nan)
    los = np.zeros(t.size)
    data = rc
    if config.envelope_step:
        for j, m in enumerate(members):
            lines = _line_rates(rc[m], t[m], range_m, geometry, config)
            env_lines[j] = lines
            (ay, az), accel_res[j] = _fit_accel(lines, geometry)
            accel[j] = (ay, az)
        a_los = splice(centres, _los_accel(accel, geometry), t)
        los = double_integrate(t, a_los, "mean_trend")[:, 0]
        data = shift_range(rc, los, float(range_m[1] - range_m[0]))
    shifted = data
    report = AutofocusReport()
    kappa = np.zeros((starts.size, 3))
    kres = np.full(starts.size, np.nan)
    phase_lines: list[LineRates | None] = [None] * starts.size
    cycles = np.zeros((t.size, 3))
    for _ in range(config.phase_passes):
        if np.any(cycles):
            data = shifted * np.exp(-1j * phase_screen(cycles, range_m - geometry.ref_range_m))
        for j, m in enumerate(members):
            lines = _line_rates(data[m], t[m], range_m, geometry, config)
            step, kres[j] = _fit_kappa(lines, geometry, config.range_order)
            kappa[j] += step
            phase_lines[j] = lines
        cycles = double_integrate(t, splice(centres, kappa, t), "mean_trend")
    for j in range(starts.size):
        report.subapertures.append(
            SubapertureReport(
                j,
                float(centres[j]),
                env_lines[j],
                phase_lines[j],
                (float(accel[j, 0]), float(accel[j, 1]))
                if config.envelope_step
                else (float("nan"), float("nan")),
                float(accel_res[j]),
                kappa[j].copy(),
                float(kres[j]),
            )
        )
    return Corrections(t_ns.copy(), los, cycles, geometry.ref_range_m), report


@dataclass
class _Carry:
    """Integrator state at the first buffered pulse."""

    los: FloatArray = field(default_factory=lambda: np.zeros(2))  # value, slope
    cycles: FloatArray = field(default_factory=lambda: np.zeros((2, 3)))


class SlidingSubapertureAutofocus:
    """Streaming two-step autofocus with carried state.

    Feed navigation-compensated range-compressed blocks with :meth:`push`; each call
    returns the pulses whose corrections are final, corrected, with their
    :class:`Corrections`. :meth:`flush` releases the rest at the end of a run.

    Parameters
    ----------
    geometry : AutofocusGeometry
    range_m : ndarray, shape (S,)
        Uniform slant-range axis of every block, m.
    config : AutofocusConfig
    """

    def __init__(
        self, geometry: AutofocusGeometry, range_m: FloatArray, config: AutofocusConfig
    ) -> None:
        self.geometry = geometry
        self.range_m = np.asarray(range_m, dtype=float)
        self.config = config
        self.report = AutofocusReport()
        self._t0_ns: int | None = None
        self._t = np.zeros(0)
        self._t_ns = np.zeros(0, dtype=np.int64)
        self._data: ComplexArray = np.zeros((0, self.range_m.size), dtype=np.complex64)
        self._carry = _Carry()
        self._centres: list[float] = []
        self._accel: list[tuple[float, float]] = []
        self._accel_res: list[float] = []
        self._env_lines: list[LineRates | None] = []
        self._kappa: list[FloatArray] = []
        self._released_s = -np.inf

    @property
    def latency_s(self) -> float:
        """Upper bound of the delay from a pulse's arrival to its release, s.

        Subaperture + hop: reached by the first pulses of a run (released when the second
        subaperture is complete); later pulses wait at most 2 hop + subaperture / 2.
        """
        return self.config.subaperture_s + self.config.hop_s

    def _start(self, j: int) -> float:
        return j * self.config.hop_s

    def _complete(self, j: int) -> bool:
        return self._t.size > 0 and self._t[-1] >= self._start(j) + self.config.subaperture_s - 1e-9

    def _subaperture(self, j: int) -> tuple[FloatArray, ComplexArray, slice]:
        m = _members(self._t, self._start(j), self.config)
        return self._t[m], self._data[m], m

    def _envelope_step(self, j: int) -> None:
        t, sub, _ = self._subaperture(j)
        self._centres.append(self._start(j) + 0.5 * self.config.subaperture_s)
        if self.config.envelope_step:
            lines = _line_rates(sub, t, self.range_m, self.geometry, self.config)
            (ay, az), res = _fit_accel(lines, self.geometry)
            self._env_lines.append(lines)
            self._accel.append((ay, az))
            self._accel_res.append(res)
        else:
            self._env_lines.append(None)
            self._accel.append((float("nan"), float("nan")))
            self._accel_res.append(float("nan"))

    def _los(self) -> tuple[FloatArray, FloatArray]:
        """LOS displacement (m) and its rate (m/s) of every buffered pulse, from the carry."""
        if not self.config.envelope_step or not self._centres:
            return np.zeros(self._t.size), np.zeros(self._t.size)
        a = _los_accel(np.array(self._accel, dtype=float), self.geometry)
        a_t = splice(np.array(self._centres), a, self._t)
        val, slope = integrate_twice(self._t, a_t, self._carry.los[:1], self._carry.los[1:])
        return val[:, 0], slope[:, 0]

    def _cycles(
        self, kappa: list[FloatArray], end_points: int = 3, end_degree: int = 1
    ) -> tuple[FloatArray, FloatArray]:
        """Double integral of the spliced κ series (and its slope) on the buffered pulses."""
        if not kappa:
            return np.zeros((self._t.size, 3)), np.zeros((self._t.size, 3))
        centres = np.array(self._centres[: len(kappa)])
        k = splice(centres, np.array(kappa), self._t, end_points, end_degree)
        return integrate_twice(self._t, k, self._carry.cycles[0], self._carry.cycles[1])

    def _phase_step(self, j: int) -> None:
        """κ of subaperture j: ``phase_passes`` passes, each on the data corrected with the
        series known so far (κ of j - 1 held beyond its centre on the first pass)."""
        t, sub, m = self._subaperture(j)
        if self.config.envelope_step:
            bin_m = float(self.range_m[1] - self.range_m[0])
            sub = shift_range(sub, self._los()[0][m], bin_m)
        delta_r = self.range_m - self.geometry.ref_range_m
        kappa = self._kappa[-1].copy() if self._kappa else np.zeros(3)
        known = list(self._kappa)
        for _ in range(self.config.phase_passes):
            first = len(known) == j
            cyc = self._cycles(known, 1 if first else 3, 1 if first else 2)[0][m]
            data = sub * np.exp(-1j * phase_screen(cyc, delta_r)) if known else sub
            lines = _line_rates(data, t, self.range_m, self.geometry, self.config)
            step, kres = _fit_kappa(lines, self.geometry, self.config.range_order)
            if lines.n_used == 0:  # nothing to measure: no correction for this subaperture
                kappa = np.zeros(3)
                break
            kappa = kappa + step
            known = [*self._kappa, kappa]
        self._kappa.append(kappa)
        ay, az = self._accel[j]
        self.report.subapertures.append(
            SubapertureReport(
                j,
                self._centres[j],
                self._env_lines[j],
                lines,
                (ay, az),
                self._accel_res[j],
                kappa,
                kres,
            )
        )

    def push(self, rc: ComplexArray, t_ns: IntArray) -> tuple[ComplexArray, Corrections]:
        """Add a block of pulses; return the pulses released by it, corrected.

        Parameters
        ----------
        rc : ndarray, shape (P, S)
            Navigation-compensated range-compressed pulses on ``range_m``.
        t_ns : ndarray of int64, shape (P,)
            Their times, GPS ns, increasing and later than every pulse pushed before.
        """
        return self._advance(rc, t_ns, flushing=False)

    def flush(self) -> tuple[ComplexArray, Corrections]:
        """Release every remaining pulse (the last ones with extrapolated corrections)."""
        return self._advance(
            np.zeros((0, self.range_m.size), dtype=self._data.dtype),
            np.zeros(0, dtype=np.int64),
            flushing=True,
        )

    def _advance(
        self, rc: ComplexArray, t_ns: IntArray, flushing: bool
    ) -> tuple[ComplexArray, Corrections]:
        if rc.shape[0] != t_ns.shape[0] or rc.shape[1:] != (self.range_m.size,):
            raise ProcessingError(
                f"SlidingSubapertureAutofocus.push: block {rc.shape}, t {t_ns.shape}, "
                f"range axis {self.range_m.size} disagree"
            )
        if t_ns.size:
            if self._t0_ns is None:
                self._t0_ns = int(t_ns[0])
            t_new = _seconds(t_ns, self._t0_ns)
            if self._t.size and t_new[0] <= self._t[-1]:
                raise ProcessingError("SlidingSubapertureAutofocus.push: pulse times go backwards")
            self._t = np.concatenate([self._t, t_new])
            self._t_ns = np.concatenate([self._t_ns, t_ns.astype(np.int64)])
            self._data = np.concatenate([self._data, rc.astype(self._data.dtype)])
        while self._complete(len(self._centres)):
            self._envelope_step(len(self._centres))
        while len(self._kappa) < len(self._centres) and (
            len(self._kappa) + 1 < len(self._centres) or flushing
        ):
            self._phase_step(len(self._kappa))
        return self._release(flushing)

    def _release(self, flushing: bool) -> tuple[ComplexArray, Corrections]:
        if flushing:
            upto = self._t.size
        elif self._kappa:
            upto = int(np.searchsorted(self._t, self._centres[len(self._kappa) - 1] - 1e-9))
        else:
            upto = 0
        first = int(np.searchsorted(self._t, self._released_s, side="right"))
        los, los_slope = self._los()
        cyc, cyc_slope = self._cycles(self._kappa)
        sel = slice(first, upto)
        corr = Corrections(self._t_ns[sel].copy(), los[sel], cyc[sel], self.geometry.ref_range_m)
        out = corr.apply(self._data[sel], self.range_m) if upto > first else self._data[sel]
        if upto > first:
            self._released_s = float(self._t[upto - 1])
        # Drop pulses that are released and not needed by a pending subaperture, carrying the
        # integrator state to the new first pulse (its inputs are final there).
        need = int(np.searchsorted(self._t, self._start(len(self._kappa)) - 1e-9))
        cut = min(upto, need)
        if 0 < cut < self._t.size:
            self._carry.los = np.array([los[cut], los_slope[cut]])
            self._carry.cycles = np.vstack([cyc[cut], cyc_slope[cut]])
            self._t, self._t_ns, self._data = self._t[cut:], self._t_ns[cut:], self._data[cut:]
        return out, corr
