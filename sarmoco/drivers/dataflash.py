"""ArduPilot dataflash ``.bin`` logs through pymavlink's DFReader (replay only).

Velocity from XKF1 (core 0) or NKF1 (VN, VE, VD m/s; PN, PE, PD m), attitude
from XKQ (core 0), XKQ1 or NKQ1 quaternions, else ATT (degrees). The log's
``TimeUS`` (µs since boot) is mapped onto GPS time by a least-squares offset
(and, once the records span a minute, skew) fit to the GPS records (GWk, GMS
are GPS time; fixes with Status ≥ 3), rejecting pairs more than 50 ms off
the first fit. The file is read twice: once for the GPS records, once for the
samples.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.drivers.attitude import euler_to_quat, normalized
from sarmoco.drivers.clock import GPS_LEAP_SECONDS_DEFAULT, gps_week_ms_to_gps_ns
from sarmoco.drivers.samples import AttitudeSample, Sample, Validity, VelocitySample
from sarmoco.drivers.source import Source
from sarmoco.errors import DataFileError, DriverError

log = logging.getLogger(__name__)

VELOCITY_TYPES = ("XKF1", "NKF1")
QUAT_TYPES = ("XKQ", "XKQ1", "NKQ1")
GPS_FIX_3D = 3
_OUTLIER_NS = 50_000_000
_MIN_SKEW_SPAN_US = 60_000_000
"""GPS records must span this long (µs) before a clock skew is fitted (else offset only)."""
_VEL_VALID = Validity.VELOCITY | Validity.POSITION | Validity.TIME
_ATT_VALID = Validity.ATTITUDE | Validity.HEADING | Validity.TIME


def _core0(m: Any) -> bool:
    return getattr(m, "C", 0) == 0


def _fit_gps_time(time_us: np.ndarray, gps_ns: np.ndarray) -> tuple[float, float, float]:
    """Least-squares ``gps = a + b · TimeUS`` (relative to the first pair), one outlier pass."""
    x = (time_us - time_us[0]).astype(np.float64)
    y = (gps_ns - gps_ns[0]).astype(np.float64)
    keep = np.ones(x.size, bool)
    for _ in range(2):
        if keep.sum() >= 2 and np.ptp(x[keep]) >= _MIN_SKEW_SPAN_US:
            b, a = np.polyfit(x[keep], y[keep], 1)
        else:
            b, a = 1000.0, float(np.median(y - 1000.0 * x))
        keep = np.abs(y - (a + b * x)) < _OUTLIER_NS
        if not keep.any():
            keep[:] = True
    return a, b, float(np.sqrt(np.mean((y - (a + b * x))[keep] ** 2)))


class DataflashSource(Source):
    """Samples from an ArduPilot dataflash log.

    Parameters
    ----------
    path : str or Path
        The ``.bin`` log.
    leap_s : int
        Unused by the mapping (dataflash GPS records are GPS time); kept for a
        uniform constructor.
    messages_per_poll : int
        Log records read per :meth:`poll`.

    Raises
    ------
    DataFileError
        If the log has no GPS record with a 3D fix (no GPS time to map onto).
    """

    def __init__(
        self,
        path: str | Path,
        leap_s: int = GPS_LEAP_SECONDS_DEFAULT,
        messages_per_poll: int = 5000,
    ) -> None:
        super().__init__()
        from pymavlink import mavutil

        self.path = str(path)
        try:
            self._log = mavutil.mavlink_connection(self.path)
        except (OSError, ValueError) as exc:
            raise DriverError(f"dataflash {path}: cannot open: {exc}") from exc
        t_us, g_ns, kinds = [], [], set()
        while (m := self._log.recv_match(type=["GPS", *VELOCITY_TYPES, *QUAT_TYPES])) is not None:
            kinds.add(m.get_type())
            if m.get_type() == "GPS" and m.Status >= GPS_FIX_3D and m.GWk > 0:
                t_us.append(m.TimeUS)
                g_ns.append(gps_week_ms_to_gps_ns(m.GWk, m.GMS))
        if not t_us:
            raise DataFileError(f"dataflash {path}: no GPS record with a 3D fix: no GPS time")
        self._t0_us, self._g0_ns = t_us[0], g_ns[0]
        self._a, self._b, self.residual_ns = _fit_gps_time(np.array(t_us), np.array(g_ns))
        self._vel_type = next((k for k in VELOCITY_TYPES if k in kinds), None)
        self._quat_type = next((k for k in QUAT_TYPES if k in kinds), None)
        self._att_type = self._quat_type or "ATT"
        self._log.rewind()
        self._n = messages_per_poll

    def gps_ns(self, time_us: int) -> int:
        """GPS ns of a log ``TimeUS``."""
        return self._g0_ns + round(self._a + self._b * (time_us - self._t0_us))

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        out: list[Sample] = []
        types = [t for t in (self._vel_type, self._att_type) if t]
        for _ in range(self._n):
            m = self._log.recv_match(type=types)
            if m is None:
                self.eof = True
                break
            self.counters.frames += 1
            if _core0(m):
                self._sample(m, out)
        return out

    def _sample(self, m: Any, out: list[Sample]) -> None:
        t, dev = self.gps_ns(m.TimeUS), m.TimeUS * 1000
        kind = m.get_type()
        if kind == self._vel_type:
            v = (m.VN, m.VE, m.VD)
            out.append(
                VelocitySample(t, v, _VEL_VALID, f"dataflash.{kind}", dev, (m.PN, m.PE, m.PD))
            )
            return
        if kind == "ATT":
            q = normalized(euler_to_quat(*np.radians([m.Roll, m.Pitch, m.Yaw]).tolist()))
        else:
            q = normalized((m.Q1, m.Q2, m.Q3, m.Q4))
        if q is None:
            self.counters.parse_errors += 1
            return
        out.append(AttitudeSample(t, q, _ATT_VALID, f"dataflash.{kind}", dev))

    def close(self) -> None:
        self._log.close()
