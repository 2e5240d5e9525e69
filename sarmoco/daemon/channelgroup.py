"""Group the per-channel packets of an array radar into pulses [channel, sample] by time.

An array radar sends each pulse as one VITA 49.2 packet per Tx/Rx pair (each pair, a
channel, on its own stream ID: ``array.stream_ids``), all stamped with the pulse's
transmit time. :class:`ChannelGrouper` collects
them and hands out a pulse once every channel has arrived. A pulse still missing
channels when :data:`MAX_OPEN_PULSES` newer pulses have started is dropped and counted
(``incomplete``); a packet whose stream ID is not a channel of the array is counted
(``foreign``, its ID kept in ``foreign_ids``) and skipped, a second packet of a channel
already held counted (``duplicates``) and skipped.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sarmoco.drivers.samples import EchoPackets
from sarmoco.store.flags import PulseFlag

MAX_OPEN_PULSES = 8
"""Pulses being assembled at once: the oldest is dropped when a newer one would exceed it."""


@dataclass(frozen=True)
class GroupedPulse:
    """Every channel of one pulse.

    Attributes
    ----------
    t_ns : int
        Transmit time, GPS ns.
    samples : ndarray
        ``(C, S)`` complex64 or ``(C, S, 2)`` int16, channel ``c`` in row ``c``.
    flags : int
        :class:`~sarmoco.store.flags.PulseFlag` bits of every channel's packet OR-ed.
    """

    t_ns: int
    samples: npt.NDArray[np.generic]
    flags: int


class ChannelGrouper:
    """Assembles pulses of ``n_channels`` packets (module docstring).

    Parameters
    ----------
    stream_ids : sequence of int
        VITA stream ID of each channel: channel ``c`` arrives on ``stream_ids[c]``.
    row_shape : tuple of int
        Shape of one packet's samples: ``(S,)`` or ``(S, 2)``.
    dtype : numpy dtype
        Sample type (complex64 or int16).
    """

    def __init__(
        self, stream_ids: Sequence[int], row_shape: tuple[int, ...], dtype: npt.DTypeLike
    ) -> None:
        self.channel_of = {sid: c for c, sid in enumerate(stream_ids)}
        """Channel index of each stream ID."""
        self.n_channels = len(stream_ids)
        self.row_shape = row_shape
        self.dtype = np.dtype(dtype)
        self._open: dict[int, tuple[npt.NDArray[np.generic], npt.NDArray[np.bool_], int]] = {}
        self.incomplete = 0
        self.foreign = 0
        self.foreign_ids: set[int] = set()
        """Stream IDs of the packets counted in ``foreign``."""
        self.duplicates = 0

    def add(self, rows: npt.NDArray[np.generic], packets: EchoPackets) -> list[GroupedPulse]:
        """Take decoded packets (``rows[i]`` holds ``packets[i]``'s samples).

        Returns
        -------
        list of GroupedPulse
            The pulses completed by these packets, oldest first.
        """
        done: list[GroupedPulse] = []
        packet_flags = PulseFlag.of_packets(packets).tolist()
        for row, packet, packet_flag in zip(rows, packets, packet_flags, strict=False):
            c = self.channel_of.get(packet.stream_id)
            if c is None:
                self.foreign += 1
                self.foreign_ids.add(packet.stream_id)
                continue
            t = packet.t_gps_ns
            if t not in self._open:
                self._start(t)
            samples, seen, flags = self._open[t]
            if seen[c]:
                self.duplicates += 1
                continue
            samples[c] = row
            seen[c] = True
            flags |= packet_flag
            if seen.all():
                del self._open[t]
                done.append(GroupedPulse(t, samples, flags))
            else:
                self._open[t] = (samples, seen, flags)
        done.sort(key=lambda p: p.t_ns)
        return done

    def _start(self, t_ns: int) -> None:
        if len(self._open) >= MAX_OPEN_PULSES:
            del self._open[min(self._open)]
            self.incomplete += 1
        self._open[t_ns] = (
            np.zeros((self.n_channels, *self.row_shape), self.dtype),
            np.zeros(self.n_channels, dtype=bool),
            0,
        )

    def flush(self) -> int:
        """Drop the pulses still missing channels (end of a run); returns how many."""
        n = len(self._open)
        self.incomplete += n
        self._open.clear()
        return n
