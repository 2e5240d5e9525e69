"""SBG INS over sbgECom binary: the stateful decoder and its serial and file sources.

The decoder maps the device clock (µs since power-up, 32-bit) onto GPS time
with the UTC_TIME log: each UTC_TIME pairs a device time with UTC (ns
resolution) and the GPS time of week; a sliding offset-and-skew fit
(:class:`~sarmoco.drivers.devclock.DeviceClock`) maps every other log.
GPS − UTC comes from configuration and is confirmed (or corrected, with a
warning) by the GPS time of week the device reports. Logs wait in a bounded
queue until the second valid UTC_TIME (after start and after a device reboot):
from then on the fit has a skew (a line through the first two pairs, to µs),
where an offset alone would be wrong by the drift times the distance to the
pair (16 µs at 40 ppm and 0.4 s). The wait is one UTC_TIME period, once.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import BinaryIO

import serial

from sarmoco.drivers import sbg_codec as codec
from sarmoco.drivers.attitude import euler_to_quat, normalized
from sarmoco.drivers.clock import (
    GPS_LEAP_SECONDS_DEFAULT,
    NS_PER_S,
    gps_ns_from_tow,
    unix_ns_to_gps_ns,
    utc_calendar_to_unix_ns,
)
from sarmoco.drivers.devclock import DeviceClock
from sarmoco.drivers.posframe import LocalPositions
from sarmoco.drivers.samples import (
    AttitudeSample,
    EventSample,
    Sample,
    Validity,
    VelocitySample,
)
from sarmoco.drivers.source import Source
from sarmoco.drivers.timesync import LinearClockFit
from sarmoco.errors import ClockError, DriverError

log = logging.getLogger(__name__)


def _flags(status: int) -> Validity:
    v = Validity.NONE
    if status & codec.SOL_ATTITUDE_VALID:
        v |= Validity.ATTITUDE
    if status & codec.SOL_HEADING_VALID:
        v |= Validity.HEADING
    if status & codec.SOL_VELOCITY_VALID:
        v |= Validity.VELOCITY
    if status & codec.SOL_POSITION_VALID:
        v |= Validity.POSITION
    return v


def _finite(values: tuple[float, ...]) -> bool:
    return all(math.isfinite(x) for x in values)


class SbgDecoder:
    """Bytes from an SBG INS in, samples on GPS time out.

    Parameters
    ----------
    leap_s : int
        GPS − UTC, s (configuration; checked against the device's GPS time of week).
    link : str
        Name used in log messages.

    Attributes
    ----------
    positions : LocalPositions
        The frame of the samples' local NED positions (``pos_ned``): the tangent plane
        at the first EKF_NAV with a valid position (``positions.frame``). Heights are
        above the WGS-84 ellipsoid: EKF_NAV's altitude above mean sea level plus its
        undulation.
    """

    def __init__(self, leap_s: int = GPS_LEAP_SECONDS_DEFAULT, link: str = "sbg") -> None:
        self.leap_s = leap_s
        self.positions = LocalPositions("sbg.EKF_NAV", ellipsoid_height=True)
        self.sniffer, self.counters = codec.new_sniffer(link)
        fit = LinearClockFit(window=16, outlier_ns=1_000_000, min_pairs=2, ready_pairs=2)
        self.clock = DeviceClock(link, self.counters, model=fit)
        self._leap_warned = False

    def feed(self, data: bytes, final: bool = False) -> list[Sample]:
        """Decode ``data`` (any slice of the byte stream); never raises on bad bytes.

        ``final`` marks the end of a file: a torn last frame is given up.
        """
        out: list[Sample] = []
        for frame in self.sniffer.feed(data, final):
            msg = codec.decode_payload(frame)
            if msg is not None:
                self._message(msg, self.clock.device_ns(msg.time_us), out)
        return out

    def _message(self, msg: codec.Message, dev_ns: int, out: list[Sample]) -> None:
        if isinstance(msg, codec.UtcTime):
            self._utc(msg, dev_ns, out)
        elif isinstance(msg, codec.EkfNav):
            if not _finite(msg.vel_ned):
                self.counters.parse_errors += 1
                return
            valid = _flags(msg.status)
            lla = None
            if valid & Validity.POSITION and _finite((*msg.lat_lon_alt, msg.undulation_m)):
                lat, lon, alt_msl = msg.lat_lon_alt
                lla = (lat, lon, alt_msl + msg.undulation_m)  # height above the ellipsoid
            pos, frame = self.positions.local(lla) if lla is not None else (None, None)
            sample = VelocitySample(
                0, msg.vel_ned, valid, "sbg.EKF_NAV", dev_ns, pos_ned=pos,
                vel_std_mps=msg.vel_std_mps, lat_lon_alt=lla, pos_frame=frame,
            )  # fmt: skip
            self.clock.stamp(sample, out)
        elif isinstance(msg, codec.EkfQuat | codec.EkfEuler):
            if isinstance(msg, codec.EkfQuat):
                q, name = normalized(msg.quat), "sbg.EKF_QUAT"
            else:
                q = normalized(euler_to_quat(*msg.euler_rad)) if _finite(msg.euler_rad) else None
                name = "sbg.EKF_EULER"
            if q is None:
                self.counters.parse_errors += 1
                return
            self.clock.stamp(AttitudeSample(0, q, _flags(msg.status), name, dev_ns), out)
        else:
            if msg.status & codec.EVENT_OVERFLOW:
                self.counters.drops += 1
            for ev_us in msg.event_times_us:
                ev_ns = dev_ns + (ev_us - msg.time_us) * 1000
                self.clock.stamp(EventSample(0, "A", Validity.NONE, "sbg.EVENT_A", ev_ns), out)

    def _utc(self, msg: codec.UtcTime, dev_ns: int, out: list[Sample]) -> None:
        if msg.clock_state not in (codec.CLOCK_STEERING, codec.CLOCK_VALID) or not msg.utc_status:
            return
        try:
            unix_ns = utc_calendar_to_unix_ns(
                msg.year, msg.month, msg.day, msg.hour, msg.minute, msg.second, msg.nanosecond
            )
        except ClockError as exc:
            self.counters.parse_errors += 1
            log.debug("sbg: UTC_TIME ignored: %s", exc)
            return
        gps = unix_ns_to_gps_ns(unix_ns, self.leap_s)
        delta = gps_ns_from_tow(msg.gps_tow_ms, gps) - gps
        leap_fix = round(delta / NS_PER_S)
        if leap_fix and abs(delta - leap_fix * NS_PER_S) < 2_000_000:
            gps += leap_fix * NS_PER_S
            if not self._leap_warned:
                self._leap_warned = True
                log.warning(
                    "sbg: GPS time of week says GPS-UTC = %d s, configured %d s; using the device",
                    self.leap_s + leap_fix,
                    self.leap_s,
                )
        ts = self.clock.reference(dev_ns, gps, msg.clock_state == codec.CLOCK_VALID, "sbg.UTC_TIME")
        if ts is not None:
            self.clock.stamp(ts, out)


class _SbgSource(Source):
    """An :class:`SbgDecoder` fed by a transport."""

    raw_format = "sbgecom"

    def __init__(self, leap_s: int, link: str) -> None:
        super().__init__()
        self.decoder = SbgDecoder(leap_s, link)
        self.counters = self.decoder.counters


class SbgSerialSource(_SbgSource):
    """An SBG INS on a serial port (or a pseudo-terminal in simulation).

    Parameters
    ----------
    port : str
        Device name, e.g. ``/dev/ttyUSB0``.
    baudrate : int
        Line rate, baud.
    leap_s : int
        GPS − UTC, s.
    """

    def __init__(
        self, port: str, baudrate: int = 115200, leap_s: int = GPS_LEAP_SECONDS_DEFAULT
    ) -> None:
        super().__init__(leap_s, f"sbg {port}")
        self.port = port
        try:
            self._ser = serial.Serial(port, baudrate, timeout=0)
        except (serial.SerialException, OSError) as exc:
            raise DriverError(f"sbg {port}: cannot open: {exc}") from exc

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        try:
            if self._ser.timeout != timeout_s:  # the setter reconfigures the port
                self._ser.timeout = timeout_s
            data = self._ser.read(max(1, self._ser.in_waiting))
            if data and self._ser.in_waiting:
                data += self._ser.read(self._ser.in_waiting)
        except (serial.SerialException, OSError) as exc:
            raise DriverError(f"sbg {self.port}: {exc}") from exc
        self._keep(data)
        return self.decoder.feed(data) if data else []

    def close(self) -> None:
        self._ser.close()


class SbgFileSource(_SbgSource):
    """A file of raw sbgECom bytes (as logged from the serial port).

    Parameters
    ----------
    path : str or Path
        The file.
    leap_s : int
        GPS − UTC, s.
    chunk_bytes : int
        Bytes read per poll.
    """

    def __init__(
        self, path: str | Path, leap_s: int = GPS_LEAP_SECONDS_DEFAULT, chunk_bytes: int = 65536
    ) -> None:
        super().__init__(leap_s, f"sbg {path}")
        self._chunk = chunk_bytes
        try:
            self._file: BinaryIO = open(path, "rb")
        except OSError as exc:
            raise DriverError(f"sbg {path}: cannot open: {exc}") from exc

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        data = self._file.read(self._chunk)
        if not data:
            self.eof = True
            return self.decoder.feed(b"", final=True)
        self._keep(data)
        return self.decoder.feed(data)

    def close(self) -> None:
        self._file.close()
