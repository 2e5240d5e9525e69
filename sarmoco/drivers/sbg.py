"""SBG INS over sbgECom binary: the stateful decoder and its serial and file sources.

The decoder maps the device clock (µs since power-up, 32-bit) onto GPS time
with the UTC_TIME log: each UTC_TIME pairs a device time with UTC (ns
resolution) and the GPS time of week; a sliding offset-and-skew fit
(:class:`~sarmoco.drivers.timesync.LinearClockFit`) maps every other log.
GPS − UTC comes from configuration and is confirmed (or corrected, with a
warning) by the GPS time of week the device reports. Logs that arrive before
the first valid UTC_TIME wait in a bounded queue.
"""

from __future__ import annotations

import logging
import math
from collections import deque
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
from sarmoco.drivers.samples import (
    AttitudeSample,
    EventSample,
    Sample,
    TimeSample,
    Validity,
    VelocitySample,
)
from sarmoco.drivers.source import Source
from sarmoco.drivers.timesync import CounterUnwrapper, LinearClockFit
from sarmoco.errors import ClockError, DriverError

log = logging.getLogger(__name__)

_REBOOT_BACKSTEP_US = 2_000_000


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
    max_pending : int
        Logs kept while waiting for the first valid UTC_TIME; older ones are
        dropped (counted in ``counters.drops``).
    """

    def __init__(
        self, leap_s: int = GPS_LEAP_SECONDS_DEFAULT, link: str = "sbg", max_pending: int = 2000
    ) -> None:
        self.leap_s = leap_s
        self.sniffer, self.counters = codec.new_sniffer(link)
        self.clock = LinearClockFit(window=16, outlier_ns=1_000_000)
        self._unwrap = CounterUnwrapper(32, _REBOOT_BACKSTEP_US)
        self._pending: deque[tuple[int, codec.Message]] = deque()
        self._max_pending = max_pending
        self._leap_warned = False
        self._clock_valid = False

    def feed(self, data: bytes, final: bool = False) -> list[Sample]:
        """Decode ``data`` (any slice of the byte stream); never raises on bad bytes.

        ``final`` marks the end of a file: a torn last frame is given up.
        """
        out: list[Sample] = []
        for frame in self.sniffer.feed(data, final):
            msg = codec.decode_payload(frame)
            if msg is None:
                continue
            dev_us, reset = self._unwrap.unwrap(msg.time_us)
            if reset:
                log.warning("sbg: device clock went backwards: INS rebooted, clock fit reset")
                self.clock.reset()
                self.counters.gaps += 1
            dev_ns = dev_us * 1000
            if isinstance(msg, codec.UtcTime):
                self._utc(msg, dev_ns, out)
            if not self.clock.ready:
                self._pending.append((dev_ns, msg))
                if len(self._pending) > self._max_pending:
                    self._pending.popleft()
                    self.counters.drops += 1
                continue
            self._flush(out)
            self._emit(msg, dev_ns, out)
        return out

    def _flush(self, out: list[Sample]) -> None:
        while self._pending:
            dev_ns, msg = self._pending.popleft()
            self._emit(msg, dev_ns, out)

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
        self._clock_valid = msg.clock_state == codec.CLOCK_VALID
        if not self.clock.add(dev_ns, gps):
            return
        valid = Validity.TIME if self._clock_valid else Validity.NONE
        out.append(TimeSample(gps, dev_ns, valid, "sbg.UTC_TIME"))

    def _emit(self, msg: codec.Message, dev_ns: int, out: list[Sample]) -> None:
        t = self.clock.map(dev_ns)
        tflag = Validity.TIME if self._clock_valid else Validity.NONE
        if isinstance(msg, codec.EkfNav):
            if not _finite(msg.vel_ned_mps):
                self.counters.parse_errors += 1
                return
            out.append(
                VelocitySample(
                    t,
                    msg.vel_ned_mps,
                    _flags(msg.status) | tflag,
                    "sbg.EKF_NAV",
                    dev_ns,
                    vel_std_mps=msg.vel_std_mps,
                    lat_lon_alt=msg.lat_lon_alt,
                )
            )
        elif isinstance(msg, codec.EkfQuat | codec.EkfEuler):
            if isinstance(msg, codec.EkfQuat):
                q, name = normalized(msg.quat_wxyz), "sbg.EKF_QUAT"
            else:
                q = normalized(euler_to_quat(*msg.euler_rad)) if _finite(msg.euler_rad) else None
                name = "sbg.EKF_EULER"
            if q is None:
                self.counters.parse_errors += 1
                return
            out.append(AttitudeSample(t, q, _flags(msg.status) | tflag, name, dev_ns))
        elif isinstance(msg, codec.Event):
            if msg.status & codec.EVENT_OVERFLOW:
                self.counters.drops += 1
            for ev_us in msg.event_times_us:
                ev_ns = dev_ns + (ev_us - msg.time_us) * 1000
                out.append(EventSample(self.clock.map(ev_ns), "A", tflag, "sbg.EVENT_A", ev_ns))


class _SbgSource(Source):
    """An :class:`SbgDecoder` fed by a transport."""

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
            self._ser.timeout = timeout_s
            data = self._ser.read(max(1, self._ser.in_waiting))
            if data and self._ser.in_waiting:
                data += self._ser.read(self._ser.in_waiting)
        except (serial.SerialException, OSError) as exc:
            raise DriverError(f"sbg {self.port}: {exc}") from exc
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
        return self.decoder.feed(data)

    def close(self) -> None:
        self._file.close()
