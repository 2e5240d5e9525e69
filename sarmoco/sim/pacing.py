"""Pacing of the simulator's event schedule: real time, scaled real time, or a virtual clock.

Every emitter turns its part of a simulated run into a time-ordered stream of
:class:`Event` (a GPS time and an action that writes bytes to a link). The
streams are merged into one schedule and played by :func:`play` against a
clock. The schedule is the same whatever the clock: a :class:`RealtimeClock`
waits on the wall clock until each event is due (servicing incoming bytes
meanwhile), a :class:`VirtualClock` jumps straight to it (trio's ``MockClock``
idea), so a run played "as fast as possible" emits exactly the bytes of a
real-time run, in the same order.
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Protocol

from sarmoco.drivers.clock import unix_ns_to_gps_ns
from sarmoco.errors import ConfigError

Idle = Callable[[float], None]
"""Called while waiting: service incoming bytes for at most the given seconds."""


@dataclass(frozen=True, order=True)
class Event:
    """One scheduled action of an emitter.

    Attributes
    ----------
    t_ns : int
        When it is due, simulated GPS ns.
    rank : int
        Tie-break among events due at the same time (lower first); emitters use
        their link's rank so the merged order never depends on dict or set order.
    action : callable
        Writes the bytes; called with no argument.
    """

    t_ns: int
    rank: int
    action: Callable[[], None] = field(compare=False)


class Clock(Protocol):
    """What :func:`play` needs from a clock."""

    def now_ns(self) -> int:
        """The current simulated GPS time, ns."""

    def wait_until(self, t_ns: int, idle: Idle) -> None:
        """Return when the simulated time reaches ``t_ns``, calling ``idle`` meanwhile."""


class VirtualClock:
    """A clock that jumps to each event: the run goes as fast as the links take the bytes.

    Parameters
    ----------
    start_ns : int
        Initial simulated GPS time, ns.
    """

    def __init__(self, start_ns: int) -> None:
        self._now = int(start_ns)

    def now_ns(self) -> int:
        """The simulated GPS time of the last event reached, ns."""
        return self._now

    def wait_until(self, t_ns: int, idle: Idle) -> None:
        """Service incoming bytes once without blocking, then jump to ``t_ns`` (never back)."""
        idle(0.0)
        self._now = max(self._now, int(t_ns))


class RealtimeClock:
    """A clock that follows the host's monotonic clock, optionally sped up.

    Parameters
    ----------
    start_ns : int
        Simulated GPS time at the moment of construction, ns.
    speed : float
        Simulated seconds per wall-clock second (1.0 = real time).
    max_idle_s : float
        Longest single call to ``idle`` while waiting, s.
    """

    def __init__(self, start_ns: int, speed: float = 1.0, max_idle_s: float = 0.05) -> None:
        if not speed > 0:
            raise ConfigError(f"sim speed: {speed!r} is not > 0")
        self._start = int(start_ns)
        self._mono0 = time.monotonic_ns()
        self.speed = float(speed)
        self.max_idle_s = max_idle_s

    def now_ns(self) -> int:
        """Simulated GPS time now, ns."""
        return self._start + round((time.monotonic_ns() - self._mono0) * self.speed)

    def wait_until(self, t_ns: int, idle: Idle) -> None:
        """Service incoming bytes until the simulated time reaches ``t_ns``."""
        while True:
            remaining_s = (t_ns - self.now_ns()) / 1e9 / self.speed
            if remaining_s <= 0:
                idle(0.0)
                return
            idle(min(remaining_s, self.max_idle_s))


def host_gps_ns(leap_s: int) -> int:
    """The host's clock now as GPS ns (POSIX UTC + ``leap_s``)."""
    return unix_ns_to_gps_ns(time.time_ns(), leap_s)


def merge(streams: Iterable[Iterable[Event]]) -> Iterator[Event]:
    """Merge time-ordered event streams into one schedule.

    Ties are broken by rank, then by the stream's position in ``streams``, then by
    order within the stream, so the schedule is fully determined by its inputs.
    """
    keyed = [_keyed(i, stream) for i, stream in enumerate(streams)]
    return (e for _, e in heapq.merge(*keyed, key=lambda pair: pair[0]))


def _keyed(
    index: int, stream: Iterable[Event]
) -> Iterator[tuple[tuple[int, int, int, int], Event]]:
    for n, e in enumerate(stream):
        yield (e.t_ns, e.rank, index, n), e


def play(schedule: Iterable[Event], clock: Clock, idle: Idle) -> int:
    """Run each event when the clock says it is due; return the number of events run."""
    n = 0
    for event in schedule:
        clock.wait_until(event.t_ns, idle)
        event.action()
        n += 1
    return n
