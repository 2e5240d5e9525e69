"""The daemon's data path, in two parts that do not wait for each other.

Recording (ingest): readers → echo ring → store, and the INS log. Readers (threads in
a live run, a loop in a replay) call :meth:`Pipeline.read_radar` and
:meth:`Pipeline.add_nav`; :meth:`Pipeline.record` takes the pulses out of the ring as
they come, stores them (raw echoes, time, flags), and puts them in the focus backlog
(:class:`~sarmoco.daemon.backlog.FocusBacklog`); it also stores the INS samples and
bytes received. Nothing on this path waits for focusing: a pulse that arrives is
stored.

Focusing: focus backlog → aligner (with the nav buffer) → focuser → recorder (motion,
autofocus estimates, tiles, the navigation flags of the pulses). :meth:`Pipeline.focus`
runs it with the current GPS time. It may lag; when it falls
:data:`FOCUS_BACKLOG_S` behind, it skips ahead to the newest pulses (counted in
``pulses_focus_skipped``). The nav buffer holds the navigation of every pulse the
focuser has not reached (:meth:`~sarmoco.daemon.navbuffer.NavBuffer.hold`), so a lag
never leaves a pulse without navigation.

A live run calls the two from threads of their own (and the readers from theirs);
:meth:`Pipeline.process` runs one after the other (a replay, tests), and
:meth:`Pipeline.finish` records and focuses what is left at the end. The ring, the
nav buffer and the backlog are the thread-safe hand-over points, and none of them
blocks a reader; the recorder takes calls from both parts.

The "current time" of the aligner is the radar's own clock: the newest pulse
time stamp plus the host's monotonic time elapsed since it arrived (live), or
the newest pulse time alone (replay, a virtual clock). Pulses therefore wait
for the INS by radar time, whatever the epoch of the radar and however the
host clock is set.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from typing import Any, Protocol, TypeVar

import numpy as np
import numpy.typing as npt

from sarmoco.daemon.aligner import AlignedBlock, Aligner, PulseQueue
from sarmoco.daemon.backlog import FocusBacklog, RecordedBatch
from sarmoco.daemon.config import Config
from sarmoco.daemon.echoring import Block, EchoRing
from sarmoco.daemon.focuser import Focuser, FocusOutput, SinkFactory, nan_motion
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
from sarmoco.processing.imaging.tiles import Tile
from sarmoco.processing.metrics import image_contrast, image_entropy
from sarmoco.processing.mocomp import MocompSolution
from sarmoco.processing.types import BoolArray, ComplexArray, FloatArray, IntArray
from sarmoco.store import schema
from sarmoco.store.flags import NAV_FLAGS, NAV_UNUSABLE, UNFOCUSABLE, PulseFlag
from sarmoco.store.recorder import Recorder

log = logging.getLogger(__name__)

RING_SECONDS = 4.0
"""Echo ring capacity in seconds of pulses at the nominal PRF."""
FOCUS_BACKLOG_S = 2.0
"""Most the focusing path lags behind the recording, in seconds of pulses at the nominal
PRF (at least two processing blocks): further behind, it skips ahead to the newest."""
REORDER_HOLD_S = 0.1
"""A live pulse is recorded once the radar clock is this far past it, s: a datagram
late by less still finds its place among the pulses waiting in the echo ring."""
RECORD_BLOCK_PULSES = 1024
"""Most pulses stored by one write of :meth:`Pipeline.record`."""
INS_RECORD_S = 0.25
"""Queued INS samples and raw INS bytes go to the store at most this often (host clock):
each write costs milliseconds, s."""
READ_BLOCK_PULSES = UDP_BATCH_PACKETS
"""Ring slots reserved per radar read: room for one batch of the UDP driver (batched
receive and decode, and its short gathering pause, need at least
:data:`~sarmoco.drivers.vita49.BATCH_MIN_PACKETS` rows)."""
TIME_JUMP_S = 10.0
"""A pulse stamped further ahead than this of both the INS (its newest sample) and the
radar's own clock (the newest pulse taken plus the host time since it came) is refused as
a time jump, when :class:`Pipeline` refuses jumps (a live run's network radar link), s."""


class PulseSource(Protocol):
    """What :meth:`Pipeline.read_radar` reads from: a radar link or file
    (:class:`~sarmoco.drivers.radar.RadarSource`), or a recording's pulses (a replay,
    :class:`~sarmoco.store.reader.StorePulses`)."""

    def read_into(self, out: npt.NDArray[np.generic], timeout_s: float = ...) -> EchoPackets:
        """Write the pulses available within ``timeout_s`` into ``out[0], out[1], ...``."""


def ring_format(cfg: Config) -> SampleFormat:
    """How echoes are held and recorded: int16 I/Q as on the wire, or complex64 for float32."""
    return "int16" if cfg.radar.sample_format == "int16" else "complex64"


def nav_alignment(cfg: Config, ring: PulseQueue, max_block: int) -> tuple[NavBuffer, Aligner]:
    """A run's navigation buffer and the aligner that joins it to the pulses of ``ring``,
    both configured from ``ins.*`` (clock-step tolerance, gap, bridged silence, latency
    budget, lever arm), releasing at most ``max_block`` pulses at a time. One place for
    both the single-channel and the array pipeline."""
    nav = NavBuffer(clock_tolerance_ns=round(cfg.ins.clock_step_tolerance_s * 1e9))
    aligner = Aligner(
        ring,
        nav,
        max_gap_ns=round(cfg.ins.max_gap_s * 1e9),
        latency_budget_ns=round(cfg.ins.latency_budget_s * 1e9),
        lever_arm_body_m=cfg.ins.lever_arm_m,
        max_block=max_block,
        bridge_gap_ns=round(cfg.ins.bridge_gap_s * 1e9),
    )
    return nav, aligner


@dataclass
class RunSummary:
    """Totals of a run, for the report and the store's ``metrics`` attribute."""

    pulses_received: int = 0
    pulses_processed: int = 0
    pulses_nav_flagged: int = 0
    pulses_nav_bridged: int = 0
    """Pulses focused with navigation bridged across an INS silence (``NAV_BRIDGED``)."""
    nav_samples: int = 0
    tiles: int = 0
    tile_metrics: list[dict[str, float]] = field(default_factory=list)
    pulses_dropped_ring: int = 0
    pulses_duplicate: int = 0
    pulses_reordered: int = 0
    pulses_late_dropped: int = 0
    pulses_focus_skipped: int = 0
    """Pulses recorded but skipped by live focusing, fallen behind (a replay focuses them)."""
    pulses_out_of_order: int = 0
    """Pulses not newer than one before them, kept from the focuser (the ring sorts pulses
    out already, so this stays 0 unless something upstream breaks)."""
    pulses_unfocused: int = 0
    """Pulses that reached focusing unfit for it (without navigation, or taken under radar
    parameters other than the configured ones): in the motion table without a solution.
    Every pulse recorded is processed, unfocused, skipped or out of time order, one of
    them."""
    doppler_attitude_hz: float = math.nan
    """Doppler centroid of the latest block from the attitude and the antenna mount, Hz."""
    doppler_echo_hz: float = math.nan
    """Doppler centroid of the latest block measured from the echoes, Hz (a wrong mount or
    attitude source shows as a difference from ``doppler_attitude_hz``)."""

    def as_dict(self) -> dict[str, Any]:
        """JSON-able form."""
        return {
            "pulses_received": self.pulses_received,
            "pulses_processed": self.pulses_processed,
            "pulses_nav_flagged": self.pulses_nav_flagged,
            "pulses_nav_bridged": self.pulses_nav_bridged,
            "nav_samples": self.nav_samples,
            "tiles": self.tiles,
            "tile_metrics": self.tile_metrics,
            "pulses_dropped_ring": self.pulses_dropped_ring,
            "pulses_duplicate": self.pulses_duplicate,
            "pulses_reordered": self.pulses_reordered,
            "pulses_late_dropped": self.pulses_late_dropped,
            "pulses_focus_skipped": self.pulses_focus_skipped,
            "pulses_out_of_order": self.pulses_out_of_order,
            "pulses_unfocused": self.pulses_unfocused,
            "doppler_attitude_hz": _finite_or_none(self.doppler_attitude_hz),
            "doppler_echo_hz": _finite_or_none(self.doppler_echo_hz),
        }


def _finite_or_none(value: float) -> float | None:
    """``value``, or None when it is not finite (JSON has no NaN)."""
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class _Pulses:
    """Aligned pulses gathered for one focusing step (rows in time order).

    Attributes
    ----------
    t_ns, pulse_id : ndarray of int64, shape (P,)
        Transmit time (GPS ns) and running number.
    usable : ndarray of bool, shape (P,)
        The pulse is focused (no :data:`~sarmoco.store.flags.UNFOCUSABLE` flag: it has
        navigation and was taken under the configured radar parameters).
    flags : ndarray of uint32, shape (P,)
        :class:`~sarmoco.store.flags.PulseFlag` bits.
    raw : ndarray of complex64, shape (P, S)
        Raw echoes.
    pos_ned, vel_ned : ndarray, shape (P, 3)
        Antenna position (m, relative) and velocity (m/s) at the pulses, NED.
    quat : ndarray, shape (P, 4)
        Attitude at the pulses (body to NED, scalar first).
    row : ndarray of int64, shape (P,)
        Row of each pulse in the store's ``pulses`` table.
    """

    t_ns: IntArray
    pulse_id: IntArray
    usable: BoolArray
    flags: npt.NDArray[np.uint32]
    raw: ComplexArray
    pos_ned: FloatArray
    vel_ned: FloatArray
    quat: FloatArray
    row: IntArray

    @classmethod
    def join(cls, blocks: list[AlignedBlock]) -> _Pulses:
        """The pulses of ``blocks`` (recorded ones), one after the other."""
        flags = np.concatenate([b.echoes.flags for b in blocks])
        t_ns = np.concatenate([b.echoes.t_ns for b in blocks])
        return cls(
            t_ns=t_ns,
            pulse_id=np.concatenate([b.echoes.pulse_id for b in blocks]),
            usable=(flags & UNFOCUSABLE) == 0,
            flags=flags,
            raw=np.concatenate([b.echoes.complex_samples() for b in blocks]),
            pos_ned=np.concatenate([b.nav.pos_ned for b in blocks]),
            vel_ned=np.concatenate([b.nav.vel_ned for b in blocks]),
            quat=np.concatenate([b.nav.quat for b in blocks]),
            row=np.concatenate([_recorded(b).row for b in blocks]),
        )

    @classmethod
    def cat(cls, parts: list[_Pulses]) -> _Pulses:
        """``parts`` one after the other (one part: itself)."""
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))

    def since(self, first: int) -> _Pulses:
        """The pulses from row ``first`` on."""
        return _Pulses(*(getattr(self, f.name)[first:] for f in fields(self)))

    def upto(self, stop: int) -> _Pulses:
        """The pulses before row ``stop``."""
        return _Pulses(*(getattr(self, f.name)[:stop] for f in fields(self)))

    def rows(self, keep: BoolArray) -> _Pulses:
        """The pulses where ``keep`` is True."""
        return _Pulses(*(getattr(self, f.name)[keep] for f in fields(self)))


class Pipeline:
    """One run's buffers, recording, alignment and focusing (see the module doc).

    Parameters
    ----------
    cfg : Config
        Daemon configuration.
    recorder : Recorder
        The run's store (written by both the recording and the focusing part).
    counters : Counters
        Status counters (updated here, served by the status endpoint).
    sink : SinkFactory, optional
        Imaging deferred: the focuser's segments hand their pulses to sinks made by this
        and record no tiles (:class:`~sarmoco.daemon.focuser.Focuser`).
    refuse_jumps : bool
        Refuse pulses stamped more than :data:`TIME_JUMP_S` ahead of the INS and of the
        radar clock (:meth:`read_radar`): a live network link, where the host clock runs
        with the radar's. Not for files and replays, read faster than real time (a pause
        of the radar would look like a jump).
    focus_skips : bool
        Focusing that falls :data:`FOCUS_BACKLOG_S` behind skips ahead (a live network
        link: the radar does not wait). Otherwise :meth:`record` takes no more pulses
        from the ring than the focus backlog has room for (a file or a replay, read at
        the pace of focusing).
    """

    def __init__(
        self,
        cfg: Config,
        recorder: Recorder,
        counters: Counters,
        sink: SinkFactory | None = None,
        refuse_jumps: bool = False,
        focus_skips: bool = False,
    ) -> None:
        self.cfg = cfg
        self.sink = sink
        self.recorder = recorder
        self.counters = counters
        capacity = max(1024, math.ceil(RING_SECONDS * cfg.radar.prf_hz))
        self.ring = EchoRing(capacity, cfg.radar.n_samples, ring_format(cfg))
        block = cfg.imaging.block_pulses
        self.backlog = FocusBacklog(max(math.ceil(FOCUS_BACKLOG_S * cfg.radar.prf_hz), 2 * block))
        self._focus_skips = focus_skips
        self.nav, self.aligner = nav_alignment(cfg, self.backlog, block)
        self.focuser: Focuser | None = None
        self.summary = RunSummary()
        counters.add_source("pipeline", self.totals)
        self._nav_rows: queue.SimpleQueue[schema.NavRow] = queue.SimpleQueue()
        self._geodetic_origin: schema.GeodeticOrigin | None = None
        self.frame = StoreFrame()
        """The frame of the store's positions."""
        self._ins_raw: queue.SimpleQueue[tuple[bytes, int | None]] = queue.SimpleQueue()
        self._ins_recorded_mono = -math.inf
        self._id_lock = threading.Lock()
        self._next_pulse_id = 0
        self._latest_pulse_ns: int | None = None
        self._latest_pulse_mono_ns = 0
        self._first_pulse_ns: int | None = None
        """Time of the first pulse read, GPS ns."""
        self._pending: list[_Pulses] = []
        """Aligned pulses not focused yet, oldest first."""
        self._pending_n = 0
        self._recorded_ns: int | None = None
        """Time of the newest pulse recorded, GPS ns."""
        self._taken_ns: int | None = None
        """Time of the newest pulse the aligner took from the backlog, GPS ns."""
        self._focused_ns: int | None = None
        """Time of the newest pulse given to the focuser, GPS ns."""
        self._refuse_jumps = refuse_jumps
        self.time_jumps = 0
        """Pulses refused as stamped too far ahead (:data:`TIME_JUMP_S`)."""
        self._jump_logged_mono = -math.inf
        self._last_nav: tuple[int, FloatArray, FloatArray] = (0, np.zeros(3), np.eye(4)[0])
        """Time (GPS ns), velocity and attitude of the last pulse with navigation."""
        fmt = ring_format(cfg)
        self._scratch = np.empty(
            (READ_BLOCK_PULSES, *sample_shape(cfg.radar.n_samples, fmt)), sample_dtype(fmt)
        )
        """Where pulses that find the ring full are decoded, then dropped."""

    # -- readers --------------------------------------------------------------------------

    def read_radar(
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
                self.counters.inc("pulses_not_captured", len(packets))
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
                self._latest_pulse_ns = int(t_ns[-1])
                self._latest_pulse_mono_ns = time.monotonic_ns()
                if self._first_pulse_ns is None:
                    self._first_pulse_ns = int(t_ns[0])
        self.ring.commit_block(block, t_ns, np.arange(first, first + k), channel, flags)

    def _not_jumped(self, t_ns: IntArray) -> BoolArray:
        """Mask of the pulses not stamped more than :data:`TIME_JUMP_S` ahead of the newest
        INS sample and of the radar clock (each pulse taken moves the clock on); counts
        and logs the others."""
        refs = []
        with self._id_lock:
            if self._latest_pulse_ns is not None:
                elapsed = time.monotonic_ns() - self._latest_pulse_mono_ns
                refs.append(self._latest_pulse_ns + elapsed)
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

    def add_nav(self, samples: list[Sample], rx_ns: int | None) -> None:
        """Offer INS samples to the nav buffer and queue them for the recorder."""
        for s in samples:
            if isinstance(s, VelocitySample):
                s = self.frame.express(s)
            if isinstance(s, VelocitySample | AttitudeSample):
                result = self.nav.push_sample(s, rx_ns)
                self._nav_rows.put((s, rx_ns, result))

    def add_ins_raw(self, data: bytes, rx_ns: int | None) -> None:
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
            self._ins_raw.put((data, rx_ns))

    # -- processing loop --------------------------------------------------------------------

    def now_ns(self, live: bool) -> int | None:
        """Radar-clock "now" (see the module doc); None before the first pulse."""
        with self._id_lock:
            if self._latest_pulse_ns is None:
                return None
            elapsed = time.monotonic_ns() - self._latest_pulse_mono_ns if live else 0
            return self._latest_pulse_ns + elapsed

    def oldest_unaligned_ns(self) -> tuple[int | None, bool]:
        """Where the pulses still waiting for their navigation begin; any thread.

        Returns
        -------
        oldest_ns : int or None
            GPS ns, a bound from below: the oldest pulse in the focus backlog, else the
            newest recorded (the echo ring's pulses come after it), else the first pulse
            read; None before the first pulse.
        all_aligned : bool
            Every pulse read has been recorded and taken by the aligner.
        """
        waiting = self.backlog.oldest_ns()
        if waiting is not None:
            return waiting, False
        with self._id_lock:
            latest, first = self._latest_pulse_ns, self._first_pulse_ns
        recorded = self._recorded_ns
        if recorded is not None:
            return recorded, recorded == latest
        return first, False

    def process(self, now_ns: int | None, on_block: Callable[[], None] | None = None) -> int:
        """:meth:`record` then :meth:`focus` (one thread does both: a replay, tests);
        returns the pulses released by the aligner."""
        self.record(now_ns)
        return self.focus(now_ns, on_block)

    def record(self, now_ns: int | None = None) -> int:
        """Store the pulses waiting in the echo ring and hand them to focusing; store the
        INS samples and bytes queued (every :data:`INS_RECORD_S`). Returns the pulses stored.

        Parameters
        ----------
        now_ns : int, optional
            The radar clock, GPS ns: pulses within :data:`REORDER_HOLD_S` of it wait (a
            late datagram may still go before them). None: every pulse is taken.
        """
        if time.monotonic() - self._ins_recorded_mono >= INS_RECORD_S:
            self._record_nav()
        hold_ns = None if now_ns is None else now_ns - round(REORDER_HOLD_S * 1e9)
        stored = 0
        while True:
            t = self.ring.peek_times(RECORD_BLOCK_PULSES)
            k = t.size if hold_ns is None else int(np.searchsorted(t, hold_ns, side="right"))
            if not self._focus_skips:
                k = min(k, self.backlog.free)
            if k == 0:
                break
            e = self.ring.pop(k)
            first = self.recorder.pulses.rows
            self.recorder.append_pulses(e.t_ns, e.pulse_id, e.channel, e.flags, e.samples)
            row = np.arange(first, first + k, dtype=np.int64)
            self.backlog.put(RecordedBatch(e.samples, e.t_ns, e.pulse_id, e.channel, e.flags, row))
            self.summary.pulses_received += k
            self._recorded_ns = int(e.t_ns[-1])
            stored += k
            if k < RECORD_BLOCK_PULSES:
                break
        self.counters.set("echo_backlog_pulses", len(self.ring))
        return stored

    def focus(self, now_ns: int | None, on_block: Callable[[], None] | None = None) -> int:
        """Release aligned pulses from the focus backlog, focus them and record their
        products; returns the number of pulses released.

        A pass goes through the pulses waiting when it began (those recorded meanwhile
        wait for the next), so that it ends while recording goes on. ``on_block`` is
        called after each released block (focused, when it completes a processing
        block): a pass takes many blocks, and the caller's watchdog must hear that the
        loop is progressing.
        """
        released, waiting = 0, len(self.backlog)
        while now_ns is not None and released < waiting:
            block = self.aligner.poll(now_ns)
            if block is None:
                break
            released += len(block)
            self._accept(block)
            self._hold_nav()
            self._update_counters()
            if on_block is not None:
                on_block()
        self._hold_nav()
        self._update_counters()
        return released

    def finish(self) -> RunSummary:
        """Record every remaining pulse, focus it, close all tiles, write the run metrics."""
        self._record_nav()
        while True:
            self.record()
            block = self.aligner.flush()
            if block is not None:
                self._accept(block)
            if len(self.ring) == 0:
                break
        while self._pending_n > 0:  # a block at a time: held for the heading window, or the last
            self._focus_pending(min(self._pending_n, self.cfg.imaging.block_pulses))
        if self.focuser is not None:
            self._record(self.focuser.finish())
        r, summary = self.ring, self.summary
        summary.pulses_dropped_ring, summary.pulses_duplicate = r.dropped, r.duplicates
        summary.pulses_nav_bridged = self.aligner.nav_bridged
        summary.pulses_reordered, summary.pulses_late_dropped = r.reordered, r.late_dropped
        summary.pulses_focus_skipped = self.backlog.skipped
        self.recorder.set_metrics(self.summary.as_dict())
        self._update_counters()
        return self.summary

    def _hold_nav(self) -> None:
        """Keep the navigation of the pulses not focused yet: from the oldest waiting in the
        backlog (or, with none waiting, the last one taken) less the aligner's reach."""
        waiting = self.backlog.oldest_ns()
        oldest = waiting if waiting is not None else self._taken_ns
        self.nav.hold(None if oldest is None else oldest - self.aligner.reach_ns)

    def _accept(self, block: AlignedBlock) -> None:
        e = _recorded(block)
        self._taken_ns = int(e.t_ns[-1])
        nav_flags = e.flags & np.uint32(NAV_FLAGS)
        for flag in np.unique(nav_flags[nav_flags != 0]).tolist():
            self.recorder.flag_pulses(e.row[nav_flags == flag], flag)
        self._pending.append(_Pulses.join([block]))
        self._pending_n += len(block)
        if self.focuser is None and not self._heading_window_held():
            return  # the first track waits for its heading window
        while self._pending_n >= self.cfg.imaging.block_pulses:
            self._focus_pending(self.cfg.imaging.block_pulses)

    def _focus_pending(self, n: int) -> None:
        """Focus the first ``n`` pulses accepted and not focused yet, and record their
        motion and products.

        The focuser takes ``imaging.block_pulses`` at a time however the aligner released
        them, so that a live run and a replay of its store cut the stream alike (the
        autofocus estimates depend on the cuts at the level of rounding).
        """
        if not self._pending:
            return
        pending = _Pulses.cat(self._pending)
        self._pending = [pending.since(n)] if n < pending.t_ns.size else []
        self._pending_n = pending.t_ns.size - n
        in_order = self._in_time_order(pending.upto(n))
        if in_order is None:
            return
        self.summary.pulses_nav_flagged += int(np.count_nonzero(in_order.flags & NAV_UNUSABLE))
        p = in_order if self.focuser is not None else self._start_focusing(in_order, pending)
        if p is None:
            return  # no navigation yet: the aperture has not begun
        assert self.focuser is not None
        if not p.usable.all():
            p = self._blank_unusable(p)
        if p.usable.any():
            k = int(np.flatnonzero(p.usable)[-1])
            self._last_nav = (int(p.t_ns[k]), p.vel_ned[k], p.quat[k])
        out = self.focuser.push(p.raw, p.t_ns, p.vel_ned, p.usable, p.quat)
        self.summary.pulses_processed += int(np.count_nonzero(p.usable))
        self.summary.pulses_unfocused += int(np.count_nonzero(~p.usable))
        self._record_motion(p, out)
        self._record(out)

    def _in_time_order(self, p: _Pulses) -> _Pulses | None:
        """``p`` without the pulses not after every pulse focused before (counted in
        :attr:`RunSummary.pulses_out_of_order`: the focuser needs strictly increasing
        times); None if none is left."""
        fresh = _strictly_increasing(p.t_ns, self._focused_ns)
        if not fresh.all():
            self.summary.pulses_out_of_order += int(np.count_nonzero(~fresh))
            log.warning("pulses out of time order kept from the focuser",
                        extra={"pulses": int(np.count_nonzero(~fresh))})  # fmt: skip
            p = p.rows(fresh)
            if p.t_ns.size == 0:
                return None
        self._focused_ns = int(p.t_ns[-1])
        return p

    def _record_motion(self, p: _Pulses, out: FocusOutput) -> None:
        """Record the motion solution of the pulses pushed, and flag the turn pulses."""
        assert out.motion is not None
        self._append_motion(p, out.motion)
        if out.turn.any():
            self.recorder.flag_pulses(p.row[out.turn], PulseFlag.TURN)

    def _heading_window_held(self) -> bool:
        """Whether the pulses accepted and not focused cover ``mocomp.heading_window_s``
        from the first one with navigation (or none has navigation: nothing to wait for)."""
        first = next((int(p.t_ns[p.usable][0]) for p in self._pending if p.usable.any()), None)
        if first is None or self.cfg.mocomp.heading_window_s == 0.0:
            return True
        window_ns = round(self.cfg.mocomp.heading_window_s * 1e9)
        return int(self._pending[-1].t_ns[-1]) >= first + window_ns

    def _start_focusing(self, p: _Pulses, held: _Pulses) -> _Pulses | None:
        """Start the focuser at the first pulse of ``p`` with navigation; the pulses from
        there on (the pulses before it are recorded unfocused).

        The first reference track follows the mean velocity of the usable pulses ``held``
        (``p`` and the pulses accepted after it) within ``mocomp.heading_window_s`` of that
        first one (0: of the first ``imaging.block_pulses`` usable pulses of ``p``), however
        the blocks were cut (live and replay cut them differently: the reference track must
        not depend on it). None while no pulse has navigation.
        """
        if not p.usable.any():
            self._record_unfocused(p)
            return None
        first_usable = int(np.argmax(p.usable))
        self._record_unfocused(p.upto(first_usable))
        p = p.since(first_usable)
        t0 = int(p.t_ns[0])
        first = slice(0, self.cfg.imaging.block_pulses)
        if self.cfg.mocomp.heading_window_s == 0.0:
            start_vel = p.vel_ned[p.usable][first].mean(axis=0)
        else:
            window = held.usable & (held.t_ns >= t0)
            window &= held.t_ns < t0 + round(self.cfg.mocomp.heading_window_s * 1e9)
            start_vel = held.vel_ned[window].mean(axis=0)
        self.focuser = Focuser(self.cfg, t0, start_vel, self.sink, quat=p.quat[p.usable][first])
        self.recorder.set_attribute(
            schema.REFERENCE_TRACK_ATTR, schema.encode_reference_track(self.focuser.track)
        )
        self._last_nav = (int(p.t_ns[0]), p.vel_ned[0], p.quat[0])
        return p

    def _record_unfocused(self, p: _Pulses) -> None:
        """Record pulses before the aperture begins (none has navigation, or all were taken
        under other radar parameters) in the motion table without a solution, and count
        them (:attr:`RunSummary.pulses_unfocused`)."""
        if p.t_ns.size == 0:
            return
        self._append_motion(p, nan_motion(p.t_ns))
        self.summary.pulses_unfocused += p.t_ns.size

    def _append_motion(self, p: _Pulses, m: MocompSolution) -> None:
        """Record the navigation and the motion solution ``m`` of pulses ``p``."""
        self.recorder.append_motion(
            p.pulse_id, p.t_ns, p.pos_ned, p.vel_ned, p.quat, m.d_los_m, m.phase_rad,
            m.range_shift_m,
        )  # fmt: skip

    def _blank_unusable(self, p: _Pulses) -> _Pulses:
        """Zero the echoes of pulses without navigation and give them placeholder motion.

        The pulses keep their place in time, so the autofocus and the image see a
        uniformly sampled aperture with a hole (zeros) rather than a silent jump. The
        placeholder velocity is the straight line between the usable neighbours (the
        last one of the previous block before the first): across the hole D_los
        integrates exactly as if the pulses had been left out, and the placeholder
        never reaches the image because those echoes are zero. The pulses stay
        flagged in the store.
        """
        usable = p.usable
        raw = p.raw.copy()
        raw[~usable] = 0
        known_t = p.t_ns[usable].astype(np.float64)
        known_v, known_q = p.vel_ned[usable], p.quat[usable]
        last_t, last_v, last_q = self._last_nav
        if known_t.size == 0 or p.t_ns[0] < known_t[0]:
            known_t = np.concatenate([[float(last_t)], known_t])
            known_v = np.concatenate([last_v[None, :], known_v])
            known_q = np.concatenate([last_q[None, :], known_q])
        tf = p.t_ns.astype(np.float64)
        vel = np.column_stack([np.interp(tf, known_t, known_v[:, k]) for k in range(3)])
        nearest = np.clip(np.searchsorted(known_t, tf), 0, known_t.size - 1)
        quat = np.where(usable[:, None], p.quat, known_q[nearest])
        return replace(p, raw=raw, vel_ned=vel, quat=quat)

    def _record(self, out: FocusOutput) -> None:
        """Record the autofocus estimates made so far, the Doppler centroids and the tiles
        of ``out``."""
        self._record_autofocus()
        if out.doppler:
            self.recorder.append_rows(schema.DOPPLER, schema.encode_doppler(out.doppler))
            last = out.doppler[-1]
            self.summary.doppler_attitude_hz, self.summary.doppler_echo_hz = (
                last.attitude_hz,
                last.echo_hz,
            )
        for tile, track in zip(out.tiles, out.tracks, strict=True):
            metrics = recorded_tile_metrics(tile)
            self.recorder.add_image(
                tile.image(), tile.t0_ns, tile.t1_ns, metrics, schema.encode_reference_track(track)
            )
            self.summary.tiles += 1
            self.summary.tile_metrics.append(metrics)

    def _record_autofocus(self) -> None:
        """Take the autofocus engine's new subaperture estimates into the store."""
        engine = self.focuser.autofocus if self.focuser is not None else None
        if engine is None:
            return
        subs = engine.take_report().subapertures
        if subs:
            self.recorder.append_rows(schema.AUTOFOCUS, schema.encode_autofocus(subs))

    def _record_nav(self) -> None:
        """Write the queued INS samples and raw INS bytes (the bytes as one chunk whose
        ``rx_ns`` is that of its newest part)."""
        self._ins_recorded_mono = time.monotonic()
        chunks = _drain(self._ins_raw)
        if chunks:
            rx_ns = chunks[-1][1]
            data = b"".join(c for c, _ in chunks)
            self.recorder.append_ins_bytes(data, -1 if rx_ns is None else rx_ns)
        rows = _drain(self._nav_rows)
        if rows:
            self.recorder.append_nav(**schema.encode_nav(rows))
            self.summary.nav_samples += len(rows)
            if self._geodetic_origin is None:
                self._geodetic_origin = schema.first_geodetic_origin(rows)
                if self._geodetic_origin is not None:
                    self.recorder.set_attribute(
                        schema.GEODETIC_ORIGIN_ATTR,
                        schema.encode_geodetic_origin(self._geodetic_origin),
                    )

    def totals(self) -> dict[str, float]:
        """Monotonic counts of the run (served as Prometheus counters ``pipeline_*``)."""
        return {
            "pulses_received": self.summary.pulses_received,
            "pulses_processed": self.summary.pulses_processed,
            "pulses_nav_flagged": self.summary.pulses_nav_flagged,
            "pulses_nav_gap": self.aligner.nav_gap,
            "pulses_nav_timeout": self.aligner.nav_timeout,
            "pulses_nav_bridged": self.aligner.nav_bridged,
            "pulses_dropped_ring": self.ring.dropped,
            "pulses_duplicate": self.ring.duplicates,
            "pulses_reordered": self.ring.reordered,
            "pulses_late_dropped": self.ring.late_dropped,
            "pulses_out_of_order": self.summary.pulses_out_of_order,
            "pulses_time_jump": self.time_jumps,
            "pulses_focus_skipped": self.backlog.skipped,
            "pulses_unfocused": self.summary.pulses_unfocused,
            "nav_samples": self.summary.nav_samples,
            "tiles": self.summary.tiles,
        }

    def _update_counters(self) -> None:
        """The gauges of the focusing part: ``focus_backlog_pulses`` (recorded pulses
        waiting to be focused), ``focus_lag_seconds`` (the newest pulse recorded less
        the newest taken by focusing, s) and the live image's degraded level and load."""
        self.counters.set("focus_backlog_pulses", len(self.backlog))
        recorded, taken = self._recorded_ns, self._taken_ns
        lag = 0.0 if recorded is None or taken is None else max(recorded - taken, 0) * 1e-9
        self.counters.set("focus_lag_seconds", lag)
        live = self.focuser.live if self.focuser is not None else None
        if live is not None:  # the live image's degraded level (sarmoco.daemon.livelevel)
            self.counters.set("live_image_level", live.level)
            self.counters.set("live_image_load", live.load)


def tile_metrics(data: ComplexArray) -> dict[str, float]:
    """Entropy and contrast of a focused tile; NaN for a tile with no energy.

    A tile no echo reached (every pulse of its aperture without navigation, or
    culled) is a valid, empty product, not a processing error.
    """
    if not np.any(data):
        return {"entropy": math.nan, "contrast": math.nan}
    return {"entropy": image_entropy(data), "contrast": image_contrast(data)}


def recorded_tile_metrics(tile: Tile) -> dict[str, float]:
    """The ``metrics`` a tile is recorded with: :func:`tile_metrics`, the pulses
    backprojected into it and its index in its segment's layout."""
    return tile_metrics(tile.data) | {"pulses": float(tile.n_pulses), "index": float(tile.index)}


def _recorded(block: AlignedBlock) -> RecordedBatch:
    """The recorded pulses of a block the aligner took from the focus backlog."""
    assert isinstance(block.echoes, RecordedBatch)
    return block.echoes


def _strictly_increasing(t_ns: IntArray, after_ns: int | None) -> BoolArray:
    """Mask of the pulses later than ``after_ns`` (GPS ns) and than every pulse before them."""
    floor = np.iinfo(np.int64).min if after_ns is None else after_ns
    before = np.maximum.accumulate(np.concatenate([[floor], t_ns[:-1]]))
    return np.asarray(t_ns > before, dtype=bool)


_T = TypeVar("_T")


def _drain(q: queue.SimpleQueue[_T]) -> list[_T]:
    """Everything queued now, oldest first."""
    items: list[_T] = []
    while True:
        try:
            items.append(q.get_nowait())
        except queue.Empty:
            return items
