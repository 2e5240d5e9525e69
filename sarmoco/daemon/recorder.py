"""The run recorder: one zarr v3 store per run, readable after a crash.

Layout (every group is a *table*: arrays that share their first dimension,
plus a ``committed`` attribute counting the rows that are complete)::

    <run>.zarr/                 attrs: sarmoco_store (layout version), created_utc,
                                       config, versions, metrics, complete
      pulses/   echo (pulse, sample[, iq])    raw echoes, int16 I/Q or complex64 (optional)
                t_ns, pulse_id (pulse) int64  transmit time GPS ns, running number
                channel (pulse) int32, flags (pulse) uint32 (PulseFlag bits)
      nav/      t_ns, rx_ns (nav) int64       INS samples as received (rx_ns: host
                kind (nav) uint8              receive clock, -1 unknown);
                vel_ned (nav, ned) m/s,       kind 0 velocity, 1 attitude, 2 both;
                pos_ned (nav, ned) m,         fields a sample lacks are NaN;
                quat (nav, quat),             result: PushResult of the nav buffer
                result (nav) int8
      ins_raw/  rx_ns, offset, length (raw_chunk) int64: raw INS bytes as read,
      ins_bytes/ byte (byte) uint8              so a log can be decoded again
      motion/   pulse_id, t_ns (motion) int64; pos_ned, vel_ned (motion, ned);
                quat (motion, quat); d_los_m, phase_rad, range_shift_m (motion)
      <name>/   free tables (autofocus estimates per subaperture, metrics over
                time): columns given by the first append
      images/   attrs committed = tiles complete; tile_000000/ ... each with
                data (axis0, axis1) complex64, axis0_m (axis0), axis1_m (axis1),
                attrs frame, t0_ns, t1_ns, metrics

Crash safety: the zarr local store writes every chunk and metadata file to a
temporary name and renames it into place, so a file is either old or new,
never torn. Arrays grow by whole steps *before* rows are written, rows are
written, and only then does ``committed`` advance; a reader trusts rows below
``committed`` and nothing else (:mod:`sarmoco.daemon.store`). Files written are
fsynced (with their directories) every ``fsync_interval_s``, and at close.
:meth:`Recorder.close` trims every array to its committed length and marks the
store ``complete``.

One thread writes to a recorder; it is not safe for concurrent use.
"""

from __future__ import annotations

import asyncio
import datetime
import importlib.metadata
import json
import os
import platform
import threading
import time
from collections.abc import Collection, Coroutine, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import zarr
from zarr.core.buffer import Buffer
from zarr.core.sync import sync as zarr_sync
from zarr.storage import LocalStore

from sarmoco.closing import Closing
from sarmoco.daemon.echoring import SampleFormat, sample_dtype, sample_shape
from sarmoco.daemon.flags import FLAG_DTYPE
from sarmoco.errors import RecorderError
from sarmoco.processing.types import Image

STORE_LAYOUT_VERSION = 1
"""Value of the root attribute ``sarmoco_store``; bumped when the layout changes."""

COMMITTED_ATTR = "committed"
"""Group attribute holding the number of complete rows (tiles for ``images``)."""

NAV_KIND_VELOCITY, NAV_KIND_ATTITUDE, NAV_KIND_BOTH = 0, 1, 2
"""Values of ``nav/kind``."""

_VERSION_PACKAGES = ("sarmoco", "numpy", "scipy", "zarr", "xarray", "pymavlink", "python-can")


class _SyncingStore(LocalStore):
    """A zarr local store that remembers which files it wrote, for fsync."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        self._dirty: set[str] = set()
        self._dirty_lock = threading.Lock()

    async def set(self, key: str, value: Buffer) -> None:
        await super().set(key, value)
        with self._dirty_lock:
            self._dirty.add(key)

    async def set_if_not_exists(self, key: str, value: Buffer) -> None:
        await super().set_if_not_exists(key, value)
        with self._dirty_lock:
            self._dirty.add(key)

    def sync(self) -> int:
        """fsync every file written since the last call, then their directories; returns files."""
        with self._dirty_lock:
            keys, self._dirty = self._dirty, set()
        root = Path(str(self.root))
        dirs = set()
        for key in keys:
            path = root / key
            _fsync_path(path, os.O_RDONLY)
            dirs.add(path.parent)
        for directory in dirs:
            _fsync_path(directory, os.O_RDONLY | os.O_DIRECTORY)
        return len(keys)


async def _gather(writes: list[Coroutine[Any, Any, None]]) -> None:
    await asyncio.gather(*writes)


def _fsync_path(path: Path, flags: int) -> None:
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:  # deleted since (an array trimmed at close)
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def software_versions() -> dict[str, str]:
    """Versions of Python, the platform and the packages that shape the products."""
    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in _VERSION_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


class Table:
    """Arrays of one group that grow together along their first dimension.

    Parameters
    ----------
    group : zarr.Group
        The table's group (created by the caller).
    row_dim : str
        Name of the first dimension (e.g. ``"pulse"``).
    columns : mapping of str to (dtype, trailing shape, trailing dimension names)
        The arrays.
    chunk_rows : int
        Rows per chunk.
    grow_rows : int
        Rows added to every array when it is full (a multiple of ``chunk_rows``
        keeps metadata writes rare).
    uncompressed : collection of str
        Columns stored without compression (raw echoes: noise does not
        compress, and the CPU is needed for focusing).
    """

    def __init__(
        self,
        group: zarr.Group,
        row_dim: str,
        columns: Mapping[str, tuple[npt.DTypeLike, tuple[int, ...], tuple[str, ...]]],
        chunk_rows: int,
        grow_rows: int,
        uncompressed: Collection[str] = (),
    ) -> None:
        self.group = group
        self.grow_rows = grow_rows
        self.committed = 0
        self.arrays: dict[str, zarr.Array] = {}
        for name, (dtype, trailing, dims) in columns.items():
            dt = np.dtype(dtype)
            self.arrays[name] = group.create_array(
                name,
                shape=(0, *trailing),
                chunks=(chunk_rows, *trailing),
                dtype=dt,
                dimension_names=(row_dim, *dims),
                fill_value=np.nan if dt.kind == "f" else 0,
                compressors=None if name in uncompressed else "auto",
            )
        group.update_attributes({COMMITTED_ATTR: 0})

    def append(self, **columns: npt.ArrayLike) -> int:
        """Write rows to every column, then advance ``committed``; returns the new count.

        Raises
        ------
        RecorderError
            Columns missing, unknown, or with different row counts or wrong shapes.
        """
        if set(columns) != set(self.arrays):
            raise RecorderError(
                f"table {self.group.path!r}: columns {sorted(columns)} given, "
                f"{sorted(self.arrays)} expected"
            )
        rows = {k: np.asarray(v) for k, v in columns.items()}
        n_rows = {v.shape[0] if v.ndim else -1 for v in rows.values()}
        if len(n_rows) != 1 or -1 in n_rows:
            raise RecorderError(f"table {self.group.path!r}: columns differ in row count {n_rows}")
        n = n_rows.pop()
        start, stop = self.committed, self.committed + n
        for name, arr in self.arrays.items():
            if rows[name].shape[1:] != arr.shape[1:]:
                raise RecorderError(
                    f"table {self.group.path!r}: column {name!r} rows of shape "
                    f"{rows[name].shape[1:]}, expected {arr.shape[1:]}"
                )
            if arr.shape[0] < stop:
                grow = -(-(stop - arr.shape[0]) // self.grow_rows) * self.grow_rows
                arr.resize((arr.shape[0] + grow, *arr.shape[1:]))
        writes = [
            a.async_array.setitem(slice(start, stop), rows[k]) for k, a in self.arrays.items()
        ]
        zarr_sync(_gather(writes))  # one trip to zarr's event loop for all columns
        self.group.update_attributes({COMMITTED_ATTR: stop})
        self.committed = stop
        return stop

    def trim(self) -> None:
        """Shrink every array to the committed rows (at the end of a run)."""
        for arr in self.arrays.values():
            if arr.shape[0] != self.committed:
                arr.resize((self.committed, *arr.shape[1:]))


class Recorder(Closing):
    """Writes one run into a new zarr v3 store (the layout is in the module doc).

    Parameters
    ----------
    path : str or Path
        Store directory to create (it must not exist).
    n_samples : int
        Complex samples per pulse of the raw echoes.
    sample_format : {"int16", "complex64"}
        How raw echoes are stored (as they come from the ring).
    config : mapping
        The run's full configuration (JSON-able), stored in the ``config`` attribute.
    raw_echoes : bool
        Store raw echoes (``pulses/echo``); per-pulse metadata is always stored.
    chunk_pulses : int
        Pulses per chunk of the per-pulse arrays.
    fsync_interval_s : float
        Interval between fsyncs of the files written, s (0: after every append).
    chunk_rows : int
        Rows per chunk of the other tables.
    """

    def __init__(
        self,
        path: str | Path,
        n_samples: int,
        sample_format: SampleFormat = "int16",
        config: Mapping[str, Any] | None = None,
        raw_echoes: bool = True,
        chunk_pulses: int = 256,
        fsync_interval_s: float = 1.0,
        chunk_rows: int = 1024,
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise RecorderError(f"recorder: {self.path} exists; a run never overwrites a store")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._store = _SyncingStore(self.path)
            self.root = zarr.open_group(self._store, mode="w-", zarr_format=3)
        except OSError as exc:
            raise RecorderError(f"recorder: cannot create {self.path}: {exc}") from exc
        self.fsync_interval_s = fsync_interval_s
        self._chunk_rows = chunk_rows
        self._last_sync = time.monotonic()
        self.n_samples = n_samples
        self.sample_format: SampleFormat = sample_format
        self.root.update_attributes(
            {
                "sarmoco_store": STORE_LAYOUT_VERSION,
                "created_utc": datetime.datetime.now(datetime.UTC).isoformat(),
                "config": json.loads(json.dumps(dict(config or {}), default=str)),
                "versions": software_versions(),
                "complete": False,
            }
        )
        echo_trailing = sample_shape(n_samples, sample_format)
        echo_dims = ("sample",) if sample_format == "complex64" else ("sample", "iq")
        pulse_cols: dict[str, tuple[npt.DTypeLike, tuple[int, ...], tuple[str, ...]]] = {
            "t_ns": (np.int64, (), ()),
            "pulse_id": (np.int64, (), ()),
            "channel": (np.int32, (), ()),
            "flags": (FLAG_DTYPE, (), ()),
        }
        if raw_echoes:
            pulse_cols["echo"] = (sample_dtype(sample_format), echo_trailing, echo_dims)
        self.raw_echoes = raw_echoes
        self.pulses = Table(
            self.root.create_group("pulses"),
            "pulse",
            pulse_cols,
            chunk_pulses,
            chunk_pulses * 16,
            uncompressed=("echo",),
        )
        self.nav = self._table(
            "nav",
            "nav",
            {
                "t_ns": (np.int64, (), ()),
                "rx_ns": (np.int64, (), ()),
                "kind": (np.uint8, (), ()),
                "vel_ned": (np.float64, (3,), ("ned",)),
                "pos_ned": (np.float64, (3,), ("ned",)),
                "quat": (np.float64, (4,), ("quat",)),
                "result": (np.int8, (), ()),
            },
        )
        self.ins_raw = self._table(
            "ins_raw",
            "raw_chunk",
            {
                "rx_ns": (np.int64, (), ()),
                "offset": (np.int64, (), ()),
                "length": (np.int64, (), ()),
            },
        )
        self.ins_bytes = self._table("ins_bytes", "byte", {"byte": (np.uint8, (), ())}, 1 << 16)
        self.motion = Table(
            self.root.create_group("motion"),
            "motion",
            {
                "pulse_id": (np.int64, (), ()),
                "t_ns": (np.int64, (), ()),
                "pos_ned": (np.float64, (3,), ("ned",)),
                "vel_ned": (np.float64, (3,), ("ned",)),
                "quat": (np.float64, (4,), ("quat",)),
                "d_los_m": (np.float64, (), ()),
                "phase_rad": (np.float64, (), ()),
                "range_shift_m": (np.float64, (), ()),
            },
            chunk_pulses,
            chunk_pulses * 16,
        )
        self.tables: dict[str, Table] = {}
        self._images = self.root.create_group("images")
        self._images.update_attributes({COMMITTED_ATTR: 0})
        self.n_images = 0
        self._closed = False
        self.sync()

    def _table(
        self,
        name: str,
        row_dim: str,
        columns: Mapping[str, tuple[npt.DTypeLike, tuple[int, ...], tuple[str, ...]]],
        chunk_rows: int | None = None,
    ) -> Table:
        rows = chunk_rows or self._chunk_rows
        return Table(self.root.create_group(name), row_dim, columns, rows, rows * 16)

    def append_pulses(
        self,
        t_ns: npt.ArrayLike,
        pulse_id: npt.ArrayLike,
        channel: npt.ArrayLike,
        flags: npt.ArrayLike,
        samples: npt.ArrayLike | None = None,
    ) -> None:
        """Record a block of pulses: rows of every column, then the ``committed`` count.

        Parameters
        ----------
        t_ns, pulse_id, channel, flags : array_like, shape (P,)
            As in :class:`~sarmoco.daemon.echoring.EchoBatch`.
        samples : array_like, optional
            Raw samples ``(P, S)`` complex64 or ``(P, S, 2)`` int16, in the
            recorder's ``sample_format``; required when raw echoes are recorded.
        """
        cols: dict[str, npt.ArrayLike] = {
            "t_ns": t_ns,
            "pulse_id": pulse_id,
            "channel": channel,
            "flags": flags,
        }
        if self.raw_echoes:
            if samples is None:
                raise RecorderError("append_pulses: raw echoes are recorded, samples missing")
            cols["echo"] = samples
        self.pulses.append(**cols)
        self._maybe_sync()

    def append_nav(
        self,
        t_ns: npt.ArrayLike,
        kind: npt.ArrayLike,
        vel_ned: npt.ArrayLike,
        pos_ned: npt.ArrayLike,
        quat: npt.ArrayLike,
        result: npt.ArrayLike,
        rx_ns: npt.ArrayLike | None = None,
    ) -> None:
        """Record INS samples as received (NaN for fields a sample lacks; see the layout)."""
        t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        rx = np.full(t.shape, -1, dtype=np.int64) if rx_ns is None else rx_ns
        self.nav.append(
            t_ns=t,
            rx_ns=np.atleast_1d(np.asarray(rx, dtype=np.int64)),
            kind=np.atleast_1d(np.asarray(kind, dtype=np.uint8)),
            vel_ned=np.asarray(vel_ned, dtype=np.float64).reshape(-1, 3),
            pos_ned=np.asarray(pos_ned, dtype=np.float64).reshape(-1, 3),
            quat=np.asarray(quat, dtype=np.float64).reshape(-1, 4),
            result=np.atleast_1d(np.asarray(result, dtype=np.int8)),
        )
        self._maybe_sync()

    def append_ins_bytes(self, data: bytes, rx_ns: int = -1) -> None:
        """Record raw bytes read from the INS link (bytes first, then their index row)."""
        offset = self.ins_bytes.committed
        self.ins_bytes.append(byte=np.frombuffer(data, dtype=np.uint8))
        self.ins_raw.append(rx_ns=[rx_ns], offset=[offset], length=[len(data)])
        self._maybe_sync()

    def append_motion(
        self,
        pulse_id: npt.ArrayLike,
        t_ns: npt.ArrayLike,
        pos_ned: npt.ArrayLike,
        vel_ned: npt.ArrayLike,
        quat: npt.ArrayLike,
        d_los_m: npt.ArrayLike,
        phase_rad: npt.ArrayLike,
        range_shift_m: npt.ArrayLike,
    ) -> None:
        """Record the motion solution of a block of pulses (NED m, m/s; LOS m; rad; m)."""
        self.motion.append(
            pulse_id=pulse_id,
            t_ns=t_ns,
            pos_ned=pos_ned,
            vel_ned=vel_ned,
            quat=quat,
            d_los_m=d_los_m,
            phase_rad=phase_rad,
            range_shift_m=range_shift_m,
        )
        self._maybe_sync()

    def append_rows(
        self, table: str, columns: Mapping[str, npt.ArrayLike], row_dim: str | None = None
    ) -> None:
        """Record rows of a free table (autofocus estimates, metrics over time).

        The first call creates the table from the columns given (dtype and
        trailing shape of each; trailing dimensions named ``<column>_<k>``);
        later calls must give the same columns.

        Parameters
        ----------
        table : str
            Group name, e.g. ``"autofocus"``; not one of the fixed tables.
        columns : mapping of str to array_like
            Arrays with the same number of rows.
        row_dim : str, optional
            Name of the row dimension (default: the table name).
        """
        if table not in self.tables:
            if table in self.root:
                raise RecorderError(f"append_rows: {table!r} is a fixed part of the store")
            specs = {}
            for name, value in columns.items():
                arr = np.asarray(value)
                dims = tuple(f"{name}_{k}" for k in range(1, arr.ndim))
                specs[name] = (arr.dtype, arr.shape[1:], dims)
            self.tables[table] = self._table(table, row_dim or table, specs)
        self.tables[table].append(**columns)
        self._maybe_sync()

    def add_image(
        self,
        image: Image,
        t0_ns: int,
        t1_ns: int,
        metrics: Mapping[str, float] | None = None,
    ) -> int:
        """Record a focused tile with its grid; returns its index.

        Parameters
        ----------
        image : Image
            Complex pixels and their axes (m) and frame.
        t0_ns, t1_ns : int
            GPS time span of the pulses that formed it.
        metrics : mapping, optional
            Quality numbers of the tile (PSLR dB, entropy...), stored as attributes.
        """
        index = self.n_images
        group = self._images.create_group(f"tile_{index:06d}")
        data = np.asarray(image.data, dtype=np.complex64)
        n0, n1 = data.shape
        for name, value, dims, chunks in (
            ("data", data, ("axis0", "axis1"), (min(n0, 1024), min(n1, 1024))),
            ("axis0_m", np.asarray(image.axis0_m, dtype=np.float64), ("axis0",), (n0,)),
            ("axis1_m", np.asarray(image.axis1_m, dtype=np.float64), ("axis1",), (n1,)),
        ):
            arr = group.create_array(
                name, shape=value.shape, chunks=chunks, dtype=value.dtype, dimension_names=dims
            )
            arr[...] = value
        group.update_attributes(
            {
                "frame": image.frame,
                "t0_ns": int(t0_ns),
                "t1_ns": int(t1_ns),
                "metrics": {k: float(v) for k, v in (metrics or {}).items()},
            }
        )
        self.n_images = index + 1
        self._images.update_attributes({COMMITTED_ATTR: self.n_images})
        self._maybe_sync()
        return index

    def set_metrics(self, metrics: Mapping[str, Any]) -> None:
        """Store run-level metrics (JSON-able) in the root ``metrics`` attribute."""
        self.set_attribute("metrics", metrics)

    def set_attribute(self, name: str, value: Mapping[str, Any]) -> None:
        """Store a JSON-able mapping in the root attribute ``name``."""
        self.root.update_attributes({name: json.loads(json.dumps(dict(value), default=str))})

    def sync(self) -> int:
        """fsync what was written since the last sync; returns the number of files."""
        self._last_sync = time.monotonic()
        return self._store.sync()

    def _maybe_sync(self) -> None:
        if time.monotonic() - self._last_sync >= self.fsync_interval_s:
            self.sync()

    def close(self) -> None:
        """Trim the arrays to their committed rows, mark the store complete, fsync."""
        if self._closed:
            return
        tables = [self.pulses, self.nav, self.ins_raw, self.ins_bytes, self.motion]
        tables += self.tables.values()
        for table in tables:
            table.trim()
        self.root.update_attributes({"complete": True})
        self.sync()
        self._closed = True
