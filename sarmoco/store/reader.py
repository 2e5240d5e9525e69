"""Reading a run store back: committed rows only, as numpy or xarray, or as sources.

A store written by :class:`~sarmoco.store.recorder.Recorder` may come from a
run that crashed: arrays may be longer than their data, and rows past a
table's ``committed`` attribute may hold anything. Everything here reads below
``committed`` and nothing else. ``xarray.open_zarr(path, group=...)`` also
works on a store (zarr v3 dimension names); on a store that is not
``complete``, slice each table to its ``committed`` rows yourself, or use
:meth:`RunStore.dataset`. :class:`StorePulses` and :class:`StoreNav` serve a
recording as a radar and a navigation source, for a replay.
"""

from __future__ import annotations

import functools
import itertools
import logging
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Concatenate, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt
import zarr
from zarr.core.metadata import ArrayV3Metadata

from sarmoco.closing import Closing
from sarmoco.drivers.samples import EchoPackets, Sample
from sarmoco.drivers.source import Source
from sarmoco.errors import RecorderError
from sarmoco.processing.array.imaging3d import DemProduct
from sarmoco.processing.types import Image
from sarmoco.store import schema
from sarmoco.store.flags import PushResult
from sarmoco.store.schema import COMMITTED_ATTR
from sarmoco.store.verify import DAMAGE, chunk_present, chunk_rows, describe

if TYPE_CHECKING:
    import xarray as xr

log = logging.getLogger(__name__)
_P = ParamSpec("_P")
_R = TypeVar("_R")


def _reading(
    method: Callable[Concatenate[RunStore, _P], _R],
) -> Callable[Concatenate[RunStore, _P], _R]:
    """A :class:`RunStore` method whose damaged-store failures become a RecorderError
    naming the store (the reader's own RecorderErrors pass unchanged)."""

    @functools.wraps(method)
    def wrapper(self: RunStore, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        try:
            return method(self, *args, **kwargs)
        except RecorderError:
            raise
        except DAMAGE as exc:
            raise RecorderError(
                f"{self.path}: damaged store ({type(exc).__name__}: {exc})"
            ) from exc

    return wrapper


def _array(group: zarr.Group, name: str) -> zarr.Array:
    node = group.get(name)
    if not isinstance(node, zarr.Array):
        raise RecorderError(f"{group.store_path}: {name!r} is not an array")
    return node


class RunStore:
    """A recorded run, opened read-only.

    Parameters
    ----------
    path : str or Path
        The store directory.
    skip_damaged : bool
        Rows in chunks that are missing, fail their checksum or do not decode are left out
        of what :meth:`read` returns, and damaged tiles out of :meth:`images`, each logged
        once as a warning and counted in :attr:`skipped` (a replay or report of a store
        off a failing card focuses the rest). False: such a chunk raises RecorderError.

    Raises
    ------
    RecorderError
        The path is not a readable sarmoco store.
    """

    def __init__(self, path: str | Path, skip_damaged: bool = False) -> None:
        self.path = Path(path)
        self.skip_damaged = skip_damaged
        self.skipped: dict[str, int] = {}
        """Damaged chunks skipped (``"pulses/echo chunk 3: checksum mismatch"``) to the rows
        (tiles: 1) each cost."""
        try:
            self.root = zarr.open_group(str(self.path), mode="r", zarr_format=3)
        except (OSError, ValueError, KeyError) as exc:  # zarr reports a missing store so
            raise RecorderError(f"{self.path}: not a readable zarr v3 store: {exc}") from exc
        if schema.LAYOUT_ATTR not in self.root.attrs:
            raise RecorderError(
                f"{self.path}: not a sarmoco store (no {schema.LAYOUT_ATTR} attribute)"
            )
        version = schema.read_attr(self.root.attrs, schema.LAYOUT_ATTR, int, str(self.path))
        if version != schema.STORE_LAYOUT_VERSION:
            raise RecorderError(
                f"{self.path}.{schema.LAYOUT_ATTR}: layout {version}, this sarmoco reads "
                f"{schema.STORE_LAYOUT_VERSION}"
            )

    @property
    @_reading
    def attrs(self) -> dict[str, Any]:
        """Root attributes (read fresh): ``config``, ``versions``, ``metrics``, ``complete``..."""
        return dict(zarr.open_group(str(self.path), mode="r", zarr_format=3).attrs)

    @_reading
    def tables(self) -> list[str]:
        """Names of the tables (groups with a committed row count), images excluded."""
        return sorted(
            name
            for name, node in self.root.groups()
            if name != schema.IMAGES_GROUP and COMMITTED_ATTR in node.attrs
        )

    @_reading
    def _group(self, table: str) -> zarr.Group:
        try:
            node = self.root[table]
        except KeyError as exc:
            raise RecorderError(f"{self.path}: no table {table!r} (have {self.tables()})") from exc
        if not isinstance(node, zarr.Group):
            raise RecorderError(f"{self.path}: {table!r} is not a table")
        return node

    @_reading
    def committed(self, table: str) -> int:
        """Rows of ``table`` that are complete (read fresh from the store; an int >= 0)."""
        group = zarr.open_group(str(self.path / table), mode="r", zarr_format=3)
        return schema.read_committed(group.attrs, f"{self.path}/{table}")

    @_reading
    def read(
        self, table: str, columns: list[str] | None = None, start: int = 0, stop: int | None = None
    ) -> dict[str, npt.NDArray[Any]]:
        """Committed rows ``[start, stop)`` of a table's columns as numpy arrays.

        Parameters
        ----------
        table : str
            E.g. ``"pulses"``, ``"nav"``, ``"motion"``, ``"autofocus"``.
        columns : list of str, optional
            Columns to read (default all).
        start, stop : int
            Row range; ``stop`` is clipped to the committed count.
        """
        n = self.committed(table)
        stop = n if stop is None else min(stop, n)
        group = self._group(table)
        names = columns if columns is not None else sorted(k for k, _ in group.arrays())
        arrays = {name: _array(group, name) for name in names}
        for name, arr in arrays.items():
            if arr.ndim == 0 or arr.shape[0] < stop:
                raise RecorderError(
                    f"{self.path}/{table}/{name}: shape {arr.shape} holds fewer rows than "
                    f"{table}.{COMMITTED_ATTR} = {n}"
                )
        out: dict[str, npt.NDArray[Any]] = {}
        bad = np.zeros(max(stop - start, 0), dtype=bool)
        for name, arr in arrays.items():
            if self.skip_damaged:
                out[name] = self._read_intact(arr, f"{table}/{name}", start, stop, n, bad)
            else:
                out[name] = np.asarray(arr[start:stop])
        return {k: v[~bad] for k, v in out.items()} if bad.any() else out

    def _read_intact(
        self,
        arr: zarr.Array,
        where: str,
        start: int,
        stop: int,
        committed: int,
        bad: npt.NDArray[np.bool_],
    ) -> npt.NDArray[Any]:
        """Rows ``[start, stop)`` of ``arr``; those of damaged chunks marked in ``bad``
        (their values are left as the fill value) and the chunks noted in :attr:`skipped`
        with their ``committed`` rows."""
        rows = chunk_rows(arr)
        first, last = start // rows, -(-stop // rows)
        tail = (0,) * (arr.ndim - 1)

        def held(i: int) -> int:  # committed rows of chunk i
            return min((i + 1) * rows, committed) - i * rows

        missing = [i for i in range(first, last) if not chunk_present(self.path, arr, (i, *tail))]
        try:
            values = np.asarray(arr[start:stop])
        except DAMAGE:
            values = np.full((stop - start, *arr.shape[1:]), arr.fill_value, dtype=arr.dtype)
            for i in range(first, last):
                lo, hi = max(i * rows, start), min((i + 1) * rows, stop)
                try:
                    values[lo - start : hi - start] = arr[lo:hi]
                except DAMAGE as exc:
                    self._skip(f"{where} chunk {i}: {describe(exc)}", held(i))
                    bad[lo - start : hi - start] = True
        for i in missing:
            lo, hi = max(i * rows, start), min((i + 1) * rows, stop)
            self._skip(f"{where} chunk {i}: missing", held(i))
            bad[lo - start : hi - start] = True
        return values

    def _skip(self, what: str, rows: int) -> None:
        """Note a damaged chunk (logged the first time it is met)."""
        if what not in self.skipped:
            log.warning("%s: %s: skipped (%d rows)", self.path, what, rows)
            self.skipped[what] = rows

    def damage_text(self) -> str:
        """The damaged chunks skipped, counted: empty when none was."""
        if not self.skipped:
            return ""
        return (
            f"{self.path}: {len(self.skipped)} damaged chunks skipped "
            f"({sum(self.skipped.values())} rows or tiles): " + "; ".join(self.skipped)
        )

    @_reading
    def dataset(self, table: str) -> xr.Dataset:
        """A table as a lazy (dask) xarray Dataset cut to its committed rows.

        Each array is cut on its own before the Dataset is assembled: after a crash the
        arrays of a table may have been grown to different lengths (growth happens
        before rows are written), which ``xarray.open_zarr`` on the group would refuse.
        The chunks are read when the Dataset is computed: a damaged chunk raises then, from
        zarr or numcodecs. The columns the others name in their ``coordinates`` attribute
        (``t_ns``...) are coordinates, as ``xarray.open_zarr`` makes them.
        """
        import dask.array as da  # the daemon, which reads no Dataset, starts without them
        import xarray as xr

        n = self.committed(table)
        group = self._group(table)
        data_vars = {}
        coords: set[str] = set()
        for name, arr in sorted(group.arrays()):
            if not isinstance(arr.metadata, ArrayV3Metadata):
                raise RecorderError(f"{self.path}: {table}/{name} is not a zarr v3 array")
            dims = tuple(str(d) for d in arr.metadata.dimension_names or ())
            data_vars[name] = (dims, da.from_zarr(arr)[:n])
            named = arr.attrs.get("coordinates", "")
            coords.update(named.split() if isinstance(named, str) else ())
        return xr.Dataset(data_vars).set_coords(sorted(coords & data_vars.keys()))

    @property
    def n_images(self) -> int:
        """Image tiles that are complete."""
        return self.committed(schema.IMAGES_GROUP)

    def images(self) -> Iterator[tuple[int, Image, dict[str, Any]]]:
        """Every committed tile: its index, image and attributes (:meth:`image`); with
        ``skip_damaged``, a tile with a damaged chunk is left out and noted in
        :attr:`skipped`."""
        for k in range(self.n_images):
            try:
                image, attrs = self.image(k)
            except RecorderError as exc:
                if not self.skip_damaged:
                    raise
                self._skip(f"{schema.IMAGES_GROUP}/{schema.tile_name(k)}: {exc}", 1)
                continue
            yield k, image, attrs

    @_reading
    def image(self, index: int) -> tuple[Image, dict[str, Any]]:
        """Tile ``index`` and its attributes (``t0_ns``, ``t1_ns``, ``metrics``).

        Raises
        ------
        RecorderError
            Not committed, or damaged (a chunk missing, failing its checksum, undecodable).
        """
        if not 0 <= index < self.n_images:
            raise RecorderError(f"{self.path}: image {index} not committed ({self.n_images} are)")
        name = f"{schema.IMAGES_GROUP}/{schema.tile_name(index)}"
        group = self._group(name)
        for key in ("data", "axis0_m", "axis1_m"):
            arr = _array(group, key)
            grid = [range(-(-n // c)) for n, c in zip(arr.shape, arr.chunks, strict=True)]
            for index_ in itertools.product(*grid):
                if not chunk_present(self.path, arr, index_):
                    raise RecorderError(f"{self.path}/{name}/{key}: chunk {index_} missing")
        attrs = dict(group.attrs)
        image = Image(
            data=np.asarray(_array(group, "data")[...]),
            axis0_m=np.asarray(_array(group, "axis0_m")[...]),
            axis1_m=np.asarray(_array(group, "axis1_m")[...]),
            frame=schema.read_attr(attrs, "frame", str, f"{self.path}/{name}"),
        )
        return image, attrs

    @_reading
    def dem(self, name: str) -> tuple[DemProduct, float]:
        """DEM product ``name`` of an array run and its height resolution cell, m
        (:func:`~sarmoco.store.schema.decode_dem`).

        Raises
        ------
        RecorderError
            The store has no such product (a single-channel run has none) or it is damaged.
        """
        where = f"{schema.DEM_GROUP}/{name}"
        dems = self.root.get(schema.DEM_GROUP)
        if not isinstance(dems, zarr.Group) or name not in dems:
            raise RecorderError(f"{self.path}: no DEM product {where!r} (not an array run?)")
        group = self._group(where)
        arrays = {k: np.asarray(_array(group, k)[...]) for k in schema.DEM_ARRAYS}
        return schema.decode_dem(arrays, dict(group.attrs), f"{self.path}/{where}")

    def ins_bytes(self, index: int | None = None) -> bytes:
        """Raw INS bytes: chunk ``index`` as read, or all committed bytes in order."""
        if index is None:
            return self.read(schema.INS_BYTES.name, ["byte"])["byte"].tobytes()
        row = self.read(schema.INS_RAW.name, ["offset", "length"], start=index, stop=index + 1)
        if row["offset"].shape[0] == 0:
            raise RecorderError(f"{self.path}: raw INS chunk {index} not committed")
        off, length = int(row["offset"][0]), int(row["length"][0])
        byte = self.read(schema.INS_BYTES.name, ["byte"], start=off, stop=off + length)["byte"]
        return byte.tobytes()


def open_store(path: str | Path, skip_damaged: bool = False) -> RunStore:
    """Open a run store read-only (see :class:`RunStore`)."""
    return RunStore(path, skip_damaged)


class StorePulses(Closing):
    """A store's recorded pulses as a radar source, for a replay through the radar path.

    It serves :meth:`read_into` as :class:`~sarmoco.drivers.radar.RadarSource` does, so
    a replay reads pulses into the pipeline through the same call as a live run.

    Parameters
    ----------
    store : RunStore
        A recording with raw echoes.

    Raises
    ------
    RecorderError
        The recording has no raw echoes (``recorder.raw_echoes`` was off).
    """

    def __init__(self, store: RunStore) -> None:
        if "echo" not in store._group("pulses"):
            raise RecorderError(f"{store.path}: no raw echoes recorded (recorder.raw_echoes)")
        self._store = store
        self._next = 0
        self.total = store.committed("pulses")
        """Pulses recorded."""
        self.eof = self.total == 0

    def read_into(self, out: npt.NDArray[np.generic], timeout_s: float = 0.0) -> EchoPackets:
        """Copy the next recorded echoes into ``out[0], out[1], ...``; their packet metadata.

        Parameters
        ----------
        out : ndarray
            Rows of the recording's echo shape and type.
        timeout_s : float
            Ignored (the store never waits).

        Raises
        ------
        RecorderError
            ``out`` rows are not of the recording's echo shape and type.
        """
        stop = min(self._next + out.shape[0], self.total)
        rows = self._store.read("pulses", ["t_ns", "channel", "flags", "echo"], self._next, stop)
        echo = rows["echo"]
        if echo.shape[1:] != out.shape[1:] or echo.dtype != out.dtype:
            raise RecorderError(
                f"{self._store.path}: recorded echoes {echo.dtype}{echo.shape[1:]} do not fit "
                f"rows of {out.dtype}{out.shape[1:]} (radar.n_samples, radar.sample_format)"
            )
        out[: echo.shape[0]] = echo
        self._next = stop
        self.eof = stop >= self.total
        return schema.decode_pulses(rows, echo.shape[1])

    @property
    def fraction(self) -> float:
        """Share of the recorded pulses read so far."""
        return self._next / max(self.total, 1)

    def close(self) -> None:
        """Nothing to release (the store is read per call)."""


class StoreNav(Source):
    """The INS samples a run accepted, in time order, as a navigation source (a replay).

    Samples the live run's nav buffer rejected (duplicates, stale, clock steps) are left
    out: the replay offers what the live aligner used. When :meth:`keep_raw` is called
    the recording's raw INS bytes come out of :meth:`take_raw` after the first poll, in
    the recording's format.

    Parameters
    ----------
    store : RunStore
        The recording.
    chunk : int
        Samples per :meth:`poll`.
    """

    def __init__(self, store: RunStore, chunk: int = 256) -> None:
        super().__init__()
        cols = store.read(schema.NAV.name, [*schema.NAV_SAMPLE_COLUMNS, "result"])
        keep = np.flatnonzero(cols["result"] == int(PushResult.ACCEPTED))
        keep = keep[np.argsort(cols["t_ns"][keep], kind="stable")]
        try:
            origin = schema.decode_geodetic_origin(store.attrs, str(store.path))
            frame = origin.frame
        except RecorderError:  # no absolute position: the positions are in the INS's frame
            frame = None
        self._samples = schema.decode_nav({k: v[keep] for k, v in cols.items()}, frame=frame)
        self._next = 0
        self._chunk = chunk
        self._raw_store: RunStore | None = store
        self.raw_format = ""
        """Format of the recording's raw INS bytes ("" when none were kept)."""
        attrs = store.attrs
        if schema.INS_RAW_ATTR in attrs:
            raw = schema.read_attr(attrs, schema.INS_RAW_ATTR, dict, str(store.path))
            where = f"{store.path}.{schema.INS_RAW_ATTR}"
            self.raw_format = schema.read_attr(raw, "format", str, where)
        self.eof = not self._samples

    def poll(self, timeout_s: float = 0.0) -> list[Sample]:
        """The next ``chunk`` samples (``timeout_s`` is ignored)."""
        if self._raw_store is not None:
            self._keep(self._raw_store.ins_bytes())
            self._raw_store = None
        batch = self._samples[self._next : self._next + self._chunk]
        self._next += len(batch)
        self.eof = self._next >= len(self._samples)
        return list(batch)

    def close(self) -> None:
        """Nothing to release."""
