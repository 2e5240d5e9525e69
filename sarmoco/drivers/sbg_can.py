"""SBG CAN message set: pure codec (our own struct layouts) and the stateful decoder.

Default identifiers and layouts (11-bit IDs, little-endian, from SBG's CAN
documentation; a test cross-checks every one against the vendor DBC):

======  ==============  ==================================================================
ID      message         payload
======  ==============  ==================================================================
0x100   STATUS_01       u32 time (µs), u16 general status, u16 clock status
0x102   STATUS_03       u32 solution status, u16 heave status
0x110   UTC_0           u32 time (µs), u32 GPS time of week (ms)
0x111   UTC_1           u8 year − 2000, month, day, hour, minute, second, u16 × 100 µs
0x130   EKF_INFO        u32 time (µs) of the EKF outputs that follow
0x131   EKF_QUAT        i16 q0..q3 × 1/32767 (w, x, y, z; body → NED)
0x132   EKF_EULER       i16 roll, pitch, yaw × 1e-4 rad
0x137   EKF_VEL_NED     i16 north, east, down × 0.01 m/s
0x200   EVENT_INFO_A    u32 time (µs), u16 status
0x201   EVENT_TIME_A    u16 × 4 time offsets (µs)
======  ==============  ==================================================================

Time: UTC_0 pairs the device clock with the GPS time of week (ms); UTC_1 gives
the date, which fixes the GPS week. The device clock is mapped onto GPS time by
:class:`~sarmoco.drivers.devclock.DeviceClock`; the resolution of the pairing is
the 1 ms of the time of week (exact when the device sends UTC_0 on whole
milliseconds of GPS time; otherwise averaged by the fit).
"""

from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass

from sarmoco.drivers import sbg_codec
from sarmoco.drivers.attitude import euler_to_quat, normalized
from sarmoco.drivers.clock import (
    GPS_LEAP_SECONDS_DEFAULT,
    gps_ns_from_tow,
    unix_ns_to_gps_ns,
    utc_calendar_to_unix_ns,
)
from sarmoco.drivers.counters import BurstLog, DriverCounters
from sarmoco.drivers.devclock import DeviceClock
from sarmoco.drivers.samples import AttitudeSample, EventSample, Sample, Validity, VelocitySample
from sarmoco.errors import ClockError, ProtocolError

log = logging.getLogger(__name__)

ID_STATUS_01 = 0x100
ID_STATUS_03 = 0x102
ID_UTC_0 = 0x110
ID_UTC_1 = 0x111
ID_EKF_INFO = 0x130
ID_EKF_QUAT = 0x131
ID_EKF_EULER = 0x132
ID_EKF_VEL_NED = 0x137
ID_EVENT_INFO_A = 0x200
ID_EVENT_TIME_A = 0x201

QUAT_SCALE = 1.0 / 32767.0
EULER_SCALE_RAD = 1e-4
VEL_SCALE_MPS = 0.01
UTC_SUBSECOND_US = 100

LAYOUTS: dict[int, struct.Struct] = {
    ID_STATUS_01: struct.Struct("<IHH"),
    ID_STATUS_03: struct.Struct("<IH"),
    ID_UTC_0: struct.Struct("<II"),
    ID_UTC_1: struct.Struct("<6BH"),
    ID_EKF_INFO: struct.Struct("<I"),
    ID_EKF_QUAT: struct.Struct("<4h"),
    ID_EKF_EULER: struct.Struct("<3h"),
    ID_EKF_VEL_NED: struct.Struct("<3h"),
    ID_EVENT_INFO_A: struct.Struct("<IH"),
    ID_EVENT_TIME_A: struct.Struct("<4H"),
}
"""Payload layout of each message; the data length must be at least its size (≤ 8)."""


def _i16(value: float, scale: float) -> int:
    return max(-32768, min(32767, round(value / scale)))


def encode(can_id: int, *fields: int) -> tuple[int, bytes]:
    """Raw fields → (arbitration ID, data) using :data:`LAYOUTS`."""
    return can_id, LAYOUTS[can_id].pack(*fields)


def encode_ekf_quat(q_wxyz: tuple[float, float, float, float]) -> tuple[int, bytes]:
    """EKF_QUAT from a unit quaternion (w, x, y, z)."""
    return encode(ID_EKF_QUAT, *(_i16(c, QUAT_SCALE) for c in q_wxyz))


def encode_ekf_euler(roll: float, pitch: float, yaw: float) -> tuple[int, bytes]:
    """EKF_EULER from angles in rad (yaw wrapped to ±π)."""
    yaw = math.remainder(yaw, 2 * math.pi)
    return encode(ID_EKF_EULER, *(_i16(a, EULER_SCALE_RAD) for a in (roll, pitch, yaw)))


def encode_ekf_vel_ned(vel_ned: tuple[float, float, float]) -> tuple[int, bytes]:
    """EKF_VEL_NED from a velocity in m/s."""
    return encode(ID_EKF_VEL_NED, *(_i16(v, VEL_SCALE_MPS) for v in vel_ned))


def encode_utc_1(
    year: int, month: int, day: int, hour: int, minute: int, second: int, microsecond: int
) -> tuple[int, bytes]:
    """UTC_1 (date and time of day; sub-second in units of 100 µs)."""
    sub = microsecond // UTC_SUBSECOND_US
    return encode(ID_UTC_1, year - 2000, month, day, hour, minute, second, sub)


@dataclass(frozen=True, slots=True)
class CanMessage:
    """One decoded SBG CAN message: its ID and raw fields (scaled on use)."""

    can_id: int
    fields: tuple[int, ...]


def decode(can_id: int, data: bytes | bytearray) -> CanMessage | None:
    """Decode a frame of the SBG set; None for other IDs.

    Raises
    ------
    sarmoco.errors.ProtocolError
        If the data are too short for the message or longer than 8 bytes.
    """
    layout = LAYOUTS.get(can_id)
    if layout is None:
        return None
    if not layout.size <= len(data) <= 8:
        raise ProtocolError(f"SBG CAN 0x{can_id:03x}: {len(data)} data bytes, need {layout.size}")
    return CanMessage(can_id, layout.unpack_from(data))


class SbgCanDecoder:
    """SBG CAN frames in, samples on GPS time out (never raises on bad frames).

    Parameters
    ----------
    leap_s : int
        GPS − UTC, s, used to find the GPS week from the UTC date.
    link : str
        Name used in log messages.
    """

    def __init__(self, leap_s: int = GPS_LEAP_SECONDS_DEFAULT, link: str = "sbg-can") -> None:
        self.leap_s = leap_s
        self.counters = DriverCounters()
        self._burst = BurstLog(log, link)
        self.clock = DeviceClock(link, self.counters)
        self._ekf_dev_ns: int | None = None
        self._solution = 0
        self._clock_status: int | None = None
        self._week_ref_gps_ns: int | None = None
        self._pending_utc0: tuple[int, int] | None = None
        self._event: tuple[int, int] | None = None

    def feed(self, can_id: int, data: bytes | bytearray) -> list[Sample]:
        """Decode one frame; returns the samples it completes."""
        self.counters.bytes += len(data)
        try:
            msg = decode(can_id, data)
        except ProtocolError as exc:
            self.counters.parse_errors += 1
            self._burst.error("frame", str(exc))
            return []
        if msg is None:
            return []
        self.counters.frames += 1
        self._burst.ok()
        out: list[Sample] = []
        self._dispatch(msg, out)
        return out

    def _valid(self) -> Validity:
        v = Validity.NONE
        for bit, flag in (
            (sbg_codec.SOL_ATTITUDE_VALID, Validity.ATTITUDE),
            (sbg_codec.SOL_HEADING_VALID, Validity.HEADING),
            (sbg_codec.SOL_VELOCITY_VALID, Validity.VELOCITY),
            (sbg_codec.SOL_POSITION_VALID, Validity.POSITION),
        ):
            if self._solution & bit:
                v |= flag
        return v

    def _dispatch(self, msg: CanMessage, out: list[Sample]) -> None:
        cid, f = msg.can_id, msg.fields
        if cid == ID_EKF_INFO:
            self._ekf_dev_ns = self.clock.device_ns(f[0])
        elif cid in (ID_EKF_QUAT, ID_EKF_EULER, ID_EKF_VEL_NED):
            if self._ekf_dev_ns is None:
                self.counters.drops += 1
                return
            self._ekf(cid, f, self._ekf_dev_ns, out)
        elif cid == ID_STATUS_03:
            self._solution = f[0]
        elif cid == ID_STATUS_01:
            self._clock_status = f[2]
        elif cid == ID_UTC_0:
            self._pending_utc0 = (self.clock.device_ns(f[0]), f[1])
            self._pair(out)
        elif cid == ID_UTC_1:
            self._utc1(f)
            self._pair(out)
        elif cid == ID_EVENT_INFO_A:
            dev = self.clock.device_ns(f[0])
            self._event = (dev, f[1])
            self.clock.stamp(EventSample(0, "A", Validity.NONE, "sbg_can.EVENT_A", dev), out)
        elif cid == ID_EVENT_TIME_A and self._event is not None:
            dev, status = self._event
            for k, off in enumerate(f):
                if (status >> (k + 1)) & 1:
                    ev = EventSample(0, "A", Validity.NONE, "sbg_can.EVENT_A", dev + off * 1000)
                    self.clock.stamp(ev, out)
            self._event = None

    def _ekf(self, cid: int, f: tuple[int, ...], dev_ns: int, out: list[Sample]) -> None:
        valid = self._valid()
        if cid == ID_EKF_VEL_NED:
            vel = (f[0] * VEL_SCALE_MPS, f[1] * VEL_SCALE_MPS, f[2] * VEL_SCALE_MPS)
            self.clock.stamp(VelocitySample(0, vel, valid, "sbg_can.EKF_VEL_NED", dev_ns), out)
            return
        if cid == ID_EKF_QUAT:
            q, name = normalized(tuple(c * QUAT_SCALE for c in f)), "sbg_can.EKF_QUAT"
        else:
            rpy = (f[0] * EULER_SCALE_RAD, f[1] * EULER_SCALE_RAD, f[2] * EULER_SCALE_RAD)
            q, name = euler_to_quat(*rpy), "sbg_can.EKF_EULER"
        if q is None:
            self.counters.parse_errors += 1
            return
        self.clock.stamp(AttitudeSample(0, q, valid, name, dev_ns), out)

    def _utc1(self, f: tuple[int, ...]) -> None:
        try:
            unix_ns = utc_calendar_to_unix_ns(
                2000 + f[0], f[1], f[2], f[3], f[4], f[5], f[6] * UTC_SUBSECOND_US * 1000
            )
        except ClockError as exc:
            self.counters.parse_errors += 1
            self._burst.error("UTC_1", str(exc))
            return
        self._week_ref_gps_ns = unix_ns_to_gps_ns(unix_ns, self.leap_s)

    def _pair(self, out: list[Sample]) -> None:
        if self._pending_utc0 is None or self._week_ref_gps_ns is None:
            return
        dev_ns, tow_ms = self._pending_utc0
        self._pending_utc0 = None
        gps = gps_ns_from_tow(tow_ms, self._week_ref_gps_ns)
        state = None if self._clock_status is None else (self._clock_status >> 1) & 0xF
        valid = state in (None, sbg_codec.CLOCK_VALID)
        ts = self.clock.reference(dev_ns, gps, valid, "sbg_can.UTC_0")
        if ts is not None:
            self.clock.stamp(ts, out)
