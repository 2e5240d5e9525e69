"""Array mode ingest: the packets of every Tx/Rx pair into whole pulses in an echo ring.

An array radar sends each pulse as one VITA 49.2 packet per Tx/Rx pair. The reader (a
thread in a live run, a loop in a replay) decodes them, groups them by transmit time
(:class:`~sarmoco.daemon.channelgroup.ChannelGrouper`) and commits each whole pulse to an
:class:`~sarmoco.daemon.echoring.EchoRing` as one row of ``channels x samples``, where the
recording path (:meth:`sarmoco.daemon.array_pipeline.ArrayPipeline.record`) takes it.
Nothing here waits: a full ring drops pulses (counted by the ring).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from sarmoco.daemon.channelgroup import ChannelGrouper
from sarmoco.daemon.config import Config, array_stream_ids
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.ingest import PulseSource, RadarClock, ring_format
from sarmoco.daemon.status import Counters
from sarmoco.drivers.samples import sample_dtype, sample_shape

READ_PACKETS = 1024
"""Packets decoded per radar read."""
RING_PULSES = 256
"""Whole pulses the ring holds between the reader and the recording path."""


class ArrayIngest:
    """The echo ring of an array run and the reads that fill it with whole pulses.

    Parameters
    ----------
    cfg : Config
        ``radar.mode = "array"`` configuration.
    counters : Counters
        Status counters (``pulses_not_captured``).
    stream_ids : sequence of int, optional
        The stream ID (or recorded channel) of each Tx/Rx pair, in pair order; default
        ``array.stream_ids`` (a store's pulses are recorded by pair index: ``range``).
    """

    def __init__(
        self, cfg: Config, counters: Counters, stream_ids: Sequence[int] | None = None
    ) -> None:
        fmt = ring_format(cfg)
        n_c, n_s = cfg.radar.channels, cfg.radar.n_samples
        self.row = sample_shape(n_s, fmt)
        """Shape of one channel's samples."""
        ids = array_stream_ids(cfg) if stream_ids is None else stream_ids
        self.grouper = ChannelGrouper(ids, self.row, sample_dtype(fmt))
        self.ring = EchoRing(RING_PULSES, n_c * n_s, fmt)
        self.clock = RadarClock()
        """The radar's clock (the whole pulses taken)."""
        self._counters = counters
        self._scratch = np.empty((READ_PACKETS, *self.row), sample_dtype(fmt))
        self._next_id = 0

    def read(
        self,
        source: PulseSource,
        timeout_s: float,
        max_pulses: int | None = None,
        capturing: Callable[[], bool] | None = None,
    ) -> int:
        """Decode the packets ``source`` has within ``timeout_s`` and commit the pulses they
        complete to the ring; returns the packets read (0: nothing now, or a file's end).

        ``max_pulses`` reads no more packets than that (so no more pulses complete: a file
        read at its own pace). ``capturing`` (None: always) is asked when pulses complete:
        while it says False they are let go, counted in ``pulses_not_captured``.
        """
        n = READ_PACKETS if max_pulses is None else min(READ_PACKETS, max_pulses)
        packets = source.read_into(self._scratch[:n], timeout_s)
        pulses = self.grouper.add(self._scratch, packets)
        if not pulses:
            return len(packets)
        if capturing is not None and not capturing():
            self._counters.inc("pulses_not_captured", len(pulses))
            return len(packets)
        for pulse in pulses:
            slot = self.ring.reserve()
            if slot is None:  # the recording path is RING_PULSES behind
                self.ring.note_dropped(1)
                continue
            slot.samples[...] = pulse.samples.reshape(slot.samples.shape)
            self.ring.commit(slot, pulse.t_ns, self._next_id, 0, pulse.flags)
            self._next_id += 1
        self.clock.advance(pulses[0].t_ns, pulses[-1].t_ns)
        return len(packets)

    def now_ns(self, live: bool) -> int | None:
        """The radar clock, GPS ns (:meth:`~sarmoco.daemon.ingest.RadarClock.now_ns`)."""
        return self.clock.now_ns(live)

    def first_and_latest_ns(self) -> tuple[int | None, int | None]:
        """Times of the first and of the newest whole pulse, GPS ns (None before the first)."""
        return self.clock.first_and_latest_ns()
