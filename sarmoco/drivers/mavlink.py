"""MAVLink autopilots through pymavlink: live links (UDP, TCP, serial) and ``.tlog`` replay.

Velocity from LOCAL_POSITION_NED (also GLOBAL_POSITION_INT and ODOMETRY),
attitude from ATTITUDE_QUATERNION (or ATTITUDE). An autopilot streams GLOBAL_POSITION_INT
and ATTITUDE by default beside what the daemon asks for; while LOCAL_POSITION_NED
(ATTITUDE_QUATERNION) arrives, GLOBAL_POSITION_INT (ATTITUDE) gives no sample, so that the
coarser message (cm/s velocities) never takes the place of the finer one at the same
instant; after :data:`FINER_HOLD_MS` without the finer one it does.

Positions (:class:`~sarmoco.drivers.posframe.LocalPositions`): GPS_GLOBAL_ORIGIN states the
EKF origin, the point LOCAL_POSITION_NED (and ODOMETRY in the local NED frame) is about;
with it those positions also get their latitude, longitude and altitude. An autopilot
that has not sent GPS_GLOBAL_ORIGIN (it does so when the origin is set, perhaps before the
log began) still sends GLOBAL_POSITION_INT at the instants of some LOCAL_POSITION_NED:
the first such pair (with a valid position) gives the EKF origin, forgotten when the boot
time goes back (a reboot). GLOBAL_POSITION_INT positions become NED about the EKF origin,
or about the first of them while none is known. Every sample names its frame
(``pos_frame``).

Autopilot boot time is mapped onto GPS time by :class:`BootClockModel`:

* TIMESYNC (live links): the source sends a request every ``timesync_period_s``;
  :class:`~sarmoco.drivers.timesync.TimesyncEstimator` fits boot time → host
  clock from the exchanges within a margin of the fastest recent round trip. The
  host clock must be UTC-disciplined (chrony/PTP/GPS); GPS = host + leap seconds. It is
  read on the monotonic clock (:class:`~sarmoco.drivers.hostclock.HostClock`): a step of
  the wall clock is logged and taken only when it brings the host nearer the autopilot's
  SYSTEM_TIME (:meth:`MavlinkSource._judge_step`). The estimate's stated error bound is
  :attr:`MavlinkSource.time_bound_ns`.
* SYSTEM_TIME (always; the only reference in replay): pairs of
  ``time_boot_ms`` and the autopilot's GPS-derived UNIX time, fitted with
  outlier rejection.

A boot time that goes backwards (reboot) resets both. The wanted message rates
are requested with MAV_CMD_SET_MESSAGE_INTERVAL when the autopilot's first
HEARTBEAT arrives and again after a reboot. With a signing key, unsigned and
badly signed packets are rejected and counted in ``counters.rejected``.

Only the vehicle's autopilot is listened to: the configured ``system_id``, or by default
the first system whose HEARTBEAT says it is an autopilot (an ``autopilot`` field other
than MAV_AUTOPILOT_INVALID, a vehicle ``type``: not a ground station, companion computer,
gimbal, camera... :data:`NOT_A_VEHICLE`). Until one has, the messages of each system are
held (:data:`HOLD_MESSAGES` each, :data:`HOLD_SYSTEMS` systems), and the autopilot's are
decoded when its HEARTBEAT comes; a log without such a HEARTBEAT (by its end, or by the
time a system's hold is full) falls back to the first system heard; a live link logs that
it is waiting. Rate requests go to the autopilot (``target_system``); TIMESYNC carries no
target in this dialect, and only the autopilot's replies count. Every other system on the
link (a second vehicle, a companion computer relaying its own estimate, a stray sender) is
named in the log when first heard, its messages ignored and counted in
``counters.rejected`` and per system in :attr:`MavlinkSource.other_systems`.

pymavlink picks MAVLink 1 or 2 from the ``MAVLINK20`` environment variable at
import time; this module sets it (to MAVLink 2) unless the caller already did.
"""

from __future__ import annotations

import logging
import math
import os
import struct
import time
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import numpy as np
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sarmoco.drivers.attitude import euler_to_quat, normalized
from sarmoco.drivers.clock import (
    GPS_LEAP_SECONDS_DEFAULT,
    unix_ns_to_gps_ns,
)
from sarmoco.drivers.devclock import DeviceClock
from sarmoco.drivers.hostclock import HostClock
from sarmoco.drivers.posframe import LocalPositions
from sarmoco.drivers.samples import (
    AttitudeSample,
    Sample,
    Validity,
    VelocitySample,
)
from sarmoco.drivers.source import Source
from sarmoco.drivers.timesync import (
    LinearClockFit,
    TimesyncEstimator,
    TimesyncExchange,
)
from sarmoco.errors import ClockError, ConfigError, DriverError
from sarmoco.geodesy import tangent_origin

log = logging.getLogger(__name__)

REQUESTED_RATES_HZ: dict[str, float] = {
    "LOCAL_POSITION_NED": 50.0,
    "ATTITUDE_QUATERNION": 50.0,
    "SYSTEM_TIME": 2.0,
}
"""Message rates the source asks for, Hz."""
FINER: dict[str, str] = {
    "GLOBAL_POSITION_INT": "LOCAL_POSITION_NED",
    "ATTITUDE": "ATTITUDE_QUATERNION",
}
"""Message → the finer message of the same quantity that takes precedence over it."""
FINER_HOLD_MS = 1000
"""Autopilot boot time after the last finer message during which the coarser one gives no
sample, ms."""
UNIX_USEC_THRESHOLD = 10**15
"""MAVLink ``time_usec`` above this is UNIX time, below it time since boot, µs."""
MAX_UNIX_USEC = (2**63 - 1) // 1000 - 10**9
"""Latest UNIX time accepted, µs (year 2262: its GPS ns still fit an int64 column)."""
_ALL_VALID = Validity.ATTITUDE | Validity.HEADING | Validity.VELOCITY | Validity.POSITION
_SYSTIME_OUTLIER_NS = 50_000_000
_SYSTIME_JITTER_NS = 1_000_000


class BootClockModel:
    """Autopilot boot time (ns) → GPS time (ns), from TIMESYNC or SYSTEM_TIME.

    Parameters
    ----------
    leap_s : int
        GPS − UTC, s.
    use_timesync : bool
        Whether the host clock is UTC-disciplined so TIMESYNC can map boot
        time to GPS time (live links); otherwise only SYSTEM_TIME is used.
    """

    def __init__(self, leap_s: int, use_timesync: bool) -> None:
        self.leap_s = leap_s
        self.use_timesync = use_timesync
        self.timesync = TimesyncEstimator()
        self.systime = LinearClockFit(window=32, outlier_ns=_SYSTIME_OUTLIER_NS)
        self.host_error_ns = 0
        """Error of the host clock's own reading of UTC (its wall and monotonic clocks
        paired, :attr:`~sarmoco.drivers.hostclock.HostClock.read_error_ns`), ns: part of
        the TIMESYNC bound, whose local times are host UTC."""

    @property
    def _by_timesync(self) -> bool:
        return self.use_timesync and self.timesync.ready

    @property
    def ready(self) -> bool:
        """Whether boot time can be mapped."""
        return self._by_timesync or self.systime.ready

    @property
    def bound_ns(self) -> int:
        """Stated error bound of :meth:`map`, ns (TIMESYNC bound and the host clock's
        reading error, or SYSTEM_TIME jitter)."""
        if self._by_timesync:
            return self.timesync.bound_ns + self.host_error_ns
        return _SYSTIME_JITTER_NS + round(3 * self.systime.residual_ns)

    def add(self, device_ns: int, reference_ns: int) -> bool:
        """Add a SYSTEM_TIME pair (boot ns, GPS ns)."""
        return self.systime.add(device_ns, reference_ns)

    def map(self, device_ns: int) -> int:
        """GPS ns of a boot time (ns); raises ClockError before any reference."""
        if self._by_timesync:
            return unix_ns_to_gps_ns(self.timesync.to_local(device_ns), self.leap_s)
        return self.systime.map(device_ns)

    def reset(self) -> None:
        """Forget both references (autopilot reboot)."""
        self.systime.reset()
        self.timesync.reset()


class MavlinkDecoder:
    """MAVLink messages in, samples on GPS time out.

    Parameters
    ----------
    leap_s : int
        GPS − UTC, s.
    use_timesync : bool
        See :class:`BootClockModel`.
    link : str
        Name used in log messages.
    counters_from : Source
        The source whose counters are updated.
    """

    def __init__(self, leap_s: int, use_timesync: bool, link: str, counters_from: Source) -> None:
        self.counters = counters_from.counters
        self.model = BootClockModel(leap_s, use_timesync)
        self.clock = DeviceClock(link, self.counters, model=self.model, tick_ns=1_000_000)
        self.valid = _ALL_VALID
        self.positions = LocalPositions("mavlink.GLOBAL_POSITION_INT")
        """The EKF origin (stated by GPS_GLOBAL_ORIGIN) and the frame of the positions."""
        self._local: tuple[int, tuple[float, float, float]] | None = None
        """Boot time (ms) and position (NED m) of the last LOCAL_POSITION_NED."""
        self._global: tuple[int, tuple[float, float, float]] | None = None
        """Boot time (ms) and valid position (deg, deg, m) of the last GLOBAL_POSITION_INT."""
        self._finer_ms: dict[str, int] = {}
        """Boot time of the last message of each finer kind (:data:`FINER`), ms."""
        self._handlers: dict[str, Callable[[Any, list[Sample]], None]] = {
            "LOCAL_POSITION_NED": self._local_position,
            "GLOBAL_POSITION_INT": self._global_position,
            "ODOMETRY": self._odometry,
            "ATTITUDE_QUATERNION": self._attitude_quaternion,
            "ATTITUDE": self._attitude,
            "SYSTEM_TIME": self._system_time,
            "EKF_STATUS_REPORT": self._ekf_status,
            "GPS_GLOBAL_ORIGIN": self._origin,
        }

    def handle(self, msg: Any) -> list[Sample]:
        """Samples completed by one pymavlink message (others are ignored)."""
        out: list[Sample] = []
        name = msg.get_type()
        handler = self._handlers.get(name)
        if handler is None:
            return out
        if name == "LOCAL_POSITION_NED":
            if self._local is not None and msg.time_boot_ms < self._local[0]:
                self.positions.stated = None  # rebooted: the EKF sets a new origin
            self._local = (msg.time_boot_ms, (msg.x, msg.y, msg.z))
        elif name == "GLOBAL_POSITION_INT" and self.valid & Validity.POSITION:
            lla = self._geodetic(msg.lat, msg.lon, msg.alt)
            self._global = None if lla is None else (msg.time_boot_ms, lla)
        if name in ("LOCAL_POSITION_NED", "GLOBAL_POSITION_INT"):
            self._origin_from_pair()
        if not self._superseded(name, msg):
            handler(msg, out)
        return out

    def _origin_from_pair(self) -> None:
        """The EKF origin from a GLOBAL_POSITION_INT and a LOCAL_POSITION_NED of the same
        instant, while the autopilot has stated none."""
        if self.positions.stated is not None or self._local is None or self._global is None:
            return
        (boot_local, ned), (boot_global, lla) = self._local, self._global
        if boot_local != boot_global or not all(map(math.isfinite, ned)):
            return
        lat, lon, alt = tangent_origin(np.asarray(lla), np.asarray(ned)).tolist()
        self.positions.state((lat, lon, alt), "mavlink.GLOBAL_POSITION_INT - LOCAL_POSITION_NED")

    def _superseded(self, name: str, msg: Any) -> bool:
        """Whether ``msg`` is the coarser of two messages of a quantity (:data:`FINER`) and
        the finer one arrived within :data:`FINER_HOLD_MS` before it; notes finer ones."""
        boot_ms = getattr(msg, "time_boot_ms", None)
        if boot_ms is None:
            return False
        if name in FINER.values():
            self._finer_ms[name] = boot_ms
            return False
        finer = FINER.get(name)
        last = self._finer_ms.get(finer, None) if finer is not None else None
        return last is not None and 0 <= boot_ms - last <= FINER_HOLD_MS

    def _boot(self, time_boot_ms: int) -> int:
        return self.clock.device_ns(time_boot_ms)

    def _velocity(
        self,
        out: list[Sample],
        dev_ns: int,
        vel: tuple[float, float, float],
        source: str,
        pos: tuple[float, float, float] | None = None,
        lla: tuple[float, float, float] | None = None,
    ) -> None:
        """Stamp one velocity sample; ``pos`` is NED about the EKF origin, ``lla`` a
        geodetic position (either may be None)."""
        if not all(map(math.isfinite, vel)):  # would reach the motion compensation as NaN
            self.counters.parse_errors += 1
            return
        pos = pos if pos is not None and all(map(math.isfinite, pos)) else None
        frame = self.positions.stated if pos is not None else None
        if lla is not None:
            pos, frame = self.positions.local(lla)
        elif pos is not None:
            lla = self.positions.geodetic(pos)
        sample = VelocitySample(
            0, vel, self.valid & ~Validity.ATTITUDE & ~Validity.HEADING, source, dev_ns,
            pos_ned=pos, lat_lon_alt=lla, pos_frame=frame,
        )  # fmt: skip
        self.clock.stamp(sample, out)

    def _local_position(self, m: Any, out: list[Sample]) -> None:
        self._velocity(
            out, self._boot(m.time_boot_ms), (m.vx, m.vy, m.vz), "mavlink.LOCAL_POSITION_NED",
            pos=(m.x, m.y, m.z),
        )  # fmt: skip

    def _global_position(self, m: Any, out: list[Sample]) -> None:
        vel = (m.vx / 100.0, m.vy / 100.0, m.vz / 100.0)
        lla = self._geodetic(m.lat, m.lon, m.alt)
        if lla is not None and not self.valid & Validity.POSITION:
            lla = None
        dev_ns = self._boot(m.time_boot_ms)
        self._velocity(out, dev_ns, vel, "mavlink.GLOBAL_POSITION_INT", lla=lla)

    def _origin(self, m: Any, out: list[Sample]) -> None:
        lla = self._geodetic(m.latitude, m.longitude, m.altitude)
        if lla is not None:
            self.positions.state(lla, "mavlink.GPS_GLOBAL_ORIGIN")

    def _geodetic(self, lat_e7: int, lon_e7: int, alt_mm: int) -> tuple[float, float, float] | None:
        """A MAVLink position (degE7, degE7, mm) in deg, deg, m; None for none (both zero,
        as an autopilot without a fix sends) or out of range (counted as a parse error)."""
        if lat_e7 == 0 and lon_e7 == 0:
            return None
        lla = (lat_e7 / 1e7, lon_e7 / 1e7, alt_mm / 1000.0)
        if not (-90.0 <= lla[0] <= 90.0 and -180.0 <= lla[1] <= 180.0):
            self.counters.parse_errors += 1
            return None
        return lla

    def _odometry(self, m: Any, out: list[Sample]) -> None:
        if m.frame_id != mavlink2.MAV_FRAME_LOCAL_NED:
            self.counters.rejected += 1
            return
        q = normalized(tuple(m.q))
        if m.child_frame_id == mavlink2.MAV_FRAME_LOCAL_NED:
            vel = (m.vx, m.vy, m.vz)
        elif m.child_frame_id == mavlink2.MAV_FRAME_BODY_FRD and q is not None:
            vel = _rotate(q, (m.vx, m.vy, m.vz))
        else:
            self.counters.rejected += 1
            return
        if m.time_usec > MAX_UNIX_USEC:
            self.counters.parse_errors += 1
            return
        if m.time_usec >= UNIX_USEC_THRESHOLD:
            t = unix_ns_to_gps_ns(m.time_usec * 1000, self.model.leap_s)
            pos = (m.x, m.y, m.z)
            out.append(
                VelocitySample(
                    t, vel, self.valid, "mavlink.ODOMETRY", t, pos,
                    lat_lon_alt=self.positions.geodetic(pos), pos_frame=self.positions.stated,
                )
            )  # fmt: skip
            return
        dev_ns = self._boot(m.time_usec // 1000) + (m.time_usec % 1000) * 1000
        self._velocity(out, dev_ns, vel, "mavlink.ODOMETRY", pos=(m.x, m.y, m.z))

    def _attitude_quaternion(self, m: Any, out: list[Sample]) -> None:
        q = normalized((m.q1, m.q2, m.q3, m.q4))
        if q is None:
            self.counters.parse_errors += 1
            return
        dev = self._boot(m.time_boot_ms)
        valid = self.valid & (Validity.ATTITUDE | Validity.HEADING)
        self.clock.stamp(AttitudeSample(0, q, valid, "mavlink.ATTITUDE_QUATERNION", dev), out)

    def _attitude(self, m: Any, out: list[Sample]) -> None:
        angles = (m.roll, m.pitch, m.yaw)
        q = normalized(euler_to_quat(*angles)) if all(map(math.isfinite, angles)) else None
        if q is None:
            self.counters.parse_errors += 1
            return
        dev = self._boot(m.time_boot_ms)
        valid = self.valid & (Validity.ATTITUDE | Validity.HEADING)
        self.clock.stamp(AttitudeSample(0, q, valid, "mavlink.ATTITUDE", dev), out)

    def _system_time(self, m: Any, out: list[Sample]) -> None:
        if not m.time_unix_usec:
            return
        if not UNIX_USEC_THRESHOLD <= m.time_unix_usec <= MAX_UNIX_USEC:
            self.counters.parse_errors += 1
            return
        dev = self._boot(m.time_boot_ms)
        gps = unix_ns_to_gps_ns(m.time_unix_usec * 1000, self.model.leap_s)
        ts = self.clock.reference(dev, gps, True, "mavlink.SYSTEM_TIME")
        if ts is not None:
            self.clock.stamp(ts, out)

    def _ekf_status(self, m: Any, out: list[Sample]) -> None:
        f = m.flags
        v = Validity.NONE
        if f & mavlink2.EKF_ATTITUDE:
            v |= Validity.ATTITUDE | Validity.HEADING
        if f & mavlink2.EKF_VELOCITY_HORIZ and f & mavlink2.EKF_VELOCITY_VERT:
            v |= Validity.VELOCITY
        if f & (mavlink2.EKF_POS_HORIZ_REL | mavlink2.EKF_POS_HORIZ_ABS):
            v |= Validity.POSITION
        self.valid = v

    def timesync(self, ex: TimesyncExchange) -> None:
        """Feed one TIMESYNC round trip (boot-time reboots reset it)."""
        self.model.timesync.add(ex)


def _rotate(
    q: tuple[float, float, float, float], v: tuple[float, float, float]
) -> tuple[float, float, float]:
    w, x, y, z = q
    vx, vy, vz = v
    return (
        (1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
        2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
        2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz,
    )


NOT_A_VEHICLE = frozenset(
    getattr(mavlink2, f"MAV_TYPE_{name}")
    for name in (
        "GCS", "ONBOARD_CONTROLLER", "GIMBAL", "ADSB", "CAMERA", "ANTENNA_TRACKER",
        "CHARGING_STATION", "FLARM", "SERVO", "ODID", "BATTERY", "PARACHUTE", "LOG", "OSD",
        "IMU", "GPS", "WINCH", "GENERIC",
    )
    if hasattr(mavlink2, f"MAV_TYPE_{name}")
)  # fmt: skip
"""HEARTBEAT ``type`` values of systems that are not a vehicle's autopilot."""
HOLD_MESSAGES = 2000
"""Messages held per system until an autopilot is chosen (a few seconds of a 100 Hz INS)."""
HOLD_SYSTEMS = 4
"""Systems whose messages are held until an autopilot is chosen (others': dropped, counted)."""


def is_autopilot(heartbeat: Any) -> bool:
    """Whether a HEARTBEAT is that of a vehicle's autopilot (see :data:`NOT_A_VEHICLE`)."""
    return (
        heartbeat.autopilot != mavlink2.MAV_AUTOPILOT_INVALID
        and heartbeat.type not in NOT_A_VEHICLE
    )


def tlog_record(msg: Any) -> bytes:
    """A received message as a telemetry-log record: receive time (UNIX µs, 8 bytes
    big-endian; the log's own time for a ``.tlog``) then the frame as on the wire."""
    stamp = getattr(msg, "_timestamp", None)
    us = round((time.time() if stamp is None else stamp) * 1e6)
    return struct.pack(">Q", us) + bytes(msg.get_msgbuf())


class MavlinkSource(Source):
    """A MAVLink link or ``.tlog`` file.

    Parameters
    ----------
    url : str
        pymavlink connection string: ``udpin:127.0.0.1:14550``, ``udpout:host:port``,
        ``tcp:127.0.0.1:5760``, a serial device (with ``baudrate``), or a ``.tlog`` path.
    leap_s : int
        GPS − UTC, s.
    rates_hz : mapping of str to float
        Message name → rate requested with MAV_CMD_SET_MESSAGE_INTERVAL (live links).
    signing_key : bytes or None
        32-byte MAVLink 2 signing secret; when given, unsigned and badly signed
        packets are rejected (counted in ``counters.rejected``) and ours are signed.
    host_clock_is_utc : bool
        Whether the host wall clock is UTC-disciplined (then TIMESYNC maps boot
        time to GPS; otherwise only SYSTEM_TIME does).
    timesync_period_s : float
        Interval between TIMESYNC requests, s (live links); a fifth of it until the
        estimator has the exchanges it needs (after start and after a reboot), so
        samples do not wait long for their first time stamps.
    baudrate : int
        Serial line rate, baud.
    source_system, source_component : int
        Our MAVLink identity.
    system_id : int
        MAVLink system id of the vehicle whose messages are used; 0: the first system whose
        HEARTBEAT says it is an autopilot (see the module doc). Messages from other systems
        are counted in ``counters.rejected`` and :attr:`other_systems`, and ignored.
    """

    raw_format = "tlog"

    def __init__(
        self,
        url: str,
        leap_s: int = GPS_LEAP_SECONDS_DEFAULT,
        rates_hz: Mapping[str, float] | None = None,
        signing_key: bytes | None = None,
        host_clock_is_utc: bool = True,
        timesync_period_s: float = 0.25,
        baudrate: int = 115200,
        source_system: int = 255,
        source_component: int = mavlink2.MAV_COMP_ID_ONBOARD_COMPUTER,
        system_id: int = 0,
    ) -> None:
        super().__init__()
        if signing_key is not None and len(signing_key) != 32:  # before a socket is opened
            raise ConfigError(f"mavlink.signing_key: {len(signing_key)} bytes, need 32")
        self.url = url
        self.is_file = os.path.isfile(url)
        try:
            if self.is_file:
                # Not mavlink_connection(): it opens a .tlog as a mavmmaplog, whose index
                # pass decodes the first message of every type through the sequence, loss
                # and byte counters and then rewinds, so every counter would start wrong.
                mavutil.set_dialect("ardupilotmega")
                self._conn = mavutil.mavlogfile(
                    url, source_system=source_system, source_component=source_component
                )
            else:
                self._conn = mavutil.mavlink_connection(
                    url, baud=baudrate, source_system=source_system,
                    source_component=source_component, dialect="ardupilotmega",
                )  # fmt: skip
        except (OSError, ValueError) as exc:
            raise DriverError(f"mavlink {url}: cannot open: {exc}") from exc
        self.decoder = MavlinkDecoder(leap_s, host_clock_is_utc and not self.is_file, url, self)
        self.rates_hz = dict(REQUESTED_RATES_HZ if rates_hz is None else rates_hz)
        self._timesync_period_ns = round(timesync_period_s * 1e9)
        self._next_timesync_ns = 0
        self._outstanding: dict[int, int] = {}
        self._target: tuple[int, int] | None = None
        self._loss_seen = 0
        self._host = HostClock()
        """Host UTC for TIMESYNC, on the monotonic clock (wall clock steps are judged)."""
        self._last_remote_ns: int | None = None
        """Autopilot boot time of the last TIMESYNC reply, ns."""
        self.system_id = system_id
        """The vehicle's system id (0 until its autopilot's HEARTBEAT when not configured)."""
        self.other_systems: dict[int, int] = {}
        """Messages ignored, by the system id that sent them (all but the vehicle's)."""
        self._held: dict[int, deque[Any]] = {}
        """Messages of each system heard before the autopilot was chosen, oldest first."""
        if isinstance(self._conn, mavutil.mavtcp):
            # pymavlink prints and carries on (returning no data) when the peer goes away
            self._conn.handle_eof = self._conn.handle_disconnect = self._peer_closed
        if signing_key is not None:
            self._conn.setup_signing(
                signing_key, sign_outgoing=True, allow_unsigned_callback=lambda _m, _id: False
            )

    @property
    def time_bound_ns(self) -> int:
        """Stated bound on the error of the GPS times now being produced, ns."""
        return self.decoder.model.bound_ns

    def request_rates(self) -> None:
        """Send MAV_CMD_SET_MESSAGE_INTERVAL for every message in :attr:`rates_hz`."""
        if self._target is None:
            return
        sysid, compid = self._target
        for name, hz in self.rates_hz.items():
            msg_id = getattr(mavlink2, f"MAVLINK_MSG_ID_{name}")
            self._conn.mav.command_long_send(
                sysid, compid, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                msg_id, round(1e6 / hz), 0, 0, 0, 0, 0,
            )  # fmt: skip

    def _now_ns(self) -> int:
        """Host UTC now, ns (:class:`~sarmoco.drivers.hostclock.HostClock`); a step of the
        wall clock since the last read is judged first (:meth:`_judge_step`)."""
        now = self._host.now_ns()
        self.decoder.model.host_error_ns = self._host.read_error_ns
        step = self._host.take_step()
        if step and self._judge_step(step):
            now += step
        return now

    def _judge_step(self, step_ns: int) -> bool:
        """Take or ignore a step of the host's wall clock by ``step_ns``; returns whether it
        was taken.

        With TIMESYNC and SYSTEM_TIME both mapping the autopilot's boot clock, the step is
        taken when it brings the host clock nearer the autopilot's GPS-derived time (chrony
        or NTP correcting a clock that was wrong), and ignored when it takes the host clock
        away from it (the daemon goes on with the clock before the step, on the monotonic
        clock). Without SYSTEM_TIME to judge by, the host's time service is trusted and the
        step taken. A step taken restarts the TIMESYNC fit (its exchanges were timed on the
        clock before). Either way the log says what happened.
        """
        model, boot = self.decoder.model, self._last_remote_ns
        if model.use_timesync and model.timesync.ready and model.systime.ready and boot is not None:
            gps = unix_ns_to_gps_ns(model.timesync.to_local(boot), model.leap_s)
            before = gps - model.systime.map(boot)
            after = before + step_ns
            take = abs(after) < abs(before)
            why = (
                f"against the autopilot's GPS time (SYSTEM_TIME) the host clock was "
                f"{before / 1e6:+.1f} ms off before the step and is {after / 1e6:+.1f} ms "
                "after it"
            )
        else:
            take = True
            why = "no SYSTEM_TIME from the autopilot to judge it by: the host clock is trusted"
        if take:
            self._host.adopt(step_ns)
            self._outstanding.clear()
            self._next_timesync_ns = 0
            model.timesync.reset()
            what = "the step is taken and TIMESYNC starts again"
        else:
            what = "the step is ignored: TIMESYNC goes on with the clock before it"
        log.warning(
            "mavlink %s: the host wall clock stepped by %+.3f s; %s; %s",
            self.url, step_ns / 1e9, why, what,
        )  # fmt: skip
        return take

    def _send_timesync(self) -> None:
        now = self._now_ns()
        if now < self._next_timesync_ns or self._target is None:
            return
        settled = self.decoder.model.timesync.ready
        self._next_timesync_ns = now + self._timesync_period_ns // (1 if settled else 5)
        self._outstanding = {k: v for k, v in self._outstanding.items() if now - k < 10**9}
        self._outstanding[now] = now
        self._conn.mav.timesync_send(0, now)

    def _link_message(self, msg: Any) -> None:
        mtype = msg.get_type()
        if mtype == "HEARTBEAT":
            src = (msg.get_srcSystem(), msg.get_srcComponent())
            if is_autopilot(msg) and self._target is None:
                self._target = src
                self.request_rates()
        elif mtype == "TIMESYNC":
            now = self._now_ns()
            if msg.tc1 == 0:  # the autopilot's own request: answer it
                self._conn.mav.timesync_send(now, msg.ts1)
            elif msg.ts1 in self._outstanding:
                sent = self._outstanding.pop(msg.ts1)
                self._last_remote_ns = msg.tc1
                self.decoder.timesync(TimesyncExchange(sent, now, msg.tc1))

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        out: list[Sample] = []
        if not self.is_file:
            try:
                self._send_timesync()
            except OSError as exc:
                log.debug("mavlink %s: send failed: %s", self.url, exc)
        block = timeout_s > 0 and not self.is_file
        for _ in range(5000):
            try:
                msg = self._conn.recv_match(blocking=block, timeout=timeout_s if block else None)
            except DriverError:  # from _peer_closed
                raise
            except OSError as exc:  # port or socket gone (pyserial's SerialException is one)
                raise DriverError(f"mavlink {self.url}: {exc}") from exc
            except ValueError as exc:  # pymavlink choked on the bytes
                if self.is_file:
                    raise DriverError(f"mavlink {self.url}: {exc}") from exc
                self.counters.parse_errors += 1
                continue
            block = False
            if msg is None:
                if self.is_file:
                    self.eof = True
                    if self.system_id == 0 and self._held:  # a log without its HEARTBEAT
                        out += self._use(self._first_heard())
                break
            if self._count(msg):
                out += self._use(self._vehicle_messages(msg))
        self._sync_counters()
        return out

    def _use(self, msgs: list[Any]) -> list[Sample]:
        """Record, answer and decode messages of the vehicle, in order."""
        out: list[Sample] = []
        for msg in msgs:
            if self._raw is not None:
                self._keep(tlog_record(msg))
            if not self.is_file:
                self._link_message(msg)
            try:
                out += self.decoder.handle(msg)
            except ClockError as exc:  # pragma: no cover - stamping queues instead of raising
                log.debug("mavlink %s: %s", self.url, exc)
        return out

    def _count(self, msg: Any) -> bool:
        """Count one message from pymavlink; returns whether it is a good frame.

        A message id outside the dialect comes back as ``UNKNOWN_<id>``, whose CRC
        pymavlink cannot check (the CRC seed depends on the message): it is most
        likely a damaged id byte, and counts as a parse error.
        """
        loss = self._conn.mav_loss
        if loss != self._loss_seen:  # pymavlink saw this message's sequence number jump
            self.counters.gaps += 1
            self.counters.drops += loss - self._loss_seen
            self._loss_seen = loss
        mtype = msg.get_type()
        if mtype.startswith("UNKNOWN_"):
            self.counters.parse_errors += 1
            return False
        if mtype != "BAD_DATA":
            self.counters.frames += 1
            return True
        reason = str(getattr(msg, "reason", ""))
        if "signature" in reason:
            pass  # counted from pymavlink's signing state
        elif "CRC" in reason:
            self.counters.crc_errors += 1
        else:
            self.counters.parse_errors += 1
        return False

    def _vehicle_messages(self, msg: Any) -> list[Any]:
        """The vehicle's messages that ``msg`` lets through: itself when it is the vehicle's;
        when it is the HEARTBEAT that makes its system the vehicle (module doc), that
        system's held messages and it; none otherwise (held, or counted as another
        system's)."""
        sysid = msg.get_srcSystem()
        if self.system_id == 0:
            if msg.get_type() == "HEARTBEAT" and is_autopilot(msg):
                log.info(
                    "mavlink %s: listening to the autopilot of system %d (component %d, "
                    "MAV_TYPE %d, MAV_AUTOPILOT %d)", self.url, sysid, msg.get_srcComponent(),
                    msg.type, msg.autopilot,
                )  # fmt: skip
                self._held.setdefault(sysid, deque(maxlen=HOLD_MESSAGES))
                return [*self._choose(sysid), msg]
            held = self._held.get(sysid)
            if held is None and len(self._held) < HOLD_SYSTEMS:
                held = self._held[sysid] = deque(maxlen=HOLD_MESSAGES)
            if held is None:
                self._other(sysid, msg)
                return []
            held.append(msg)
            if len(held) == HOLD_MESSAGES:  # full: the oldest would be lost from now on
                if self.is_file:  # a log without the HEARTBEAT: as at its end
                    return self._first_heard()
                log.warning(
                    "mavlink %s: no HEARTBEAT of an autopilot heard in %d messages; holding "
                    "the latest of systems %s (ins.mavlink_system_id names the vehicle)",
                    self.url, HOLD_MESSAGES, ", ".join(map(str, sorted(self._held))),
                )  # fmt: skip
            return []
        if sysid == self.system_id:
            return [msg]
        self._other(sysid, msg)
        return []

    def _first_heard(self) -> list[Any]:
        """Make the first system heard the vehicle (a log without an autopilot's HEARTBEAT);
        its held messages."""
        first = next(iter(self._held))
        log.warning(
            "mavlink %s: no HEARTBEAT of an autopilot in the log: using system %d, the first "
            "heard", self.url, first,
        )  # fmt: skip
        return self._choose(first)

    def _choose(self, sysid: int) -> list[Any]:
        """Make ``sysid`` the vehicle; its held messages (the others' counted as ignored)."""
        self.system_id = sysid
        held, self._held = self._held, {}
        for other, msgs in held.items():
            if other != sysid:
                for m in msgs:
                    self._other(other, m)
        return list(held.get(sysid, ()))

    def _other(self, sysid: int, msg: Any) -> None:
        """Count a message of a system that is not the vehicle (named in the log once)."""
        if sysid not in self.other_systems:
            self.other_systems[sysid] = 0
            log.warning(
                "mavlink %s: system %d also speaks on the link (first %s); the vehicle is "
                "system %s: its messages are ignored and counted (ins rejected)",
                self.url, sysid, msg.get_type(), self.system_id or "not chosen yet",
            )  # fmt: skip
        self.other_systems[sysid] += 1

    def _sync_counters(self) -> None:
        mav = self._conn.mav
        self.counters.bytes = mav.total_bytes_received
        signing = mav.signing.reject_count if mav.signing.secret_key is not None else 0
        self.counters.rejected = signing + sum(self.other_systems.values())

    def _peer_closed(self) -> None:
        raise DriverError(f"mavlink {self.url}: peer closed the connection")

    def close(self) -> None:
        if self.other_systems:
            log.warning(
                "mavlink %s: messages ignored from systems other than the vehicle (%d): %s",
                self.url, self.system_id,
                ", ".join(f"system {k}: {n}" for k, n in sorted(self.other_systems.items())),
            )  # fmt: skip
        try:
            self._conn.close()
        except OSError as exc:
            log.debug("mavlink %s: close: %s", self.url, exc)


def open_mavlink(path_or_url: str | Path, **kwargs: Any) -> Source:
    """A MAVLink source for a URL or ``.tlog``, or a dataflash source for a ``.bin`` file."""
    if str(path_or_url).endswith(".bin"):
        from sarmoco.drivers.dataflash import DataflashSource

        return DataflashSource(path_or_url, leap_s=kwargs.get("leap_s", GPS_LEAP_SECONDS_DEFAULT))
    return MavlinkSource(str(path_or_url), **kwargs)
