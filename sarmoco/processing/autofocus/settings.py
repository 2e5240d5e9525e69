"""Settings of the sliding-subaperture autofocus: the nominal geometry and the tuning."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from sarmoco.errors import ProcessingError


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
    max_below_strongest_db : float
        Lines whose compressed peak is more than this below the strongest line's get zero
        weight, dB.
    min_lines : int
        A subaperture with fewer usable lines makes no correction (rate error 0) rather than
        a fit through noise.
    rate_span_hz_per_s : float
        Search half-width of contrast optimisation, Hz/s.
    phase_passes : int
        The phase step is repeated on its own output this many times in all (the residual
        rates shrink, so the looks are sharper and the rate change inside a subaperture no
        longer biases them); κ of the passes add up. Offline a pass covers the whole
        aperture; streaming, pass p of a subaperture waits until pass p - 1 is known on
        all of its pulses (latency grows by about 2 hops a pass at 75 % overlap).
    pin_window_s : float
        Streaming: the constant and linear terms of the corrections (not observable from
        Doppler rates; a linear phase moves targets along track) get zero mean and zero
        trend from the first subaperture centre of a run to ``pin_window_s`` later, and the
        first pulses are released once that is covered, s. Offline (``inf``) the window
        runs to the last centre.
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
    max_below_strongest_db: float = 20.0
    min_lines: int = 2
    rate_span_hz_per_s: float = 150.0
    phase_passes: int = 3
    pin_window_s: float = 2.0

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
        if not self.pin_window_s > 0:
            raise ProcessingError(
                f"AutofocusConfig.pin_window_s: {self.pin_window_s} must be positive"
            )
        if self.estimator not in ("map_drift", "contrast"):
            raise ProcessingError(f"AutofocusConfig.estimator: {self.estimator!r} is unknown")
