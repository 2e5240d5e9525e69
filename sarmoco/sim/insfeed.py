"""The INS samples of a run as a simulated INS sends them: dropouts removed, device uptime,
output latency, and the geodetic position an INS reports.

Shared by the MAVLink, SBG serial and SBG CAN emitters, so every INS link
carries the same samples on the same clock.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sarmoco.processing.types import FloatArray, IntArray
from sarmoco.sim.faults import Faults, dropout_keep
from sarmoco.sim.ins import InsGrade
from sarmoco.sim.insclock import InsClock
from sarmoco.sim.run import SimRun
from sarmoco.sim.trajectory import true_trajectory

OUTPUT_LATENCY_S = 0.001
"""Time from an INS sample's epoch to its message leaving the device, s."""
GEODETIC_ORIGIN = (47.3769, 8.5417, 408.0)
"""Latitude (deg), longitude (deg) and height above the WGS-84 ellipsoid (m) of the local
NED origin (the scenario frame's tangent point). The simulated autopilot sends that height
where MAVLink has the altitude above mean sea level (it has no geoid model); the simulated
SBG INS sends the altitude above mean sea level and :data:`GEOID_UNDULATION_M`, as an SBG
does."""
GEOID_UNDULATION_M = 47.4
"""Height of the geoid above the WGS-84 ellipsoid at :data:`GEODETIC_ORIGIN`, m (about its
value at Zurich)."""


@dataclass(frozen=True)
class InsFeed:
    """INS samples to send (only those outside dropouts), on the device clock.

    Attributes
    ----------
    index : ndarray of int64, shape (N,)
        Index of each sample in the run's INS record (so rates can decimate on it).
    t_ns : ndarray of int64, shape (N,)
        Sample epochs, scenario GPS ns.
    uptime_ns : ndarray of int64, shape (N,)
        The same epochs on the device clock (time since power-up), ns.
    vel_ned : ndarray, shape (N, 3)
        Measured velocity, m/s.
    quat : ndarray, shape (N, 4)
        Measured attitude, scalar-first, body → NED.
    pos_ned : ndarray, shape (N, 3) or None
        Measured position, m (None when the grade gives none).
    pulse_t_ns : ndarray of int64
        Pulse transmit times outside dropouts (sync-in events), scenario GPS ns.
    grade : InsGrade
        Error levels (for the accuracies the messages report).
    clock : InsClock
        The device clock.
    rate_hz : float
        Nominal sample rate on the device clock, Hz.
    latency_ns : int
        Output latency, ns.
    start_pos_ned : ndarray, shape (3,)
        True position of the INS at the first sample sent, scenario NED, m: where the
        position an INS without a measured one reports (its velocity integrated) starts.
    """

    index: IntArray
    t_ns: IntArray
    uptime_ns: IntArray
    vel_ned: FloatArray
    quat: FloatArray
    pos_ned: FloatArray | None
    pulse_t_ns: IntArray
    grade: InsGrade
    clock: InsClock
    rate_hz: float
    latency_ns: int = round(OUTPUT_LATENCY_S * 1e9)
    start_pos_ned: FloatArray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def from_run(cls, run: SimRun, faults: Faults) -> InsFeed:
        """The feed of ``run``; the run's INS clock must have ``faults``' offset and drift."""
        nav, ins = run.ins.nav, run.ins
        clock = InsClock.from_faults(run.scenario.t0_ns, run.t0_ns, faults)
        keep = dropout_keep(nav.t_ns, run.t0_ns, faults.ins_dropouts_s)
        uptime = clock.sample_uptime_ns(ins.t_device_ns, nav.t_ns)
        dt = np.diff(ins.t_device_ns)
        rate = 1e9 / float(np.median(dt)) if dt.size else 1.0
        pulses = run.t_ns[dropout_keep(run.t_ns, run.t0_ns, faults.ins_dropouts_s)]
        t_first_s = (nav.t_ns[keep][:1] - run.scenario.t0_ns) * 1e-9
        start = true_trajectory(run.scenario, t_first_s, run.motion).pos_ned
        return cls(
            index=np.flatnonzero(keep).astype(np.int64),
            t_ns=nav.t_ns[keep],
            uptime_ns=uptime[keep],
            vel_ned=nav.vel_ned[keep],
            quat=nav.quat[keep],
            pos_ned=None if nav.pos_ned is None else nav.pos_ned[keep],
            pulse_t_ns=pulses,
            grade=ins.grade,
            clock=clock,
            rate_hz=rate,
            latency_ns=round((OUTPUT_LATENCY_S + faults.ins_late_s) * 1e9),
            start_pos_ned=start[0] if start.size else np.zeros(3),
        )

    def every(self, period_s: float) -> int:
        """Decimation factor giving one sample per ``period_s`` (at least 1)."""
        return max(1, round(period_s * self.rate_hz))
