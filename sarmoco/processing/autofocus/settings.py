"""Settings of the sliding-subaperture autofocus: the nominal geometry and the tuning."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from sarmoco.errors import ProcessingError
from sarmoco.keys import key
from sarmoco.processing.beam import doppler_hz


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
    squint_rad : float
        Squint of the beam centre from the plane normal to the track, rad (positive: ahead;
        an antenna fixed to a crabbed body). A target seen at squint ψ has the Doppler rate
        ``-2 (v cos ψ)² / (λ R)``, walks through range at ``-v sin ψ`` and has the Doppler
        frequency ``2 v sin ψ / λ``.
    """

    wavelength_m: float
    speed_mps: float
    depth_m: float
    ref_range_m: float
    squint_rad: float = 0.0

    @property
    def rate_speed_mps(self) -> float:
        """Speed across the beam centre's line of sight, ``v cos ψ`` (of its Doppler rate), m/s."""
        return self.speed_mps * math.cos(self.squint_rad)

    @property
    def centroid_hz(self) -> float:
        """Doppler frequency of a target at the beam centre, ``2 v sin ψ / λ``, Hz (slow time
        on the reference track's uniform speed: the pulses' time is their along-track
        position over v)."""
        return float(doppler_hz(self.speed_mps, self.wavelength_m, self.squint_rad))

    @property
    def walk_mps(self) -> float:
        """Range rate of a target at the beam centre, ``-v sin ψ``, m/s."""
        return -self.speed_mps * math.sin(self.squint_rad)


@dataclass(frozen=True)
class AutofocusConfig:
    """Settings of the two-step autofocus (docs/methods.md §3).

    Each field is a configuration key (:func:`sarmoco.keys.key`): its meaning, unit and
    bounds are in its metadata, and the daemon's ``[autofocus]`` section is this class
    plus the daemon's own switches, so the key table of docs/configuration.md documents every field.
    Offline (:func:`autofocus_offline`) ``pin_window_s`` runs to the last subaperture centre.
    """

    subaperture_s: float = key(
        0.6,
        "Subaperture length: longer estimates each Doppler rate from more pulses, shorter "
        "follows faster motion errors (docs/measurements/acceptance.md compares 0.4, 0.6 "
        "and 0.8 s on the acceptance flight)",
        unit="s",
        gt=0,
    )
    hop_s: float = key(
        0.1,
        "Hop between subaperture starts (overlap = 1 - hop / subaperture, at least 50 % "
        "advised); at most subaperture_s",
        unit="s",
        gt=0,
    )
    n_lines: int = key(16, "Range lines used per subaperture", gt=0)
    guard_bins: int = key(6, "Minimum spacing of two range lines, in range bins", ge=0)
    half_band: int = key(
        1,
        "Each line is a band of 2 half_band + 1 range bins (magnitudes summed for map drift)",
        ge=0,
    )
    estimator: Literal["map-drift", "contrast"] = key("map-drift", "Doppler-rate estimator")
    envelope_step: bool = key(
        True,
        "Estimate cross-track accelerations and correct the envelope (step 1); false: the "
        "paper's phase-only baseline",
    )
    range_order: Literal[0, 1, 2] = key(
        2, "Order of the range model of the phase step (2: the paper's second-order model)"
    )
    min_quality: float = key(
        0.3, "Lines of lower estimator quality (0..1) get zero weight", ge=0, le=1
    )
    min_peak_db: float = key(
        15.0,
        "Lines whose azimuth-compressed peak stands less than this above the line's median "
        "power get zero weight (the peak of ~M exponential noise samples is about 8 dB over "
        "their median)",
        unit="dB",
    )
    max_below_strongest_db: float = key(
        20.0,
        "Lines whose compressed peak is more than this below the strongest line's get zero weight",
        unit="dB",
        ge=0,
    )
    min_lines: int = key(
        2,
        "A subaperture with fewer usable lines, none of them lit throughout it, makes no "
        "estimate of its own (bridged from its neighbours) rather than a fit through noise",
        ge=1,
    )
    rate_span_hz_per_s: float = key(
        150.0, "Search half-width of the contrast estimator", unit="Hz/s", gt=0
    )
    phase_passes: int = key(
        3,
        "Passes of the phase step, each on the output of the one before (their kappa add "
        "up); the release latency is subaperture_s/2 + (phase_passes * ceil(subaperture_s / "
        "(2 hop_s)) + 1) * hop_s (1.3 s by default, 0.7 s = subaperture_s + hop_s with one "
        "pass)",
        ge=1,
    )
    pin_window_s: float = key(
        2.0,
        "Span of subaperture centres over which the unobservable constant and linear "
        "corrections are pinned to zero mean and trend (first pulses wait this long)",
        unit="s",
        gt=0,
    )

    def __post_init__(self) -> None:
        if not 0 < self.hop_s <= self.subaperture_s:
            raise ProcessingError(
                f"AutofocusConfig.hop_s: {self.hop_s} must be in (0, subaperture_s "
                f"{self.subaperture_s}]"
            )
        if self.min_lines < 1 or self.phase_passes < 1:
            raise ProcessingError(
                f"AutofocusConfig.min_lines {self.min_lines} and phase_passes "
                f"{self.phase_passes}: each must be at least 1"
            )
        if not self.pin_window_s > 0:
            raise ProcessingError(
                f"AutofocusConfig.pin_window_s: {self.pin_window_s} must be positive"
            )
        if self.estimator not in ("map-drift", "contrast"):
            raise ProcessingError(f"AutofocusConfig.estimator: {self.estimator!r} is unknown")
