"""The simulated array radar: one VITA 49.2 stream per Tx/Rx pair.

Each pulse goes out as one signal data packet per channel, stream ID = channel
``c = m * n_rx + n`` (tx-major, :mod:`sarmoco.processing.array.geometry`), all stamped
with the pulse's transmit time and its running number; context packets as for a
single channel (:class:`~sarmoco.sim.emit_radar.RadarEmitter`, on stream 0). int16
payloads share one scale over every channel, so the channels keep their relative
amplitudes and phases.
"""

from __future__ import annotations

from typing import Any

from sarmoco.drivers.vita49 import PayloadFormat, encode_signal_packet
from sarmoco.processing.types import ComplexArray, IntArray, RadarParams
from sarmoco.sim.emit_radar import OUI_SIM, RadarEmitter
from sarmoco.sim.transports import Link


class ArrayRadarEmitter(RadarEmitter):
    """Plays the pulses of an array run, every channel of a pulse together.

    Parameters
    ----------
    link : Link
        UDP, TCP or file.
    radar : RadarParams
        Waveform and receiver shared by the channels.
    t_ns : ndarray of int64, shape (P,)
        Pulse transmit times, scenario GPS ns.
    echo : ndarray of complex64, shape (P, C, S)
        Raw samples [pulse, channel, fast time].
    payload : {"int16", "float32"}
        Wire format of I and Q.
    **options
        ``faults``, ``seed``, ``rank``, ``context_period_s`` of :class:`RadarEmitter`.
    """

    def __init__(
        self,
        link: Link,
        radar: RadarParams,
        t_ns: IntArray,
        echo: ComplexArray,
        *,
        payload: PayloadFormat = "int16",
        **options: Any,
    ) -> None:
        n_p, self.n_channels, n_s = echo.shape
        super().__init__(
            link, radar, t_ns, echo.reshape(n_p * self.n_channels, n_s), payload=payload, **options
        )
        self.packets_sent = 0

    def _pulse(self, k: int) -> None:
        t = int(self.t_ns[k])
        gps = self.wire.gps_ns(t)
        for c in range(self.n_channels):
            row = self.wire_samples(k * self.n_channels + c)
            packet = encode_signal_packet(c, gps, k, row, self.payload, oui=OUI_SIM)
            self.packets_sent += 1
            self.send(packet, t + self.window_ns)
        self.pulses_sent += 1

    def connect_hint(self) -> dict[str, Any]:
        return {**super().connect_hint(), "channels": self.n_channels}

    def stats(self) -> dict[str, Any]:
        return {**super().stats(), "packets": self.packets_sent}
