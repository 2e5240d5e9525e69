"""What each autofocus stage estimated, kept per subaperture for the recorder and the operator.

Every field is a plain number or array so the record can be written to zarr/JSON as is.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sarmoco.processing.types import FloatArray


@dataclass(frozen=True)
class LineRates:
    """Doppler-rate errors measured on the selected range lines of one subaperture.

    Parameters
    ----------
    range_m : ndarray, shape (N,)
        Slant range of each selected line, m.
    rate_hz_per_s : ndarray, shape (N,)
        Doppler-rate error of each line relative to the nominal rate, Hz/s.
    weight : ndarray, shape (N,)
        Weight in the fits: the line's compressed peak-to-median power ratio minus one (its
        signal-to-noise ratio; docs/methods.md §3 eq. 13 uses the mean magnitude, see
        ``streaming._line_rates``), zero for a rejected line.
    quality : ndarray, shape (N,)
        Reliability in [0, 1] (map drift: normalised correlation peak; contrast: relative
        contrast gain); lines under the configured floor get zero weight in the fits.
    peak_db : ndarray, shape (N,)
        Peak of the line's azimuth-compressed power over its median, dB: how far the line's
        dominant scatterer stands above noise and clutter; lines under the configured floor
        get zero weight.
    """

    range_m: FloatArray
    rate_hz_per_s: FloatArray
    weight: FloatArray
    quality: FloatArray
    peak_db: FloatArray

    @property
    def n_used(self) -> int:
        """Number of lines with non-zero weight."""
        return int(np.count_nonzero(self.weight))


@dataclass(frozen=True)
class SubapertureReport:
    """Estimates of one subaperture (both steps of docs/methods.md §3).

    Parameters
    ----------
    index : int
        Running subaperture number.
    t_center_s : float
        Centre time of the subaperture, s on the caller's time axis.
    envelope_lines, phase_lines : LineRates or None
        Line rates of the envelope step (uncorrected data) and the phase step
        (envelope-corrected data); None for a step that did not run.
    accel_yz_mps2 : tuple of float
        Cross-track accelerations (a_y, a_z) in the imaging frame, m/s² (NaN if not run).
    accel_residual_hz_per_s : float
        Weighted RMS residual of the acceleration fit, Hz/s.
    kappa : ndarray, shape (3,)
        Range model of the rate error, κ0 (Hz/s), κ1 (Hz/s/m), κ2 (Hz/s/m²);
        unused orders are zero.
    kappa_residual_hz_per_s : float
        Weighted RMS residual of the κ fit, Hz/s.
    applied : bool
        Whether the corrections were applied to the pulses released with this estimate
        (False: they lowered the focus of that block, which left uncorrected).
    """

    index: int
    t_center_s: float
    envelope_lines: LineRates | None
    phase_lines: LineRates | None
    accel_yz_mps2: tuple[float, float]
    accel_residual_hz_per_s: float
    kappa: FloatArray
    kappa_residual_hz_per_s: float
    applied: bool = True


@dataclass
class AutofocusReport:
    """All subaperture reports of a run plus the spliced series and the PGA record.

    Parameters
    ----------
    subapertures : list of SubapertureReport
        In time order.
    pga_rms_updates_rad : list of float
        RMS phase update of each PGA iteration, rad (empty if PGA did not run).
    """

    subapertures: list[SubapertureReport] = field(default_factory=list)
    pga_rms_updates_rad: list[float] = field(default_factory=list)

    def series(self) -> dict[str, FloatArray]:
        """Per-subaperture estimates: ``t_center_s``, ``a_y``, ``a_z``, ``kappa`` (J, 3)."""
        subs = self.subapertures
        return {
            "t_center_s": np.array([s.t_center_s for s in subs], dtype=float),
            "a_y": np.array([s.accel_yz_mps2[0] for s in subs], dtype=float),
            "a_z": np.array([s.accel_yz_mps2[1] for s in subs], dtype=float),
            "kappa": np.array([s.kappa for s in subs], dtype=float).reshape(len(subs), 3),
        }
