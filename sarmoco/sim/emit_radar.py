"""The simulated radar: VITA 49.2 packets of a run over UDP, TCP or into a ``.vrt`` file.

One signal data packet per pulse (stream ID = channel, GPS timestamp = pulse
transmit time, 4-bit packet count, I/Q int16 or float32 big-endian), sent when
the pulse's receive window has closed; a context packet (bandwidth, RF
reference frequency, sample rate) before the first pulse and then every
``context_period_s``. The bytes are made by the drivers' encoder
(:mod:`sarmoco.drivers.vita49`): the profile has one definition.

int16 payloads need a scale: the raw echo is multiplied by :attr:`RadarEmitter.iq_scale`
(peak magnitude of I or Q at :data:`INT16_PEAK`; for an
:class:`~sarmoco.sim.echostream.EchoStream` its peak's upper bound) and rounded,
saturating at the int16 limits as an ADC would.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.drivers.vita49 import PayloadFormat, encode_context_packet, encode_signal_packet
from sarmoco.errors import ConfigError
from sarmoco.processing.types import ComplexArray, IntArray, RadarParams
from sarmoco.sim.echostream import EchoStream
from sarmoco.sim.emitter import Emitter
from sarmoco.sim.faults import PacketFaults
from sarmoco.sim.pacing import Event
from sarmoco.sim.transports import Link, UdpOutLink

INT16_PEAK = 16384.0
"""Largest |I| or |Q| of the run after scaling to int16 (6 dB below full scale)."""
UDP_MAX_PAYLOAD = 65507
"""Largest UDP datagram on IPv4, bytes."""
OUI_SIM = 0xFFFFFE
"""OUI written in the class ID of simulated packets (any OUI is accepted)."""


def int16_scale(echo: ComplexArray | EchoStream) -> float:
    """Scale that puts the run's largest |I| or |Q| (a stream: its bound) at :data:`INT16_PEAK`."""
    if isinstance(echo, EchoStream):
        peak = echo.peak_iq_bound()
    else:
        peak = float(np.max(np.abs(echo.view(echo.real.dtype)))) if echo.size else 0.0
    return INT16_PEAK / peak if peak > 0 else 1.0


class RadarEmitter(Emitter):
    """Plays the pulses of a run as VITA 49.2 packets.

    Parameters
    ----------
    link : Link
        UDP (one packet per datagram), TCP or file (packets back to back).
    radar : RadarParams
        Waveform and receiver (context packet values, receive window). The context's
        bandwidth is the digitised band: the chirp's (matched), the sample rate (dechirp).
    t_ns : ndarray of int64, shape (P,)
        Pulse transmit times, scenario GPS ns.
    echo : ndarray of complex64, shape (P, S), or EchoStream
        Raw samples (a stream is read in pulse order).
    payload : {"int16", "float32"}
        Wire format of I and Q.
    stream_id : int
        VITA 49 stream ID (receive channel).
    context_period_s : float
        Interval between context packets, s.
    faults, seed, rank
        See :class:`~sarmoco.sim.emitter.Emitter`.
    """

    protocol = "vita49"

    def __init__(
        self,
        link: Link,
        radar: RadarParams,
        t_ns: IntArray,
        echo: ComplexArray | EchoStream,
        *,
        payload: PayloadFormat = "int16",
        stream_id: int = 0,
        context_period_s: float = 1.0,
        faults: PacketFaults | None = None,
        seed: int = 0,
        rank: int = 0,
    ) -> None:
        super().__init__(link, faults, seed, rank)
        if payload not in ("int16", "float32"):
            raise ConfigError(f"radar payload: {payload!r} is not one of 'int16', 'float32'")
        self.radar = radar
        self.t_ns = t_ns
        self.echo = echo
        self.payload: PayloadFormat = payload
        self.stream_id = stream_id
        self.context_period_ns = round(context_period_s * 1e9)
        # the context's Bandwidth is that of the digitised signal (VITA 49.2 CIF0 bit 29):
        # the chirp for a matched receiver, the beat band its I/Q samples hold for dechirp
        self.digitised_band_hz = (
            radar.bandwidth_hz if radar.receive == "matched" else radar.sample_rate_hz
        )
        self.iq_scale = int16_scale(echo) if payload == "int16" else 1.0
        packet_bytes = 32 + 2 * echo.shape[1] * (2 if payload == "int16" else 4)
        if isinstance(link, UdpOutLink) and packet_bytes > UDP_MAX_PAYLOAD:
            raise ConfigError(
                f"radar over UDP: a pulse of {echo.shape[1]} {payload} samples needs "
                f"{packet_bytes} bytes, more than a datagram holds ({UDP_MAX_PAYLOAD}); use TCP"
            )
        self.window_ns = round(
            (radar.range_gate_delay_s + echo.shape[1] / radar.sample_rate_hz) * 1e9
        )
        self.pulses_sent = 0
        self.contexts_sent = 0
        self._wire: np.ndarray | None = None
        """Every pulse's wire samples, rendered before playback (:meth:`pregenerate`)."""

    def events(self) -> Iterator[Event]:
        """A context packet before the first pulse and then periodically; one packet per pulse."""
        next_context = int(self.t_ns[0]) if self.t_ns.size else 0
        for k in range(self.t_ns.size):
            t = int(self.t_ns[k])
            if t >= next_context:
                yield Event(t, self.rank, partial(self._context, t))
                next_context = t + self.context_period_ns
            yield Event(t + self.window_ns, self.rank, partial(self._pulse, k))

    def _context(self, t: int) -> None:
        packet = encode_context_packet(
            self.stream_id,
            self.wire.gps_ns(t),
            self.contexts_sent,
            bandwidth_hz=self.digitised_band_hz,
            rf_reference_hz=self.radar.carrier_hz,
            sample_rate_hz=self.radar.sample_rate_hz,
            oui=OUI_SIM,
        )
        self.contexts_sent += 1
        self.send(packet, t)

    def pregenerate(self, path: Path) -> None:
        """Render every pulse's wire samples into ``path`` (a ``.npy`` file, memory-mapped)
        before playback, so that playing costs a packet's header and a send per pulse: a
        full-rate radar's echoes (an :class:`~sarmoco.sim.echostream.EchoStream` is
        synthesized as it is read) cost far more to make than to send, and a simulator
        that makes them while it plays falls behind the radar's clock."""
        first = self.wire_samples(0)
        rows = np.lib.format.open_memmap(
            path, mode="w+", dtype=first.dtype, shape=(self.t_ns.size, *first.shape)
        )
        for k in range(self.t_ns.size):
            rows[k] = self.wire_samples(k)
        rows.flush()
        self._wire = rows

    def wire_samples(self, k: int) -> np.ndarray:
        """Pulse ``k`` as it goes on the wire (int16-scaled and rounded, or float32)."""
        if self._wire is not None:
            return self._wire[k]
        row = self.echo[k]
        if self.payload == "int16":
            scaled = np.rint(row.view(row.real.dtype) * self.iq_scale)
            return np.clip(scaled, -32768, 32767).astype(np.int16)
        return row.astype(np.complex64)

    def _pulse(self, k: int) -> None:
        t = int(self.t_ns[k])
        packet = encode_signal_packet(
            self.stream_id, self.wire.gps_ns(t), k, self.wire_samples(k), self.payload, oui=OUI_SIM
        )
        self.pulses_sent += 1
        self.send(packet, t + self.window_ns)

    def connect_hint(self) -> dict[str, Any]:
        where = self.link.describe()
        connect = {
            "udp": f"udp://{where.get('to')}",  # the daemon binds this port
            "tcp": f"tcp://{where.get('listen')}",  # the daemon connects here
        }.get(where["link"], where.get("path"))
        return {
            "connect": connect,
            "stream_id": self.stream_id,
            "payload": self.payload,
            "n_samples": int(self.echo.shape[1]),
            "iq_scale": self.iq_scale,
        }

    def stats(self) -> dict[str, Any]:
        return {**super().stats(), "pulses": self.pulses_sent, "contexts": self.contexts_sent}
