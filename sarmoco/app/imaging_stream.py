"""The pulses a replay would backproject, kept in a scratch zarr store for imaging elsewhere.

A batch (:mod:`sarmoco.app.batch`) replays a recording once with its imaging deferred:
each segment of the focuser hands what its tile imager would take (range-compressed,
compensated, autofocused, pre-filtered pulses, their imaging times, APCs, the ΔY
of eq. 29 and their beams' squint intervals) to a :class:`StreamSink`, which appends
them to ``seg_NNN/`` of a scratch store and remembers where each imager call began.
Blocks of tiles are then formed from it on any worker by replaying the calls whose
pulses' footprints reach the block
(:meth:`SegmentStream.calls_within`), so a block's tiles get exactly the calls, in the
same order and cut the same way, as in the single-process replay.

Scratch layout (zarr v3, one group per segment)::

    seg_000/  rc (pulse, bin) complex   pulses ready for backprojection
              t_ns (pulse) int64        imaging time, GPS ns
              apc_m (pulse, xyz) m      APC in the segment's imaging frame
              dy_m (pulse) m            compensated ΔY (eq. 29; absent when not used)
              beam_rad (pulse, bound)   squint interval of each pulse's beam, rad
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zarr

from sarmoco.daemon.focuser import TileFormer
from sarmoco.errors import RecorderError
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.processing.imaging.tiles import Tile, TileLayout
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray

SCRATCH_CHUNK_PULSES = 256
"""Pulses per chunk of the scratch arrays."""


@dataclass(frozen=True)
class SegmentStream:
    """One segment's kept pulses: where they are, what images them, how they were cut.

    Attributes
    ----------
    path : str
        The segment's group in the scratch store (a directory).
    track : ReferenceTrack
        The segment's reference track (the tiles' frame).
    layout : TileLayout
        The segment's tile layout.
    rows : ndarray of int64, shape (C + 1,)
        Row where each imager call began, then the row count.
    x_m : ndarray, shape (C, 2)
        Along-track extent (imaging x) of the beam footprints of each call's pulses on
        the swath (:meth:`TileLayout.reach_m`), least and greatest, m.
    with_dy : bool
        The calls carried the compensated ΔY of eq. 29.
    """

    path: str
    track: ReferenceTrack
    layout: TileLayout
    rows: IntArray
    x_m: FloatArray
    with_dy: bool

    @property
    def tiles(self) -> range:
        """Indices of the tiles the segment's imager forms (contiguous: the APC only
        advances along track; those wholly outside the layout's ``keep`` are not formed)."""
        if self.x_m.shape[0] == 0:
            return range(0)
        length = self.layout.tile_length_m
        first = math.floor(float(self.x_m[0, 0]) / length)
        last = math.floor(float(self.x_m[-1, 1]) / length)
        return self.layout.formed(range(first, last + 1))

    def calls_within(self, x_lo_m: float, x_hi_m: float) -> range:
        """The imager calls with a pulse whose footprint meets along-track
        ``x_lo_m <= x <= x_hi_m`` (m), and at least the first call that reaches ``x_lo_m``:
        after a gap in the pulses it may lie wholly beyond ``x_hi_m`` and still be the call
        that opens a tile of the span (with no pulse in it, and its start time from that
        call)."""
        c0 = int(np.searchsorted(self.x_m[:, 1], x_lo_m, side="left"))
        c1 = int(np.searchsorted(self.x_m[:, 0], x_hi_m, side="right"))
        return range(c0, max(c1, min(c0 + 1, self.x_m.shape[0])))

    def read(
        self, call: int
    ) -> tuple[ComplexArray, IntArray, FloatArray, FloatArray | None, FloatArray]:
        """Pulses, times (GPS ns), APCs (m), ΔY (m, or None) and beam squint intervals
        (rad, (P, 2)) of imager call ``call``."""
        group = zarr.open_group(self.path, mode="r", zarr_format=3)
        rows = slice(int(self.rows[call]), int(self.rows[call + 1]))

        def column(name: str) -> np.ndarray:
            arr = group[name]
            assert isinstance(arr, zarr.Array)
            return np.asarray(arr[rows])

        dy = column("dy_m") if self.with_dy else None
        return column("rc"), column("t_ns"), column("apc_m"), dy, column("beam_rad")


@dataclass
class StreamSink:
    """Keeps one segment's pulses in the scratch store instead of backprojecting them.

    Parameters
    ----------
    path : Path
        The segment's group to create in the scratch store.
    imager : TileFormer
        The imager the segment would have used (its layout is kept).
    track : ReferenceTrack
        The segment's reference track.
    """

    path: Path
    imager: TileFormer
    track: ReferenceTrack
    _rows: list[int] = field(default_factory=lambda: [0])
    _x: list[tuple[float, float]] = field(default_factory=list)
    _with_dy: bool | None = None

    def add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None = None,
        beam_squint_rad: FloatArray | None = None,
    ) -> list[Tile]:
        """Append one imager call's pulses (see :meth:`TileImager.add`); no tile comes out."""
        if rc.shape[0] == 0:
            return []
        beam = (
            self.imager.layout.broadside_rad(rc.shape[0])
            if beam_squint_rad is None
            else np.asarray(beam_squint_rad, dtype=np.float64)
        )
        with_dy = compensated_dy_m is not None
        if self._with_dy is None:
            self._create(rc, with_dy)
        elif with_dy != self._with_dy:
            raise RecorderError(f"{self.path}: ΔY given to some imager calls only")
        group = zarr.open_group(str(self.path), mode="r+", zarr_format=3)
        columns = {"rc": rc, "t_ns": t_ns, "apc_m": apc_m, "beam_rad": beam}
        if compensated_dy_m is not None:
            columns["dy_m"] = compensated_dy_m
        for name, value in columns.items():
            arr = group[name]
            assert isinstance(arr, zarr.Array)
            arr.append(np.asarray(value, dtype=arr.dtype))
        self._rows.append(self._rows[-1] + rc.shape[0])
        back, ahead = self.imager.layout.reach_m(beam)
        self._x.append((float((apc_m[:, 0] + back).min()), float((apc_m[:, 0] + ahead).max())))
        return []

    def _create(self, rc: ComplexArray, with_dy: bool) -> None:
        group = zarr.open_group(str(self.path), mode="w-", zarr_format=3)
        specs = [
            ("rc", rc.dtype, (rc.shape[1],), ("pulse", "bin")),
            ("t_ns", np.dtype(np.int64), (), ("pulse",)),
            ("apc_m", np.dtype(np.float64), (3,), ("pulse", "xyz")),
            ("beam_rad", np.dtype(np.float64), (2,), ("pulse", "bound")),
        ]
        if with_dy:
            specs.append(("dy_m", np.dtype(np.float64), (), ("pulse",)))
        for name, dtype, shape, dims in specs:
            group.create_array(
                name,
                shape=(0, *shape),
                chunks=(SCRATCH_CHUNK_PULSES, *shape),
                dtype=dtype,
                dimension_names=dims,
                compressors=None,
            )
        self._with_dy = with_dy

    def close(self) -> list[Tile]:
        """End of the segment: nothing is open (no tile comes out)."""
        return []

    def stream(self) -> SegmentStream:
        """What was kept, for the workers that image it."""
        return SegmentStream(
            path=str(self.path),
            track=self.track,
            layout=self.imager.layout,
            rows=np.asarray(self._rows, dtype=np.int64),
            x_m=np.asarray(self._x, dtype=np.float64).reshape(-1, 2),
            with_dy=bool(self._with_dy),
        )


@dataclass
class StreamRecorder:
    """The sink factory of a deferred replay: one :class:`StreamSink` per segment, in order.

    Parameters
    ----------
    scratch : Path
        Scratch store to create (``seg_000``, ``seg_001``... inside).
    """

    scratch: Path
    sinks: list[StreamSink] = field(default_factory=list)

    def __call__(self, imager: TileFormer, track: ReferenceTrack) -> StreamSink:
        """The sink of the next segment (:data:`~sarmoco.daemon.focuser.SinkFactory`)."""
        if not self.sinks:
            zarr.open_group(str(self.scratch), mode="w-", zarr_format=3)
        sink = StreamSink(self.scratch / f"seg_{len(self.sinks):03d}", imager, track)
        self.sinks.append(sink)
        return sink

    def streams(self) -> list[SegmentStream]:
        """Every segment's stream, in the order the segments began."""
        return [sink.stream() for sink in self.sinks]
