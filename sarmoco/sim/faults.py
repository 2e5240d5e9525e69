"""Fault injection for the simulated links: what goes wrong on the wire and in the INS.

Switches (``sarmoco sim --fault SPEC``, repeatable):

================================  ===========================================================
``loss=P[@LINK]``                 drop each packet (datagram, frame, CAN frame) with probability P
``corrupt=P[@LINK]``              flip one random bit of each packet with probability P
``dup=P[@LINK]``                  send each packet twice with probability P
``reorder=P[@LINK]``              hold a packet back and send it after the next one, probability P
``burst=EVERY:LENGTH[@LINK]``     lose every packet sent during LENGTH s at the end of each EVERY s
                                  (from the link's first packet): bursts of loss
``ins-dropout=START:DURATION``    the INS sends nothing for DURATION s from START s after the
                                  first pulse (repeatable)
``clock-offset=S``                INS device clock offset against GPS, s (its time messages
                                  stay honest: a correct driver recovers GPS time)
``clock-drift=PPM``               INS device clock rate error, ppm (time messages honest)
``clock-step=AT:STEP``            the INS device clock jumps by STEP s at AT s after the first
                                  pulse (repeatable; time messages follow the new clock; a
                                  step back to near zero is an autopilot reboot)
``ins-late=S``                    every INS message leaves S s after its sample time (on top
                                  of the INS's own output latency): the INS lags the radar
``serial-garbage=AT:DURATION``    the INS line carries random bytes instead of its frames for
                                  DURATION s from AT s after its first packet
``serial-baud=AT:DURATION:RATIO`` the INS frames of that window are read at RATIO x the
                                  sender's baud rate (:func:`~sarmoco.sim.uart.misread`)
``can-errors=AT:DURATION``        the slcan adapter reports its CAN bus error passive (status
                                  flags 0x24) for DURATION s from AT s after the INS link's first
                                  packet; frames still pass
``can-bus-off=AT:DURATION``       the slcan adapter's CAN bus is off (status flags 0xA4) for
                                  DURATION s from AT s after the INS link's first packet: every
                                  CAN frame of that window is lost
``mavlink-rogue=SYSID``           a second MAVLink system SYSID (a companion computer by its
                                  HEARTBEAT) on the INS link sends the same messages with its
                                  own boot clock (7 ms ahead) and values (velocity 5 m/s more
                                  north, heading 90 deg off), random bytes and frames with a
                                  broken CRC; it speaks first, from before playback starts
================================  ===========================================================

``LINK`` is ``radar`` or ``ins``; without it the packet fault applies to both.
A "packet" is the unit the protocol frames: a VITA 49 packet, a MAVLink
message, an sbgECom frame, one CAN frame (slcan line, socketcand frame, log
line). VITA 49 has no checksum: a bit flip in the payload is silent, one in the
header is rejected by the decoder. Every injected fault is counted
(:class:`FaultCounts`) and written to ``truth.json``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from sarmoco.errors import ConfigError
from sarmoco.processing.types import IntArray
from sarmoco.sim.uart import misread

LINKS = ("radar", "ins")


@dataclass(frozen=True)
class PacketFaults:
    """Per-packet fault probabilities of one link (each in [0, 1])."""

    loss: float = 0.0
    corrupt: float = 0.0
    dup: float = 0.0
    reorder: float = 0.0
    burst_every_s: float = 0.0
    """Period of the loss bursts, s (0: none)."""
    burst_s: float = 0.0
    """Length of each loss burst, s."""
    garbage_at_s: float = 0.0
    """Start of the window of random bytes, s after the link's first packet."""
    garbage_s: float = 0.0
    """Length of the window of random bytes, s (0: none)."""
    baud_at_s: float = 0.0
    """Start of the window read at the wrong baud rate, s after the link's first packet."""
    baud_s: float = 0.0
    """Length of the window read at the wrong baud rate, s (0: none)."""
    baud_ratio: float = 0.0
    """Receiver over sender baud rate in that window."""
    can_errors_at_s: float = 0.0
    """Start of the CAN error-passive window, s after the link's first packet."""
    can_errors_s: float = 0.0
    """Length of the CAN error-passive window, s (0: none)."""
    bus_off_at_s: float = 0.0
    """Start of the CAN bus-off, s after the link's first packet."""
    bus_off_s: float = 0.0
    """Length of the CAN bus-off, s (0: none); its frames are lost."""

    def in_burst(self, since_first_ns: int) -> bool:
        """Whether a packet sent ``since_first_ns`` after the link's first one falls in a
        loss burst (the last ``burst_s`` of each ``burst_every_s``)."""
        if not self.burst_every_s > 0:
            return False
        every_ns = round(self.burst_every_s * 1e9)
        return since_first_ns % every_ns >= every_ns - round(self.burst_s * 1e9)

    @property
    def any(self) -> bool:
        """Whether any fault is switched on."""
        return any(getattr(self, f.name) > 0 for f in fields(self))  # per packet: no copy


@dataclass(frozen=True)
class Faults:
    """Every fault of a simulated run.

    Attributes
    ----------
    radar, ins : PacketFaults
        Packet faults of the radar link and of the INS link(s).
    ins_dropouts_s : tuple of (start_s, duration_s)
        INS silences, s after the first pulse.
    clock_offset_s : float
        INS device clock offset, s.
    clock_drift_ppm : float
        INS device clock rate error, ppm.
    clock_steps_s : tuple of (at_s, step_s)
        INS device clock steps: at ``at_s`` after the first pulse the clock jumps by ``step_s``.
    ins_late_s : float
        Extra delay of every INS message after its sample time, s.
    mavlink_rogue_system : int
        System id of a second MAVLink system on the INS link (0: none).
    """

    radar: PacketFaults = PacketFaults()
    ins: PacketFaults = PacketFaults()
    ins_dropouts_s: tuple[tuple[float, float], ...] = ()
    clock_offset_s: float = 0.0
    clock_drift_ppm: float = 0.0
    clock_steps_s: tuple[tuple[float, float], ...] = ()
    ins_late_s: float = 0.0
    mavlink_rogue_system: int = 0

    def to_dict(self) -> dict[str, object]:
        """JSON-able form (for truth.json)."""
        d = asdict(self)
        d["ins_dropouts_s"] = [list(x) for x in self.ins_dropouts_s]
        d["clock_steps_s"] = [list(x) for x in self.clock_steps_s]
        return d


_PACKET_KEYS = {"loss": "loss", "corrupt": "corrupt", "dup": "dup", "reorder": "reorder"}


def _number(spec: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ConfigError(f"--fault {spec!r}: {text!r} is not a number") from None


def _pair(spec: str, text: str) -> tuple[float, float]:
    parts = text.split(":")
    if len(parts) != 2:
        raise ConfigError(f"--fault {spec!r}: want two numbers as A:B, got {text!r}")
    return _number(spec, parts[0]), _number(spec, parts[1])


def parse_faults(specs: list[str] | None) -> Faults:
    """Build :class:`Faults` from ``--fault`` strings (module docstring gives the syntax)."""
    faults = Faults()
    for spec in specs or []:
        key, sep, value = spec.partition("=")
        if not sep:
            raise ConfigError(f"--fault {spec!r}: want KEY=VALUE")
        if key in _PACKET_KEYS:
            text, _, link = value.partition("@")
            p = _number(spec, text)
            if not 0.0 <= p <= 1.0:
                raise ConfigError(f"--fault {spec!r}: probability {p} is not in [0, 1]")
            if link and link not in LINKS:
                raise ConfigError(f"--fault {spec!r}: link {link!r} is not one of {LINKS}")
            if link in ("", "radar"):
                faults = replace(faults, radar=replace(faults.radar, **{_PACKET_KEYS[key]: p}))
            if link in ("", "ins"):
                faults = replace(faults, ins=replace(faults.ins, **{_PACKET_KEYS[key]: p}))
        elif key == "burst":
            text, _, link = value.partition("@")
            every, length = _pair(spec, text)
            if not 0 < length < every:
                raise ConfigError(f"--fault {spec!r}: want 0 < LENGTH < EVERY, got {text!r}")
            if link and link not in LINKS:
                raise ConfigError(f"--fault {spec!r}: link {link!r} is not one of {LINKS}")
            burst = {"burst_every_s": every, "burst_s": length}
            if link in ("", "radar"):
                faults = replace(faults, radar=replace(faults.radar, **burst))
            if link in ("", "ins"):
                faults = replace(faults, ins=replace(faults.ins, **burst))
        elif key == "ins-dropout":
            start, duration = _pair(spec, value)
            if not duration > 0:
                raise ConfigError(f"--fault {spec!r}: duration {duration} is not > 0")
            faults = replace(faults, ins_dropouts_s=(*faults.ins_dropouts_s, (start, duration)))
        elif key == "clock-offset":
            faults = replace(faults, clock_offset_s=_number(spec, value))
        elif key == "clock-drift":
            faults = replace(faults, clock_drift_ppm=_number(spec, value))
        elif key == "clock-step":
            faults = replace(faults, clock_steps_s=(*faults.clock_steps_s, _pair(spec, value)))
        elif key == "ins-late":
            late = _number(spec, value)
            if not late >= 0:
                raise ConfigError(f"--fault {spec!r}: delay {late} is not >= 0")
            faults = replace(faults, ins_late_s=late)
        elif key == "serial-garbage":
            at, duration = _pair(spec, value)
            faults = replace(faults, ins=replace(faults.ins, garbage_at_s=at, garbage_s=duration))
        elif key == "serial-baud":
            at_duration, _, ratio_text = value.rpartition(":")
            at, duration = _pair(spec, at_duration)
            ratio = _number(spec, ratio_text)
            if not ratio > 0:
                raise ConfigError(f"--fault {spec!r}: baud ratio {ratio} is not > 0")
            baud = {"baud_at_s": at, "baud_s": duration, "baud_ratio": ratio}
            faults = replace(faults, ins=replace(faults.ins, **baud))
        elif key in ("can-errors", "can-bus-off"):
            at, duration = _pair(spec, value)
            if not duration > 0:
                raise ConfigError(f"--fault {spec!r}: duration {duration} is not > 0")
            field_ = "can_errors" if key == "can-errors" else "bus_off"
            window = {f"{field_}_at_s": at, f"{field_}_s": duration}
            faults = replace(faults, ins=replace(faults.ins, **window))
        elif key == "mavlink-rogue":
            sysid = _number(spec, value)
            if sysid not in range(1, 256):
                raise ConfigError(f"--fault {spec!r}: system id {value!r} is not 1..255")
            faults = replace(faults, mavlink_rogue_system=int(sysid))
        else:
            known = ", ".join([*_PACKET_KEYS, "burst", "ins-dropout", "clock-offset",
                               "clock-drift", "clock-step", "ins-late", "serial-garbage",
                               "serial-baud", "can-errors", "can-bus-off"])  # fmt: skip
            raise ConfigError(
                f"--fault {spec!r}: unknown fault {key!r} (known: {known}, mavlink-rogue)"
            )
    return faults


def dropout_keep(
    t_ns: IntArray, t0_ns: int, dropouts_s: tuple[tuple[float, float], ...]
) -> np.ndarray:
    """Mask of the INS samples that survive the dropouts (True = sent).

    Parameters
    ----------
    t_ns : ndarray of int64
        Sample times, GPS ns.
    t0_ns : int
        GPS time of the first pulse, ns (dropouts are relative to it).
    dropouts_s : tuple of (start_s, duration_s)
        Silences; a sample at ``start <= t - t0 < start + duration`` is not sent.
    """
    keep = np.ones(t_ns.shape, dtype=bool)
    for start_s, duration_s in dropouts_s:
        a = t0_ns + round(start_s * 1e9)
        b = a + round(duration_s * 1e9)
        keep &= ~((t_ns >= a) & (t_ns < b))
    return keep


@dataclass
class FaultCounts:
    """Faults injected on one link (packets as the protocol frames them)."""

    packets: int = 0
    """Packets offered to the link."""
    lost: int = 0
    """Packets lost, at random or in bursts."""
    burst_lost: int = 0
    """Of those, the packets lost in bursts."""
    corrupted: int = 0
    duplicated: int = 0
    reordered: int = 0
    garbled: int = 0
    """Packets replaced by random bytes or read at the wrong baud rate."""
    bus_off_lost: int = 0
    """CAN frames lost while the adapter's bus was off."""


@dataclass
class PacketFaultInjector:
    """Applies :class:`PacketFaults` to each packet as it is sent.

    Parameters
    ----------
    faults : PacketFaults
        Probabilities.
    seed : int
        Seed of this link's random stream (a run with the same seed injects the
        same faults into the same packets).

    Notes
    -----
    Each offered packet draws the same four uniforms whatever the outcome, so
    which packets are hit does not depend on the outcome of earlier draws.
    A packet in a loss burst (by its send time) is lost whatever it drew.
    A lost packet is neither corrupted, duplicated nor reordered; a reordered
    packet is held and sent right after the next packet that is sent (or at
    :meth:`flush`).
    """

    faults: PacketFaults
    seed: int
    counts: FaultCounts = field(default_factory=FaultCounts)

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._held: bytes | None = None
        self._first_ns: int | None = None

    def send(self, data: bytes, write: Callable[[bytes], None], t_ns: int | None = None) -> None:
        """Offer one packet; ``write`` is called for each copy that goes on the wire.

        ``t_ns``: its send time (scenario ns), which places it in or out of a loss burst
        (None: never in one).
        """
        f = self.faults
        self.counts.packets += 1
        if not f.any:
            write(data)
            return
        u_loss, u_corrupt, u_dup, u_reorder = self._rng.random(4)
        where = int(self._rng.integers(0, 8 * len(data))) if data else 0
        if t_ns is not None:
            self._first_ns = t_ns if self._first_ns is None else self._first_ns
            if f.in_burst(t_ns - self._first_ns):
                self.counts.lost += 1
                self.counts.burst_lost += 1
                return
            since_s = (t_ns - self._first_ns) * 1e-9
            if f.garbage_at_s <= since_s < f.garbage_at_s + f.garbage_s:
                self.counts.garbled += 1
                write(self._rng.integers(0, 256, len(data), dtype=np.uint8).tobytes())
                return
            if f.baud_at_s <= since_s < f.baud_at_s + f.baud_s:
                self.counts.garbled += 1
                write(misread(data, f.baud_ratio))
                return
            if f.bus_off_at_s <= since_s < f.bus_off_at_s + f.bus_off_s:
                self.counts.bus_off_lost += 1
                return
        if u_loss < f.loss:
            self.counts.lost += 1
            return
        if u_corrupt < f.corrupt and data:
            buf = bytearray(data)
            buf[where // 8] ^= 1 << (where % 8)
            data = bytes(buf)
            self.counts.corrupted += 1
        copies = 2 if u_dup < f.dup else 1
        self.counts.duplicated += copies - 1
        if u_reorder < f.reorder and self._held is None:
            self._held = data
            self.counts.reordered += 1
            if copies == 2:
                write(data)
            return
        for _ in range(copies):
            write(data)
        self.flush(write)

    def since_first_s(self, t_ns: int | None) -> float | None:
        """Time from the link's first packet to scenario time ``t_ns``, s (None before the
        first packet or without a time)."""
        if t_ns is None or self._first_ns is None:
            return None
        return (t_ns - self._first_ns) * 1e-9

    def flush(self, write: Callable[[bytes], None]) -> None:
        """Send a packet still held back for reordering."""
        if self._held is not None:
            held, self._held = self._held, None
            write(held)
