"""sbgECom binary protocol: frame codec, byte-stream sniffer and the log payloads we use.

Frame (little-endian)::

    FF 5A | msg id u8 | class u8 | length u16 | payload | CRC-16/KERMIT u16 | 33

The CRC covers ``msg id`` through the end of the payload. Payload layouts
(class ``SBG_ECOM_CLASS_LOG_ECOM_0`` = 0), from SBG's public sbgECom
documentation; all little-endian, times are the device clock in µs since power-up:

* UTC_TIME (2): u32 time, u16 clock status, u16 year, i8 month, day, hour,
  minute, second, i32 nanosecond, u32 GPS time of week (ms) [+ 3 f32 clock stats]
* EKF_EULER (6): u32 time, f32 roll, pitch, yaw (rad), f32 ×3 std (rad),
  u32 solution status [+ f32 magnetic declination, inclination]
* EKF_QUAT (7): u32 time, f32 q0..q3 (w, x, y, z), f32 ×3 std (rad), u32 status [+ 2 f32]
* EKF_NAV (8): u32 time, f32 velocity N, E, D (m/s), f32 ×3 std, f64 latitude,
  longitude (deg), altitude above MSL (m), f32 undulation, f32 ×3 position std, u32 status
* EVENT_A (24): u32 time, u16 status, u16 ×4 time offsets (µs) of further events

This module is pure (no I/O) and holds the encoders the simulator uses.
"""

from __future__ import annotations

import binascii
import logging
import struct
from dataclasses import dataclass

from sarmoco.drivers.counters import BurstLog, DriverCounters

log = logging.getLogger(__name__)

SYNC = b"\xff\x5a"
ETX = 0x33
CLASS_LOG_ECOM_0 = 0x00
MAX_PAYLOAD = 4086
"""Largest payload of a standard sbgECom frame, bytes."""
OVERHEAD = 9
"""Frame bytes besides the payload."""
MAX_FRAME = MAX_PAYLOAD + OVERHEAD

MSG_UTC_TIME = 2
MSG_EKF_EULER = 6
MSG_EKF_QUAT = 7
MSG_EKF_NAV = 8
MSG_EVENT_A = 24

# Solution status bits (EKF logs)
SOL_MODE_MASK = 0xF
SOL_ATTITUDE_VALID = 1 << 4
SOL_HEADING_VALID = 1 << 5
SOL_VELOCITY_VALID = 1 << 6
SOL_POSITION_VALID = 1 << 7
# UTC_TIME status: clock state in bits 1-4, UTC status in bits 6-9
CLOCK_STATE_SHIFT = 1
UTC_STATUS_SHIFT = 6
CLOCK_STEERING = 2
CLOCK_VALID = 3
UTC_NO_LEAP_SEC = 1
UTC_INITIALIZED = 2
UTC_ACCURATE = 1 << 5
# EVENT status: bit 0 overflow, bits 1-4 offset 0..3 valid
EVENT_OVERFLOW = 1

_UTC = struct.Struct("<IHHbbbbbiI")
_EULER = struct.Struct("<I3f3fI")
_QUAT = struct.Struct("<I4f3fI")
_NAV = struct.Struct("<I3f3f3df3fI")
_EVENT = struct.Struct("<IH4H")
_HEAD = struct.Struct("<BBH")

# Accepted payload sizes per known message (base layout, optional trailing fields).
PAYLOAD_SIZES: dict[int, tuple[int, ...]] = {
    MSG_UTC_TIME: (_UTC.size, _UTC.size + 12),
    MSG_EKF_EULER: (_EULER.size, _EULER.size + 8),
    MSG_EKF_QUAT: (_QUAT.size, _QUAT.size + 8),
    MSG_EKF_NAV: (_NAV.size,),
    MSG_EVENT_A: (_EVENT.size,),
}

_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def crc16_kermit(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/KERMIT (poly 0x1021 reflected, init 0, no final xor) of ``data``.

    Computed with the C CRC-CCITT of :mod:`binascii` on bit-reversed bytes; the
    reflected CRC is the bit-reversal of that.
    """
    crc = binascii.crc_hqx(bytes(data).translate(_REV8), 0)
    return (_REV8[crc & 0xFF] << 8) | _REV8[crc >> 8]


def encode_frame(msg_id: int, msg_class: int, payload: bytes) -> bytes:
    """One sbgECom frame around ``payload``."""
    body = _HEAD.pack(msg_id, msg_class, len(payload)) + payload
    return SYNC + body + struct.pack("<HB", crc16_kermit(body), ETX)


@dataclass(frozen=True, slots=True)
class Frame:
    """A frame whose CRC and end byte checked."""

    msg_id: int
    msg_class: int
    payload: bytes


class FrameSniffer:
    """Finds valid frames in a byte stream and resynchronises after garbage or a torn frame.

    Parameters
    ----------
    counters : DriverCounters
        Updated with bytes, skipped bytes, CRC and parse errors.
    burst : BurstLog
        Reports errors once per burst.

    Notes
    -----
    The length field is checked against :data:`PAYLOAD_SIZES` (known
    messages of the log class) or :data:`MAX_PAYLOAD` before waiting for the
    frame, so the buffer never holds more than one maximal frame plus the
    last read. After any bad frame the search restarts one byte after its sync
    word, so a valid frame that begins inside a damaged one is recovered.
    """

    def __init__(self, counters: DriverCounters, burst: BurstLog) -> None:
        self._buf = bytearray()
        self._counters = counters
        self._burst = burst

    def feed(self, data: bytes, final: bool = False) -> list[Frame]:
        """Add bytes; return the complete valid frames found.

        With ``final`` (end of file) an incomplete frame at the end is treated
        as torn and the bytes after its sync word are searched too.
        """
        self._counters.bytes += len(data)
        buf = self._buf
        buf += data
        frames: list[Frame] = []
        pos = 0
        while True:
            start = buf.find(SYNC, pos)
            if start < 0:
                keep = len(buf) - 1 if buf.endswith(b"\xff") else len(buf)
                self._counters.skipped_bytes += keep - pos
                pos = keep
                break
            self._counters.skipped_bytes += start - pos
            pos = start
            if len(buf) - start < 6:
                if final:
                    self._counters.skipped_bytes += len(buf) - start
                    pos = len(buf)
                break
            msg_id, msg_class, length = _HEAD.unpack_from(buf, start + 2)
            sizes = PAYLOAD_SIZES.get(msg_id) if msg_class == CLASS_LOG_ECOM_0 else None
            if length > MAX_PAYLOAD or (sizes is not None and length not in sizes):
                self._reject("length", f"msg {msg_class}/{msg_id} announces {length} bytes")
                pos = start + 1
                continue
            end = start + OVERHEAD + length
            if len(buf) < end:
                if not final:
                    break
                self._reject("torn frame", f"stream ends {end - len(buf)} bytes short")
                pos = start + 1
                continue
            crc, etx = struct.unpack_from("<HB", buf, end - 3)
            if etx != ETX:
                self._reject("end byte", f"0x{etx:02x} instead of 0x33")
                pos = start + 1
                continue
            if crc != crc16_kermit(memoryview(buf)[start + 2 : end - 3]):
                self._counters.crc_errors += 1
                self._burst.error("CRC", f"msg {msg_class}/{msg_id} of {length} bytes")
                pos = start + 1
                continue
            frames.append(Frame(msg_id, msg_class, bytes(buf[start + 6 : end - 3])))
            self._counters.frames += 1
            self._burst.ok()
            pos = end
        del buf[:pos]
        return frames

    def _reject(self, kind: str, detail: str) -> None:
        self._counters.parse_errors += 1
        self._burst.error(kind, detail)


# --- payloads -------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class UtcTime:
    """UTC_TIME: the device clock against UTC and GPS time of week."""

    time_us: int
    status: int
    year: int
    month: int
    day: int
    hour: int
    minute: int
    second: int
    nanosecond: int
    gps_tow_ms: int

    @property
    def clock_state(self) -> int:
        """0 error, 1 free running, 2 steering, 3 valid."""
        return (self.status >> CLOCK_STATE_SHIFT) & 0xF

    @property
    def utc_status(self) -> int:
        """0 invalid, 1 no leap seconds yet, 2 initialised."""
        return (self.status >> UTC_STATUS_SHIFT) & 0xF


@dataclass(frozen=True, slots=True)
class EkfEuler:
    """EKF_EULER: roll, pitch, yaw (rad) with 1-sigma accuracies."""

    time_us: int
    euler_rad: tuple[float, float, float]
    std_rad: tuple[float, float, float]
    status: int


@dataclass(frozen=True, slots=True)
class EkfQuat:
    """EKF_QUAT: attitude quaternion (w, x, y, z), body → NED."""

    time_us: int
    quat: tuple[float, float, float, float]
    std_rad: tuple[float, float, float]
    status: int


@dataclass(frozen=True, slots=True)
class EkfNav:
    """EKF_NAV: velocity NED (m/s), position (deg, deg, m above MSL), accuracies."""

    time_us: int
    vel_ned: tuple[float, float, float]
    vel_std_mps: tuple[float, float, float]
    lat_lon_alt: tuple[float, float, float]
    undulation_m: float
    pos_std_m: tuple[float, float, float]
    status: int


@dataclass(frozen=True, slots=True)
class Event:
    """EVENT_A..E: first event time (µs) and offsets (µs) of up to four more."""

    time_us: int
    status: int
    offsets_us: tuple[int, int, int, int]

    @property
    def event_times_us(self) -> list[int]:
        """Device times of every event the log reports, µs."""
        return [self.time_us] + [
            self.time_us + off
            for k, off in enumerate(self.offsets_us)
            if (self.status >> (k + 1)) & 1
        ]


Message = UtcTime | EkfEuler | EkfQuat | EkfNav | Event


def decode_payload(frame: Frame) -> Message | None:
    """Decode a frame of a known message; None for messages this module does not use.

    The sniffer has already checked the length against :data:`PAYLOAD_SIZES`.
    """
    if frame.msg_class != CLASS_LOG_ECOM_0:
        return None
    p, mid = frame.payload, frame.msg_id
    if mid == MSG_EKF_NAV:
        v = _NAV.unpack_from(p)
        return EkfNav(v[0], v[1:4], v[4:7], v[7:10], v[10], v[11:14], v[14])
    if mid == MSG_EKF_QUAT:
        v = _QUAT.unpack_from(p)
        return EkfQuat(v[0], v[1:5], v[5:8], v[8])
    if mid == MSG_EKF_EULER:
        v = _EULER.unpack_from(p)
        return EkfEuler(v[0], v[1:4], v[4:7], v[7])
    if mid == MSG_UTC_TIME:
        return UtcTime(*_UTC.unpack_from(p))
    if mid == MSG_EVENT_A:
        v = _EVENT.unpack_from(p)
        return Event(v[0], v[1], v[2:6])
    return None


def encode_message(msg: Message) -> bytes:
    """A complete frame carrying ``msg`` (what an SBG INS sends)."""
    if isinstance(msg, EkfNav):
        mid = MSG_EKF_NAV
        payload = _NAV.pack(
            msg.time_us & 0xFFFFFFFF, *msg.vel_ned, *msg.vel_std_mps, *msg.lat_lon_alt,
            msg.undulation_m, *msg.pos_std_m, msg.status,
        )  # fmt: skip
    elif isinstance(msg, EkfQuat):
        mid = MSG_EKF_QUAT
        payload = _QUAT.pack(msg.time_us & 0xFFFFFFFF, *msg.quat, *msg.std_rad, msg.status)
        payload += struct.pack("<2f", 0.0, 0.0)
    elif isinstance(msg, EkfEuler):
        mid = MSG_EKF_EULER
        payload = _EULER.pack(msg.time_us & 0xFFFFFFFF, *msg.euler_rad, *msg.std_rad, msg.status)
        payload += struct.pack("<2f", 0.0, 0.0)
    elif isinstance(msg, UtcTime):
        mid = MSG_UTC_TIME
        payload = _UTC.pack(
            msg.time_us & 0xFFFFFFFF, msg.status, msg.year, msg.month, msg.day, msg.hour,
            msg.minute, msg.second, msg.nanosecond, msg.gps_tow_ms,
        )  # fmt: skip
        payload += struct.pack("<3f", 0.0, 0.0, 0.0)
    else:
        mid = MSG_EVENT_A
        payload = _EVENT.pack(msg.time_us & 0xFFFFFFFF, msg.status, *msg.offsets_us)
    return encode_frame(mid, CLASS_LOG_ECOM_0, payload)


def new_sniffer(link: str) -> tuple[FrameSniffer, DriverCounters]:
    """A sniffer with fresh counters and a burst logger named ``link``."""
    counters = DriverCounters()
    return FrameSniffer(counters, BurstLog(log, link)), counters
