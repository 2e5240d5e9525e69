"""Plays a set of emitters: wait for the daemon, pace the merged schedule, answer, linger.

:func:`play_emitters` is what ``sarmoco sim`` runs and what tests call
directly. While waiting and between events it watches every link for bytes
from the daemon (MAVLink commands and TIMESYNC, slcan commands, socketcand
handshakes, TCP connections) and hands them to their emitter.
"""

from __future__ import annotations

import select
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from sarmoco.drivers.clock import GPS_LEAP_SECONDS_DEFAULT
from sarmoco.errors import DriverError
from sarmoco.sim.emitter import Emitter, WireTime
from sarmoco.sim.pacing import Clock, RealtimeClock, VirtualClock, host_gps_ns, merge, play


@dataclass(frozen=True)
class Pacing:
    """How to pace a run.

    Attributes
    ----------
    realtime : bool
        Follow the wall clock (True) or a virtual clock that jumps from event to event.
    speed : float
        Simulated seconds per wall-clock second when ``realtime``.
    pin_to_host : bool
        Shift the wire's GPS times so the run happens now on the host clock
        (live runs at speed 1: MAVLink TIMESYNC then relates the autopilot's boot
        clock to the daemon host's clock as on real hardware).
    lead_s : float
        Simulated time between the start of playback and the first event, s.
    leap_s : int
        GPS − UTC, s.
    """

    realtime: bool = False
    speed: float = 1.0
    pin_to_host: bool = False
    lead_s: float = 0.5
    leap_s: int = GPS_LEAP_SECONDS_DEFAULT


@dataclass(frozen=True)
class PlayResult:
    """Outcome of a run.

    Attributes
    ----------
    events : int
        Events played.
    wall_s : float
        Wall-clock duration of the playback (waiting for peers excluded), s.
    waited_s : float
        Wall-clock time spent waiting for the peers, s.
    wire : WireTime
        Time base the wire used (its shift from scenario time).
    """

    events: int
    wall_s: float
    waited_s: float
    wire: WireTime


def _idle_for(
    emitters: Sequence[Emitter], now: Callable[[], int | None]
) -> Callable[[float], None]:
    """Wait up to the timeout for bytes from the daemon, then let every emitter service its link."""

    def idle(timeout_s: float) -> None:
        fds = [fd for e in emitters for fd in e.link.fds()]
        if fds:
            select.select(fds, [], [], timeout_s)
        elif timeout_s > 0:
            time.sleep(timeout_s)
        t = now()
        for e in emitters:
            e.service(t)

    return idle


def wait_for_peers(emitters: Sequence[Emitter], timeout_s: float, poll_s: float = 0.02) -> float:
    """Service the links until every emitter is ready; return the seconds waited.

    Bytes that arrive meanwhile are handled with no simulated time (the devices
    have not started: a MAVLink TIMESYNC request is not answered yet).

    Raises
    ------
    DriverError
        If some peer is still missing after ``timeout_s``.
    """
    idle = _idle_for(emitters, lambda: None)
    start = time.monotonic()
    while True:
        idle(0.0)
        missing = [e.describe() for e in emitters if not e.ready()]
        if not missing:
            return time.monotonic() - start
        if time.monotonic() - start > timeout_s:
            raise DriverError(f"sim: no daemon on {missing} after {timeout_s:g} s")
        idle(poll_s)


def first_event_ns(emitters: Sequence[Emitter]) -> int:
    """Scenario time of the earliest event of all schedules, ns."""
    firsts = [next(iter(e.events()), None) for e in emitters]
    return min(ev.t_ns for ev in firsts if ev is not None)


def play_emitters(
    emitters: Sequence[Emitter],
    pacing: Pacing,
    *,
    wait_s: float | None = None,
    linger_s: float = 0.0,
    on_start: Callable[[WireTime], None] | None = None,
) -> PlayResult:
    """Play every emitter's schedule.

    Parameters
    ----------
    emitters : sequence of Emitter
        The simulated devices.
    pacing : Pacing
        Real time or virtual clock, and the wire's time base.
    wait_s : float or None
        Wait up to this long for every peer before playing (None: do not wait).
    linger_s : float
        Keep answering the daemon this long (wall clock) after the last event, s.
    on_start : callable, optional
        Called with the wire time base once it is fixed, before the first event.
    """
    waited = 0.0 if wait_s is None else wait_for_peers(emitters, wait_s)
    start_ns = first_event_ns(emitters) - round(pacing.lead_s * 1e9)
    clock: Clock
    if pacing.realtime:
        host_ns = host_gps_ns(pacing.leap_s)
        clock = RealtimeClock(start_ns, pacing.speed)
        shift = host_ns - start_ns if pacing.pin_to_host else 0
    else:
        clock = VirtualClock(start_ns)
        shift = 0
    wire = WireTime(shift, pacing.leap_s)
    for e in emitters:
        e.wire = wire
    if on_start is not None:
        on_start(wire)
    idle = _idle_for(emitters, clock.now_ns)
    t_wall = time.monotonic()
    n = play(merge([e.events() for e in emitters]), clock, idle)
    for e in emitters:
        e.finish(clock.now_ns())
    end = time.monotonic() + linger_s
    while (left := end - time.monotonic()) > 0:
        idle(min(left, 0.05))
    return PlayResult(n, time.monotonic() - t_wall, waited, wire)
