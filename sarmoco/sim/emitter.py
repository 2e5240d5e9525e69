"""What every simulated device has in common: a link, packet faults, and the wire's time base.

An emitter turns a :class:`~sarmoco.sim.run.SimRun` into a time-ordered stream
of :class:`~sarmoco.sim.pacing.Event` (its schedule), sends each packet through
its :class:`~sarmoco.sim.faults.PacketFaultInjector` onto its
:class:`~sarmoco.sim.transports.Link`, and answers what the daemon sends back
(:meth:`Emitter.on_bytes`). Schedules are in scenario GPS time; what goes on
the wire is shifted by :attr:`WireTime.shift_ns` (zero unless a live run is
pinned to the host clock, so that TIMESYNC means something to the daemon).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from typing import Any

from sarmoco.drivers.clock import GPS_LEAP_SECONDS_DEFAULT, gps_ns_to_unix_ns
from sarmoco.sim.faults import PacketFaultInjector, PacketFaults
from sarmoco.sim.pacing import Event
from sarmoco.sim.transports import Link


@dataclass(frozen=True)
class WireTime:
    """Maps scenario GPS time onto the GPS and UTC times written on the wire.

    Attributes
    ----------
    shift_ns : int
        Added to every scenario GPS time before it is written, ns.
    leap_s : int
        GPS − UTC, s, for UTC fields (SBG UTC_TIME, MAVLink SYSTEM_TIME, log stamps).
    """

    shift_ns: int = 0
    leap_s: int = GPS_LEAP_SECONDS_DEFAULT

    def gps_ns(self, t_ns: int) -> int:
        """Wire GPS time of scenario time ``t_ns``, ns."""
        return int(t_ns) + self.shift_ns

    def unix_ns(self, t_ns: int) -> int:
        """Wire POSIX UTC time of scenario time ``t_ns``, ns."""
        return gps_ns_to_unix_ns(self.gps_ns(t_ns), self.leap_s)


class Emitter(ABC):
    """Base of the simulated devices.

    Parameters
    ----------
    link : Link
        Transport.
    faults : PacketFaults or None
        Packet faults of this link (None: none).
    seed : int
        Seed of the fault draws.
    rank : int
        Tie-break of this emitter's events against others due at the same time.
    """

    protocol = ""
    """Name of the protocol, e.g. ``"vita49"``, ``"mavlink"``."""

    def __init__(self, link: Link, faults: PacketFaults | None, seed: int, rank: int) -> None:
        self.link = link
        self.injector = PacketFaultInjector(faults or PacketFaults(), seed)
        self.rank = rank
        self.wire = WireTime()
        """Time base of the wire (set by the player when playback starts)."""
        self.now_ns = 0
        """Scenario time of the packet being sent, ns (file formats stamp it)."""

    @abstractmethod
    def events(self) -> Iterator[Event]:
        """This device's schedule, in scenario GPS time."""

    def send(self, packet: bytes, t_ns: int) -> None:
        """Offer one packet, sent at scenario time ``t_ns``, to the fault injector and the link."""
        self.now_ns = t_ns
        self.injector.send(packet, self.write, t_ns)

    def write(self, packet: bytes) -> None:
        """Put one packet on the link (formats with per-packet framing override this)."""
        self.link.write(packet)

    def service(self, now_ns: int | None) -> None:
        """Handle what the daemon sent; ``now_ns``: scenario time now (None before the start)."""
        data = self.link.receive()
        if data:
            self.on_bytes(data, now_ns)

    def on_bytes(self, data: bytes, now_ns: int | None) -> None:
        """React to bytes from the daemon (commands, handshakes); default: ignore them."""
        return None

    def ready(self) -> bool:
        """Whether the daemon's side is there (a client connected, a port opened, a peer heard)."""
        return self.link.peer_ready()

    def finish(self, now_ns: int) -> None:
        """Send what the fault injector still holds back."""
        self.now_ns = now_ns
        self.injector.flush(self.write)

    def connect_hint(self) -> dict[str, Any]:
        """How the daemon connects to this device (protocol-specific fields)."""
        return {}

    def describe(self) -> dict[str, Any]:
        """Protocol, link and connection hint, JSON-able (the ``--serve`` line prints it)."""
        return {"protocol": self.protocol, **self.link.describe(), **self.connect_hint()}

    def stats(self) -> dict[str, Any]:
        """Packets sent and faults injected, JSON-able."""
        return {
            "faults": asdict(self.injector.counts),
            "writes": self.link.written_writes,
            "bytes": self.link.written_bytes,
            "dropped_writes": self.link.dropped_writes,
        }

    def close(self) -> None:
        """Release the link."""
        self.link.close()
