"""The specification of a simulated platform's motion: which deviation from the nominal
line (:mod:`sarmoco.sim.trajectory` describes each kind) and its parameters.

Units: m, m/s, rad, Hz, s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal


@dataclass(frozen=True)
class MotionSpec:
    """What deviates from the nominal line, and how much.

    Parameters
    ----------
    kind : {"ideal", "turbulence", "flightlog", "survey"}
        See the module docstring.
    cross_track_rms_m, vertical_rms_m : float
        Rms displacement east / down, m (turbulence).
    along_speed_rms_mps : float
        Rms along-track speed variation, m/s (turbulence).
    attitude_rms_rad : float
        Rms of each of roll, pitch, yaw about level flight heading north, rad (turbulence).
    corner_hz : float
        Corner frequency f_c of the spectrum, Hz (turbulence).
    seed : int
        Seed of the random phases and frequencies (turbulence).
    log_path : Path or None
        MAVLink telemetry log (``*.tlog``) for ``flightlog``.
    log_start_s : float
        Time of the first pulse after the start of the log's airborne segment, s (flightlog).
    log_window_s : float
        Length of the log window the deviations are fitted on, s (flightlog); the trajectory
        is defined from ``LOG_MARGIN_S`` before the first pulse to ``log_window_s`` plus that
        margin after it.
    legs : int
        Straight legs of the survey pattern (survey).
    leg_s : float
        Duration of each leg, s (survey).
    turn_rate_dps : float or None
        Turn rate between legs, deg/s (survey); None: the real log's
        (:data:`sarmoco.sim.survey.LOG_TURN_RATE_DPS`).
    """

    kind: Literal["ideal", "turbulence", "flightlog", "survey"] = "ideal"
    cross_track_rms_m: float = 0.3
    vertical_rms_m: float = 0.3
    along_speed_rms_mps: float = 0.1
    attitude_rms_rad: float = 0.01
    corner_hz: float = 0.2
    seed: int = 0
    log_path: Path | None = None
    log_start_s: float = 10.0
    log_window_s: float = 20.0
    legs: int = 2
    leg_s: float = 20.0
    turn_rate_dps: float | None = None
