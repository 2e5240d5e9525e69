"""The run recorder: one zarr v3 store per run, readable after a crash.

The layout (tables, columns, attributes) is declared in :mod:`sarmoco.store.schema`;
this module writes it.

Crash safety: the zarr local store writes every chunk and metadata file to a
temporary name and renames it into place, so a file is either old or new,
never torn. Arrays grow by whole steps *before* rows are written, rows are
written, and only then does ``committed`` advance; a reader trusts rows below
``committed`` and nothing else (:mod:`sarmoco.store.reader`). Files written are
fsynced (with their directories) every ``fsync_interval_s``, and at close.
:meth:`Recorder.close` trims every array to its committed length and marks the
store ``complete``.

Several threads may call a recorder (a live run's recording and focusing parts): its
calls run one at a time, each whole. With a ``writer_queue`` the writes themselves run,
in call order, on the recorder's writer thread (:mod:`sarmoco.store.writer`), off the
callers'.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import errno
import functools
import importlib.metadata
import json
import mmap
import os
import platform
import threading
import time
import uuid
from collections.abc import Awaitable, Callable, Coroutine, Iterator, Mapping
from pathlib import Path
from typing import Any, Concatenate, ParamSpec, Protocol, TypeVar

import numpy as np
import numpy.typing as npt
import zarr
from zarr.core.buffer import Buffer
from zarr.core.sync import sync as zarr_sync
from zarr.storage import LocalStore

from sarmoco.closing import Closing
from sarmoco.drivers.samples import SampleFormat
from sarmoco.errors import RecorderError
from sarmoco.processing.types import Image
from sarmoco.store import schema
from sarmoco.store.schema import COMMITTED_ATTR, TableSpec
from sarmoco.store.writer import OrderedWriter

_P = ParamSpec("_P")
_R = TypeVar("_R")


def _one_at_a_time(
    method: Callable[Concatenate[Recorder, _P], _R],
) -> Callable[Concatenate[Recorder, _P], _R]:
    """A :class:`Recorder` method that runs whole before another thread's call begins."""

    @functools.wraps(method)
    def call(self: Recorder, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        with self._calls:
            return method(self, *args, **kwargs)

    return call


_VERSION_PACKAGES = ("sarmoco", "numpy", "scipy", "zarr", "xarray", "pymavlink", "python-can")


DIRECT_MIN_BYTES = 1 << 20
"""Files at least this large (chunks of raw echoes) are written with ``O_DIRECT``, bytes."""
META_CHUNK_S = 0.2
"""The columns of a per-pulse table other than the echoes (times, ids, flags, motion) are
chunked to hold at least this much of pulses at the radar's rate, s
(:func:`meta_chunk_pulses`): a chunk file costs zarr about a millisecond of CPU to write,
and at tens of kHz chunks of ``chunk_pulses`` would be hundreds of files a second."""
_WRITTEN_AT_ONCE = (schema.INS_BYTES.name, schema.INS_RAW.name)
"""Tables whose rows are written by each call, whatever ``flush_interval_s``: an ``ins_raw``
row points into ``ins_bytes``, and must not be committed before its bytes (a live run
hands them over every quarter of a second already)."""
_DIRECT_ALIGN = 4096
"""Alignment of the address and length of an ``O_DIRECT`` write, bytes (a page: what every
Linux block device and file system accepts)."""


class _SyncingStore(LocalStore):
    """A zarr local store that remembers which files it wrote, for fsync.

    A write or fsync the file system refuses (disk full, read-only, I/O error) raises
    :class:`~sarmoco.errors.RecorderError` naming the store, the file and the reason;
    so does a write after the store's directory was removed (zarr would silently
    recreate the chunk's folders without the store's metadata).

    Files of :data:`DIRECT_MIN_BYTES` or more are written with ``O_DIRECT`` where the file
    system takes it: the bytes go from an aligned buffer to the disk without being copied
    into the page cache, which on a buffered write costs about as much CPU as the rest of
    the recorder (and a radar's echoes are not read back). Like zarr's own writes, each goes
    to a temporary name first and is renamed into place.
    """

    def __init__(self, root: Path) -> None:
        root.mkdir(parents=True, exist_ok=True)
        super().__init__(root)
        self._root = root
        self._root_id = self._identity()
        """The store directory's (device, inode): a directory of the same name made later
        (a write racing ``mv``/``rm -rf`` of the store recreates it) is another one."""
        self._dirty: set[str] = set()
        self._dirty_lock = threading.Lock()
        self._rooted = False
        """The root ``zarr.json`` was written: from then on, its absence means removed."""
        self._direct = hasattr(os, "O_DIRECT")
        """Large files are written with O_DIRECT (until the file system refuses it)."""
        self._buffers = threading.local()
        """Each writing thread's aligned buffer for O_DIRECT writes."""

    def _identity(self) -> tuple[int, int] | None:
        """The store directory's (device, inode); None where there is none."""
        try:
            st = self._root.stat()
        except FileNotFoundError:
            return None
        return st.st_dev, st.st_ino

    def _removed(self) -> RecorderError | None:
        """The error of a store whose directory is gone: its root ``zarr.json`` missing, or
        the directory not the one the store made (a write that raced the removal had zarr
        make the folders again, the root's metadata with them)."""
        if (self._root / "zarr.json").is_file() and self._identity() == self._root_id:
            return None
        return RecorderError(f"recorder: {self._root}: the store's directory was removed")

    def _refused(self, key: str, exc: OSError) -> RecorderError:
        """A refused write's error; a write that failed because the store's directory went
        away meanwhile says so (the file system only says the folder does not exist)."""
        removed = self._removed()
        if removed is not None:
            return removed
        return RecorderError(f"recorder: {self._root}: cannot write {key!r}: {exc.strerror}")

    async def set(self, key: str, value: Buffer) -> None:
        large = self._direct and len(value) >= DIRECT_MIN_BYTES
        await self._set_checked(key, value, self._set_direct if large else super().set)

    async def _set_direct(self, key: str, value: Buffer) -> None:
        await asyncio.to_thread(self._put_direct, self._root / key, value.as_buffer_like())

    def _put_direct(self, path: Path, data: Any) -> None:
        """Write ``data`` to ``path`` (through a temporary name) with O_DIRECT: copied into
        this thread's aligned buffer, written padded to the alignment, cut to its length.
        A file system that refuses O_DIRECT gets a plain write, and no O_DIRECT after."""
        view = memoryview(data).cast("B")
        n = view.nbytes
        padded = -(-n // _DIRECT_ALIGN) * _DIRECT_ALIGN
        buf: mmap.mmap | None = getattr(self._buffers, "buf", None)
        if buf is None or len(buf) < padded:
            buf = self._buffers.buf = mmap.mmap(-1, padded)  # anonymous: page-aligned
        buf[:n] = view
        buf[n:padded] = bytes(padded - n)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{uuid.uuid4().hex}.partial")
        try:
            try:
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_DIRECT, 0o644)
            except OSError as exc:
                if exc.errno != errno.EINVAL:
                    raise
                self._direct = False  # e.g. tmpfs
                fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                done = 0
                with memoryview(buf) as aligned:
                    while done < padded:
                        done += os.write(fd, aligned[done:padded])
                os.ftruncate(fd, n)
            finally:
                os.close(fd)
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise

    async def set_if_not_exists(self, key: str, value: Buffer) -> None:
        await self._set_checked(key, value, super().set_if_not_exists)

    async def delete(self, key: str) -> None:
        try:
            await super().delete(key)
        except OSError as exc:
            raise self._refused(key, exc) from exc

    async def _set_checked(
        self, key: str, value: Buffer, write: Callable[[str, Buffer], Awaitable[None]]
    ) -> None:
        # the root's metadata may be written where there is none only when the store is
        # created: later, it would recreate a removed store (a root attribute update)
        removed = None if key == "zarr.json" and not self._rooted else self._removed()
        if removed is not None:
            raise removed
        try:
            await write(key, value)
        except OSError as exc:
            raise self._refused(key, exc) from exc
        self._rooted = self._rooted or key == "zarr.json"
        with self._dirty_lock:
            self._dirty.add(key)

    def sync(self) -> int:
        """fsync every file written since the last call, then their directories; returns files."""
        with self._dirty_lock:
            keys, self._dirty = self._dirty, set()
        dirs = set()
        for key in keys:
            path = self._root / key
            try:
                _fsync_path(path, os.O_RDONLY)
            except OSError as exc:
                with self._dirty_lock:  # fsynced again at the next call
                    self._dirty |= keys
                raise self._refused(key, exc) from exc
            dirs.add(path.parent)
        for directory in dirs:
            _fsync_path(directory, os.O_RDONLY | os.O_DIRECTORY)
        return len(keys)


async def _gather(writes: list[Coroutine[Any, Any, None]]) -> None:
    await asyncio.gather(*writes)


def _settle_zarr_tasks() -> None:
    """Wait until every other task on zarr's event loop has ended, retrieving their exceptions.

    Called when a write fails (:class:`~sarmoco.store.writer.OrderedWriter`'s
    ``on_failure``, :func:`_settling`). A zarr write returns at its first failure
    (``asyncio.gather``) while the other writes it started go on; if one of those fails
    too, its exception is retrieved only by a callback of that gather, which never runs
    when the loop stops first (zarr stops it at interpreter exit): asyncio then logs
    "Task exception was never retrieved", "Future exception was never retrieved" or
    "Task was destroyed but it is pending!" for it, after the daemon's last word. The
    failure is reported once, by the exception of the write that failed first.
    """
    zarr_sync(_settle())


@contextlib.contextmanager
def _settling() -> Iterator[None]:
    """Run zarr writes made outside the writer (table creation, the close); on a failure,
    :func:`_settle_zarr_tasks` before it goes on."""
    try:
        yield
    except BaseException:
        _settle_zarr_tasks()
        raise


async def _settle() -> None:
    current = asyncio.current_task()
    await asyncio.gather(
        *(t for t in asyncio.all_tasks() if t is not current), return_exceptions=True
    )


def _fsync_path(path: Path, flags: int) -> None:
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:  # deleted since (an array trimmed at close)
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def meta_chunk_pulses(chunk_pulses: int, prf_hz: float) -> int:
    """Pulses per chunk of the per-pulse columns other than the echoes: ``chunk_pulses``
    times the smallest power of two that holds :data:`META_CHUNK_S` at ``prf_hz`` (Hz)."""
    factor = 1
    while chunk_pulses * factor < META_CHUNK_S * prf_hz:
        factor *= 2
    return chunk_pulses * factor


def software_versions() -> dict[str, str]:
    """Versions of Python, the platform and the packages that shape the products."""
    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in _VERSION_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def create_tile(
    images: zarr.Group, index: int, axis0_m: npt.ArrayLike, axis1_m: npt.ArrayLike
) -> zarr.Group:
    """Create image tile ``index`` in the ``images`` group: its axes (m) written, its
    complex64 ``data`` array created empty, to be filled by :func:`write_tile`.

    A batch creates every tile of a run this way first, then writes each tile's pixels
    from wherever it was formed (region writes into arrays that exist).
    """
    group = images.create_group(schema.tile_name(index))
    _create_image(group, schema.TILE_DIMS, schema.TILE_COORDS, (axis0_m, axis1_m))
    return group


def _create_image(
    group: zarr.Group,
    dims: tuple[str, str],
    coords: tuple[str, str],
    axes: tuple[npt.ArrayLike, npt.ArrayLike],
) -> zarr.Array:
    """An empty complex64 ``data`` array of dimensions ``dims`` in ``group``, and its two
    coordinate arrays ``coords`` written from ``axes``."""
    values = [np.asarray(a, dtype=np.float64) for a in axes]
    shape = (values[0].size, values[1].size)
    data = group.create_array(
        "data",
        shape=shape,
        chunks=tuple(min(n, 1024) for n in shape),
        dtype=np.complex64,
        dimension_names=dims,
        attributes={"coordinates": " ".join(coords)},
        **schema.chunk_codecs(),
    )
    for name, dim, value in zip(coords, dims, values, strict=True):
        arr = group.create_array(
            name,
            shape=value.shape,
            chunks=value.shape,
            dtype=value.dtype,
            dimension_names=(dim,),
            **schema.chunk_codecs(),
        )
        arr[...] = value
    return data


def write_north_up(
    path: str | Path,
    segment: int,
    data: npt.NDArray[np.complexfloating[Any, Any]],
    north_m: npt.ArrayLike,
    east_m: npt.ArrayLike,
    attributes: Mapping[str, Any],
) -> None:
    """Write segment ``segment``'s north-up image into the finished store at ``path``
    (group :data:`~sarmoco.store.schema.NORTH_UP_GROUP`, replaced if there).

    Raises
    ------
    RecorderError
        The store cannot be opened for writing, or the image is not of its axes' shape.
    """
    try:
        root = zarr.open_group(str(path), mode="r+", zarr_format=3)
    except (OSError, ValueError, KeyError) as exc:
        raise RecorderError(f"{path}: cannot add a north-up image: {exc}") from exc
    shape = (np.size(north_m), np.size(east_m))
    if data.shape != shape:
        raise RecorderError(f"{path}: north-up image {data.shape} for axes {shape}")
    parent = root.require_group(schema.NORTH_UP_GROUP)
    group = parent.create_group(schema.north_up_name(segment), overwrite=True)
    array = _create_image(group, schema.NORTH_UP_DIMS, schema.NORTH_UP_COORDS, (north_m, east_m))
    array.with_config(schema.CHUNK_CONFIG)[...] = np.asarray(data, dtype=np.complex64)
    group.update_attributes(dict(attributes))


def write_tile(
    group: zarr.Group,
    image: Image,
    t0_ns: int,
    t1_ns: int,
    metrics: Mapping[str, float] | None = None,
    reference_track: Mapping[str, Any] | None = None,
) -> None:
    """Write a tile's pixels into the ``data`` array :func:`create_tile` made (a region
    write of the whole array) and its attributes (:func:`~sarmoco.store.schema.encode_tile_attrs`).

    Raises
    ------
    RecorderError
        The image is not of the tile's shape.
    """
    data = group["data"]
    assert isinstance(data, zarr.Array)
    data = data.with_config(schema.CHUNK_CONFIG)  # opened again: every chunk written
    if image.data.shape != data.shape:
        raise RecorderError(
            f"{group.store_path}: image of shape {image.data.shape} for a tile of {data.shape}"
        )
    data[...] = np.asarray(image.data, dtype=np.complex64)
    group.update_attributes(
        schema.encode_tile_attrs(image.frame, t0_ns, t1_ns, metrics, reference_track)
    )


class Table:
    """Arrays of one group that grow together along their first dimension.

    Parameters
    ----------
    root : zarr.Group
        The store's root; the table's group is created there.
    spec : TableSpec
        The table's name, row dimension and columns.
    chunk_rows : int
        Rows per chunk (unless the spec fixes it).
    meta_rows : int, optional
        Rows per chunk of the columns of a per-pulse table other than the echoes, a
        multiple of ``chunk_rows`` (:func:`meta_chunk_pulses`; None: ``chunk_rows``).
    flush_interval_s : float
        Longest time rows wait in memory before they are written, s (0: every
        :meth:`write` writes them); a column of whole-chunk writes (below) aside.

    Notes
    -----
    Every column keeps in memory the rows of its last, partial chunk (``held``), so that
    no chunk is ever read back to be written again with more rows: a partial chunk is
    written whole, its rows then the fill value, and written again whole when more rows
    come. Zarr would otherwise read the chunk (from the disk) for each write that ends
    inside it, and blocks of pulses rarely end on a chunk boundary.

    A column whose chunks hold :data:`DIRECT_MIN_BYTES` or more (raw echoes) is written a
    whole chunk at a time: the rows of its partial chunk wait until it is full (or
    :meth:`trim` writes them), and ``committed`` stays at the chunk boundary until then;
    its rows are gathered in a staging buffer made once, so each block is copied into
    memory already written rather than into a fresh array.
    The other columns are written once their oldest row not written has waited
    ``flush_interval_s``: each file zarr writes costs about a millisecond of CPU, which a
    table written in small blocks (a recording pass every 10 ms) would pay for every
    column many times a second. A crash loses the rows waiting: fewer than a chunk's of
    the echoes, at most ``flush_interval_s`` of the others.
    """

    def __init__(
        self,
        root: zarr.Group,
        spec: TableSpec,
        chunk_rows: int,
        meta_rows: int | None = None,
        flush_interval_s: float = 0.0,
    ) -> None:
        rows = spec.chunk_rows or chunk_rows
        meta = meta_rows if spec.per_pulse and meta_rows else rows
        if meta % rows:
            raise RecorderError(f"table {spec.name!r}: chunks of {meta} rows, not of {rows}")
        self.group = root.create_group(spec.name)
        self.grow_rows = meta * 16  # a multiple of every chunk keeps metadata writes rare
        self.flush_interval_s = flush_interval_s
        self.committed = 0
        """Rows written and counted in the store's ``committed`` attribute."""
        self._handed = 0
        """Rows handed to :meth:`write` (written, or held)."""
        self.rows = 0
        """Rows handed to :meth:`prepare` (the caller's count: ``committed`` once written)."""
        self.arrays: dict[str, zarr.Array] = {}
        self._fill: dict[str, float] = {}
        self._whole: set[str] = set()
        """Columns written a whole chunk at a time (class notes)."""
        for name, col in spec.columns.items():
            col_rows = rows if "sample" in col.dims else meta
            self._fill[name] = np.nan if col.dtype.kind == "f" else 0
            self.arrays[name] = self.group.create_array(
                name,
                shape=(0, *col.shape),
                chunks=(col_rows, *col.shape),
                dtype=col.dtype,
                dimension_names=(spec.row_dim, *col.dims),
                fill_value=self._fill[name],
                **schema.chunk_codecs(spec.compressors.get(name, schema.DEFAULT_COMPRESSOR)),
                attributes=spec.column_attrs(name),
            )
            if col_rows * col.dtype.itemsize * int(np.prod(col.shape)) >= DIRECT_MIN_BYTES:
                self._whole.add(name)
        self.group.update_attributes({COMMITTED_ATTR: 0})
        self._held: dict[str, npt.NDArray[Any]] = {
            name: np.zeros((0, *col.shape), col.dtype) for name, col in spec.columns.items()
        }
        """Each column's rows from :attr:`_held_from` on (class notes)."""
        self._stage: dict[str, npt.NDArray[Any]] = {}
        """Staging buffer of each whole-chunk column: its rows held, then the rows being
        written (:meth:`_with_held`)."""
        self._held_from = dict.fromkeys(spec.columns, 0)
        """First row held of each column (the start of a chunk)."""
        self._stored = dict.fromkeys(spec.columns, 0)
        """Rows of each column in the store."""
        self._waiting_since: float | None = None
        """When the oldest rows or flags not written yet came (host monotonic clock, s;
        None: none is waiting)."""
        self._late_flags: list[tuple[str, npt.NDArray[np.int64], npt.NDArray[Any]]] = []
        """Flags to OR into rows of the store at the next write that is due: (column, rows,
        value)."""

    def append(self, **columns: npt.ArrayLike) -> int:
        """Write rows to every column, then advance ``committed``; returns the new count.

        Raises
        ------
        RecorderError
            Columns missing, unknown, or with different row counts or wrong shapes.
        """
        return self.write(*self.prepare(False, **columns))

    def prepare(
        self, copy: bool, **columns: npt.ArrayLike
    ) -> tuple[dict[str, npt.NDArray[Any]], int]:
        """Check rows of every column and give them their place: (rows, first row).

        Runs on the caller's thread and advances :attr:`rows`; :meth:`write` then
        writes them (on the writer thread). ``copy``: the arrays are copied, so that
        the caller may reuse its own while the write waits.

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
        rows = {k: np.array(v, copy=copy or None) for k, v in columns.items()}
        n_rows = {v.shape[0] if v.ndim else -1 for v in rows.values()}
        if len(n_rows) != 1 or -1 in n_rows:
            raise RecorderError(f"table {self.group.path!r}: columns differ in row count {n_rows}")
        for name, arr in self.arrays.items():
            if rows[name].shape[1:] != arr.shape[1:]:
                raise RecorderError(
                    f"table {self.group.path!r}: column {name!r} rows of shape "
                    f"{rows[name].shape[1:]}, expected {arr.shape[1:]}"
                )
        start = self.rows
        self.rows += n_rows.pop()
        return rows, start

    def write(self, rows: Mapping[str, npt.NDArray[Any]], start: int, force: bool = False) -> int:
        """Hand over rows :meth:`prepare` placed at ``start``: write what is due (class
        notes; ``force``: every row held), then advance ``committed`` to the rows of every
        column in the store; returns it. Rows are handed in the order they were prepared.
        """
        if start != self._handed:
            raise RecorderError(
                f"table {self.group.path!r}: rows from {start} written after {self._handed}"
            )
        stop = start + next(iter(rows.values())).shape[0]
        now = time.monotonic()
        self._waiting_since = now if self._waiting_since is None else self._waiting_since
        due = force or now - self._waiting_since >= self.flush_interval_s
        try:
            if due:
                self._apply_late_flags()
            for arr in self.arrays.values():
                if arr.shape[0] < stop:
                    grow = -(-(stop - arr.shape[0]) // self.grow_rows) * self.grow_rows
                    arr.resize((arr.shape[0] + grow, *arr.shape[1:]))
            regions, held, held_from, stored, moves = {}, {}, {}, {}, {}
            for name, arr in self.arrays.items():
                both = self._with_held(name, rows[name])
                first, chunk = self._held_from[name], arr.chunks[0]
                whole_end = stop // chunk * chunk
                if force or (due and name not in self._whole):
                    regions[name] = (slice(first, first + both.shape[0]), both)
                    stored[name] = stop
                elif name in self._whole:
                    regions[name] = (slice(first, whole_end), both[: whole_end - first])
                    stored[name] = whole_end
                else:  # not due: all held
                    held[name] = both if both is not rows[name] else both.copy()
                    held_from[name] = first
                    continue
                if name in self._whole:  # moved to the front of its buffer once written
                    moves[name] = (whole_end - first, stop - whole_end)
                else:
                    held[name] = both[whole_end - first :].copy()
                held_from[name] = whole_end
            committed = min({**self._stored, **stored}.values())
            self._write_regions(regions, committed)
        except BaseException:
            # not committed: the next rows take their place (a writer thread runs no
            # write after a failed one, so none was placed after these)
            self.rows = start
            raise
        for name, (offset, n) in moves.items():
            held[name] = self._restage(name, offset, n)
        self._held.update(held)
        self._held_from.update(held_from)
        self._stored.update(stored)
        self._handed = stop
        self.committed = committed
        if due:
            self._waiting_since = None
        return committed

    def _with_held(self, name: str, new: npt.NDArray[Any]) -> npt.NDArray[Any]:
        """The rows of column ``name`` held, then ``new``: one array (``new`` itself when
        none is held). A whole-chunk column's rows are gathered in its staging buffer, made
        once and grown to the largest write: the rows of every block are copied into memory
        already written (a fresh array per block is a page fault per 4 KiB of echoes)."""
        old = self._held[name]
        if name not in self._whole:
            return np.concatenate([old, new]) if old.shape[0] else new
        n = old.shape[0] + new.shape[0]
        stage = self._stage.get(name)
        if stage is None or stage.shape[0] < n:
            stage = self._stage[name] = np.empty((n, *new.shape[1:]), new.dtype)
            stage[: old.shape[0]] = old
        stage[old.shape[0] : n] = new
        return stage[:n]

    def _restage(self, name: str, offset: int, n: int) -> npt.NDArray[Any]:
        """Hold the ``n`` rows of whole-chunk column ``name`` from ``offset`` of its staging
        buffer on (those after its last whole chunk written) at the buffer's start."""
        stage = self._stage[name]
        if offset:  # a multiple of the chunk, and n is less than one: no overlap
            stage[:n] = stage[offset : offset + n]
        return stage[:n]

    def flush(self) -> int:
        """Write every row held (:meth:`write` of none, forced); returns ``committed``."""
        empty = {k: v[:0] for k, v in self._held.items()}
        return self.write(empty, self._handed, force=True)

    def flush_due(self) -> None:
        """Write the rows and flags that have waited ``flush_interval_s`` (rows of
        whole-chunk columns wait for their chunk to fill)."""
        since = self._waiting_since
        if since is not None and time.monotonic() - since >= self.flush_interval_s:
            empty = {k: v[:0] for k, v in self._held.items()}
            self.write(empty, self._handed)

    def or_flags(self, column: str, rows: npt.NDArray[np.int64], flags: int) -> None:
        """OR ``flags`` into ``column`` at ``rows`` (handed rows): in memory for the rows
        held; for the rows in the store at the next write that is due (:meth:`write`: each
        chunk touched read and written once)."""
        value = np.asarray(flags, dtype=self._held[column].dtype)
        first = self._held_from[column]
        held = rows[rows >= first]
        self._held[column][held - first] |= value
        self._late_flags.append((column, rows[rows < first], value))
        self._waiting_since = self._waiting_since or time.monotonic()
        if self.flush_interval_s == 0:
            self.flush_due()

    def _apply_late_flags(self) -> None:
        """OR the flags :meth:`or_flags` left for rows in the store into their chunks."""
        for column, rows, value in self._late_flags:
            arr = self.arrays[column]
            chunk = arr.chunks[0]
            for c in np.unique(rows // chunk).tolist():
                lo = c * chunk
                span = np.asarray(arr[lo : lo + chunk])  # a whole chunk: held rows are after
                span[rows[rows // chunk == c] - lo] |= value
                arr[lo : lo + chunk] = span
        self._late_flags = []

    def _write_regions(
        self, regions: Mapping[str, tuple[slice, npt.NDArray[Any]]], committed: int
    ) -> None:
        """Write each column's rows into its region (none when empty): a region that ends
        inside a chunk is padded to the chunk's end with the fill value, so that zarr writes
        whole chunks only. Then set ``committed`` (when it moved)."""
        writes = []
        for name, (region, data) in regions.items():
            if not data.shape[0]:
                continue
            arr, chunk = self.arrays[name], self.arrays[name].chunks[0]
            end = -(-region.stop // chunk) * chunk
            if end != region.stop:
                padded = np.full(
                    (end - region.start, *data.shape[1:]), self._fill[name], data.dtype
                )
                padded[: data.shape[0]] = data
                region, data = slice(region.start, end), padded
            writes.append(arr.async_array.setitem(region, data))
        if writes:  # one trip to zarr's event loop for all columns, none for no rows
            zarr_sync(_gather(writes))
        if committed != self.committed:
            self.group.update_attributes({COMMITTED_ATTR: committed})

    def trim(self) -> None:
        """Write the rows still held (class notes), then shrink every array to the
        committed rows (at the end of a run)."""
        self.flush()
        for arr in self.arrays.values():
            if arr.shape[0] != self.committed:
                arr.resize((self.committed, *arr.shape[1:]))


class RecordingListener(Protocol):
    """What a :class:`Recorder` tells, in memory, of what it records (the daemon's live
    page feed is one); called on the thread that records."""

    def add_tile(self, index: int, image: Image, t0_ns: int, t1_ns: int) -> None:
        """A tile was recorded at store index ``index``, formed of the pulses from ``t0_ns``
        to ``t1_ns`` (GPS ns)."""

    def add_autofocus(self, columns: Mapping[str, npt.ArrayLike]) -> None:
        """Rows of the ``autofocus`` table were recorded, by column."""


class Recorder(Closing):
    """Writes one run into a new zarr v3 store (layout: :mod:`sarmoco.store.schema`).

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
    flush_interval_s : float
        Longest time rows wait in memory before they are written, s (0: each call writes
        its rows); raw echoes are written a whole chunk at a time either way
        (:class:`Table`). :meth:`flush_due` writes the rows whose time has come.
    meta_chunk_pulses : int, optional
        Pulses per chunk of the per-pulse columns other than the echoes, a multiple of
        ``chunk_pulses`` (:func:`meta_chunk_pulses`; None: ``chunk_pulses``).
    chunk_rows : int
        Rows per chunk of the other tables.
    echo_compression : str
        Lossless compressor of the raw echoes, a key of
        :data:`~sarmoco.store.schema.ECHO_COMPRESSION` (``"none"``: stored as they are).
    live : RecordingListener, optional
        Told in memory of each tile and autofocus row recorded (the daemon's live page
        feed), so that the live page never opens the store.
    writer_queue : int
        Writes that may wait for the recorder's writer thread
        (:class:`~sarmoco.store.writer.OrderedWriter`): every method then checks its
        arguments, copies them and returns, and the thread writes in call order (the
        ``committed`` counts advance after their rows, fsync every interval, as on one
        thread); a failed write is raised by the next call, and is
        :attr:`write_failure` meanwhile. 0: each method writes before it returns.
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
        flush_interval_s: float = 0.0,
        meta_chunk_pulses: int | None = None,
        chunk_rows: int = 1024,
        echo_compression: str = "none",
        live: RecordingListener | None = None,
        writer_queue: int = 0,
    ) -> None:
        self.path = Path(path)
        self.live = live
        self._calls = threading.RLock()
        """Held by each call that places rows or hands a write over (:func:`_one_at_a_time`)."""
        if self.path.exists():
            raise RecorderError(f"recorder: {self.path} exists; a run never overwrites a store")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._store = _SyncingStore(self.path)
            self.root = zarr.open_group(self._store, mode="w-", zarr_format=3)
        except OSError as exc:
            raise RecorderError(f"recorder: cannot create {self.path}: {exc}") from exc
        self.fsync_interval_s = fsync_interval_s
        self.flush_interval_s = flush_interval_s
        self._meta_rows = meta_chunk_pulses
        self._last_sync = time.monotonic()
        self._chunk = {True: chunk_pulses, False: chunk_rows}
        """Rows per chunk of per-pulse tables and of the others."""
        self.n_samples = n_samples
        self.sample_format: SampleFormat = sample_format
        self.raw_echoes = raw_echoes
        self.tables: dict[str, Table] = {}
        """Every table created so far, by name."""
        self.root.update_attributes(
            {
                schema.LAYOUT_ATTR: schema.STORE_LAYOUT_VERSION,
                "created_utc": datetime.datetime.now(datetime.UTC).isoformat(),
                "config": json.loads(json.dumps(dict(config or {}), default=str)),
                "versions": software_versions(),
                schema.COMPLETE_ATTR: False,
                schema.GEODETIC_ORIGIN_ATTR: schema.encode_geodetic_origin(None),
            }
        )
        self.pulses = self._create(
            schema.pulses_table(n_samples, sample_format, raw_echoes, echo_compression)
        )
        self.nav = self._create(schema.NAV)
        self.ins_raw = self._create(schema.INS_RAW)
        self.ins_bytes = self._create(schema.INS_BYTES)
        self.motion = self._create(schema.MOTION)
        self._images = self.root.create_group(schema.IMAGES_GROUP)
        self._images.update_attributes({COMMITTED_ATTR: 0})
        self.n_images = 0
        self._closed = False
        self._writer = OrderedWriter(
            f"recorder {self.path.name}", writer_queue, on_failure=_settle_zarr_tasks
        )
        self.sync()

    def _create(self, spec: TableSpec) -> Table:
        flush_s = 0.0 if spec.name in _WRITTEN_AT_ONCE else self.flush_interval_s
        table = Table(self.root, spec, self._chunk[spec.per_pulse], self._meta_rows, flush_s)
        self.tables[spec.name] = table
        return table

    @_one_at_a_time
    def _append(self, table: Table, **columns: npt.ArrayLike) -> None:
        """Place rows in ``table`` now, write them on the writer thread (or now)."""
        self._writer.raise_error()
        rows, start = table.prepare(self._writer.threaded, **columns)
        self._writer.submit(self._write_rows, table, rows, start)

    def _write_rows(self, table: Table, rows: Mapping[str, npt.NDArray[Any]], start: int) -> None:
        table.write(rows, start)
        self._maybe_sync()

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
        t_ns : array_like of int64, shape (P,)
            Transmit times, GPS ns.
        pulse_id : array_like of int64, shape (P,)
            Running pulse numbers given by the producer.
        channel : array_like of int32, shape (P,)
            Receive channels (VITA 49 stream IDs).
        flags : array_like of uint32, shape (P,)
            :class:`~sarmoco.store.flags.PulseFlag` bits.
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
        self._append(self.pulses, **cols)

    def append_nav(
        self,
        t_ns: npt.ArrayLike,
        kind: npt.ArrayLike,
        vel_ned: npt.ArrayLike,
        pos_ned: npt.ArrayLike,
        quat: npt.ArrayLike,
        result: npt.ArrayLike,
        rx_ns: npt.ArrayLike | None = None,
        lla: npt.ArrayLike | None = None,
    ) -> None:
        """Record INS samples as received (NaN for fields a sample lacks; see the layout)."""
        t = np.atleast_1d(np.asarray(t_ns, dtype=np.int64))
        lla = np.full((t.shape[0], 3), np.nan) if lla is None else lla
        rx = np.full(t.shape, -1, dtype=np.int64) if rx_ns is None else rx_ns
        self._append(
            self.nav,
            t_ns=t,
            rx_ns=np.atleast_1d(np.asarray(rx, dtype=np.int64)),
            kind=np.atleast_1d(np.asarray(kind, dtype=np.uint8)),
            vel_ned=np.asarray(vel_ned, dtype=np.float64).reshape(-1, 3),
            pos_ned=np.asarray(pos_ned, dtype=np.float64).reshape(-1, 3),
            quat=np.asarray(quat, dtype=np.float64).reshape(-1, 4),
            result=np.atleast_1d(np.asarray(result, dtype=np.int8)),
            lla=np.asarray(lla, dtype=np.float64).reshape(-1, 3),
        )

    @_one_at_a_time
    def append_ins_bytes(self, data: bytes, rx_ns: int = -1) -> None:
        """Record raw bytes read from the INS link (bytes first, then their index row)."""
        offset = self.ins_bytes.rows
        self._append(self.ins_bytes, byte=np.frombuffer(data, dtype=np.uint8))
        self._append(self.ins_raw, rx_ns=[rx_ns], offset=[offset], length=[len(data)])

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
        self._append(
            self.motion,
            pulse_id=pulse_id,
            t_ns=t_ns,
            pos_ned=pos_ned,
            vel_ned=vel_ned,
            quat=quat,
            d_los_m=d_los_m,
            phase_rad=phase_rad,
            range_shift_m=range_shift_m,
        )

    @_one_at_a_time
    def append_rows(self, spec: TableSpec, columns: Mapping[str, npt.ArrayLike]) -> None:
        """Record rows of a table that appears with its first row (``autofocus``).

        Parameters
        ----------
        spec : TableSpec
            The table, e.g. :data:`~sarmoco.store.schema.AUTOFOCUS`; created by the
            first call.
        columns : mapping of str to array_like
            Every column of ``spec``, with the same number of rows.
        """
        table = self.tables.get(spec.name)
        if table is None:
            if spec.name in self.root:
                raise RecorderError(f"append_rows: {spec.name!r} is a fixed part of the store")
            self._writer.drain()  # the writer thread is not writing while it is created
            with _settling():
                table = self._create(spec)
        self._append(table, **columns)
        if self.live is not None and spec.name == schema.AUTOFOCUS.name:
            self.live.add_autofocus(columns)

    @_one_at_a_time
    def add_image(
        self,
        image: Image,
        t0_ns: int,
        t1_ns: int,
        metrics: Mapping[str, float] | None = None,
        reference_track: Mapping[str, Any] | None = None,
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
        reference_track : mapping, optional
            The track whose imaging frame the axes are in
            (:func:`~sarmoco.store.schema.encode_reference_track`).
        """
        index = self.n_images
        if self._writer.threaded:
            image = Image(np.array(image.data), image.axis0_m, image.axis1_m, image.frame)
        self._writer.submit(self._write_image, index, image, t0_ns, t1_ns, metrics, reference_track)
        self.n_images = index + 1
        if self.live is not None:
            self.live.add_tile(index, image, t0_ns, t1_ns)
        return index

    def _write_image(
        self,
        index: int,
        image: Image,
        t0_ns: int,
        t1_ns: int,
        metrics: Mapping[str, float] | None,
        reference_track: Mapping[str, Any] | None,
    ) -> None:
        group = create_tile(self._images, index, image.axis0_m, image.axis1_m)
        write_tile(group, image, t0_ns, t1_ns, metrics, reference_track)
        self._images.update_attributes({COMMITTED_ATTR: index + 1})
        self._maybe_sync()

    @_one_at_a_time
    def flag_pulses(self, rows: npt.ArrayLike, flags: int) -> None:
        """Set ``flags`` (:class:`~sarmoco.store.flags.PulseFlag` bits) on recorded pulses.

        Parameters
        ----------
        rows : array_like of int, shape (K,)
            Rows of the ``pulses`` table (committed ones).
        flags : int
            Bits OR-ed into their ``flags``.
        """
        r = np.array(rows, dtype=np.int64)  # a copy: the write may wait on the writer thread
        if r.size == 0:
            return
        lo, hi = int(r.min()), int(r.max()) + 1
        if lo < 0 or hi > self.pulses.rows:
            raise RecorderError(f"flag_pulses: rows {lo}..{hi - 1} not all recorded")
        self._writer.submit(self._write_flags, r, flags)

    def _write_flags(self, rows: npt.NDArray[np.int64], flags: int) -> None:
        self.pulses.or_flags("flags", rows, flags)
        self._maybe_sync()

    @_one_at_a_time
    def flush_due(self) -> None:
        """Write the rows that have waited ``flush_interval_s`` in memory (on the writer
        thread, after the writes handed over so far); a live run's recording thread calls
        it after each pass, so that rows do not wait for the next call of their table."""
        if self.flush_interval_s > 0:
            self._writer.submit(self._flush_due)

    def _flush_due(self) -> None:
        for table in self.tables.values():
            table.flush_due()
        self._maybe_sync()

    @_one_at_a_time
    def add_dem(
        self,
        name: str,
        arrays: Mapping[str, tuple[tuple[str, ...], npt.NDArray[Any]]],
        attrs: Mapping[str, Any],
    ) -> None:
        """Record a DEM product as ``dem/<name>`` (content from
        :func:`~sarmoco.store.schema.encode_dem`).

        Parameters
        ----------
        name : str
            Product name (``compensated``, ``uncompensated``).
        arrays : mapping
            Array name to (dimension names, values).
        attrs : mapping
            The product's attributes (JSON-able).
        """
        self._writer.submit(
            self._write_dem, name, dict(arrays), json.loads(json.dumps(dict(attrs)))
        )

    def _write_dem(
        self,
        name: str,
        arrays: Mapping[str, tuple[tuple[str, ...], npt.NDArray[Any]]],
        attrs: dict[str, Any],
    ) -> None:
        dems = self.root.require_group(schema.DEM_GROUP)
        group = dems.create_group(name)
        for key, (dims, value) in arrays.items():
            arr = group.create_array(
                key,
                shape=value.shape,
                chunks=value.shape,
                dtype=value.dtype,
                dimension_names=dims,
                **schema.chunk_codecs(),
            )
            arr[...] = value
        group.update_attributes(attrs)
        self._maybe_sync()

    def set_metrics(self, metrics: Mapping[str, Any]) -> None:
        """Store run-level metrics (JSON-able) in the root ``metrics`` attribute."""
        self.set_attribute("metrics", metrics)

    @_one_at_a_time
    def set_attribute(self, name: str, value: Mapping[str, Any]) -> None:
        """Store a JSON-able mapping in the root attribute ``name``."""
        attrs = {name: json.loads(json.dumps(dict(value), default=str))}
        self._writer.submit(self.root.update_attributes, attrs)

    @property
    def write_failure(self) -> RecorderError | None:
        """The store write failure that stands (None: none).

        With the writer thread, its first failure: the store takes no write after it and
        every later call raises it; a caller that makes no more calls (the last pulses
        recorded) sees it here. Without, the last write's failure (which that call
        raised) until a write succeeds.
        """
        return self._writer.failure

    def sync(self) -> int:
        """fsync what was written since the last sync, after the writes handed over so far
        (called on the writer thread, by a write: what was written before it); returns the
        number of files."""
        self._writer.drain()
        self._last_sync = time.monotonic()
        return self._store.sync()

    def _maybe_sync(self) -> None:
        if time.monotonic() - self._last_sync >= self.fsync_interval_s:
            self.sync()

    def close(self) -> None:
        """Finish the writes handed over (a failed one is raised), trim the arrays to their
        committed rows, mark the store complete, fsync."""
        if self._closed:
            return
        self._writer.close()
        try:
            self._writer.raise_error()
        except RecorderError:
            self._closed = True
            raise
        with _settling():
            for table in self.tables.values():
                table.trim()
            self.root.update_attributes({schema.COMPLETE_ATTR: True})
            self.sync()
        self._closed = True
