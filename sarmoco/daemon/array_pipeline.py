"""Array mode (``radar.mode = "array"``): pulses of every Tx/Rx pair to a DEM.

The same drivers, aligner and store as the single-channel pipeline, and the same two parts
that do not wait for each other (:mod:`sarmoco.daemon.pipeline`), a different product:

1. recording (ingest): the radar's packets (one VITA 49.2 stream ID per pair) are grouped
   by transmit time into whole pulses [channel, sample] in an echo ring
   (:class:`~sarmoco.daemon.array_ingest.ArrayIngest`); :meth:`ArrayPipeline.record` takes
   them out as they come and stores them per channel (``pulses`` rows: time, pulse id,
   channel, flags, echo), and the INS samples and bytes received: nothing on this path
   waits for the navigation or the imaging;
2. alignment: :meth:`ArrayPipeline.focus` releases the recorded pulses through the
   :class:`~sarmoco.daemon.aligner.Aligner` with the INS position, velocity and attitude
   of the array's reference point (the lever arm applied), flags them in the store with
   the navigation flags the aligner set, and keeps them for the imaging;
3. at the end of the run (or of a strip) :meth:`ArrayPipeline.finish` images the pulses
   with navigation in 3-D (:func:`sarmoco.processing.array.imaging3d.form_dem`) with the
   INS attitude (roll compensated, ``array.sub_blocks``) and, with
   ``array.record_uncompensated``, once more as if the wing were level; both DEMs go to
   the store's ``dem`` group.

A live run (``sarmoco run``), a replay of files and a replay of a store make the same
calls, so the replay of a store forms the DEMs its live run formed.

Frame of the DEMs: the INS reference point at the first imaged pulse is placed at
``(0, 0, -geometry.height_m)`` in NED, so heights are above a datum ``geometry.height_m``
below it (the INS gives no absolute position here: a report registers the DEM against a
truth by the first pulse, as the tiles of a single-channel run).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.daemon.aligner import AlignedBlock
from sarmoco.daemon.array_ingest import RING_PULSES, ArrayIngest
from sarmoco.daemon.backlog import FocusBacklog, RecordedBatch
from sarmoco.daemon.config import Config, array_stream_ids
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.ingest import InsIngest
from sarmoco.daemon.links import open_ins, open_radar
from sarmoco.daemon.navframe import StoreFrame
from sarmoco.daemon.navigation import nav_alignment, recorded
from sarmoco.daemon.pipeline import FOCUS_BACKLOG_S, REORDER_HOLD_S, unaligned_since
from sarmoco.daemon.status import Counters
from sarmoco.daemon.storeopen import open_recorder, record_ins_format
from sarmoco.daemon.tables import RunTables
from sarmoco.drivers.radar import RadarSource
from sarmoco.drivers.samples import Sample, to_complex64
from sarmoco.drivers.source import Source
from sarmoco.errors import DataFileError
from sarmoco.processing.array.geometry import mimo_layout
from sarmoco.processing.array.imaging3d import Array3dOptions, ArraySystem, DemProduct, form_dem
from sarmoco.processing.navinterp import integrate_velocity
from sarmoco.processing.types import NavSamples
from sarmoco.store import schema
from sarmoco.store.flags import NAV_FLAGS
from sarmoco.store.reader import StoreNav, StorePulses, open_store
from sarmoco.store.recorder import Recorder

log = logging.getLogger(__name__)


def array_system(cfg: Config) -> ArraySystem:
    """The radar, array layout and beams of an ``array``-mode configuration."""
    a = cfg.array
    return ArraySystem(
        radar=cfg.radar.params(),
        layout=mimo_layout(a.n_tx, a.n_rx, a.epc_spacing_m),
        antenna_length_m=a.antenna_length_m,
        max_look_rad=math.radians(a.max_look_deg),
    )


@dataclass
class ArraySummary:
    """What an array run did; its fields are the names of the store's ``metrics``.

    Attributes
    ----------
    pulses : int
        Whole pulses (every channel) recorded.
    pulses_imaged : int
        Of them, those with navigation, imaged.
    pulses_incomplete : int
        Pulses dropped for missing channels.
    packets_foreign, packets_duplicate : int
        Packets of other stream IDs; repeated packets.
    pulses_nav_flagged : int
        Pulses without navigation (INS gap or timeout).
    pulses_dropped_ring : int
        Whole pulses dropped because the echo ring was full (recording behind).
    pulses_focus_skipped : int
        Recorded pulses the alignment skipped, fallen behind (a live run; a replay of
        the store images them).
    dem : dict
        Per DEM product name: its cells, valid cells and imaging time (s).
    """

    pulses: int = 0
    pulses_imaged: int = 0
    pulses_incomplete: int = 0
    packets_foreign: int = 0
    packets_duplicate: int = 0
    pulses_nav_flagged: int = 0
    pulses_dropped_ring: int = 0
    pulses_focus_skipped: int = 0
    dem: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def pulses_received(self) -> int:
        """Whole pulses recorded (the name the live run's totals use)."""
        return self.pulses

    def as_dict(self) -> dict[str, Any]:
        """JSON-able form (the store's ``metrics`` attribute): ``mode`` ``"array"`` and
        the fields by name."""
        return {"mode": "array", **dataclasses.asdict(self)}

    def dem_text(self) -> str:
        """The DEMs formed, for the operator: ``DEM compensated 1234 cells, ...`` (``no
        DEM`` when none was)."""
        if not self.dem:
            return "no DEM"
        return "DEM " + ", ".join(f"{k} {int(v['valid_cells'])} cells" for k, v in self.dem.items())


class ArrayPipeline:
    """One array run's recording, alignment and imaging (see the module doc).

    Parameters
    ----------
    cfg : Config
        ``radar.mode = "array"`` configuration.
    recorder : Recorder
        The run's store (per-channel rows: ``n_samples`` of the radar).
    counters : Counters
        Status counters (the run's totals are served as ``pipeline_*``).
    radar : ArrayIngest, optional
        The echo ring and reads to take over, with the pulses already in its ring (a
        strip's store opened while its first pulses were read); default: a new one.
    focus_skips : bool
        The alignment that falls :data:`~sarmoco.daemon.pipeline.FOCUS_BACKLOG_S` behind
        skips ahead (a live network link: the radar does not wait). Otherwise
        :meth:`record` takes no more pulses from the ring than the backlog has room for (a
        file or a replay, read at the pace of the processing).
    """

    def __init__(
        self,
        cfg: Config,
        recorder: Recorder,
        counters: Counters,
        radar: ArrayIngest | None = None,
        focus_skips: bool = False,
    ) -> None:
        self.cfg = cfg
        self.recorder = recorder
        self.system = array_system(cfg)
        self.radar = ArrayIngest(cfg, counters) if radar is None else radar
        capacity = max(math.ceil(FOCUS_BACKLOG_S * cfg.radar.prf_hz), RING_PULSES)
        self.backlog = FocusBacklog(capacity)
        self._focus_skips = focus_skips
        self.nav, self.aligner = nav_alignment(cfg, self.backlog, RING_PULSES)
        self.ins = InsIngest(self.nav)
        self.tables = RunTables(recorder)
        self._blocks: list[AlignedBlock] = []
        self.summary = ArraySummary()
        counters.add_source("pipeline", self.totals)

    @property
    def ring(self) -> EchoRing:
        """The echo ring the radar is read into (whole pulses)."""
        return self.radar.ring

    @property
    def frame(self) -> StoreFrame:
        """The frame of the store's positions."""
        return self.ins.frame

    # -- readers --------------------------------------------------------------------------

    def add_nav(self, samples: list[Sample], rx_ns: int | None) -> None:
        """Offer INS samples to the nav buffer and queue them for the store."""
        self.ins.add(samples, rx_ns)

    def add_ins_raw(self, data: bytes, rx_ns: int | None) -> None:
        """Queue bytes received from the INS link for the store."""
        self.ins.add_raw(data, rx_ns)

    def now_ns(self, live: bool) -> int | None:
        """Radar-clock "now" (:meth:`ArrayIngest.now_ns`); None before the first pulse."""
        return self.radar.now_ns(live)

    def oldest_unaligned_ns(self) -> tuple[int | None, bool]:
        """Where the pulses still waiting for their navigation begin; any thread
        (:func:`~sarmoco.daemon.pipeline.unaligned_since`)."""
        return unaligned_since(self.backlog, self.radar.first_and_latest_ns(),
                               self.tables.recorded_ns)  # fmt: skip

    # -- the two parts --------------------------------------------------------------------

    def process(self, now_ns: int | None, on_block: Callable[[], None] | None = None) -> int:
        """:meth:`record` then :meth:`focus` (a replay); returns the pulses aligned."""
        self.record(now_ns)
        return self.focus(now_ns, on_block)

    def record(self, now_ns: int | None = None) -> int:
        """Store the whole pulses waiting in the ring, every channel a row, and hand them to
        the alignment; store the INS samples and bytes queued. Returns the pulses stored.

        Parameters
        ----------
        now_ns : int, optional
            The radar clock, GPS ns: pulses within
            :data:`~sarmoco.daemon.pipeline.REORDER_HOLD_S` of it wait (a late pulse may
            still go before them). None: every pulse is taken.
        """
        if self.tables.nav_due():
            self.tables.store_nav(self.ins)
        t = self.ring.peek_times()
        hold_ns = None if now_ns is None else now_ns - round(REORDER_HOLD_S * 1e9)
        k = t.size if hold_ns is None else int(np.searchsorted(t, hold_ns, side="right"))
        if not self._focus_skips:
            k = min(k, self.backlog.free)
        if k == 0:
            return 0
        e = self.ring.pop(k)
        n_c = self.cfg.radar.channels
        first = self.recorder.pulses.rows
        self.recorder.append_pulses(
            np.repeat(e.t_ns, n_c),
            np.repeat(e.pulse_id, n_c),
            np.tile(np.arange(n_c, dtype=np.int32), k),
            np.repeat(e.flags, n_c),
            e.samples.reshape(k * n_c, *self.radar.row),
        )
        rows = first + n_c * np.arange(k, dtype=np.int64)  # each pulse's channel 0
        self.backlog.put(RecordedBatch(e.samples, e.t_ns, e.pulse_id, e.channel, e.flags, rows))
        self.summary.pulses += k
        self.tables.recorded_ns = int(e.t_ns[-1])
        return k

    def focus(self, now_ns: int | None, on_block: Callable[[], None] | None = None) -> int:
        """Release the recorded pulses the INS covers (or that waited too long), flag them
        in the store and keep them for the imaging; returns the pulses released.
        ``on_block`` is called after each block released."""
        released, waiting = 0, len(self.backlog)
        while now_ns is not None and released < waiting:
            block = self.aligner.poll(now_ns)
            if block is None:
                break
            released += len(block)
            self._accept(block)
            if on_block is not None:
                on_block()
        return released

    def _accept(self, block: AlignedBlock) -> None:
        """Flag every channel's row of the pulses of ``block`` with their navigation flags,
        keep the block for the imaging."""
        e = recorded(block)
        channels = np.arange(self.cfg.radar.channels, dtype=np.int64)
        nav_flags = e.flags & np.uint32(NAV_FLAGS)
        for flag in np.unique(nav_flags[nav_flags != 0]).tolist():
            rows = e.row[nav_flags == flag]
            self.recorder.flag_pulses((rows[:, None] + channels).ravel(), flag)
        self.summary.pulses_nav_flagged += int(np.count_nonzero(~block.nav.valid))
        self._blocks.append(block)

    def current(self) -> ArraySummary:
        """The run's totals now, with the counts the grouper, the ring and the backlog keep."""
        g = self.radar.grouper
        return dataclasses.replace(
            self.summary,
            pulses_incomplete=g.incomplete,
            packets_foreign=g.foreign,
            packets_duplicate=g.duplicates,
            pulses_dropped_ring=self.ring.dropped,
            pulses_focus_skipped=self.backlog.skipped,
        )

    def totals(self) -> dict[str, float]:
        """Monotonic counts of the run (served as Prometheus counters ``pipeline_*``)."""
        s = self.current()
        return {
            "pulses_received": s.pulses,
            "pulses_nav_flagged": s.pulses_nav_flagged,
            "pulses_incomplete": s.pulses_incomplete,
            "packets_foreign": s.packets_foreign,
            "packets_duplicate": s.packets_duplicate,
            "pulses_dropped_ring": s.pulses_dropped_ring,
            "pulses_focus_skipped": s.pulses_focus_skipped,
        }

    def finish(self) -> ArraySummary:
        """Record and align what is left, image and record the DEMs and the run's metrics."""
        self.radar.grouper.flush()
        self.tables.store_nav(self.ins)
        while True:
            self.record()
            block = self.aligner.flush()
            if block is not None:
                self._accept(block)
            if len(self.ring) == 0:
                break
        self.summary = self.current()
        self._image()
        self.recorder.set_metrics(self.summary.as_dict())
        return self.summary

    def _image(self) -> None:
        """Image the pulses with navigation: roll compensated, and level if configured."""
        blocks, self._blocks = self._blocks, []
        if not blocks:
            return
        valid = np.concatenate([b.nav.valid for b in blocks])
        if np.count_nonzero(valid) < 2:
            return
        t_ns = np.concatenate([b.nav.t_ns for b in blocks])[valid]
        vel = np.concatenate([b.nav.vel_ned for b in blocks])[valid]
        quat = np.concatenate([b.nav.quat for b in blocks])[valid]
        pos = np.concatenate([b.nav.pos_ned for b in blocks])[valid]
        n_c = self.cfg.radar.channels
        echoes = to_complex64(
            np.concatenate([b.echoes.samples for b in blocks])[valid].reshape(
                -1, n_c, *self.radar.row
            )
        )
        if np.isnan(pos).any():  # an INS without position: its velocity integrated
            pos = integrate_velocity(NavSamples(t_ns, vel, quat)).pos_ned
            assert pos is not None
        pos = pos - pos[0] + np.array([0.0, 0.0, -self.cfg.geometry.height_m])
        self.summary.pulses_imaged = int(t_ns.size)
        a = self.cfg.array
        runs = [("compensated", a.roll_compensation)]
        if a.record_uncompensated:
            runs.append(("uncompensated", False))
        for name, compensate in runs:
            options = Array3dOptions(
                compensate_attitude=compensate, blocks=a.sub_blocks, grid_spacing_m=a.dem_spacing_m
            )
            start = time.perf_counter()
            dem = form_dem(echoes, t_ns, pos, quat, self.system, options)
            seconds = time.perf_counter() - start
            self._record_dem(name, dem, seconds)

    def _record_dem(self, name: str, dem: DemProduct, seconds: float) -> None:
        ok = np.isfinite(dem.height_m)
        self.summary.dem[name] = {
            "cells": float(dem.height_m.size),
            "valid_cells": float(np.count_nonzero(ok)),
            "imaging_s": seconds,
        }
        self.recorder.add_dem(
            name,
            *schema.encode_dem(dem, self.system.height_resolution_m, self.cfg.geometry.height_m),
        )
        log.info("array DEM %s: %d cells in %.2f s", name, int(np.count_nonzero(ok)), seconds)


def replay_array_files(cfg: Config, radar_file: Path, nav_file: Path, out: Path) -> ArraySummary:
    """Replay an array run's ``.vrt`` and INS log into a new store on a virtual clock
    (:func:`_replay_array`).

    Raises
    ------
    DataFileError
        When no pulse could be imaged (the store is closed complete): what each stream gave.
    """
    with (
        open_radar(cfg, str(radar_file)) as radar,
        open_ins(cfg, str(nav_file), keep_raw=cfg.recorder.raw_ins) as ins,
    ):
        return _replay_array(
            cfg, radar, ins, out, array_stream_ids(cfg), f"radar {radar_file}, INS {nav_file}"
        )


def replay_array_store(cfg: Config, recording: Path, out: Path) -> ArraySummary:
    """Replay an array run's store (its pulses per channel, the INS samples it accepted and
    its raw INS bytes) into a new store on a virtual clock (:func:`_replay_array`): the
    DEMs of the recording's run, formed again.

    Raises
    ------
    DataFileError
        When no pulse could be imaged (the store is closed complete).
    """
    src = open_store(recording, skip_damaged=True)
    with StorePulses(src) as radar, StoreNav(src) as ins:
        if cfg.recorder.raw_ins:
            ins.keep_raw()
        summary = _replay_array(
            cfg, radar, ins, out, range(cfg.radar.channels), f"recording {recording}"
        )
    if src.skipped:
        log.warning("%s", src.damage_text())
    return summary


def _replay_array(
    cfg: Config,
    radar: RadarSource | StorePulses,
    ins: Source,
    out: Path,
    pair_ids: Sequence[int],
    inputs: str,
) -> ArraySummary:
    """Run recorded packets and INS samples through a new array pipeline on a virtual clock.

    As :func:`sarmoco.daemon.runner.replay_files`: the radar is read a block at a time, the
    INS read ahead to cover the newest pulse plus ``ins.max_gap_s``, the aligner's clock is
    the newest pulse time. ``pair_ids``: the stream ID (or recorded channel) of each pair;
    ``inputs`` names the inputs in an error.
    """
    lead_ns = round(cfg.ins.max_gap_s * 1e9)
    counters = Counters()
    with open_recorder(cfg, out) as recorder:
        pipe = ArrayPipeline(cfg, recorder, counters, ArrayIngest(cfg, counters, pair_ids))
        record_ins_format(recorder, ins)
        ahead: list[Sample] = []
        while pipe.radar.read(radar, 0.0, pipe.ring.free) or not radar.eof:
            now = pipe.now_ns(live=False)
            _feed_ins(pipe, ins, ahead, now, lead_ns)
            pipe.process(now)
        _feed_ins(pipe, ins, ahead, None, lead_ns)
        summary = pipe.finish()
    if summary.pulses_imaged == 0:
        g = pipe.radar.grouper
        raise DataFileError(
            f"array replay imaged no pulse: {summary.pulses} whole pulses "
            f"({summary.pulses_incomplete} dropped for missing channels, "
            f"{summary.packets_foreign} packets of VITA streams {_id_list(sorted(g.foreign_ids))} "
            f"that are no Tx/Rx pair of array.stream_ids {_id_list(list(g.channel_of))}), "
            f"{summary.pulses_nav_flagged} without navigation; {inputs}; store {out}"
        )
    return summary


def _id_list(ids: list[int], most: int = 8) -> str:
    """``ids`` in a message: the first ``most`` and how many more."""
    text = ", ".join(map(str, ids[:most]))
    return f"[{text}{f', ... {len(ids) - most} more' if len(ids) > most else ''}]"


def _feed_ins(
    pipe: ArrayPipeline, ins: Source, ahead: list[Sample], newest_ns: int | None, lead_ns: int
) -> None:
    """Read the INS until it covers ``newest_ns + lead_ns`` (all of it for None) and offer
    the samples due (and the bytes read)."""
    horizon = None if newest_ns is None else newest_ns + lead_ns
    while not ins.eof and (horizon is None or not ahead or ahead[-1].t_gps_ns < horizon):
        ahead += ins.poll(0.0)
        pipe.add_ins_raw(ins.take_raw(), None)
    due = len(ahead) if horizon is None else sum(s.t_gps_ns <= horizon for s in ahead)
    pipe.add_nav(ahead[:due], None)
    del ahead[:due]
