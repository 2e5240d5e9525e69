"""Array mode (``radar.mode = "array"``): pulses of every Tx/Rx pair to a DEM.

The same drivers, aligner and store as the single-channel pipeline, a different product:

1. the radar's packets (one VITA 49.2 stream ID per pair) are grouped by transmit time
   into pulses [channel, sample] (:class:`~sarmoco.daemon.channelgroup.ChannelGrouper`);
2. each whole pulse enters an :class:`~sarmoco.daemon.echoring.EchoRing` as one row of
   ``channels x samples`` and leaves it through the :class:`~sarmoco.daemon.aligner.Aligner`
   with the INS position, velocity and attitude of the array's reference point (the lever
   arm applied); pulses are recorded per channel (``pulses`` rows: time, pulse id, channel,
   flags, echo) with the navigation flags the aligner set;
3. at the end of the run the pulses with navigation are imaged in 3-D
   (:func:`sarmoco.processing.array.imaging3d.form_dem`) with the INS attitude (roll
   compensated, ``array.sub_blocks``) and, with ``array.record_uncompensated``, once more
   as if the wing were level; both DEMs go to the store's ``dem`` group.

Frame of the DEMs: the INS reference point at the first imaged pulse is placed at
``(0, 0, -geometry.height_m)`` in NED, so heights are above a datum ``geometry.height_m``
below it (the INS gives no absolute position here: a report registers the DEM against a
truth by the first pulse, as the tiles of a single-channel run).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.daemon.aligner import AlignedBlock
from sarmoco.daemon.channelgroup import ChannelGrouper
from sarmoco.daemon.config import Config, array_stream_ids
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.ingest import ring_format
from sarmoco.daemon.links import open_ins, open_radar
from sarmoco.daemon.navframe import StoreFrame
from sarmoco.daemon.navigation import nav_alignment
from sarmoco.daemon.runner import open_recorder, record_ins_format
from sarmoco.drivers.samples import (
    AttitudeSample,
    VelocitySample,
    sample_dtype,
    sample_shape,
    to_complex64,
)
from sarmoco.drivers.source import Sample, Source
from sarmoco.errors import DataFileError
from sarmoco.processing.array.geometry import mimo_layout
from sarmoco.processing.array.imaging3d import Array3dOptions, ArraySystem, DemProduct, form_dem
from sarmoco.processing.navinterp import integrate_velocity
from sarmoco.processing.types import NavSamples
from sarmoco.store import schema
from sarmoco.store.flags import FLAG_DTYPE
from sarmoco.store.recorder import Recorder

log = logging.getLogger(__name__)

READ_PACKETS = 1024
"""Packets decoded per radar read."""
RING_PULSES = 256
"""Whole pulses the ring holds between the reader and the aligner."""


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
    """What an array run did.

    Attributes
    ----------
    pulses : int
        Whole pulses (every channel) released by the aligner.
    pulses_imaged : int
        Of them, those with navigation, imaged.
    incomplete, foreign, duplicates : int
        Pulses dropped for missing channels; packets of other stream IDs; repeated packets.
    nav_flagged : int
        Pulses without navigation (INS gap or timeout).
    dems : dict
        Per DEM product name: its cells, valid cells and imaging time (s).
    """

    pulses: int = 0
    pulses_imaged: int = 0
    incomplete: int = 0
    foreign: int = 0
    duplicates: int = 0
    nav_flagged: int = 0
    dems: dict[str, dict[str, float]] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON-able form (the store's ``metrics`` attribute)."""
        return {
            "mode": "array",
            "pulses": self.pulses,
            "pulses_imaged": self.pulses_imaged,
            "pulses_incomplete": self.incomplete,
            "packets_foreign": self.foreign,
            "packets_duplicate": self.duplicates,
            "pulses_nav_flagged": self.nav_flagged,
            "dem": self.dems,
        }


class ArrayPipeline:
    """One array run's grouping, alignment, recording and imaging.

    Parameters
    ----------
    cfg : Config
        ``radar.mode = "array"`` configuration.
    recorder : Recorder
        The run's store (per-channel rows: ``n_samples`` of the radar).
    """

    def __init__(self, cfg: Config, recorder: Recorder) -> None:
        self.cfg = cfg
        self.recorder = recorder
        self.system = array_system(cfg)
        fmt = ring_format(cfg)
        n_c, n_s = cfg.radar.channels, cfg.radar.n_samples
        row = sample_shape(n_s, fmt)
        self.grouper = ChannelGrouper(array_stream_ids(cfg), row, sample_dtype(fmt))
        self.ring = EchoRing(RING_PULSES, n_c * n_s, fmt)
        self.nav, self.aligner = nav_alignment(cfg, self.ring, RING_PULSES)
        self._scratch = np.empty((READ_PACKETS, *row), sample_dtype(fmt))
        self._row = row
        self._nav_rows: list[schema.NavRow] = []
        self.frame = StoreFrame()
        """The frame of the store's positions."""
        self._blocks: list[AlignedBlock] = []
        self._next_id = 0
        self.newest_ns: int | None = None
        self.summary = ArraySummary()

    def read_radar(self, source: Any) -> int:
        """Decode what ``source`` has now and commit the whole pulses to the ring.

        Returns the number of packets read (0: nothing now, or the end of a file).
        """
        packets = source.read_into(self._scratch, 0.0)
        for pulse in self.grouper.add(self._scratch, packets):
            slot = self.ring.reserve()
            if slot is None:  # the ring holds RING_PULSES; the caller polls between reads
                self.ring.note_dropped(1)
                continue
            slot.samples[...] = pulse.samples.reshape(slot.samples.shape)
            self.ring.commit(slot, pulse.t_ns, self._next_id, 0, pulse.flags)
            self._next_id += 1
            self.newest_ns = pulse.t_ns
        return len(packets)

    def add_nav(self, samples: list[Sample]) -> None:
        """Offer INS samples to the nav buffer and keep them for the store."""
        for s in samples:
            if isinstance(s, VelocitySample):
                s = self.frame.express(s)
            if isinstance(s, VelocitySample | AttitudeSample):
                self._nav_rows.append((s, None, self.nav.push_sample(s)))

    def process(self, now_ns: int) -> None:
        """Release the pulses the INS covers (or that waited too long) and record them."""
        while (block := self.aligner.poll(now_ns)) is not None:
            self._accept(block)

    def _accept(self, block: AlignedBlock) -> None:
        e = block.echoes
        n_p, n_c = len(e), self.cfg.radar.channels
        self.recorder.append_pulses(
            np.repeat(e.t_ns, n_c),
            np.repeat(e.pulse_id, n_c),
            np.tile(np.arange(n_c, dtype=np.int32), n_p),
            np.repeat(e.flags, n_c).astype(FLAG_DTYPE),
            e.samples.reshape(n_p * n_c, *self._row),
        )
        self.summary.pulses += n_p
        self.summary.nav_flagged += int(np.count_nonzero(~block.nav.valid))
        self._blocks.append(block)

    def finish(self) -> ArraySummary:
        """Release the rest, record the INS samples, image and record the DEMs."""
        g = self.grouper
        g.flush()
        self.summary.incomplete, self.summary.foreign = g.incomplete, g.foreign
        self.summary.duplicates = g.duplicates
        block = self.aligner.flush()
        if block is not None:
            self._accept(block)
        if self._nav_rows:
            self.recorder.append_nav(**schema.encode_nav(self._nav_rows))
            origin = schema.first_geodetic_origin(self._nav_rows)
            if origin is not None:
                self.recorder.set_attribute(
                    schema.GEODETIC_ORIGIN_ATTR, schema.encode_geodetic_origin(origin)
                )
        self._image()
        self.recorder.set_metrics(self.summary.as_dict())
        return self.summary

    def _image(self) -> None:
        """Image the pulses with navigation: roll compensated, and level if configured."""
        if not self._blocks:
            return
        valid = np.concatenate([b.nav.valid for b in self._blocks])
        if np.count_nonzero(valid) < 2:
            return
        t_ns = np.concatenate([b.nav.t_ns for b in self._blocks])[valid]
        vel = np.concatenate([b.nav.vel_ned for b in self._blocks])[valid]
        quat = np.concatenate([b.nav.quat for b in self._blocks])[valid]
        pos = np.concatenate([b.nav.pos_ned for b in self._blocks])[valid]
        n_c = self.cfg.radar.channels
        echoes = to_complex64(
            np.concatenate([b.echoes.samples for b in self._blocks])[valid].reshape(
                -1, n_c, *self._row
            )
        )
        if np.isnan(pos).any():  # an INS without position: its velocity integrated
            pos = integrate_velocity(NavSamples(t_ns, vel, quat)).pos_ned
            assert pos is not None
        pos = pos - pos[0] + np.array([0.0, 0.0, -self.cfg.geometry.height_m])
        self._blocks.clear()
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
        self.summary.dems[name] = {
            "cells": float(dem.height_m.size),
            "valid_cells": float(np.count_nonzero(ok)),
            "imaging_s": seconds,
        }
        self.recorder.add_dem(
            name,
            *schema.encode_dem(dem, self.system.height_resolution_m, self.cfg.geometry.height_m),
        )
        log.info("array DEM %s: %d cells in %.2f s", name, int(np.count_nonzero(ok)), seconds)


def replay_array_files(
    cfg: Config,
    radar_file: Path,
    nav_file: Path,
    out: Path,
) -> ArraySummary:
    """Replay an array run's ``.vrt`` and INS log into a new store on a virtual clock.

    As :func:`sarmoco.daemon.runner.replay_files`: the radar is read a block at a time, the
    INS read ahead to cover the newest pulse plus ``ins.max_gap_s``, the aligner's clock is
    the newest pulse time.

    Raises
    ------
    DataFileError
        When no pulse could be imaged (the store is closed complete): what each stream gave.
    """
    lead_ns = round(cfg.ins.max_gap_s * 1e9)
    with (
        open_radar(cfg, str(radar_file)) as radar,
        open_ins(cfg, str(nav_file), keep_raw=cfg.recorder.raw_ins) as ins,
        open_recorder(cfg, out) as recorder,
    ):
        pipe = ArrayPipeline(cfg, recorder)
        record_ins_format(recorder, ins)
        ahead: list[Sample] = []
        while pipe.read_radar(radar) or not radar.eof:
            _feed_ins(pipe, ins, ahead, pipe.newest_ns, lead_ns, recorder)
            if pipe.newest_ns is not None:
                pipe.process(pipe.newest_ns)
        _feed_ins(pipe, ins, ahead, None, lead_ns, recorder)
        summary = pipe.finish()
    if summary.pulses_imaged == 0:
        foreign = sorted(pipe.grouper.foreign_ids)
        raise DataFileError(
            f"array replay imaged no pulse: {summary.pulses} whole pulses "
            f"({summary.incomplete} dropped for missing channels, {summary.foreign} packets of "
            f"VITA streams {_id_list(foreign)} that are no Tx/Rx pair of array.stream_ids "
            f"{_id_list(list(pipe.grouper.channel_of))}), {summary.nav_flagged} without "
            f"navigation; radar {radar_file}, INS {nav_file}; store {out}"
        )
    return summary


def _id_list(ids: list[int], most: int = 8) -> str:
    """``ids`` in a message: the first ``most`` and how many more."""
    text = ", ".join(map(str, ids[:most]))
    return f"[{text}{f', ... {len(ids) - most} more' if len(ids) > most else ''}]"


def _feed_ins(
    pipe: ArrayPipeline,
    ins: Source,
    ahead: list[Sample],
    newest_ns: int | None,
    lead_ns: int,
    recorder: Recorder,
) -> None:
    """Read the INS until it covers ``newest_ns + lead_ns`` (all of it for None) and offer
    the samples due."""
    horizon = None if newest_ns is None else newest_ns + lead_ns
    while not ins.eof and (horizon is None or not ahead or ahead[-1].t_gps_ns < horizon):
        ahead += ins.poll(0.0)
        raw = ins.take_raw()
        if raw:
            recorder.append_ins_bytes(raw)
    due = len(ahead) if horizon is None else sum(s.t_gps_ns <= horizon for s in ahead)
    pipe.add_nav(ahead[:due])
    del ahead[:due]
