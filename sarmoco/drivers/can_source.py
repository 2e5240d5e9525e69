"""SBG CAN sources over python-can: live buses and log replay.

* :class:`CanSource` wraps any python-can bus: ``socketcan`` on the aircraft,
  ``slcan`` (a serial adapter, or a simulated one on a pseudo-terminal; opened as
  :class:`~sarmoco.drivers.slcan_status.SlcanStatusBus`, which also reads the
  adapter's error state: :attr:`Source.bus_fault` while it is passive or bus-off),
  ``socketcand`` (TCP), ``virtual`` (in-process). Open one with
  :meth:`CanSource.open`.
* :class:`CanLogSource` replays candump ``.log``, ``.asc``, ``.blf`` (anything
  :class:`can.LogReader` reads).
"""

from __future__ import annotations

import io
import logging
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can

from sarmoco.drivers.clock import GPS_LEAP_SECONDS_DEFAULT
from sarmoco.drivers.counters import BurstLog
from sarmoco.drivers.samples import Sample
from sarmoco.drivers.sbg_can import SbgCanDecoder
from sarmoco.drivers.slcan_status import BusState, SlcanStatusBus
from sarmoco.drivers.source import Source
from sarmoco.errors import DriverError

log = logging.getLogger(__name__)

MAX_FRAMES_PER_POLL = 2000
MAX_ERRORS_IN_ROW = 1000
"""Bus errors in a row, with no good frame between, after which the link counts as dead."""


def _device_gone(exc: BaseException) -> bool:
    """Whether a python-can exception reports the device or its connection failing.

    Interfaces wrap the failure of the port or socket underneath (pyserial's
    SerialException, a socket error: both OSError) in a CanError; bytes they
    could not parse surface as ValueError, IndexError, or a CanError wrapping one.
    """
    cause: BaseException | None = exc
    while cause is not None:
        if isinstance(cause, OSError):
            return True
        cause = cause.__cause__
    return False


def _stream_closed(bus: can.BusABC) -> bool:
    """Whether the TCP peer of a socketcand bus closed the connection.

    python-can's socketcand interface reads end of stream as "no message" and
    spins until its timeout, so the end is checked here on its socket (a private
    attribute of python-can 4.6, as pinned).
    """
    sock = getattr(bus, "_SocketCanDaemonBus__socket", None)
    if not isinstance(sock, socket.socket):
        return False
    try:
        return sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b""
    except BlockingIOError:
        return False
    except OSError:
        return True


class _CanSourceBase(Source):
    raw_format = "candump"

    def __init__(self, leap_s: int, link: str) -> None:
        super().__init__()
        self.decoder = SbgCanDecoder(leap_s, link)
        self.counters = self.decoder.counters
        self._burst = BurstLog(log, link)
        self._raw_text = io.StringIO()
        self._raw_writer = can.CanutilsLogWriter(self._raw_text)

    def _frame(self, msg: can.Message, out: list[Sample]) -> None:
        if self._raw is not None:  # every frame as received, as a candump -L line
            self._raw_writer.on_message_received(msg)
            self._keep(self._raw_text.getvalue().encode())
            self._raw_text.seek(0)
            self._raw_text.truncate()
        if msg.is_error_frame or msg.is_remote_frame:
            self.counters.parse_errors += 1
            self._burst.error("bus", "error or remote frame")
            return
        out += self.decoder.feed(msg.arbitration_id, bytes(msg.data))


class CanSource(_CanSourceBase):
    """SBG CAN messages from a live python-can bus.

    Parameters
    ----------
    bus : can.BusABC
        An open bus; closed by :meth:`close`.
    leap_s : int
        GPS − UTC, s.
    link : str
        Name used in log messages.
    """

    def __init__(
        self, bus: can.BusABC, leap_s: int = GPS_LEAP_SECONDS_DEFAULT, link: str = "sbg-can"
    ) -> None:
        super().__init__(leap_s, link)
        self.bus = bus
        self._link = link
        self._errors_in_row = 0
        self._closed = False
        self._bus_state = BusState.OK

    @classmethod
    def open(
        cls,
        interface: str,
        channel: str,
        leap_s: int = GPS_LEAP_SECONDS_DEFAULT,
        **bus_kwargs: Any,
    ) -> CanSource:
        """Open ``can.Bus(interface=..., channel=..., **bus_kwargs)`` and wrap it.

        Examples: ``("socketcan", "can0")``, ``("slcan", "/dev/ttyACM0", bitrate=500000)``,
        ``("socketcand", "can0", host="127.0.0.1", port=29536)``, ``("virtual", "sim")``.
        """
        try:
            if interface == "slcan":
                bus: can.BusABC = SlcanStatusBus(channel, **bus_kwargs)
            else:
                bus = can.Bus(interface=interface, channel=channel, **bus_kwargs)
        except (can.CanError, OSError, ValueError) as exc:
            raise DriverError(f"can {interface}:{channel}: cannot open: {exc}") from exc
        return cls(bus, leap_s, f"sbg-can {interface}:{channel}")

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        out: list[Sample] = []
        wait = timeout_s
        for _ in range(MAX_FRAMES_PER_POLL):
            try:
                msg = self.bus.recv(wait)
            except (can.CanError, ValueError, IndexError, UnicodeDecodeError) as exc:
                if _device_gone(exc):
                    raise DriverError(f"{self._link}: device gone: {exc}") from exc
                # python-can interfaces raise these for unparsable wire data too
                self.counters.parse_errors += 1
                self._burst.error("bus frame", str(exc).splitlines()[0] if str(exc) else "")
                self._errors_in_row += 1
                if self._errors_in_row > MAX_ERRORS_IN_ROW:
                    raise DriverError(f"can: {self._errors_in_row} errors in a row: {exc}") from exc
                continue
            if msg is None:
                if _stream_closed(self.bus):
                    raise DriverError(f"{self._link}: peer closed the connection")
                break
            self._errors_in_row = 0
            wait = 0.0
            self._frame(msg, out)
        self._check_bus_state()
        return out

    def _check_bus_state(self) -> None:
        """Follow the adapter's reported bus state (slcan): count each step into a worse
        error state, log each change once, and set :attr:`bus_fault` while passive or off."""
        if not isinstance(self.bus, SlcanStatusBus):
            return
        state = self.bus.bus_state
        if state is None or state == self._bus_state:
            return
        what = f"CAN bus {state.label} (adapter status flags 0x{self.bus.status_flags:02X})"
        if state > self._bus_state:
            self.counters.bus_error_states += 1
            log.warning("%s: %s", self._link, what)
        else:
            log.info("%s: %s again", self._link, what)
        self._bus_state = state
        self.bus_fault = what if state >= BusState.PASSIVE else ""

    def close(self) -> None:
        """Shut the bus down; idempotent, and quiet when the device is already gone."""
        if self._closed:
            return
        self._closed = True
        try:
            self.bus.shutdown()
        except (can.CanError, OSError) as exc:  # slcan writes "C" to a port that may be gone
            log.info("%s: closed (the device was already gone: %s)", self._link, exc)


class CanLogSource(_CanSourceBase):
    """Replays a CAN log file (candump ``.log``, ``.asc``, ``.blf``...).

    Parameters
    ----------
    path : str or Path
        The log.
    leap_s : int
        GPS − UTC, s.
    frames_per_poll : int
        Frames decoded per :meth:`poll`.
    """

    def __init__(
        self,
        path: str | Path,
        leap_s: int = GPS_LEAP_SECONDS_DEFAULT,
        frames_per_poll: int = MAX_FRAMES_PER_POLL,
    ) -> None:
        super().__init__(leap_s, f"sbg-can {path}")
        try:
            self._reader = can.LogReader(path)
        except (OSError, ValueError, can.CanError) as exc:
            raise DriverError(f"can log {path}: cannot open: {exc}") from exc
        self._it: Iterator[can.Message] = iter(self._reader)
        self._n = frames_per_poll
        self._path = path

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        out: list[Sample] = []
        for _ in range(self._n):
            try:
                msg = next(self._it)
            except StopIteration:
                self.eof = True
                break
            except (ValueError, IndexError, can.CanError) as exc:
                self.counters.parse_errors += 1
                log.warning("can log %s: unreadable from here on: %s", self._path, exc)
                self.eof = True
                break
            self._frame(msg, out)
        return out

    def close(self) -> None:
        self._reader.stop()
