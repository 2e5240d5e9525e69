"""The error state of an slcan (Lawicel) CAN adapter, which python-can's slcan bus drops.

python-can 4.6's :class:`can.interfaces.slcan.slcanBus` turns the adapter's data
and remote frame lines into messages and silently drops every other line, and it
has no call for the adapter's status. The Lawicel protocol reports the CAN
controller's state only on request: the host sends ``F\\r`` and the adapter
answers ``Fxx\\r``, ``xx`` an 8-bit flag register in hex (CAN232/CANUSB manual):

====  ==========================================
bit   meaning
====  ==========================================
0     CAN receive FIFO queue full
1     CAN transmit FIFO queue full
2     error warning (EI: an error counter >= 96)
3     data overrun (DOI)
4     not used
5     error passive (EPI: an error counter >= 128)
6     arbitration lost (ALI)
7     bus error (BEI)
====  ==========================================

The register has no bus-off bit. A controller that went bus-off has its transmit
error counter above 255, so both the warning and the passive flags are set, and
it got there through bus errors: :func:`bus_state` reads *error passive with a
bus error* as bus-off (:attr:`BusState.BUS_OFF`), a bus error while still error
active as a warning.

:class:`SlcanStatusBus` is python-can's slcan bus plus that request: it writes
``F`` at most every :data:`STATUS_PERIOD_S` while it is read, and keeps the last
answer (:attr:`SlcanStatusBus.status_flags`). It hooks python-can's own line
reader (``slcanBus._read``, private in python-can 4.6.1, as pinned), so the
status lines are seen on their way to ``_recv_internal``, which still drops them.
"""

from __future__ import annotations

import time
from enum import IntEnum
from typing import Any

import can
from can.interfaces.slcan import slcanBus

RX_FIFO_FULL = 0x01
TX_FIFO_FULL = 0x02
ERROR_WARNING = 0x04
DATA_OVERRUN = 0x08
ERROR_PASSIVE = 0x20
ARBITRATION_LOST = 0x40
BUS_ERROR = 0x80

STATUS_PERIOD_S = 0.1
"""Interval between two status requests (``F``), s (host monotonic clock)."""


class BusState(IntEnum):
    """The adapter's CAN controller state, worst last."""

    OK = 0
    WARNING = 1
    PASSIVE = 2
    BUS_OFF = 3

    @property
    def label(self) -> str:
        """Its name as logs and status show it: ``ok``, ``warning``, ``passive``, ``bus-off``."""
        return self.name.lower().replace("_", "-")


def bus_state(flags: int) -> BusState:
    """The controller state that Lawicel status flags ``flags`` (0..255) report.

    Bus-off is not a flag of its own: error passive together with a bus error is
    read as bus-off (module docstring).
    """
    if flags & ERROR_PASSIVE:
        return BusState.BUS_OFF if flags & BUS_ERROR else BusState.PASSIVE
    if flags & (ERROR_WARNING | BUS_ERROR):
        return BusState.WARNING
    return BusState.OK


def parse_status(line: str) -> int | None:
    """The flags of an ``Fxx\\r`` status answer; None when ``line`` is not one."""
    body = line.rstrip("\r")
    if len(body) != 3 or body[0] != "F":
        return None
    try:
        return int(body[1:], 16)
    except ValueError:
        return None


class SlcanStatusBus(slcanBus):
    """python-can's slcan bus that also asks the adapter for its status flags.

    Parameters
    ----------
    channel : str
        Serial port (``/dev/ttyACM0``, a pty), as for :class:`slcanBus`.
    status_period_s : float
        Interval between two ``F`` requests, s (host monotonic clock).
    **kwargs
        Passed to :class:`slcanBus` (``bitrate``, ``tty_baudrate``, ``sleep_after_open``...).

    Attributes
    ----------
    status_flags : int or None
        The adapter's last status answer (None before the first).
    status_answers : int
        Status answers received.
    """

    def __init__(
        self, channel: str, status_period_s: float = STATUS_PERIOD_S, **kwargs: Any
    ) -> None:
        self.status_flags: int | None = None
        self.status_answers = 0
        self._status_period_s = status_period_s
        self._next_request = 0.0
        super().__init__(channel, **kwargs)

    @property
    def bus_state(self) -> BusState | None:
        """The controller state of the last status answer (None before the first)."""
        return None if self.status_flags is None else bus_state(self.status_flags)

    def _read(self, timeout: float | None) -> str | None:
        """python-can's line reader; status answers are noted on the way."""
        line = super()._read(timeout)
        flags = parse_status(line) if line else None
        if flags is not None:
            self.status_flags = flags
            self.status_answers += 1
        return line

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        """python-can's receive, after a status request when one is due."""
        now = time.monotonic()
        if now >= self._next_request:
            self._next_request = now + self._status_period_s
            self._write("F")
        return super()._recv_internal(timeout)
