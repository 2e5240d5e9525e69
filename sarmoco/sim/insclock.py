"""The simulated INS (or autopilot) clock: time since power-up as the device counts it.

The simulator's INS model (:func:`sarmoco.sim.ins.measure_ins`) samples on a
device clock ``t_dev = epoch + offset + (t_gps - epoch)(1 + drift_ppm 1e-6)``.
The wire carries that clock as an uptime (SBG: µs since power-up; MAVLink:
``time_boot_ms`` and TIMESYNC ns since boot). :class:`InsClock` is the one
definition of that uptime, for the samples and for every time message
(SBG UTC_TIME, MAVLink SYSTEM_TIME and TIMESYNC answers), so all of them are
consistent and a correct driver recovers GPS time exactly. Clock steps (a
fault) shift the uptime of everything at and after the step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sarmoco.processing.types import IntArray
from sarmoco.sim.faults import Faults

UPTIME_AT_EPOCH_NS = 600_000_000_000
"""Uptime of the INS at the scenario epoch (a whole number of ms), ns."""


@dataclass(frozen=True)
class InsClock:
    """Uptime of the simulated INS as a function of (scenario) GPS time.

    Attributes
    ----------
    epoch_ns : int
        Scenario epoch, GPS ns (the INS model's ``epoch_ns``).
    offset_ns : int
        Device clock offset at the epoch, ns.
    drift_ppm : float
        Device clock rate error, ppm.
    steps : tuple of (t_gps_ns, step_ns)
        Clock steps: from ``t_gps_ns`` on, the uptime is larger by ``step_ns``.
    uptime_at_epoch_ns : int
        Uptime when the device clock reads the epoch, ns.
    """

    epoch_ns: int
    offset_ns: int = 0
    drift_ppm: float = 0.0
    steps: tuple[tuple[int, int], ...] = ()
    uptime_at_epoch_ns: int = UPTIME_AT_EPOCH_NS

    @classmethod
    def from_faults(cls, epoch_ns: int, t0_ns: int, faults: Faults) -> InsClock:
        """The clock of a run: offset and drift as given to the INS model, steps after ``t0_ns``."""
        steps = tuple(
            (t0_ns + round(at_s * 1e9), round(step_s * 1e9))
            for at_s, step_s in faults.clock_steps_s
        )
        return cls(epoch_ns, round(faults.clock_offset_s * 1e9), faults.clock_drift_ppm, steps)

    def _steps_ns(self, t_gps_ns: IntArray) -> IntArray:
        total = np.zeros(t_gps_ns.shape, dtype=np.int64)
        for at_ns, step_ns in self.steps:
            total += np.where(t_gps_ns >= at_ns, step_ns, 0)
        return total

    def uptime_ns(self, t_gps_ns: int) -> int:
        """Uptime at GPS time ``t_gps_ns`` (any instant, e.g. a TIMESYNC request), ns."""
        dt = t_gps_ns - self.epoch_ns
        base = self.uptime_at_epoch_ns + self.offset_ns + dt + round(dt * self.drift_ppm * 1e-6)
        return base + int(self._steps_ns(np.asarray([t_gps_ns], dtype=np.int64))[0])

    def sample_uptime_ns(self, t_device_ns: IntArray, t_gps_ns: IntArray) -> IntArray:
        """Uptime of INS samples from the INS model's device stamps (exact ticks), ns."""
        return t_device_ns - self.epoch_ns + self.uptime_at_epoch_ns + self._steps_ns(t_gps_ns)

    def to_dict(self) -> dict[str, object]:
        """JSON-able form (for truth.json)."""
        return {
            "epoch_ns": self.epoch_ns,
            "offset_ns": self.offset_ns,
            "drift_ppm": self.drift_ppm,
            "steps": [list(s) for s in self.steps],
            "uptime_at_epoch_ns": self.uptime_at_epoch_ns,
            "model": "uptime = uptime_at_epoch + offset + (t_gps - epoch)(1 + drift_ppm 1e-6)"
            " + sum(step for t_gps >= at)",
        }
