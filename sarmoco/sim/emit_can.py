"""The simulated SBG INS on CAN: through a simulated slcan adapter, a socketcand server, or
into a candump ``.log``.

Frames (the drivers' SBG CAN codec, :mod:`sarmoco.drivers.sbg_can`): per INS
sample EKF_INFO (device time), EKF_QUAT (or EKF_EULER) and EKF_VEL_NED; every
``utc_period_s`` STATUS_01 (clock valid), STATUS_03 (solution status), UTC_0
(device time and GPS time of week, sent on a whole millisecond of GPS time so
the 1 ms field is exact) and UTC_1 (date); per radar pulse EVENT_INFO_A.

Framings of a CAN frame on the three links:

* ``slcan``: the adapter side of the Lawicel serial protocol on the pty master
  (``tIIILDD..\\r``); it answers the host's commands (``C``, ``O``, ``L``,
  ``S0``-``S8``, ``V``, ``N``, ``Z``, ...) with ``\\r``, the status request ``F`` with
  ``Fxx\\r`` (the Lawicel status flags: ``00``, or those of the ``can-errors`` and
  ``can-bus-off`` faults while they last), and forwards frames only while the channel
  is open, as a real adapter does;
* ``socketcand``: ``< hi >`` on connect, ``< ok >`` to ``< open CH >`` and
  ``< rawmode >``, then ``< frame III SEC.USEC DATA >``;
* ``candump``: ``(SEC.USEC) can0 III#DATA`` lines, readable by ``can.LogReader``.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from functools import partial
from typing import Any, Literal

import numpy as np

from sarmoco.drivers import sbg_can as sc
from sarmoco.drivers import sbg_codec
from sarmoco.drivers.attitude import quat_to_euler
from sarmoco.drivers.clock import NS_PER_S
from sarmoco.drivers.slcan_status import BUS_ERROR, ERROR_PASSIVE, ERROR_WARNING
from sarmoco.sim.emit_sbg import (
    SOLUTION_NAV_POSITION,
    UTC_STATUS,
    SbgDevice,
    gps_tow_ms,
    utc_fields,
    vec3,
    vec4,
)
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.pacing import Event, merge
from sarmoco.sim.transports import Link, TcpServerLink

Framing = Literal["slcan", "socketcand", "candump"]
CHANNEL = "can0"
"""CAN channel name the socketcand server offers and candump logs carry."""
SOCKETCAND_SETTLE_S = 0.1
"""Quiet time after the last handshake answer before frames flow (python-can reads each
handshake answer with one ``recv``; a frame in the same segment would spoil it), s."""
SLCAN_VERSION = b"V1013\r"
SLCAN_SERIAL = b"NSIM1\r"
SLCAN_FLAGS_PASSIVE = ERROR_WARNING | ERROR_PASSIVE
"""Status flags of an error-passive bus (0x24)."""
SLCAN_FLAGS_BUS_OFF = SLCAN_FLAGS_PASSIVE | BUS_ERROR
"""Status flags of a bus-off adapter (0xA4; read as bus-off by
:func:`~sarmoco.drivers.slcan_status.bus_state`)."""


def _unix_seconds(unix_ns: int) -> str:
    seconds, ns = divmod(unix_ns, NS_PER_S)
    return f"{seconds}.{ns // 1000:06d}"


class SbgCanEmitter(SbgDevice):
    """Plays a run's INS samples as SBG CAN frames.

    Parameters
    ----------
    link : Link
        Pseudo-terminal (``slcan``), TCP server (``socketcand``) or file (``candump``).
    feed : InsFeed
        Samples, device clock and pulse events.
    framing : {"slcan", "socketcand", "candump"}
        How frames are written on the link.
    **options
        ``attitude`` (EKF_QUAT or EKF_EULER), ``utc_period_s`` (interval between the time
        references UTC_0/UTC_1 and status, s), ``events`` (an EVENT_INFO_A per radar pulse),
        ``faults``, ``seed``, ``rank``: see :class:`~sarmoco.sim.emit_sbg.SbgDevice` (one CAN
        frame is one packet).
    """

    protocol = "sbg-can"

    def __init__(self, link: Link, feed: InsFeed, framing: Framing, **options: Any) -> None:
        super().__init__(link, feed, **options)
        self.framing: Framing = framing
        self.solution = SOLUTION_NAV_POSITION | sbg_codec.SOL_ATTITUDE_VALID
        self.solution |= sbg_codec.SOL_HEADING_VALID | sbg_codec.SOL_VELOCITY_VALID
        self.channel_open = framing == "candump"
        self._rx = b""
        self._settle_until: float | None = None
        self.frames_sent = 0
        self.frames_unsent = 0
        """Frames the adapter could not forward (channel closed)."""
        self._greeted = 0
        """Connections greeted (socketcand)."""
        self.status_answers = 0
        """Status requests (slcan ``F``) answered."""
        self.error_answers = 0
        """Of those, the answers with an error flag set."""

    # --- schedule -------------------------------------------------------------------

    def events(self) -> Iterator[Event]:
        """Samples, time references (on whole GPS ms) and pulse events, after the latency."""
        streams = [self._samples(), self._references()]
        if self.with_events:
            streams.append(self._pulse_events())
        yield from merge(streams)

    def _references(self) -> Iterator[Event]:
        f = self.feed
        for i in np.flatnonzero(f.index % self.utc_every == 0):
            # the next whole millisecond of (wire) GPS time
            t_ref = -(-self.wire.gps_ns(int(f.t_ns[i])) // 1_000_000) * 1_000_000
            t_ref -= self.wire.shift_ns
            yield Event(t_ref + f.latency_ns, self.rank, partial(self._reference, t_ref))

    # --- frames -----------------------------------------------------------------------

    def _frame(self, frame: tuple[int, bytes], t_ns: int) -> None:
        self.send(self._encode(*frame), t_ns)

    def _encode(self, can_id: int, data: bytes) -> bytes:
        if self.framing == "slcan":
            return f"t{can_id:03X}{len(data)}{data.hex().upper()}\r".encode()
        stamp = _unix_seconds(self.wire.unix_ns(self.now_ns))
        if self.framing == "socketcand":
            return f"< frame {can_id:03X} {stamp} {data.hex().upper()} >".encode()
        return f"({stamp}) {CHANNEL} {can_id:03X}#{data.hex().upper()}\n".encode()

    def write(self, packet: bytes) -> None:
        if not self.channel_open:
            self.frames_unsent += 1
            return
        self.frames_sent += 1
        self.link.write(packet)

    def _sample(self, i: int) -> None:
        f = self.feed
        t = int(f.t_ns[i]) + f.latency_ns
        self._frame(sc.encode(sc.ID_EKF_INFO, round(int(f.uptime_ns[i]) / 1000) & 0xFFFFFFFF), t)
        q = vec4(f.quat[i])
        if self.attitude == "quat":
            self._frame(sc.encode_ekf_quat(q), t)
        else:
            self._frame(sc.encode_ekf_euler(*quat_to_euler(q)), t)
        self._frame(sc.encode_ekf_vel_ned(vec3(f.vel_ned[i])), t)

    def _reference(self, t_ref: int) -> None:
        t = t_ref + self.feed.latency_ns
        time_us = round(self.feed.clock.uptime_ns(t_ref) / 1000) & 0xFFFFFFFF
        self._frame(sc.encode(sc.ID_STATUS_01, time_us, 0, UTC_STATUS & 0xFFFF), t)
        self._frame(sc.encode(sc.ID_STATUS_03, self.solution, 0), t)
        self._frame(sc.encode(sc.ID_UTC_0, time_us, gps_tow_ms(self.wire.gps_ns(t_ref))), t)
        year, month, day, hour, minute, second, ns = utc_fields(self.wire.unix_ns(t_ref))
        self._frame(sc.encode_utc_1(year, month, day, hour, minute, second, ns // 1000), t)

    def _event(self, t_pulse_ns: int) -> None:
        time_us = round(self.feed.clock.uptime_ns(t_pulse_ns) / 1000) & 0xFFFFFFFF
        self._frame(sc.encode(sc.ID_EVENT_INFO_A, time_us, 0), t_pulse_ns + self.feed.latency_ns)

    # --- the host side ----------------------------------------------------------------

    def service(self, now_ns: int | None) -> None:
        if self.framing == "socketcand" and isinstance(self.link, TcpServerLink):
            if self.link.peer_ready() and self.link.connections > self._greeted:
                self._greeted = self.link.connections
                self.channel_open = False
                self._rx = b""
                self.link.write(b"< hi >")
        super().service(now_ns)

    def on_bytes(self, data: bytes, now_ns: int | None) -> None:
        self._rx += data
        if self.framing == "slcan":
            *lines, self._rx = self._rx.split(b"\r")
            for line in lines:
                self.link.write(self._slcan_command(line, now_ns))
        elif self.framing == "socketcand":
            while b">" in self._rx:
                cmd, _, self._rx = self._rx.partition(b">")
                self._socketcand_command(cmd.strip(b"< ").decode("ascii", "replace"))

    def _slcan_flags(self, now_ns: int | None) -> int:
        """The Lawicel status flags at scenario time ``now_ns`` (the CAN faults' windows)."""
        since_s = self.injector.since_first_s(now_ns)
        f = self.injector.faults
        if since_s is None:
            return 0
        if f.bus_off_at_s <= since_s < f.bus_off_at_s + f.bus_off_s:
            return SLCAN_FLAGS_BUS_OFF
        if f.can_errors_at_s <= since_s < f.can_errors_at_s + f.can_errors_s:
            return SLCAN_FLAGS_PASSIVE
        return 0

    def _slcan_command(self, line: bytes, now_ns: int | None) -> bytes:
        cmd = line[:1]
        if cmd in (b"O", b"L"):
            self.channel_open = True
        elif cmd == b"C":
            self.channel_open = False
        elif cmd == b"V":
            return SLCAN_VERSION
        elif cmd == b"N":
            return SLCAN_SERIAL
        elif cmd == b"F":
            flags = self._slcan_flags(now_ns)
            self.status_answers += 1
            self.error_answers += flags != 0
            return f"F{flags:02X}\r".encode()
        elif cmd not in (
            b"S",
            b"s",
            b"Z",
            b"M",
            b"m",
            b"X",
            b"W",
            b"Q",
            b"t",
            b"T",
            b"r",
            b"R",
            b"",
        ):
            return b"\a"
        return b"\r"

    def _socketcand_command(self, cmd: str) -> None:
        word = cmd.split(" ", 1)[0]
        if word in ("open", "rawmode"):
            self.link.write(b"< ok >")
            if word == "rawmode":
                self.channel_open = True
                self._settle_until = time.monotonic() + SOCKETCAND_SETTLE_S
        elif word:
            self.link.write(f"< error unsupported command {word} >".encode())

    def ready(self) -> bool:
        if self.framing == "socketcand":
            return (
                self.channel_open
                and self._settle_until is not None
                and time.monotonic() >= self._settle_until
            )
        return self.channel_open

    def connect_hint(self) -> dict[str, Any]:
        where = self.link.describe()
        bus: dict[str, Any] | str | None = where.get("path")
        if self.framing == "slcan":
            bus = {"interface": "slcan", "channel": where["path"]}
        elif self.framing == "socketcand":
            host, port = str(where["listen"]).split(":")
            bus = {"interface": "socketcand", "channel": CHANNEL, "host": host, "port": int(port)}
        return {"framing": self.framing, "connect": bus}

    def stats(self) -> dict[str, Any]:
        return {
            **super().stats(),
            "frames": self.frames_sent,
            "frames_unsent": self.frames_unsent,
            "status_answers": self.status_answers,
            "error_answers": self.error_answers,
        }
