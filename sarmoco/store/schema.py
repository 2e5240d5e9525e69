"""The run store's schema: every table, column, dtype and attribute, and their codecs.

This module is the one owner of the store layout. The recorder
(:mod:`sarmoco.store.recorder`) creates what is declared here, the pipeline
encodes its rows with the encoders here, and the reader
(:mod:`sarmoco.store.reader`) and the replay decode them with the decoders
beside them. A change of the layout is a change of this file (and of
:data:`STORE_LAYOUT_VERSION`).

Layout (every group but ``images`` is a *table*: arrays that share their first
dimension, plus a ``committed`` attribute counting the rows that are complete)::

    <run>.zarr/   attrs: sarmoco_store (layout version), created_utc, config, versions,
                         metrics, complete, reference_track, ins_raw (format of ins_bytes),
                         geodetic_origin (:func:`encode_geodetic_origin`: the tangent
                         point of the NED frame of nav/pos_ned and motion/pos_ned),
                         captures (live runs: ``intervals``, the capture intervals'
                         ``start_utc`` and ``stop_utc``, ISO 8601; pulses outside them
                         are not recorded)
      pulses/     t_ns, pulse_id (pulse) int64    transmit time GPS ns, running number
                  channel (pulse) int32, flags (pulse) uint32 (PulseFlag bits)
                  echo (pulse, sample[, iq])      raw echoes, int16 I/Q or complex64 (optional)
      nav/        t_ns, rx_ns (nav) int64         INS samples as received (rx_ns: host
                  kind (nav) uint8                receive clock, -1 unknown); kind
                  vel_ned (nav, ned) m/s          NAV_KIND_VELOCITY or NAV_KIND_ATTITUDE;
                  pos_ned (nav, ned) m            fields a sample lacks are NaN;
                  quat (nav, wxyz)                result: PushResult of the nav buffer;
                  result (nav) int8               lla: the INS's valid geodetic position
                  lla (nav, lat_lon_alt) deg, deg, m (lat, lon WGS-84, altitude)
      ins_raw/    rx_ns, offset, length (raw_chunk) int64: raw INS bytes as read,
      ins_bytes/  byte (byte) uint8                so a log can be decoded again
      motion/     pulse_id, t_ns (motion) int64; pos_ned m, vel_ned m/s (motion, ned);
                  quat (motion, wxyz); d_los_m m, phase_rad rad, range_shift_m m (motion)
      autofocus/  one row per subaperture estimate (:data:`AUTOFOCUS_COLUMNS`)
      doppler/    one row per processing block: Doppler centroid from the attitude and
                  from the echoes (:data:`DOPPLER_COLUMNS`)
      images/     attrs committed = tiles complete; tile_000000/ ... each with
                  data (axis0, axis1) complex64, axis0_m (axis0), axis1_m (axis1),
                  attrs frame, t0_ns, t1_ns, metrics, reference_track (the segment's
                  track, :func:`encode_reference_track`: the axes are in its frame)
      dem/        array mode only (:func:`encode_dem`): compensated/ and uncompensated/,
                  each height_m (x, y) float64 m up, x_m (x), y_m (y) imaging-frame m;
                  attrs reference_track, compensated, blocks, height_resolution_m,
                  datum_depth_m (an optional group: stores without it read as before)
      north_up/   written after a replay (optional): image_00/ ... one per reference-track
                  segment, the tiles resampled onto a north/east grid, each with
                  data (north, east) complex64, north_m (north), east_m (east), attrs
                  frame (the NED frame and origin of the coordinates), segment_tiles

Names: times are integers in ns with the unit in the name (``t_ns``, ``rx_ns``);
scalar physical columns carry their unit (``d_los_m``, ``a_y_mps2``); NED vectors
(``vel_ned``, ``pos_ned``) and quaternions are SI (m, m/s; body to NED, scalar
first) as everywhere in the processing arrays, the unit stated here and in the
docstrings.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from zarr.codecs import BloscCodec, Crc32cCodec, ZstdCodec
from zarr.core.array_spec import ArrayConfigParams

from sarmoco.drivers.samples import (
    AttitudeSample,
    EchoPackets,
    SampleFormat,
    TangentFrame,
    Validity,
    VelocitySample,
    sample_dtype,
    sample_shape,
)
from sarmoco.errors import RecorderError
from sarmoco.processing.array.imaging3d import DemProduct
from sarmoco.processing.autofocus.report import SubapertureReport
from sarmoco.processing.beam import DopplerCentroid
from sarmoco.processing.geometry import ReferenceTrack
from sarmoco.store.flags import FLAG_DTYPE, PulseFlag, PushResult

STORE_LAYOUT_VERSION = 2
"""Value of the root attribute :data:`LAYOUT_ATTR`; bumped when the layout changes."""
LAYOUT_ATTR = "sarmoco_store"
"""Root attribute that marks a sarmoco store (its value: the layout version)."""
COMPLETE_ATTR = "complete"
"""Root attribute: false while the run is written, true after a clean close."""
COMMITTED_ATTR = "committed"
"""Group attribute holding the number of complete rows (tiles for ``images``)."""
REFERENCE_TRACK_ATTR = "reference_track"
"""Root attribute: the run's reference track (:func:`encode_reference_track`)."""
INS_RAW_ATTR = "ins_raw"
"""Root attribute ``{"format": ...}`` naming the format of ``ins_bytes`` when kept."""
GEODETIC_ORIGIN_ATTR = "geodetic_origin"
"""Root attribute: where on Earth the run is (:func:`encode_geodetic_origin`)."""
NO_ABSOLUTE_POSITION = "no INS sample with a valid geodetic position"
"""``geodetic_origin.absent`` of a store whose INS gave no absolute position."""

NAV_KIND_VELOCITY, NAV_KIND_ATTITUDE = 0, 1
"""Values of ``nav/kind``: a :class:`VelocitySample` or an :class:`AttitudeSample` row."""

NAV_SAMPLE_COLUMNS = ("t_ns", "kind", "vel_ned", "pos_ned", "quat", "lla")
"""Columns of ``nav`` that :func:`decode_nav` reads."""
NavSample = VelocitySample | AttitudeSample
"""The INS samples the ``nav`` table holds."""
NavRow = tuple[NavSample, int | None, PushResult]
"""A sample as the pipeline queues it: sample, host receive clock (ns, None unknown), result."""


@dataclass(frozen=True)
class Column:
    """One array of a table.

    Attributes
    ----------
    dtype : numpy dtype
        Element type.
    shape : tuple of int
        Trailing shape of a row (``()`` for a scalar column).
    dims : tuple of str
        Names of the trailing dimensions (one per entry of ``shape``).
    """

    dtype: np.dtype[Any]
    shape: tuple[int, ...] = ()
    dims: tuple[str, ...] = ()


def _col(dtype: npt.DTypeLike, shape: tuple[int, ...] = (), dims: tuple[str, ...] = ()) -> Column:
    return Column(np.dtype(dtype), shape, dims)


@dataclass(frozen=True)
class TableSpec:
    """A table of the store: a group whose arrays share their first (row) dimension.

    Attributes
    ----------
    name : str
        Group name.
    row_dim : str
        Name of the first dimension.
    columns : mapping of str to Column
        The arrays.
    per_pulse : bool
        Rows are pulses (chunked like the pulses) rather than other records.
    chunk_rows : int or None
        Rows per chunk when fixed by the layout (None: the recorder's setting).
    compressors : mapping of str to codec or None
        Columns not stored with zarr's default compression: their compressor (a zarr
        codec), or None for none (:func:`pulses_table`'s raw echoes).
    coords : tuple of str
        Columns that are coordinates of the others (times along the row dimension): every
        other column names them in its ``coordinates`` attribute (CF and xarray
        convention), so ``xarray.open_zarr(store, group=table)`` makes them coordinates.
    """

    name: str
    row_dim: str
    columns: Mapping[str, Column]
    per_pulse: bool = False
    chunk_rows: int | None = None
    compressors: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    coords: tuple[str, ...] = ()

    def column_attrs(self, name: str) -> dict[str, Any]:
        """Attributes of column ``name``: the ``coordinates`` it has (none for a coordinate)."""
        if name in self.coords or not self.coords:
            return {}
        return {"coordinates": " ".join(self.coords)}


ECHO_COMPRESSION: Mapping[str, Any] = {
    "none": None,
    "lz4-bitshuffle": BloscCodec(cname="lz4", clevel=5, shuffle="bitshuffle"),
}
"""Lossless compressors of the raw echoes, by name (``recorder.echo_compression``). Echoes
are mostly receiver noise, whose low bits are random: a byte compressor (zstd) finds little
in them; a bit shuffle gathers the high bits of the samples, which a signal using part of
the ADC's range leaves alike, and lz4 packs those fast."""


CHUNK_CHECKSUM = Crc32cCodec()
"""The last codec of every array of a store: a CRC-32C of each stored chunk (as compressed),
checked whenever the chunk is read; ``sarmoco verify`` reads every chunk."""
DEFAULT_COMPRESSOR = ZstdCodec(level=0, checksum=False)
"""Compressor of the arrays not named otherwise (zarr's own default for numbers)."""


CHUNK_CONFIG: ArrayConfigParams = {"write_empty_chunks": True}
"""Runtime configuration of every array written (not stored in the metadata: an array
opened again for writing needs it again, ``Array.with_config``): every chunk is written."""


def chunk_codecs(compressor: Any = DEFAULT_COMPRESSOR) -> dict[str, Any]:
    """Keyword arguments of ``zarr.Group.create_array`` for an array of a store.

    The compressor (None: none) then :data:`CHUNK_CHECKSUM`; and every chunk is written
    even when it holds only the fill value, so that a chunk missing from a store is damage
    (a lost file), never an empty chunk left out.
    """
    codecs = () if compressor is None else (compressor,)
    return {"compressors": (*codecs, CHUNK_CHECKSUM), "config": dict(CHUNK_CONFIG)}


def pulses_table(
    n_samples: int, sample_format: SampleFormat, raw_echoes: bool, echo_compression: str = "none"
) -> TableSpec:
    """The ``pulses`` table for echoes of ``n_samples`` complex samples in ``sample_format``,
    compressed with :data:`ECHO_COMPRESSION` ``[echo_compression]``.

    Raises
    ------
    RecorderError
        ``echo_compression`` is not a key of :data:`ECHO_COMPRESSION`.
    """
    if echo_compression not in ECHO_COMPRESSION:
        raise RecorderError(
            f"echo compression {echo_compression!r} is not one of {sorted(ECHO_COMPRESSION)}"
        )
    columns = {
        "t_ns": _col(np.int64),
        "pulse_id": _col(np.int64),
        "channel": _col(np.int32),
        "flags": _col(FLAG_DTYPE),
    }
    if raw_echoes:
        dims = ("sample",) if sample_format == "complex64" else ("sample", "iq")
        shape = sample_shape(n_samples, sample_format)
        columns["echo"] = _col(sample_dtype(sample_format), shape, dims)
    return TableSpec(
        "pulses",
        "pulse",
        columns,
        per_pulse=True,
        compressors={"echo": ECHO_COMPRESSION[echo_compression]},
        coords=("t_ns",),
    )


NAV = TableSpec(
    "nav",
    "nav",
    {
        "t_ns": _col(np.int64),
        "rx_ns": _col(np.int64),
        "kind": _col(np.uint8),
        "vel_ned": _col(np.float64, (3,), ("ned",)),
        "pos_ned": _col(np.float64, (3,), ("ned",)),
        "quat": _col(np.float64, (4,), ("wxyz",)),
        "result": _col(np.int8),
        "lla": _col(np.float64, (3,), ("lat_lon_alt",)),
    },
    coords=("t_ns",),
)
INS_RAW = TableSpec(
    "ins_raw",
    "raw_chunk",
    {"rx_ns": _col(np.int64), "offset": _col(np.int64), "length": _col(np.int64)},
)
INS_BYTES = TableSpec("ins_bytes", "byte", {"byte": _col(np.uint8)}, chunk_rows=1 << 16)
MOTION = TableSpec(
    "motion",
    "motion",
    {
        "pulse_id": _col(np.int64),
        "t_ns": _col(np.int64),
        "pos_ned": _col(np.float64, (3,), ("ned",)),
        "vel_ned": _col(np.float64, (3,), ("ned",)),
        "quat": _col(np.float64, (4,), ("wxyz",)),
        "d_los_m": _col(np.float64),
        "phase_rad": _col(np.float64),
        "range_shift_m": _col(np.float64),
    },
    per_pulse=True,
    coords=("t_ns",),
)

AUTOFOCUS_COLUMNS: Mapping[str, tuple[Column, Callable[[SubapertureReport], Any]]] = {
    "t_center_s": (_col(np.float64), lambda s: s.t_center_s),
    "a_y_mps2": (_col(np.float64), lambda s: s.accel_yz_mps2[0]),
    "a_z_mps2": (_col(np.float64), lambda s: s.accel_yz_mps2[1]),
    "accel_residual_hz_per_s": (_col(np.float64), lambda s: s.accel_residual_hz_per_s),
    "kappa": (_col(np.float64, (3,), ("kappa_order",)), lambda s: s.kappa),
    "kappa_residual_hz_per_s": (_col(np.float64), lambda s: s.kappa_residual_hz_per_s),
    "applied": (_col(np.bool_), lambda s: s.applied),
}
"""Columns of the ``autofocus`` table, each with the field of a
:class:`~sarmoco.processing.autofocus.report.SubapertureReport` it records: centre time
(s on the autofocus time axis), cross-track accelerations a_y, a_z (m/s²) and the
residual of their fit (Hz/s), the rate model κ0, κ1, κ2 (Hz/s, Hz/s/m, Hz/s/m²) and
its residual (Hz/s), and whether the corrections were applied (False where they would
have lowered the focus of the block released with them: the autofocus never makes it
worse). A new column is one entry here."""
AUTOFOCUS = TableSpec(
    "autofocus",
    "subaperture",
    {name: col for name, (col, _) in AUTOFOCUS_COLUMNS.items()},
    coords=("t_center_s",),
)

DOPPLER_COLUMNS: Mapping[str, tuple[Column, Callable[[DopplerCentroid], Any]]] = {
    "t_ns": (_col(np.int64), lambda d: d.t_ns),
    "squint_rad": (_col(np.float64), lambda d: d.squint_rad),
    "attitude_hz": (_col(np.float64), lambda d: d.attitude_hz),
    "echo_hz": (_col(np.float64), lambda d: d.echo_hz),
}
"""Columns of the ``doppler`` table, one row per processing block, each with the field of a
:class:`~sarmoco.processing.beam.DopplerCentroid` it records: the block's first pulse (GPS
ns), the beam centre's squint from the attitude and the antenna mount (rad, positive
ahead), the Doppler centroid from them (Hz) and the one measured from the echoes (Hz,
NaN where not measured). The two disagree by much more than the estimator's noise when
the mount or the attitude source is wrong."""
DOPPLER = TableSpec(
    "doppler",
    "block",
    {name: col for name, (col, _) in DOPPLER_COLUMNS.items()},
    coords=("t_ns",),
)

FIXED_TABLES = ("pulses", NAV.name, INS_RAW.name, INS_BYTES.name, MOTION.name)
"""Tables every store has from its creation (the others appear with their first row)."""

IMAGES_GROUP = "images"
"""Group of the image tiles (not a table: one sub-group per tile)."""


def tile_name(index: int) -> str:
    """Group name of image tile ``index`` inside :data:`IMAGES_GROUP`."""
    return f"tile_{index:06d}"


TILE_DIMS = ("axis0", "axis1")
"""Dimensions of a tile's ``data``: along the reference track, then ground range."""
TILE_COORDS = ("axis0_m", "axis1_m")
"""A tile's coordinate arrays (imaging-frame metres, one per entry of :data:`TILE_DIMS`)."""

NORTH_UP_GROUP = "north_up"
"""Group of the north-up images (:func:`north_up_name`), written after a replay."""
NORTH_UP_DIMS = ("north", "east")
"""Dimension names of a north-up image's ``data``."""
NORTH_UP_COORDS = ("north_m", "east_m")
"""Coordinate arrays of a north-up image (m, NED in the frame its ``frame`` attribute names)."""


def north_up_name(segment: int) -> str:
    """Group name of reference-track segment ``segment``'s image inside :data:`NORTH_UP_GROUP`."""
    return f"image_{segment:02d}"


DEM_GROUP = "dem"
"""Group of an array run's DEM products (not a table: one sub-group per product)."""
DEM_DIMS = ("x", "y")
"""Dimensions of a DEM's ``height_m``: along the reference track, then across it."""
DEM_ARRAYS = {"height_m": DEM_DIMS, "x_m": ("x",), "y_m": ("y",)}
"""A DEM product's arrays and their dimensions: heights (m, up, NaN where no echo) and the
imaging-frame axes (m) of its reference track."""


def encode_tile_attrs(
    frame: str,
    t0_ns: int,
    t1_ns: int,
    metrics: Mapping[str, float] | None,
    reference_track: Mapping[str, Any] | None,
) -> dict[str, Any]:
    """A tile group's attributes: ``frame``, the GPS ns span ``t0_ns``/``t1_ns`` of the
    pulses that formed it, ``metrics`` (floats) and, when given, ``reference_track``
    (:func:`encode_reference_track`: the axes are in its imaging frame)."""
    attrs = {
        "frame": frame,
        "t0_ns": int(t0_ns),
        "t1_ns": int(t1_ns),
        "metrics": {k: float(v) for k, v in (metrics or {}).items()},
    }
    if reference_track is not None:
        attrs["reference_track"] = dict(reference_track)
    return attrs


# -- attributes (untrusted JSON) -----------------------------------------------------------


def read_attr(attrs: Mapping[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    """An attribute of a store read back, checked to be of the type the layout writes.

    Zarr attributes are JSON from a file that may be damaged or not ours: nothing read
    from them is used before its type is checked (and nothing is ever evaluated).

    Parameters
    ----------
    attrs : mapping
        The node's attributes.
    key : str
        Attribute name.
    kind : type or tuple of type
        Allowed Python types (``bool`` is not accepted for ``int``).
    where : str
        The node, for the message (e.g. ``run.zarr/pulses``).

    Raises
    ------
    RecorderError
        Naming ``where.key`` when the attribute is missing or of another type.
    """
    if key not in attrs:
        raise RecorderError(f"{where}.{key}: attribute missing")
    value = attrs[key]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        names = " or ".join(k.__name__ for k in kinds)
        raise RecorderError(f"{where}.{key}: {value!r} is not a {names}")
    return value


def read_committed(attrs: Mapping[str, Any], where: str) -> int:
    """The :data:`COMMITTED_ATTR` row count of a table: an int >= 0 (see :func:`read_attr`)."""
    value: int = read_attr(attrs, COMMITTED_ATTR, int, where)
    if value < 0:
        raise RecorderError(f"{where}.{COMMITTED_ATTR}: {value!r} is not >= 0")
    return value


# -- codecs ---------------------------------------------------------------------------------


def encode_nav(rows: Sequence[NavRow]) -> dict[str, npt.NDArray[Any]]:
    """Columns of the ``nav`` table for INS samples as the pipeline received them.

    Parameters
    ----------
    rows : sequence of (sample, rx_ns, result)
        Velocity or attitude sample, host receive clock (ns; None: unknown, stored as
        -1) and what the nav buffer did with it.

    Returns
    -------
    dict of str to ndarray
        Every column of :data:`NAV`; the fields a sample lacks are NaN.
    """
    n = len(rows)
    cols: dict[str, npt.NDArray[Any]] = {
        "t_ns": np.fromiter((s.t_gps_ns for s, _, _ in rows), np.int64, n),
        "rx_ns": np.fromiter((-1 if rx is None else rx for _, rx, _ in rows), np.int64, n),
        "kind": np.empty(n, np.uint8),
        "vel_ned": np.full((n, 3), math.nan),
        "pos_ned": np.full((n, 3), math.nan),
        "quat": np.full((n, 4), math.nan),
        "result": np.fromiter((int(res) for _, _, res in rows), np.int8, n),
        "lla": np.full((n, 3), math.nan),
    }
    for i, (s, _, _) in enumerate(rows):
        if isinstance(s, VelocitySample):
            cols["kind"][i] = NAV_KIND_VELOCITY
            cols["vel_ned"][i] = s.vel_ned
            if s.pos_ned is not None:
                cols["pos_ned"][i] = s.pos_ned
            if s.lat_lon_alt is not None and s.valid & Validity.POSITION:
                cols["lla"][i] = s.lat_lon_alt
        else:
            cols["kind"][i] = NAV_KIND_ATTITUDE
            cols["quat"][i] = s.quat
    return cols


def decode_nav(
    cols: Mapping[str, npt.NDArray[Any]],
    source: str = "store.nav",
    frame: TangentFrame | None = None,
) -> list[NavSample]:
    """INS samples back from rows of the ``nav`` table (:func:`encode_nav` inverted).

    Parameters
    ----------
    cols : mapping of str to ndarray
        Columns ``t_ns``, ``kind``, ``vel_ned``, ``pos_ned``, ``quat``, ``lla`` of some rows.
    source : str
        ``source`` of the samples made.
    frame : TangentFrame or None
        The frame of the rows' ``pos_ned`` (the store's ``geodetic_origin``), given to
        the samples with a position.

    Returns
    -------
    list of VelocitySample or AttitudeSample
        In row order. The store keeps no validity bits or device time: a velocity is
        ``VELOCITY`` (and ``POSITION`` with a local or geodetic position), an attitude
        ``ATTITUDE | HEADING``, and the device time is the GPS time.

    Raises
    ------
    RecorderError
        A row's ``kind`` is not one of the ``NAV_KIND_*`` values.
    """
    out: list[NavSample] = []
    for t, kind, v, p, q, g in zip(
        cols["t_ns"].tolist(),
        cols["kind"].tolist(),
        cols["vel_ned"].tolist(),
        cols["pos_ned"].tolist(),
        cols["quat"].tolist(),
        cols["lla"].tolist(),
        strict=True,
    ):
        if kind == NAV_KIND_ATTITUDE:
            valid = Validity.ATTITUDE | Validity.HEADING
            out.append(AttitudeSample(t, (q[0], q[1], q[2], q[3]), valid, source, t))
        elif kind == NAV_KIND_VELOCITY:
            pos = None if any(map(math.isnan, p)) else (p[0], p[1], p[2])
            lla = None if any(map(math.isnan, g)) else (g[0], g[1], g[2])
            valid = Validity.VELOCITY | (Validity.POSITION if pos or lla else Validity.NONE)
            out.append(
                VelocitySample(
                    t,
                    (v[0], v[1], v[2]),
                    valid,
                    source,
                    t,
                    pos,
                    lat_lon_alt=lla,
                    pos_frame=frame if pos else None,
                )
            )
        else:
            raise RecorderError(f"nav/kind: {kind} is not a sample kind (0 velocity, 1 attitude)")
    return out


def decode_pulses(cols: Mapping[str, npt.NDArray[Any]], n_samples: int) -> EchoPackets:
    """The radar packet metadata of recorded pulses (for a replay through the radar path).

    The receiver and link bits of ``flags`` (:meth:`PulseFlag.of_packets`) become the
    packet's indicators again; the packet count is not recorded (0).

    Parameters
    ----------
    cols : mapping of str to ndarray
        Columns ``t_ns``, ``channel``, ``flags`` of some rows of ``pulses``.
    n_samples : int
        Complex samples per pulse.
    """
    flags = np.asarray(cols["flags"])
    return EchoPackets(
        n_samples,
        stream_id=np.asarray(cols["channel"], np.int64),
        t_gps_ns=np.asarray(cols["t_ns"], np.int64),
        packet_count=np.zeros(flags.shape, np.uint8),
        valid_data=(flags & PulseFlag.INVALID_DATA) == 0,
        sample_loss=(flags & PulseFlag.SAMPLE_LOSS) != 0,
        over_range=(flags & PulseFlag.OVER_RANGE) != 0,
        lost_before=((flags & PulseFlag.LOST_BEFORE) != 0).astype(np.int64),
        context_mismatch=(flags & PulseFlag.CONTEXT_MISMATCH) != 0,
    )


def encode_autofocus(subapertures: Sequence[SubapertureReport]) -> dict[str, npt.NDArray[Any]]:
    """Columns of the ``autofocus`` table for subaperture reports (:data:`AUTOFOCUS_COLUMNS`)."""
    return _encode_rows(AUTOFOCUS_COLUMNS, subapertures)


def encode_doppler(centroids: Sequence[DopplerCentroid]) -> dict[str, npt.NDArray[Any]]:
    """Columns of the ``doppler`` table for block centroids (:data:`DOPPLER_COLUMNS`)."""
    return _encode_rows(DOPPLER_COLUMNS, centroids)


def _encode_rows(
    columns: Mapping[str, tuple[Column, Callable[[Any], Any]]], rows: Sequence[Any]
) -> dict[str, npt.NDArray[Any]]:
    n = len(rows)
    cols = {}
    for name, (col, field) in columns.items():
        values = [field(r) for r in rows]
        cols[name] = np.asarray(values, dtype=col.dtype).reshape(n, *col.shape)
    return cols


def encode_reference_track(track: ReferenceTrack) -> dict[str, Any]:
    """The root attribute :data:`REFERENCE_TRACK_ATTR` (the first segment's) and a tile's
    ``reference_track``: start GPS ns, origin (NED m, from the first segment's), NED unit
    axes, v0 m/s."""
    return {
        "t0_ns": track.t0_ns,
        "origin_ned": track.origin_ned.tolist(),
        "x_hat_ned": track.x_hat.tolist(),
        "y_hat_ned": track.y_hat.tolist(),
        "v0_mps": track.v0_mps,
        "origin": "APC at t0_ns (INS-integrated; on Earth through the root geodetic_origin)",
    }


def decode_reference_track(value: Mapping[str, Any], where: str) -> ReferenceTrack:
    """A :class:`ReferenceTrack` back from :func:`encode_reference_track`'s mapping.

    Raises
    ------
    RecorderError
        Naming ``where.KEY`` for a missing or mistyped field, or a vector not of 3 numbers.
    """

    def vector(key: str) -> npt.NDArray[np.float64]:
        v = read_attr(value, key, list, where)
        if len(v) != 3 or not all(
            isinstance(c, float | int) and not isinstance(c, bool) for c in v
        ):
            raise RecorderError(f"{where}.{key}: {v!r} is not 3 numbers")
        return np.asarray(v, dtype=np.float64)

    return ReferenceTrack(
        origin_ned=vector("origin_ned"),
        x_hat=vector("x_hat_ned"),
        y_hat=vector("y_hat_ned"),
        v0_mps=float(read_attr(value, "v0_mps", (float, int), where)),
        t0_ns=read_attr(value, "t0_ns", int, where),
    )


def encode_dem(
    dem: DemProduct, height_resolution_m: float, datum_depth_m: float
) -> tuple[dict[str, tuple[tuple[str, ...], npt.NDArray[np.float64]]], dict[str, Any]]:
    """A DEM product of the array imager as a :data:`DEM_GROUP` sub-group's content.

    Parameters
    ----------
    dem : DemProduct
        Heights on (along-track, cross-track) imaging-frame axes of its reference track.
    height_resolution_m : float
        The height (slant-range) resolution cell, m (half of it is the evaluation's bar).
    datum_depth_m : float
        Depth of the height datum below the first pulse's reference point, m.

    Returns
    -------
    arrays : dict
        Name to (dimension names, float64 array), the entries of :data:`DEM_ARRAYS`.
    attrs : dict
        ``reference_track`` (:func:`encode_reference_track`), ``compensated``, ``blocks``,
        ``height_resolution_m``, ``datum_depth_m``.
    """
    values = {"height_m": dem.height_m, "x_m": dem.x_m, "y_m": dem.y_m}
    arrays = {k: (dims, np.asarray(values[k], dtype=np.float64)) for k, dims in DEM_ARRAYS.items()}
    attrs = {
        "reference_track": encode_reference_track(dem.track),
        "compensated": bool(dem.compensated),
        "blocks": [int(b) for b in dem.blocks],
        "height_resolution_m": float(height_resolution_m),
        "datum_depth_m": float(datum_depth_m),
    }
    return arrays, attrs


def decode_dem(
    arrays: Mapping[str, npt.NDArray[Any]], attrs: Mapping[str, Any], where: str
) -> tuple[DemProduct, float]:
    """A DEM product back from its group (:func:`encode_dem` inverted).

    Returns
    -------
    dem : DemProduct
    height_resolution_m : float

    Raises
    ------
    RecorderError
        Naming ``where`` and the array or attribute that is missing, mistyped or of a
        shape that does not fit the axes.
    """
    h, x, y = (np.asarray(arrays[k], dtype=np.float64) for k in DEM_ARRAYS)
    if h.shape != (x.size, y.size) or x.ndim != 1 or y.ndim != 1:
        raise RecorderError(
            f"{where}: height_m {h.shape} does not fit x_m {x.shape}, y_m {y.shape}"
        )
    blocks = read_attr(attrs, "blocks", list, where)
    if len(blocks) != 2 or not all(isinstance(b, int) and not isinstance(b, bool) for b in blocks):
        raise RecorderError(f"{where}.blocks: {blocks!r} is not two integers")
    track = decode_reference_track(read_attr(attrs, "reference_track", dict, where), where)
    dem = DemProduct(
        height_m=h,
        x_m=x,
        y_m=y,
        track=track,
        compensated=read_attr(attrs, "compensated", bool, where),
        blocks=(blocks[0], blocks[1]),
    )
    return dem, float(read_attr(attrs, "height_resolution_m", (float, int), where))


@dataclass(frozen=True)
class GeodeticOrigin:
    """Where a run is on Earth: the tangent point of the local NED frame of the store's
    positions (``nav/pos_ned``, ``motion/pos_ned``), chosen by the daemon as it records.

    Attributes
    ----------
    t_ns : int
        GPS time of the first INS sample recorded in that frame, ns.
    lla : tuple of 3 float
        Latitude, longitude (deg, WGS-84) and altitude (m) as the INS gave them.
    source : str
        What set the frame (e.g. ``"mavlink.GPS_GLOBAL_ORIGIN"``, the autopilot's EKF
        origin; ``"sbg.EKF_NAV"``, its first valid position).
    ellipsoid_height : bool
        The altitude is the height above the WGS-84 ellipsoid; False: above mean sea level
        as the INS gave it, used as the ellipsoid height
        (:attr:`~sarmoco.drivers.samples.TangentFrame.ellipsoid_height`).
    stated : bool
        The INS named this point as its positions' origin (``"mavlink.GPS_GLOBAL_ORIGIN"``);
        False: the first position received (:attr:`~sarmoco.drivers.samples.TangentFrame.stated`).
    """

    t_ns: int
    lla: tuple[float, float, float]
    source: str
    ellipsoid_height: bool = False
    stated: bool = False

    @property
    def height_note(self) -> str:
        """How the altitude is used as a height (:data:`HEIGHT_ELLIPSOID` or :data:`HEIGHT_MSL`)."""
        return HEIGHT_ELLIPSOID if self.ellipsoid_height else HEIGHT_MSL

    @property
    def frame(self) -> TangentFrame:
        """The tangent frame of the store's positions."""
        return TangentFrame(self.lla, self.source, self.ellipsoid_height, self.stated)


HEIGHT_MSL = "INS altitude (MSL) used as WGS-84 ellipsoid height: geoid undulation not applied"
"""``geodetic_origin.height`` of an INS that gives altitudes above mean sea level only."""
HEIGHT_ELLIPSOID = "WGS-84 ellipsoid height (the INS's altitude above MSL plus its undulation)"
"""``geodetic_origin.height`` of an INS that gives the geoid undulation with its altitude."""
FRAME_STATED = (
    "nav/pos_ned (INS point) and motion/pos_ned (antenna phase centre): NED, m, in the tangent "
    "frame at this point"
)
"""``geodetic_origin.frame`` of a store whose INS named the frame of its positions."""
FRAME_UNSTATED = (
    "nav/pos_ned (INS point) and motion/pos_ned (antenna phase centre): NED, m, in the INS's "
    "own local frame, whose origin it did not state"
)
"""``geodetic_origin.frame`` of a store whose INS gave no absolute position."""


def encode_geodetic_origin(origin: GeodeticOrigin | None) -> dict[str, Any]:
    """The root attribute :data:`GEODETIC_ORIGIN_ATTR`: ``{"absent": why}`` while the INS
    gave no absolute position, else ``t_ns``, ``lat_deg``, ``lon_deg``, ``alt_m``,
    ``source``, ``stated`` (the INS named the point; absent in older stores: False) and
    ``height`` (:data:`HEIGHT_ELLIPSOID` or :data:`HEIGHT_MSL`); ``frame``
    says what the store's positions are in (:data:`FRAME_STATED` or :data:`FRAME_UNSTATED`)."""
    if origin is None:
        return {"absent": NO_ABSOLUTE_POSITION, "frame": FRAME_UNSTATED}
    lat, lon, alt = origin.lla
    return {
        "t_ns": origin.t_ns,
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_m": alt,
        "source": origin.source,
        "stated": origin.stated,
        "height": origin.height_note,
        "frame": FRAME_STATED,
    }


def decode_geodetic_origin(attrs: Mapping[str, Any], where: str) -> GeodeticOrigin:
    """The run's :class:`GeodeticOrigin` from the root attributes of a store.

    Raises
    ------
    RecorderError
        Naming ``where.geodetic_origin``: the attribute is missing or damaged, or the run has
        no absolute position (the INS gave none: nothing in the store is on Earth).
    """
    value = read_attr(attrs, GEODETIC_ORIGIN_ATTR, dict, where)
    key = f"{where}.{GEODETIC_ORIGIN_ATTR}"
    if "absent" in value:
        raise RecorderError(f"{key}: no absolute position ({value['absent']})")
    lat = read_attr(value, "lat_deg", (float, int), key)
    lon = read_attr(value, "lon_deg", (float, int), key)
    alt = read_attr(value, "alt_m", (float, int), key)
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0 and math.isfinite(alt)):
        raise RecorderError(f"{key}: lat {lat!r}, lon {lon!r}, alt {alt!r} out of range")
    t_ns = read_attr(value, "t_ns", int, key)
    height = read_attr(value, "height", str, key)
    if height not in (HEIGHT_ELLIPSOID, HEIGHT_MSL):
        raise RecorderError(f"{key}.height: {height!r} is neither {HEIGHT_ELLIPSOID!r} nor MSL")
    source = read_attr(value, "source", str, key)
    stated = read_attr(value, "stated", bool, key) if "stated" in value else False
    lla = (float(lat), float(lon), float(alt))
    return GeodeticOrigin(t_ns, lla, source, height == HEIGHT_ELLIPSOID, stated)


def first_geodetic_origin(rows: Sequence[NavRow]) -> GeodeticOrigin | None:
    """The origin a run takes from INS rows: the frame of the first accepted velocity
    sample whose position names one (None when there is none)."""
    for s, _, result in rows:
        if result == PushResult.ACCEPTED and isinstance(s, VelocitySample) and s.pos_frame:
            f = s.pos_frame
            return GeodeticOrigin(s.t_gps_ns, f.lat_lon_alt, f.source, f.ellipsoid_height, f.stated)
    return None
