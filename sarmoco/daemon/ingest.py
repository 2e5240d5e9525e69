"""Ingest: radar pulses into the echo ring, INS samples into the nav buffer.

The first step of a run's data path, and the only one the readers call (threads in a
live run, a loop in a replay). :class:`RadarIngest` decodes pulses from a source into
the :class:`~sarmoco.daemon.echoring.EchoRing` with running ids, keeps the radar's
clock (the newest pulse time plus the host time since it came), and, for a live
network link, refuses pulses whose time stamp jumped ahead (:data:`TIME_JUMP_S`).
:class:`InsIngest` expresses INS samples in the store's frame, offers them to the
:class:`~sarmoco.daemon.navbuffer.NavBuffer`, and queues them, and the bytes they came
in, for the store. Nothing here waits: a full ring drops pulses (counted), a queue
grows until the recording path takes it.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from typing import Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from sarmoco.daemon.config import Config
from sarmoco.daemon.echoring import Block, EchoRing
from sarmoco.daemon.navbuffer import NavBuffer
from sarmoco.daemon.navframe import StoreFrame
from sarmoco.daemon.status import Counters
from sarmoco.drivers.radar import UDP_BATCH_PACKETS
from sarmoco.drivers.samples import (
    AttitudeSample,
    EchoPackets,
    Sample,
    SampleFormat,
    VelocitySample,
    sample_dtype,
    sample_shape,
)
from sarmoco.processing.types import BoolArray, IntArray
from sarmoco.store import schema
from sarmoco.store.flags import PulseFlag

log = logging.getLogger(__name__)

RING_SECONDS = 4.0
"""Echo ring capacity in seconds of pulses at the nominal PRF."""
READ_BLOCK_PULSES = UDP_BATCH_PACKETS
"""Ring slots reserved per radar read: room for one batch of the UDP driver (batched
receive and decode, and its short gathering pause, need at least
:data:`~sarmoco.drivers.vita49.BATCH_MIN_PACKETS` rows)."""
TIME_JUMP_S = 10.0
"""A pulse stamped further ahead than this of both the INS (its newest sample) and the
radar's own clock (the newest pulse taken plus the host time since it came) is refused as
a time jump, when :class:`RadarIngest` refuses jumps (a live run's network radar link), s."""


class PulseSource(Protocol):
    """What :meth:`RadarIngest.read` reads from: a radar link or file
    (:class:`~sarmoco.drivers.radar.RadarSource`), or a recording's pulses (a replay,
    :class:`~sarmoco.store.reader.StorePulses`)."""

    def read_into(self, out: npt.NDArray[np.generic], timeout_s: float = ...) -> EchoPackets:
        """Write the pulses available within ``timeout_s`` into ``out[0], out[1], ...``."""


def ring_format(cfg: Config) -> SampleFormat:
    """How echoes are held and recorded: int16 I/Q as on the wire, or complex64 for float32."""
    return "int16" if cfg.radar.sample_format == "int16" else "complex64"


class RadarClock:
    """The radar's clock: the newest pulse time stamp plus the host's monotonic time since
    it came (any thread)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._first_ns: int | None = None
        self._latest_ns: int | None = None
        self._latest_mono_ns = 0

    def advance(self, first_ns: int, latest_ns: int) -> None:
        """Pulses stamped ``first_ns`` .. ``latest_ns`` (GPS ns) came now."""
        with self._lock:
            if self._first_ns is None:
                self._first_ns = first_ns
            self._latest_ns = latest_ns
            self._latest_mono_ns = time.monotonic_ns()

    def now_ns(self, live: bool) -> int | None:
        """The radar clock, GPS ns: the newest pulse time, plus (``live``) the host's
        monotonic time elapsed since it arrived; None before the first pulse."""
        with self._lock:
            if self._latest_ns is None:
                return None
            elapsed = time.monotonic_ns() - self._latest_mono_ns if live else 0
            return self._latest_ns + elapsed

    def first_and_latest_ns(self) -> tuple[int | None, int | None]:
        """Times of the first and of the newest pulse read, GPS ns (None before the first)."""
        with self._lock:
            return self._first_ns, self._latest_ns


class RadarIngest:
    """The echo ring of a run and the reads that fill it.

    Parameters
    ----------
    cfg : Config
        Daemon configuration (``radar.prf_hz`` and ``radar.n_samples`` size the ring,
        :data:`RING_SECONDS` of pulses, at least 1024).
    nav : NavBuffer
        The run's navigation: its newest sample is one reference of the time-jump filter
        (:attr:`nav`: a pipeline that adopts the ingest sets its own).
    counters : Counters
        Status counters (``pulses_not_captured``).
    refuse_jumps : bool
        Refuse pulses stamped more than :data:`TIME_JUMP_S` ahead of the INS and of the
        radar clock: a live network link, where the host clock runs with the radar's. Not
        for files and replays, read faster than real time (a pause of the radar would look
        like a jump).
    """

    def __init__(
        self, cfg: Config, nav: NavBuffer, counters: Counters, refuse_jumps: bool = False
    ) -> None:
        fmt = ring_format(cfg)
        capacity = max(1024, math.ceil(RING_SECONDS * cfg.radar.prf_hz))
        self.ring = EchoRing(capacity, cfg.radar.n_samples, fmt)
        self.nav = nav
        """The navigation the time-jump filter compares pulse times with."""
        self._counters = counters
        self._refuse_jumps = refuse_jumps
        self._scratch = np.empty(
            (READ_BLOCK_PULSES, *sample_shape(cfg.radar.n_samples, fmt)), sample_dtype(fmt)
        )
        """Where pulses that find the ring full are decoded, then dropped."""
        self._id_lock = threading.Lock()
        self._next_pulse_id = 0
        self.clock = RadarClock()
        """The radar's clock (the pulses taken)."""
        self.time_jumps = 0
        """Pulses refused as stamped too far ahead (:data:`TIME_JUMP_S`)."""
        self._jump_logged_mono = -math.inf

    def read(
        self,
        source: PulseSource,
        timeout_s: float,
        max_pulses: int | None = None,
        capturing: Callable[[], bool] | None = None,
    ) -> int:
        """Decode the pulses ``source`` has within ``timeout_s`` into the ring; returns the count.

        The one way pulses enter a run: live links, log files and replays of a store alike.

        Pulses are read a block of ring slots at a time (:data:`READ_BLOCK_PULSES`), so
        the driver's batched receive and decode serve many pulses per call. When the
        ring is full the pulses are read into scratch space and dropped (counted by
        the ring, and the next stored pulse flagged), so the socket is always drained.
        ``max_pulses`` stops after that many (a file read at its own pace: a replay, a
        file link of ``run``). With ``refuse_jumps`` a pulse stamped more than
        :data:`TIME_JUMP_S` ahead of the INS and of the radar clock is not taken
        (counted in ``pulses_time_jump``, logged at most once a second): a forged or
        corrupted timestamp must not become the ring's newest time, which would make
        every real pulse after it look late. ``capturing`` (None: always) is asked as each
        read returns: the pulses of a read that returns while it says False are let go,
        counted in ``pulses_not_captured``.
        """
        n, limit = 0, math.inf if max_pulses is None else max_pulses
        while n < limit:
            want = int(min(READ_BLOCK_PULSES, limit - n))
            block = self.ring.reserve_block(want)
            rows = self._scratch[:want] if block is None else block.samples
            packets = source.read_into(rows, timeout_s if n == 0 else 0.0)
            n += len(packets)
            if capturing is not None and not capturing():
                self._counters.inc("pulses_not_captured", len(packets))
                if block is not None:
                    none = np.empty(0, np.int64)
                    self.ring.commit_block(block, none, none, none, none)  # all given back
            elif block is None:
                self.ring.note_dropped(len(packets))
            else:
                self._commit(block, packets)
            if len(packets) < rows.shape[0]:
                break  # the source has nothing more now
        return n

    def now_ns(self, live: bool) -> int | None:
        """The radar clock, GPS ns (:meth:`RadarClock.now_ns`)."""
        return self.clock.now_ns(live)

    def first_and_latest_ns(self) -> tuple[int | None, int | None]:
        """Times of the first and of the newest pulse read, GPS ns (None before the first)."""
        return self.clock.first_and_latest_ns()

    def _commit(self, block: Block, packets: EchoPackets) -> None:
        """Publish the pulses decoded into ``block`` with running ids (gives back the rest)."""
        k = len(packets)
        t_ns = packets.t_gps_ns
        channel = packets.stream_id.astype(np.int32)
        flags = PulseFlag.of_packets(packets)
        if self._refuse_jumps and k:
            keep = self._not_jumped(t_ns)
            if not keep.all():
                k = int(np.count_nonzero(keep))
                block.samples[:k] = block.samples[: len(packets)][keep]
                t_ns, channel, flags = t_ns[keep], channel[keep], flags[keep]
        with self._id_lock:
            first = self._next_pulse_id
            self._next_pulse_id += k
        if k:
            self.clock.advance(int(t_ns[0]), int(t_ns[-1]))
        self.ring.commit_block(block, t_ns, np.arange(first, first + k), channel, flags)

    def _not_jumped(self, t_ns: IntArray) -> BoolArray:
        """Mask of the pulses not stamped more than :data:`TIME_JUMP_S` ahead of the newest
        INS sample and of the radar clock (each pulse taken moves the clock on); counts
        and logs the others."""
        refs = []
        clock_ns = self.clock.now_ns(live=True)
        if clock_ns is not None:
            refs.append(clock_ns)
        span = self.nav.span_ns()
        if span is not None:
            refs.append(span[1])
        keep = np.ones(t_ns.shape, dtype=bool)
        if not refs:
            return keep  # nothing to compare with: the first pulse, no INS yet
        jump_ns, ref = round(TIME_JUMP_S * 1e9), max(refs)
        if (t_ns <= ref + jump_ns).all():
            return keep
        ahead_ns = 0
        for i, t in enumerate(t_ns.tolist()):
            keep[i] = t <= ref + jump_ns
            ahead_ns = ahead_ns or (0 if keep[i] else t - ref)
            ref = max(ref, t) if keep[i] else ref
        refused = int(np.count_nonzero(~keep))
        self.time_jumps += refused
        now = time.monotonic()
        if now - self._jump_logged_mono >= 1.0:
            self._jump_logged_mono = now
            log.warning(
                "radar pulse times jumped ahead of the INS and the radar clock: refused",
                extra={"pulses": refused, "ahead_s": ahead_ns * 1e-9, "total": self.time_jumps},
            )
        return keep


class InsIngest:
    """INS samples into the nav buffer, and queued with the bytes they came in for the store.

    Parameters
    ----------
    nav : NavBuffer
        The run's navigation buffer.
    """

    def __init__(self, nav: NavBuffer) -> None:
        self._nav = nav
        self.frame = StoreFrame()
        """The frame of the store's positions."""
        self._rows: queue.SimpleQueue[schema.NavRow] = queue.SimpleQueue()
        self._raw: queue.SimpleQueue[tuple[bytes, int | None]] = queue.SimpleQueue()

    def add(self, samples: list[Sample], rx_ns: int | None) -> None:
        """Offer INS samples to the nav buffer and queue them, with the buffer's answer, for
        the store (velocity samples expressed in :attr:`frame` first).

        Parameters
        ----------
        samples : list of Sample
            Decoded samples; only velocity and attitude samples are taken.
        rx_ns : int or None
            Host receive clock, ns (None: unknown, a replay).
        """
        for s in samples:
            if isinstance(s, VelocitySample):
                s = self.frame.express(s)
            if isinstance(s, VelocitySample | AttitudeSample):
                result = self._nav.push_sample(s, rx_ns)
                self._rows.put((s, rx_ns, result))

    def add_raw(self, data: bytes, rx_ns: int | None) -> None:
        """Queue bytes received from the INS link (as its driver keeps them) for the store.

        Parameters
        ----------
        data : bytes
            :meth:`~sarmoco.drivers.source.Source.take_raw` of the INS source (nothing
            is queued when empty).
        rx_ns : int or None
            Host receive clock, ns (None: unknown, a replay).
        """
        if data:
            self._raw.put((data, rx_ns))

    def take_rows(self) -> list[schema.NavRow]:
        """The samples queued since the last call, oldest first."""
        return _drain(self._rows)

    def take_raw(self) -> list[tuple[bytes, int | None]]:
        """The byte chunks (with their host receive clock, ns) queued since the last call."""
        return _drain(self._raw)


_T = TypeVar("_T")


def _drain(q: queue.SimpleQueue[_T]) -> list[_T]:
    """Everything queued now, oldest first."""
    items: list[_T] = []
    while True:
        try:
            items.append(q.get_nowait())
        except queue.Empty:
            return items
