"""Recording of a run's tables, and the run's totals.

:class:`RunTables` is what the data path writes through: the pulses taken out of the
echo ring (raw echoes, time, flags), the INS samples and bytes received, the navigation
flags of the aligned pulses, the motion solution of each pulse, the autofocus estimates,
the Doppler centroids and the focused tiles, with the store attributes that go with them
(reference track, geodetic origin, run metrics). Each write counts what it wrote in the
run's :class:`RunSummary`. The recording path and the focusing path both write here; the
recorder (:class:`~sarmoco.store.recorder.Recorder`) takes calls from both threads.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sarmoco.daemon.aligner import AlignedBlock
from sarmoco.daemon.backlog import FocusBacklog, RecordedBatch
from sarmoco.daemon.echoring import EchoRing
from sarmoco.daemon.focuser import FocusOutput, nan_motion
from sarmoco.daemon.ingest import InsIngest
from sarmoco.daemon.navigation import NavPulses, recorded
from sarmoco.processing.autofocus import SlidingSubapertureAutofocus
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.processing.imaging.tiles import Tile
from sarmoco.processing.metrics import image_contrast, image_entropy
from sarmoco.processing.mocomp import MocompSolution
from sarmoco.processing.types import ComplexArray
from sarmoco.store import schema
from sarmoco.store.flags import NAV_FLAGS, PulseFlag
from sarmoco.store.recorder import Recorder

RECORD_UNIT_PULSES = 128
"""Pulses taken out of the echo ring and stored together by :meth:`RunTables.store_pulses`:
arrays of one size, which the ring reuses (:meth:`~sarmoco.daemon.echoring.EchoRing.pop`)."""
RECORD_PART_WAIT_S = 0.1
"""Pulses due that make less than a unit are taken once the oldest of them has been due
this long, s (the radar paused or stopped, or a low PRF)."""
_PART_WAIT_NS = round(RECORD_PART_WAIT_S * 1e9)
INS_RECORD_S = 0.25
"""Queued INS samples and raw INS bytes go to the store at most this often (host clock):
each write costs milliseconds, s."""


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
        """JSON-able form: the fields by name, a float that is not finite as None (JSON
        has no NaN)."""
        return {
            k: None if isinstance(v, float) and not math.isfinite(v) else v
            for k, v in dataclasses.asdict(self).items()
        }

    def counts(self) -> dict[str, int]:
        """The pulse and sample counts (every integer field), by name."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, int):
                out[f.name] = value
        return out


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


class RunTables:
    """The writes of one run into its store, counted in :attr:`summary`.

    Parameters
    ----------
    recorder : Recorder
        The run's store.
    """

    def __init__(self, recorder: Recorder) -> None:
        self.recorder = recorder
        self.summary = RunSummary()
        self.recorded_ns: int | None = None
        """Time of the newest pulse stored, GPS ns."""
        self._nav_recorded_mono = -math.inf
        self._geodetic_origin: schema.GeodeticOrigin | None = None

    # -- the recording path -----------------------------------------------------------------

    def store_pulses(
        self, ring: EchoRing, backlog: FocusBacklog, hold_ns: int | None, skips: bool
    ) -> int:
        """Store the pulses waiting in ``ring`` and put them in ``backlog``; returns the
        pulses stored.

        Parameters
        ----------
        ring : EchoRing
            The run's echo ring, taken from oldest first, :data:`RECORD_UNIT_PULSES` at a
            time (fewer only once they have waited :data:`RECORD_PART_WAIT_S`, or with
            ``hold_ns`` None).
        backlog : FocusBacklog
            Where the stored pulses wait for focusing.
        hold_ns : int or None
            Pulses later than this (GPS ns) stay in the ring (a late datagram may still go
            before them); None: every pulse is taken.
        skips : bool
            The backlog may skip ahead (live focusing); otherwise no more pulses are taken
            than it has room for.
        """
        stored, unit = 0, RECORD_UNIT_PULSES
        while True:
            t = ring.peek_times(unit)
            k = t.size if hold_ns is None else int(np.searchsorted(t, hold_ns, side="right"))
            if hold_ns is not None and 0 < k < unit and t[0] > hold_ns - _PART_WAIT_NS:
                k = 0  # a part of a unit: it waits for the rest
            if not skips:
                k = min(k, backlog.free)
            if k == 0:
                break
            e = ring.pop(k)
            first = self.recorder.pulses.rows
            self.recorder.append_pulses(e.t_ns, e.pulse_id, e.channel, e.flags, e.samples)
            row = np.arange(first, first + k, dtype=np.int64)
            backlog.put(RecordedBatch(e.samples, e.t_ns, e.pulse_id, e.channel, e.flags, row))
            self.summary.pulses_received += k
            self.recorded_ns = int(e.t_ns[-1])
            stored += k
            if k < unit:
                break
        return stored

    def nav_due(self) -> bool:
        """Whether :data:`INS_RECORD_S` has passed since the INS was last stored."""
        return time.monotonic() - self._nav_recorded_mono >= INS_RECORD_S

    def store_nav(self, ins: InsIngest) -> None:
        """Write the INS samples and raw INS bytes ``ins`` queued (the bytes as one chunk
        whose ``rx_ns`` is that of its newest part); the first absolute position sets the
        store's geodetic origin."""
        self._nav_recorded_mono = time.monotonic()
        chunks = ins.take_raw()
        if chunks:
            rx_ns = chunks[-1][1]
            data = b"".join(c for c, _ in chunks)
            self.recorder.append_ins_bytes(data, -1 if rx_ns is None else rx_ns)
        rows = ins.take_rows()
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

    # -- the focusing path ------------------------------------------------------------------

    def nav_flags(self, block: AlignedBlock) -> None:
        """Flag the pulses of ``block`` with the navigation flags the aligner gave them."""
        e = recorded(block)
        nav_flags = e.flags & np.uint32(NAV_FLAGS)
        for flag in np.unique(nav_flags[nav_flags != 0]).tolist():
            self.recorder.flag_pulses(e.row[nav_flags == flag], flag)

    def reference_track(self, track: ReferenceTrack) -> None:
        """Record the run's first reference track."""
        self.recorder.set_attribute(
            schema.REFERENCE_TRACK_ATTR, schema.encode_reference_track(track)
        )

    def motion(self, p: NavPulses, out: FocusOutput) -> None:
        """Record the motion solution of pulses ``p`` pushed to the focuser, flag its turn
        pulses, and count them processed (with navigation) or unfocused."""
        assert out.motion is not None
        self._append_motion(p, out.motion)
        if out.turn.any():
            self.recorder.flag_pulses(p.row[out.turn], PulseFlag.TURN)
        self.summary.pulses_processed += int(np.count_nonzero(p.usable))
        self.summary.pulses_unfocused += int(np.count_nonzero(~p.usable))

    def unfocused(self, p: NavPulses) -> None:
        """Record pulses before the aperture begins (none has navigation, or all were taken
        under other radar parameters) in the motion table without a solution, and count
        them (:attr:`RunSummary.pulses_unfocused`)."""
        if len(p) == 0:
            return
        self._append_motion(p, nan_motion(p.t_ns))
        self.summary.pulses_unfocused += len(p)

    def products(self, out: FocusOutput, engine: SlidingSubapertureAutofocus | None) -> None:
        """Record the autofocus estimates ``engine`` made so far (None: autofocus off), the
        Doppler centroids and the tiles of ``out``."""
        if engine is not None:
            subs = engine.take_report().subapertures
            if subs:
                self.recorder.append_rows(schema.AUTOFOCUS, schema.encode_autofocus(subs))
        if out.doppler:
            self.recorder.append_rows(schema.DOPPLER, schema.encode_doppler(out.doppler))
            last = out.doppler[-1]
            self.summary.doppler_attitude_hz = last.attitude_hz
            self.summary.doppler_echo_hz = last.echo_hz
        for tile, track in zip(out.tiles, out.tracks, strict=True):
            metrics = recorded_tile_metrics(tile)
            self.recorder.add_image(
                tile.image(), tile.t0_ns, tile.t1_ns, metrics, schema.encode_reference_track(track)
            )
            self.summary.tiles += 1
            self.summary.tile_metrics.append(metrics)

    def _append_motion(self, p: NavPulses, m: MocompSolution) -> None:
        """Record the navigation and the motion solution ``m`` of pulses ``p``."""
        self.recorder.append_motion(
            p.pulse_id, p.t_ns, p.pos_ned, p.vel_ned, p.quat, m.d_los_m, m.phase_rad,
            m.range_shift_m,
        )  # fmt: skip
