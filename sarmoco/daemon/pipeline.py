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

Each part is a module of its own, readable alone: :mod:`~sarmoco.daemon.ingest` (radar
reads into the ring, the time-jump filter, INS samples into the nav buffer),
:mod:`~sarmoco.daemon.navigation` (the nav buffer and aligner, pulses with their
navigation, placeholder navigation across gaps), :mod:`~sarmoco.daemon.blocks` (block
assembly and focusing) and :mod:`~sarmoco.daemon.tables` (the recording of the tables and
the run's totals). :class:`Pipeline` wires them.

The "current time" of the aligner is the radar's own clock: the newest pulse
time stamp plus the host's monotonic time elapsed since it arrived (live), or
the newest pulse time alone (replay, a virtual clock). Pulses therefore wait
for the INS by radar time, whatever the epoch of the radar and however the
host clock is set.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

from sarmoco.daemon.aligner import AlignedBlock
from sarmoco.daemon.backlog import FocusBacklog
from sarmoco.daemon.blocks import BlockFocusing
from sarmoco.daemon.config import Config
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.focuser import Focuser, SinkFactory
from sarmoco.daemon.ingest import InsIngest, PulseSource, RadarIngest
from sarmoco.daemon.navframe import StoreFrame
from sarmoco.daemon.navigation import nav_alignment, recorded
from sarmoco.daemon.status import Counters
from sarmoco.daemon.tables import RunSummary, RunTables
from sarmoco.drivers.samples import Sample
from sarmoco.store.recorder import Recorder

FOCUS_BACKLOG_S = 2.0
"""Most the focusing path lags behind the recording, in seconds of pulses at the nominal
PRF (at least two processing blocks): further behind, it skips ahead to the newest."""
REORDER_HOLD_S = 0.1
"""A live pulse is recorded once the radar clock is this far past it, s: a datagram
late by less still finds its place among the pulses waiting in the echo ring."""


class Pipeline:
    """One run's buffers, recording, alignment and focusing (see the module doc).

    The parts, each in a module of its own: ingest (:class:`~sarmoco.daemon.ingest.RadarIngest`,
    :class:`~sarmoco.daemon.ingest.InsIngest`), navigation
    (:func:`~sarmoco.daemon.navigation.nav_alignment`), block assembly and focusing
    (:class:`~sarmoco.daemon.blocks.BlockFocusing`) and the recording of the tables
    (:class:`~sarmoco.daemon.tables.RunTables`). This class wires them and runs the two
    parts of the data path.

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
        Refuse pulses stamped more than :data:`~sarmoco.daemon.ingest.TIME_JUMP_S` ahead of
        the INS and of the radar clock (:meth:`read_radar`): a live network link, where the
        host clock runs with the radar's. Not for files and replays, read faster than real
        time (a pause of the radar would look like a jump).
    focus_skips : bool
        Focusing that falls :data:`FOCUS_BACKLOG_S` behind skips ahead (a live network
        link: the radar does not wait). Otherwise :meth:`record` takes no more pulses
        from the ring than the focus backlog has room for (a file or a replay, read at
        the pace of focusing).
    radar : RadarIngest, optional
        The echo ring and reads to take over, with the pulses already in its ring (a strip's
        store opened while its first pulses were read); default: a new one.
    hold_course : bool
        Hold the first pulses until they cover ``mocomp.heading_window_s`` and lay the
        first reference track (and the image grid) along their mean velocity
        (:class:`~sarmoco.daemon.blocks.BlockFocusing`): a replay, where pulses wait for
        nothing. A live run lays it along the first processing block's.
    """

    def __init__(
        self,
        cfg: Config,
        recorder: Recorder,
        counters: Counters,
        sink: SinkFactory | None = None,
        refuse_jumps: bool = False,
        focus_skips: bool = False,
        radar: RadarIngest | None = None,
        hold_course: bool = False,
    ) -> None:
        self.cfg = cfg
        self.recorder = recorder
        self.counters = counters
        block = cfg.imaging.block_pulses
        self.backlog = FocusBacklog(max(math.ceil(FOCUS_BACKLOG_S * cfg.radar.prf_hz), 2 * block))
        self._focus_skips = focus_skips
        self.nav, self.aligner = nav_alignment(cfg, self.backlog, block)
        if radar is None:
            radar = RadarIngest(cfg, self.nav, counters, refuse_jumps)
        radar.nav = self.nav
        self.radar = radar
        self.ins = InsIngest(self.nav)
        self.tables = RunTables(recorder)
        self.blocks = BlockFocusing(cfg, self.tables, sink, hold_course)
        self._taken_ns: int | None = None
        """Time of the newest pulse the aligner took from the backlog, GPS ns."""
        counters.add_source("pipeline", self.totals)

    @property
    def ring(self) -> EchoRing:
        """The echo ring the radar is read into."""
        return self.radar.ring

    @property
    def frame(self) -> StoreFrame:
        """The frame of the store's positions."""
        return self.ins.frame

    @property
    def focuser(self) -> Focuser | None:
        """The focusing chain (None before the first pulse with navigation)."""
        return self.blocks.focuser

    @property
    def summary(self) -> RunSummary:
        """The run's totals as counted so far (the counts kept by the ring, the aligner and
        the backlog are brought in by :meth:`finish`; :meth:`current` has them now)."""
        return self.tables.summary

    # -- readers --------------------------------------------------------------------------

    def read_radar(
        self,
        source: PulseSource,
        timeout_s: float,
        max_pulses: int | None = None,
        capturing: Callable[[], bool] | None = None,
    ) -> int:
        """Decode the pulses ``source`` has within ``timeout_s`` into the ring; returns the
        count (:meth:`~sarmoco.daemon.ingest.RadarIngest.read`)."""
        return self.radar.read(source, timeout_s, max_pulses, capturing)

    def add_nav(self, samples: list[Sample], rx_ns: int | None) -> None:
        """Offer INS samples to the nav buffer and queue them for the recorder."""
        self.ins.add(samples, rx_ns)

    def add_ins_raw(self, data: bytes, rx_ns: int | None) -> None:
        """Queue bytes received from the INS link for the store
        (:meth:`~sarmoco.daemon.ingest.InsIngest.add_raw`)."""
        self.ins.add_raw(data, rx_ns)

    # -- processing loop --------------------------------------------------------------------

    def now_ns(self, live: bool) -> int | None:
        """Radar-clock "now" (see the module doc); None before the first pulse."""
        return self.radar.now_ns(live)

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
        return unaligned_since(self.backlog, self.radar.first_and_latest_ns(),
                               self.tables.recorded_ns)  # fmt: skip

    def process(self, now_ns: int | None, on_block: Callable[[], None] | None = None) -> int:
        """:meth:`record` then :meth:`focus` (one thread does both: a replay, tests);
        returns the pulses released by the aligner."""
        self.record(now_ns)
        return self.focus(now_ns, on_block)

    def record(self, now_ns: int | None = None) -> int:
        """Store the pulses waiting in the echo ring and hand them to focusing; store the
        INS samples and bytes queued (every :data:`~sarmoco.daemon.tables.INS_RECORD_S`).
        Returns the pulses stored.

        Parameters
        ----------
        now_ns : int, optional
            The radar clock, GPS ns: pulses within :data:`REORDER_HOLD_S` of it wait (a
            late datagram may still go before them). None: every pulse is taken.
        """
        if self.tables.nav_due():
            self.tables.store_nav(self.ins)
        hold_ns = None if now_ns is None else now_ns - round(REORDER_HOLD_S * 1e9)
        stored = self.tables.store_pulses(self.ring, self.backlog, hold_ns, self._focus_skips)
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
        self.tables.store_nav(self.ins)
        while True:
            self.record()
            block = self.aligner.flush()
            if block is not None:
                self._accept(block)
            if len(self.ring) == 0:
                break
        self.blocks.finish()
        self.tables.summary = self.current()
        self.recorder.set_metrics(self.summary.as_dict())
        self._update_counters()
        return self.summary

    def current(self) -> RunSummary:
        """The run's totals now, with the counts the ring, the aligner and the backlog keep."""
        r = self.ring
        return replace(
            self.summary,
            pulses_dropped_ring=r.dropped,
            pulses_duplicate=r.duplicates,
            pulses_reordered=r.reordered,
            pulses_late_dropped=r.late_dropped,
            pulses_nav_bridged=self.aligner.nav_bridged,
            pulses_focus_skipped=self.backlog.skipped,
        )

    def totals(self) -> dict[str, float]:
        """Monotonic counts of the run (served as Prometheus counters ``pipeline_*``): the
        counts of :meth:`current`, the pulses the aligner found in an INS gap or beyond
        the INS, and those refused as time jumps."""
        return {
            **self.current().counts(),
            "pulses_nav_gap": self.aligner.nav_gap,
            "pulses_nav_timeout": self.aligner.nav_timeout,
            "pulses_time_jump": self.radar.time_jumps,
        }

    def _accept(self, block: AlignedBlock) -> None:
        """Hand an aligned block to block assembly and focusing."""
        self._taken_ns = int(recorded(block).t_ns[-1])
        self.blocks.accept(block)

    def _hold_nav(self) -> None:
        """Keep the navigation of the pulses not focused yet: from the oldest waiting in the
        backlog (or, with none waiting, the last one taken) less the aligner's reach."""
        waiting = self.backlog.oldest_ns()
        oldest = waiting if waiting is not None else self._taken_ns
        self.nav.hold(None if oldest is None else oldest - self.aligner.reach_ns)

    def _update_counters(self) -> None:
        """The gauges of the focusing part: ``focus_backlog_pulses`` (recorded pulses
        waiting to be focused), ``focus_lag_seconds`` (the newest pulse recorded less
        the newest taken by focusing, s) and the live image's degraded level, whether its
        tiles are prompt, and its load."""
        self.counters.set("focus_backlog_pulses", len(self.backlog))
        recorded_ns, taken = self.tables.recorded_ns, self._taken_ns
        lag = 0.0 if recorded_ns is None or taken is None else max(recorded_ns - taken, 0) * 1e-9
        self.counters.set("focus_lag_seconds", lag)
        live = self.focuser.live if self.focuser is not None else None
        if live is not None:  # the live image's degraded level (sarmoco.daemon.livelevel)
            self.counters.set("live_image_level", live.level)
            self.counters.set("live_image_prompt", float(live.prompt))
            self.counters.set("live_image_load", live.load)


def unaligned_since(
    backlog: FocusBacklog, first_and_latest: tuple[int | None, int | None], recorded_ns: int | None
) -> tuple[int | None, bool]:
    """Where the pulses still waiting for their navigation begin (``oldest_unaligned_ns``
    of a pipeline).

    Parameters
    ----------
    backlog : FocusBacklog
        The recorded pulses waiting for the aligner.
    first_and_latest : (int or None, int or None)
        Times of the first and of the newest pulse read, GPS ns.
    recorded_ns : int or None
        Time of the newest pulse recorded, GPS ns.

    Returns
    -------
    oldest_ns : int or None
        GPS ns, a bound from below: the oldest pulse in the backlog, else the newest
        recorded, else the first read; None before the first pulse.
    all_aligned : bool
        Every pulse read has been recorded and taken by the aligner.
    """
    waiting = backlog.oldest_ns()
    if waiting is not None:
        return waiting, False
    first, latest = first_and_latest
    if recorded_ns is not None:
        return recorded_ns, recorded_ns == latest
    return first, False
