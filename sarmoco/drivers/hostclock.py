"""The host's UTC clock, read on the monotonic clock so that its steps are seen, not followed.

On a payload computer the wall clock (``CLOCK_REALTIME``) steps when chrony or NTP first
gets GNSS time, minutes into the power-up and sometimes in flight, and an operator or a
misconfigured service can step it any time. A link that uses the host clock as its UTC
reference (MAVLink TIMESYNC) reads :class:`HostClock` instead: monotonic time plus an
offset. The offset follows the wall clock's slow corrections; a change of wall minus
monotonic time by :data:`HOST_STEP_NS` or more between two reads is a step, which is not
applied but held for the link to judge (:meth:`HostClock.take_step`) and then either
adopted (:meth:`HostClock.adopt`) or ignored.
"""

from __future__ import annotations

import time
from collections.abc import Callable

HOST_STEP_NS = 10_000_000
"""A change of the wall clock against the monotonic clock this large between two reads is
a step, ns (a slew of at most 500 ppm moves it 5 µs in 10 ms, a step moves it at once)."""
READ_SPAN_NS = 1_000_000
"""Two wall clock reads about a monotonic one further apart than this were interrupted (the
thread descheduled, or the clock stepped between them): the three are read again, ns."""
READ_TRIES = 5
"""Reads tried before the last is taken as it is."""


def wall_ns() -> int:
    """The wall clock, POSIX ns (``time.time_ns`` as it is when called)."""
    return time.time_ns()


def monotonic_ns() -> int:
    """The monotonic clock, ns (``time.monotonic_ns`` as it is when called)."""
    return time.monotonic_ns()


class HostClock:
    """Host UTC time (POSIX ns) as monotonic time plus an offset that steps only when told.

    Parameters
    ----------
    wall : callable
        The wall clock, POSIX ns (default :func:`wall_ns`).
    mono : callable
        The monotonic clock, ns (default :func:`monotonic_ns`).
    """

    def __init__(
        self,
        wall: Callable[[], int] = wall_ns,
        mono: Callable[[], int] = monotonic_ns,
    ) -> None:
        self._wall = wall
        self._mono = mono
        self.read_error_ns = 0
        """Half the span of the two wall clock reads about the last monotonic one: how far
        the wall clock's instant may be from the monotonic one it is paired with, ns."""
        self._seen = self._read()[1]
        """Wall minus monotonic time at the last read, ns."""
        self.offset_ns = self._seen
        """Added to monotonic time to give host UTC, ns."""
        self._step_ns = 0
        """Steps of the wall clock seen and not yet taken by :meth:`take_step`, ns."""

    def now_ns(self) -> int:
        """Host UTC now, POSIX ns: monotonic time plus :attr:`offset_ns` (a step of the
        wall clock since the last read is held, not applied)."""
        mono, seen = self._read()
        change, self._seen = seen - self._seen, seen
        if abs(change) >= HOST_STEP_NS:
            self._step_ns += change
        else:
            self.offset_ns += change
        return mono + self.offset_ns

    def _read(self) -> tuple[int, int]:
        """Monotonic time and wall minus monotonic time, ns, from reads close together (see
        :data:`READ_SPAN_NS`: a thread descheduled between two reads would look like a
        step)."""
        for _ in range(READ_TRIES):
            before = self._wall()
            mono = self._mono()
            after = self._wall()
            if 0 <= after - before <= READ_SPAN_NS:
                break
        self.read_error_ns = (abs(after - before) + 1) // 2
        return mono, (before + after) // 2 - mono

    def take_step(self) -> int:
        """The wall clock's steps since the last call, summed, ns (0: none)."""
        step, self._step_ns = self._step_ns, 0
        return step

    def adopt(self, step_ns: int) -> None:
        """Follow a step the wall clock took (from :meth:`take_step`), ns."""
        self.offset_ns += step_ns
