"""The simulated autopilot: MAVLink 2 over UDP, TCP, a pseudo-terminal, or into a ``.tlog``.

What it sends (system 1, component 1, what ArduPilot and PX4 send by default):

* HEARTBEAT at 1 Hz, also while waiting for the daemon (so a ``udpin:`` peer learns
  where we are), and with it, for INS grades with a position, GPS_GLOBAL_ORIGIN (the EKF
  origin: :data:`~sarmoco.sim.insfeed.GEODETIC_ORIGIN`, the scenario frame's tangent
  point) and HOME_POSITION (there too);
* LOCAL_POSITION_NED (velocity NED, position NED about the EKF origin: the INS position,
  or the velocity integrated from the first sample for grades without one),
  GLOBAL_POSITION_INT (the same position as latitude, longitude and altitude, velocity in
  cm/s; grades with a position), ATTITUDE_QUATERNION and ATTITUDE at the INS sample
  epochs, decimated to the rate asked for;
* SYSTEM_TIME (GPS-derived UNIX time and ``time_boot_ms`` of the same instant);
* EKF_STATUS_REPORT at 1 Hz (position flags only when the INS has a position).

What it answers: TIMESYNC requests (``tc1 = 0``) with ``tc1`` = the boot clock now
(ns, :class:`~sarmoco.sim.insclock.InsClock`) once playback has started, and
COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL (interval µs; 0 = default rate,
-1 = off) with a COMMAND_ACK. Rates are at most the INS rate and decimate on the
INS sample index, so the sent samples are a subset of the INS record.

A ``.tlog`` is what a ground station logs: each message prefixed by the host's
receive time (UNIX µs, big-endian u64); here the wire GPS time of sending.
"""

from __future__ import annotations

import math
import os
import struct
import time
from collections.abc import Iterator, Mapping
from functools import partial
from typing import Any

import numpy as np

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from sarmoco.drivers.attitude import quat_to_euler
from sarmoco.drivers.clock import NS_PER_S
from sarmoco.errors import ConfigError
from sarmoco.geodesy import ned_to_geodetic
from sarmoco.processing.types import FloatArray
from sarmoco.sim.emitter import Emitter
from sarmoco.sim.faults import PacketFaults
from sarmoco.sim.insfeed import GEODETIC_ORIGIN, InsFeed
from sarmoco.sim.pacing import Event
from sarmoco.sim.transports import FileLink, Link

SYSTEM_ID = 1
COMPONENT_ID = mavlink2.MAV_COMP_ID_AUTOPILOT1
HEARTBEAT_PERIOD_S = 1.0
STATUS_PERIOD_S = 1.0
STREAMS = (
    "LOCAL_POSITION_NED",
    "GLOBAL_POSITION_INT",
    "ATTITUDE_QUATERNION",
    "ATTITUDE",
    "SYSTEM_TIME",
)
"""Messages whose rate MAV_CMD_SET_MESSAGE_INTERVAL sets."""
AUTOPILOT_RATES_HZ: dict[str, float] = {
    "LOCAL_POSITION_NED": 4.0,
    "GLOBAL_POSITION_INT": 4.0,
    "ATTITUDE_QUATERNION": 4.0,
    "ATTITUDE": 4.0,
    "SYSTEM_TIME": 1.0,
}
"""Rates before the daemon asks (ArduPilot streams slowly until told otherwise), Hz."""
_EKF_FLAGS_BASE = mavlink2.EKF_ATTITUDE | mavlink2.EKF_VELOCITY_HORIZ | mavlink2.EKF_VELOCITY_VERT
_EKF_FLAGS_POSITION = (
    mavlink2.EKF_POS_HORIZ_REL | mavlink2.EKF_POS_HORIZ_ABS | mavlink2.EKF_POS_VERT_ABS
)
_MSG_IDS = {getattr(mavlink2, f"MAVLINK_MSG_ID_{name}"): name for name in STREAMS}


def _int_position(lla: FloatArray | tuple[float, float, float]) -> tuple[int, int, int]:
    """Latitude, longitude (deg) and altitude (m) as MAVLink sends them: degE7, degE7, mm."""
    return round(float(lla[0]) * 1e7), round(float(lla[1]) * 1e7), round(float(lla[2]) * 1e3)


def dead_reckoned(t_ns: np.ndarray, vel_ned: FloatArray) -> FloatArray:
    """Velocity integrated with the trapezoid rule from zero at the first sample, m."""
    dt = np.diff(t_ns).astype(np.float64) * 1e-9
    steps = 0.5 * (vel_ned[1:] + vel_ned[:-1]) * dt[:, None]
    return np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])


ROGUE_BOOT_AHEAD_MS = 7
"""How far the second system's boot clock runs ahead of the vehicle's, ms (its samples fall
between the vehicle's, so that mixing them in would not be caught as duplicates)."""
ROGUE_VEL_NED = np.array([5.0, 0.0, 0.0])
"""What the second system's velocity adds to the vehicle's, NED m/s."""
ROGUE_PREROLL_PERIOD_S = 0.05
"""Interval of the second system's messages while the autopilot waits for the daemon, s."""
ROGUE_NOISE_EVERY = 10
"""The second system sends random bytes and a frame with a broken CRC with every this many
of its samples (and each time it speaks before playback)."""


def _yawed_90(q: FloatArray) -> FloatArray:
    """Body-to-NED quaternion ``q`` (scalar first) turned 90 degrees further in heading."""
    c = s = np.sqrt(0.5)  # yaw of 90 deg about NED z: (cos 45, 0, 0, sin 45)
    w, x, y, z = q
    return np.array([c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w])


class PacketSink:
    """The file pymavlink writes to: each write is one packet, handed to the emitter."""

    def __init__(self, emitter: Emitter) -> None:
        self._emitter = emitter

    def write(self, buf: bytes) -> None:
        self._emitter.send(bytes(buf), self._emitter.now_ns)


class AutopilotSpeaker(Emitter):
    """An emitter that speaks as the autopilot (:data:`SYSTEM_ID`, :data:`COMPONENT_ID`)
    over MAVLink 2: its HEARTBEAT (scheduled by the subclass, and every
    :data:`HEARTBEAT_PERIOD_S` while it waits for its peer before playback), a tally of the
    messages sent, and the parsing of what comes back (garbage skipped).

    Parameters
    ----------
    link, faults, seed, rank
        See :class:`~sarmoco.sim.emitter.Emitter`.
    """

    def __init__(self, link: Link, faults: PacketFaults | None, seed: int, rank: int) -> None:
        super().__init__(link, faults, seed, rank)
        self._tx = mavlink2.MAVLink(
            PacketSink(self), srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID
        )
        self._rx = mavlink2.MAVLink(None, srcSystem=SYSTEM_ID, srcComponent=COMPONENT_ID)
        self._rx.robust_parsing = True
        self._last_preroll_heartbeat = -HEARTBEAT_PERIOD_S
        self.sent: dict[str, int] = {}
        """Messages sent, by name."""

    def _count(self, name: str, n: int = 1) -> None:
        self.sent[name] = self.sent.get(name, 0) + n

    def _heartbeat(self, t_ns: int) -> None:
        """The autopilot's HEARTBEAT at scenario time ``t_ns``."""
        self.now_ns = t_ns
        self._tx.heartbeat_send(
            mavlink2.MAV_TYPE_FIXED_WING,
            mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
            mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            0,
            mavlink2.MAV_STATE_ACTIVE,
        )
        self._count("HEARTBEAT")

    def service(self, now_ns: int | None) -> None:
        if now_ns is None and time.monotonic() - self._last_preroll_heartbeat >= HEARTBEAT_PERIOD_S:
            self._last_preroll_heartbeat = time.monotonic()  # the peer answers whom it heard
            self._heartbeat(self.now_ns)
        super().service(now_ns)

    def on_bytes(self, data: bytes, now_ns: int | None) -> None:
        try:
            msgs = self._rx.parse_buffer(data) or []
        except mavlink2.MAVError:
            return
        for msg in msgs:
            if msg.get_type() != "BAD_DATA":
                self.on_message(msg, now_ns)

    def on_message(self, msg: Any, now_ns: int | None) -> None:
        """React to one well-formed message from the peer; default: ignore it."""
        return None


class MavlinkEmitter(AutopilotSpeaker):
    """Plays a run's INS samples as an autopilot's MAVLink 2 stream.

    Parameters
    ----------
    link : Link
        UDP (to the daemon's ``udpin:`` port), TCP server, pty or file (``.tlog``).
    feed : InsFeed
        Samples and the autopilot boot clock.
    rates_hz : mapping of str to float, optional
        Initial rates of :data:`STREAMS`, Hz (default :data:`AUTOPILOT_RATES_HZ`;
        a ``.tlog`` is usually written at the INS rate).
    signing_key : bytes, optional
        32-byte MAVLink 2 signing secret: sign every packet.
    rogue_system : int
        A fault: a second system with this id (0: none), a companion computer by its
        HEARTBEAT, sends the same messages on the link, its boot clock
        :data:`ROGUE_BOOT_AHEAD_MS` ahead, its velocity :data:`ROGUE_VEL_NED` more and its
        heading 90 degrees off, and with them random bytes and frames with a broken CRC
        (:data:`ROGUE_NOISE_EVERY`, counted as ``ROGUE_NOISE``); it speaks first: every
        :data:`ROGUE_PREROLL_PERIOD_S` while the autopilot waits for the daemon (counted as
        ``ROGUE_PREROLL``). Its well-formed messages in playback are counted as ``ROGUE``.
    faults, seed, rank
        See :class:`~sarmoco.sim.emitter.Emitter`.
    """

    protocol = "mavlink2"

    def __init__(
        self,
        link: Link,
        feed: InsFeed,
        *,
        rates_hz: Mapping[str, float] | None = None,
        signing_key: bytes | None = None,
        rogue_system: int = 0,
        faults: PacketFaults | None = None,
        seed: int = 0,
        rank: int = 1,
    ) -> None:
        super().__init__(link, faults, seed, rank)
        self.feed = feed
        self.tlog = isinstance(link, FileLink)
        self.default_rates_hz = dict(AUTOPILOT_RATES_HZ if rates_hz is None else rates_hz)
        self.rates_hz = dict(self.default_rates_hz)
        self.pos_ned = (
            feed.pos_ned if feed.pos_ned is not None else dead_reckoned(feed.t_ns, feed.vel_ned)
        )
        self.geodetic = (
            None if feed.pos_ned is None else ned_to_geodetic(feed.pos_ned, GEODETIC_ORIGIN)
        )
        """Latitude, longitude (deg) and altitude (m) of each sample (grades with a position)."""
        if signing_key is not None:
            if len(signing_key) != 32:
                raise ConfigError(f"mavlink signing key: {len(signing_key)} bytes, need 32")
            self._tx.signing.secret_key = signing_key
            self._tx.signing.sign_outgoing = True
            self._tx.signing.timestamp = 1
        self._rogue = (
            mavlink2.MAVLink(PacketSink(self), srcSystem=rogue_system, srcComponent=COMPONENT_ID)
            if rogue_system
            else None
        )
        self._rogue_rng = np.random.default_rng(rogue_system)
        self._last_rogue_preroll = -ROGUE_PREROLL_PERIOD_S
        self.peer_heard = False
        self.answered: dict[str, int] = {"TIMESYNC": 0, "SET_MESSAGE_INTERVAL": 0}

    # --- schedule -------------------------------------------------------------------

    def events(self) -> Iterator[Event]:
        """Heartbeats and EKF status each second, and every INS sample epoch (plus latency)."""
        f = self.feed
        if not f.t_ns.size:
            return
        t_first, t_last = int(f.t_ns[0]), int(f.t_ns[-1])
        period = round(HEARTBEAT_PERIOD_S * NS_PER_S)
        beats = range(t_first, t_last + 1, period)
        i = 0
        for t_beat in beats:
            while i < f.t_ns.size and int(f.t_ns[i]) + f.latency_ns < t_beat:
                yield Event(int(f.t_ns[i]) + f.latency_ns, self.rank, partial(self._sample, i))
                i += 1
            yield Event(t_beat, self.rank, partial(self._heartbeat, t_beat))
        for j in range(i, f.t_ns.size):
            yield Event(int(f.t_ns[j]) + f.latency_ns, self.rank, partial(self._sample, j))

    # --- sending ----------------------------------------------------------------------

    def write(self, packet: bytes) -> None:
        if self.tlog:
            stamp = struct.pack(">Q", self.wire.unix_ns(self.now_ns) // 1000)
            self.link.write(stamp + packet)
        else:
            self.link.write(packet)

    def _due(self, name: str, index: int) -> bool:
        hz = self.rates_hz.get(name, 0.0)
        return hz > 0 and index % max(1, round(self.feed.rate_hz / hz)) == 0

    def _heartbeat(self, t_ns: int) -> None:
        super()._heartbeat(t_ns)
        flags = _EKF_FLAGS_BASE | (_EKF_FLAGS_POSITION if self.feed.pos_ned is not None else 0)
        self._tx.ekf_status_report_send(flags, 0.0, 0.0, 0.0, 0.0, 0.0)
        self._count("EKF_STATUS_REPORT")
        if self.geodetic is not None:
            lat, lon, alt = _int_position(GEODETIC_ORIGIN)
            usec = self.wire.unix_ns(t_ns) // 1000
            self._tx.gps_global_origin_send(lat, lon, alt, usec)
            self._count("GPS_GLOBAL_ORIGIN")
            q = [1.0, 0.0, 0.0, 0.0]
            self._tx.home_position_send(lat, lon, alt, 0.0, 0.0, 0.0, q, 0.0, 0.0, 0.0, usec)
            self._count("HOME_POSITION")
        if self._rogue is not None:
            self._rogue_heartbeat()

    def _rogue_heartbeat(self, tally: str = "ROGUE") -> None:
        """The second system's HEARTBEAT: a companion computer, no autopilot (counted as
        ``tally``)."""
        assert self._rogue is not None
        self._rogue.heartbeat_send(
            mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0,
            mavlink2.MAV_STATE_ACTIVE,
        )  # fmt: skip
        self._count(tally)

    def _sample(self, i: int) -> None:
        f = self.feed
        self.now_ns = int(f.t_ns[i]) + f.latency_ns
        up_ns = int(f.uptime_ns[i])
        boot_ms = round(up_ns / 1e6)
        k = int(f.index[i])
        if self._due("SYSTEM_TIME", k):
            # the UNIX time at which the boot clock reads boot_ms exactly
            t_ref = int(f.t_ns[i]) + boot_ms * 1_000_000 - up_ns
            self._tx.system_time_send(round(self.wire.unix_ns(t_ref) / 1000), boot_ms)
            self._count("SYSTEM_TIME")
        if self._due("LOCAL_POSITION_NED", k):
            x, y, z = (float(v) for v in self.pos_ned[i])
            vx, vy, vz = (float(v) for v in f.vel_ned[i])
            self._tx.local_position_ned_send(boot_ms, x, y, z, vx, vy, vz)
            self._count("LOCAL_POSITION_NED")
        if self.geodetic is not None and self._due("GLOBAL_POSITION_INT", k):
            lat, lon, alt = _int_position(self.geodetic[i])
            vx, vy, vz = (round(float(v) * 100.0) for v in f.vel_ned[i])
            relative_mm = round(-float(self.pos_ned[i][2]) * 1000.0)
            yaw = quat_to_euler(tuple(float(v) for v in f.quat[i]))[2]  # type: ignore[arg-type]
            hdg = round(math.degrees(yaw) * 100.0) % 36000
            self._tx.global_position_int_send(boot_ms, lat, lon, alt, relative_mm, vx, vy, vz, hdg)
            self._count("GLOBAL_POSITION_INT")
        if self._due("ATTITUDE_QUATERNION", k):
            w, qx, qy, qz = (float(v) for v in f.quat[i])
            self._tx.attitude_quaternion_send(boot_ms, w, qx, qy, qz, 0.0, 0.0, 0.0)
            self._count("ATTITUDE_QUATERNION")
        if self._due("ATTITUDE", k):
            roll, pitch, yaw = quat_to_euler(tuple(float(v) for v in f.quat[i]))  # type: ignore[arg-type]
            self._tx.attitude_send(boot_ms, roll, pitch, yaw, 0.0, 0.0, 0.0)
            self._count("ATTITUDE")
        if self._rogue is not None:
            self._rogue_sample(i, boot_ms + ROGUE_BOOT_AHEAD_MS, up_ns)

    def _rogue_sample(self, i: int, boot_ms: int, up_ns: int, tally: str = "ROGUE") -> None:
        """The second system's copy of sample ``i`` (see ``rogue_system``; its well-formed
        messages counted as ``tally``)."""
        assert self._rogue is not None
        f, k = self.feed, int(self.feed.index[i])
        if self._due("SYSTEM_TIME", k):
            t_ref = int(f.t_ns[i]) + boot_ms * 1_000_000 - up_ns - ROGUE_BOOT_AHEAD_MS * 10**6
            self._rogue.system_time_send(round(self.wire.unix_ns(t_ref) / 1000), boot_ms)
            self._count(tally)
        x, y, z = (float(v) for v in self.pos_ned[i])
        vx, vy, vz = (float(v) for v in f.vel_ned[i] + ROGUE_VEL_NED)
        self._rogue.local_position_ned_send(boot_ms, x, y, z, vx, vy, vz)
        w, qx, qy, qz = (float(v) for v in _yawed_90(f.quat[i]))
        self._rogue.attitude_quaternion_send(boot_ms, w, qx, qy, qz, 0.0, 0.0, 0.0)
        self._count(tally, 2)
        if i % ROGUE_NOISE_EVERY == 0:
            self._rogue_noise(boot_ms)

    def _rogue_noise(self, boot_ms: int) -> None:
        """The second system's noise: random bytes, then a LOCAL_POSITION_NED whose CRC no
        longer matches (a payload bit flipped)."""
        assert self._rogue is not None
        rng = self._rogue_rng
        self.send(rng.bytes(int(rng.integers(1, 200))), self.now_ns)
        msg = mavlink2.MAVLink_local_position_ned_message(boot_ms, 0.0, 0.0, 0.0, 99.0, 0.0, 0.0)
        frame = bytearray(msg.pack(self._rogue))
        frame[12] ^= 0x10
        self.send(bytes(frame), self.now_ns)
        self._count("ROGUE_NOISE", 2)

    # --- answering --------------------------------------------------------------------

    def service(self, now_ns: int | None) -> None:
        if (
            now_ns is None
            and self._rogue is not None
            and time.monotonic() - self._last_rogue_preroll >= ROGUE_PREROLL_PERIOD_S
        ):
            self._last_rogue_preroll = time.monotonic()
            self._rogue_heartbeat("ROGUE_PREROLL")
            boot_ms = round(int(self.feed.uptime_ns[0]) / 1e6)
            self._rogue_sample(0, boot_ms, int(self.feed.uptime_ns[0]), "ROGUE_PREROLL")
        super().service(now_ns)

    def on_message(self, msg: Any, now_ns: int | None) -> None:
        self.peer_heard = True
        if msg.get_type() == "TIMESYNC" and msg.tc1 == 0 and now_ns is not None:
            self.now_ns = now_ns
            self._tx.timesync_send(self.feed.clock.uptime_ns(now_ns), msg.ts1)
            self.answered["TIMESYNC"] += 1
        elif msg.get_type() == "COMMAND_LONG" and msg.target_system in (0, SYSTEM_ID):
            self._command(msg, now_ns)

    def _command(self, msg: Any, now_ns: int | None) -> None:
        if now_ns is not None:
            self.now_ns = now_ns
        result = mavlink2.MAV_RESULT_UNSUPPORTED
        if msg.command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL:
            name = _MSG_IDS.get(round(msg.param1))
            result = mavlink2.MAV_RESULT_DENIED
            if name is not None:
                interval_us = msg.param2
                if interval_us == 0:
                    self.rates_hz[name] = self.default_rates_hz[name]
                elif interval_us < 0:
                    self.rates_hz[name] = 0.0
                else:
                    self.rates_hz[name] = min(1e6 / interval_us, self.feed.rate_hz)
                self.answered["SET_MESSAGE_INTERVAL"] += 1
                result = mavlink2.MAV_RESULT_ACCEPTED
        self._tx.command_ack_send(
            msg.command, result, target_system=msg.get_srcSystem(),
            target_component=msg.get_srcComponent(),
        )  # fmt: skip

    def ready(self) -> bool:
        return self.tlog or (self.link.peer_ready() and self.peer_heard)

    def connect_hint(self) -> dict[str, Any]:
        where = self.link.describe()
        connect = {
            "udp": f"udpin:{where.get('to')}",  # the daemon listens where we send
            "tcp": f"tcp:{where.get('listen')}",
        }.get(where["link"], where.get("path"))
        return {"connect": connect, "system_id": SYSTEM_ID, "component_id": COMPONENT_ID}

    def stats(self) -> dict[str, Any]:
        return {
            **super().stats(),
            "messages": dict(self.sent),
            "answered": dict(self.answered),
            "rates_hz": dict(self.rates_hz),
        }
