"""The INS protocols the simulator plays, by name: one registry, as python-can maps interfaces.

:data:`INS_EMITTERS` maps each protocol name (the daemon's ``ins.protocol`` values, the keys
of ``sarmoco.daemon.links.INS_OPENERS``) to an :class:`InsEmitterKind`: the recording that
``sarmoco sim --out`` writes and the emitter that writes it, and the live links of
``sarmoco sim --serve --ins NAME:WHERE``. A new protocol is one entry here and one opener
in the daemon; the tests check that the two registries name the same protocols.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

from sarmoco.errors import ConfigError
from sarmoco.sim.emit_can import Framing, SbgCanEmitter
from sarmoco.sim.emit_mavlink import AUTOPILOT_RATES_HZ, MavlinkEmitter
from sarmoco.sim.emit_sbg import SbgEmitter
from sarmoco.sim.emitter import Emitter
from sarmoco.sim.faults import PacketFaults
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.transports import FileLink, Link, PtyLink, TcpServerLink, UdpOutLink

TLOG_SYSTEM_TIME_HZ = 5.0
"""SYSTEM_TIME rate in a written ``.tlog``, Hz."""


@dataclass(frozen=True)
class InsEmitterOptions:
    """What an INS emitter takes besides its link and its samples.

    Attributes
    ----------
    faults, seed, rank
        The :class:`~sarmoco.sim.emitter.Emitter` parameters of those names.
    rogue_system : int
        System id of a second MAVLink system talking on the link (0: none); MAVLink only.
    """

    faults: PacketFaults | None
    seed: int
    rank: int
    rogue_system: int = 0

    def not_mavlink(self, name: str) -> None:
        """Refuse a MAVLink-only option on the protocol ``name``.

        Raises
        ------
        ConfigError
            If :attr:`rogue_system` is set.
        """
        if self.rogue_system:
            raise ConfigError(
                f"--fault mavlink-rogue={self.rogue_system}: the INS link is {name}, not MAVLink"
            )


@dataclass(frozen=True)
class InsEmitterKind:
    """How the simulator emits one INS protocol, to a file and on live links."""

    file: str
    """Name of the recording ``sarmoco sim --out`` writes (the bytes of the live link)."""
    to_file: Callable[[FileLink, InsFeed, InsEmitterOptions], Emitter]
    """The emitter that writes the recording."""
    live: Callable[[str, InsFeed, InsEmitterOptions], Emitter | None]
    """The emitter on the live link ``WHERE`` (what follows ``NAME:`` in ``--ins``);
    None when ``WHERE`` is none of :attr:`forms`."""
    forms: tuple[str, ...]
    """The ``WHERE`` forms :attr:`live` accepts (for help and error messages)."""
    loopback: str
    """The ``WHERE`` of the demo on loopback; ``{port}`` is replaced by a free UDP port."""


def host_port(text: str, what: str) -> tuple[str, int]:
    """Split ``HOST:PORT``; ``what`` names the argument in the error.

    Raises
    ------
    ConfigError
        If ``text`` is not ``HOST:PORT`` with a numeric port.
    """
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise ConfigError(f"{what} {text!r}: want HOST:PORT")
    return host, int(port)


def _mavlink(
    link: Link, feed: InsFeed, o: InsEmitterOptions, rates_hz: Mapping[str, float] | None = None
) -> Emitter:
    return MavlinkEmitter(
        link, feed, rates_hz=rates_hz, rogue_system=o.rogue_system, faults=o.faults,
        seed=o.seed, rank=o.rank,
    )  # fmt: skip


def _mavlink_file(link: FileLink, feed: InsFeed, options: InsEmitterOptions) -> Emitter:
    rates = {
        **AUTOPILOT_RATES_HZ,  # the autopilot's default streams, and what the daemon asks for
        "LOCAL_POSITION_NED": feed.rate_hz,
        "ATTITUDE_QUATERNION": feed.rate_hz,
        "SYSTEM_TIME": TLOG_SYSTEM_TIME_HZ,
    }
    return _mavlink(link, feed, options, rates)


def _mavlink_live(where: str, feed: InsFeed, options: InsEmitterOptions) -> Emitter | None:
    kind, _, address = where.partition(":")
    if kind == "udpout":
        return _mavlink(UdpOutLink(*host_port(address, "--ins")), feed, options)
    if kind == "tcp":
        return _mavlink(TcpServerLink(*host_port(address, "--ins")), feed, options)
    if kind == "pty":
        return _mavlink(PtyLink(), feed, options)
    return None


def _sbg(link: Link, feed: InsFeed, o: InsEmitterOptions) -> Emitter:
    o.not_mavlink("sbg")
    return SbgEmitter(link, feed, faults=o.faults, seed=o.seed, rank=o.rank)


def _sbg_file(link: FileLink, feed: InsFeed, options: InsEmitterOptions) -> Emitter:
    return _sbg(link, feed, options)


def _sbg_live(where: str, feed: InsFeed, options: InsEmitterOptions) -> Emitter | None:
    return _sbg(PtyLink(), feed, options) if where == "pty" else None


def _sbg_can(link: Link, feed: InsFeed, framing: Framing, o: InsEmitterOptions) -> Emitter:
    o.not_mavlink("sbg-can")
    return SbgCanEmitter(link, feed, framing, faults=o.faults, seed=o.seed, rank=o.rank)


def _sbg_can_file(link: FileLink, feed: InsFeed, options: InsEmitterOptions) -> Emitter:
    return _sbg_can(link, feed, "candump", options)


def _sbg_can_live(where: str, feed: InsFeed, options: InsEmitterOptions) -> Emitter | None:
    kind, _, port = where.partition(":")
    if kind == "slcan-pty":
        return _sbg_can(PtyLink(), feed, "slcan", options)
    if kind == "socketcand" and port.isdigit():
        return _sbg_can(TcpServerLink("127.0.0.1", int(port)), feed, "socketcand", options)
    return None


INS_EMITTERS: dict[str, InsEmitterKind] = {
    "mavlink": InsEmitterKind(
        "nav.tlog",
        _mavlink_file,
        _mavlink_live,
        ("udpout:HOST:PORT", "tcp:HOST:PORT", "pty"),
        "udpout:127.0.0.1:{port}",
    ),
    "sbg": InsEmitterKind("ins.sbg", _sbg_file, _sbg_live, ("pty",), "pty"),
    "sbg-can": InsEmitterKind(
        "ins.log",
        _sbg_can_file,
        _sbg_can_live,
        ("slcan-pty", "socketcand:PORT"),
        "slcan-pty",
    ),
}
"""Every INS protocol the simulator emits, by the daemon's ``ins.protocol`` name."""


def live_ins_emitter(spec: str, feed: InsFeed, options: InsEmitterOptions) -> Emitter:
    """The INS emitter of ``--ins NAME:WHERE`` on a live link.

    Raises
    ------
    ConfigError
        If ``spec`` is not one of the forms of :data:`INS_EMITTERS`, or ``options`` asks
        for a MAVLink fault on another protocol.
    """
    name, _, where = spec.partition(":")
    kind = INS_EMITTERS.get(name)
    emitter = None if kind is None else kind.live(where, feed, options)
    if emitter is None:
        forms = [f"{n}:{form}" for n, k in INS_EMITTERS.items() for form in k.forms]
        raise ConfigError(f"--ins {spec!r}: want {', '.join(forms[:-1])} or {forms[-1]}")
    return emitter
