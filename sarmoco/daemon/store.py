"""Reading a run store back: committed rows only, as numpy or xarray.

A store written by :class:`~sarmoco.daemon.recorder.Recorder` may come from a
run that crashed: arrays may be longer than their data, and rows past a
table's ``committed`` attribute may hold anything. Everything here reads below
``committed`` and nothing else. ``xarray.open_zarr(path, group=...)`` also
works on a store (zarr v3 dimension names); on a store that is not
``complete``, slice each table to its ``committed`` rows yourself, or use
:meth:`RunStore.dataset`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import dask.array as da
import numpy as np
import numpy.typing as npt
import xarray as xr
import zarr
from zarr.core.metadata import ArrayV3Metadata

from sarmoco.daemon.recorder import COMMITTED_ATTR
from sarmoco.errors import RecorderError
from sarmoco.processing.types import Image


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

    Raises
    ------
    RecorderError
        The path is not a readable sarmoco store.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self.root = zarr.open_group(str(self.path), mode="r", zarr_format=3)
        except (OSError, ValueError, KeyError) as exc:  # zarr reports a missing store so
            raise RecorderError(f"{self.path}: not a readable zarr v3 store: {exc}") from exc
        if "sarmoco_store" not in self.root.attrs:
            raise RecorderError(f"{self.path}: not a sarmoco store (no sarmoco_store attribute)")

    @property
    def attrs(self) -> dict[str, Any]:
        """Root attributes (read fresh): ``config``, ``versions``, ``metrics``, ``complete``..."""
        return dict(zarr.open_group(str(self.path), mode="r", zarr_format=3).attrs)

    def tables(self) -> list[str]:
        """Names of the tables (groups with a committed row count), images excluded."""
        return sorted(
            name
            for name, node in self.root.groups()
            if name != "images" and COMMITTED_ATTR in node.attrs
        )

    def _group(self, table: str) -> zarr.Group:
        try:
            node = self.root[table]
        except KeyError as exc:
            raise RecorderError(f"{self.path}: no table {table!r} (have {self.tables()})") from exc
        if not isinstance(node, zarr.Group):
            raise RecorderError(f"{self.path}: {table!r} is not a table")
        return node

    def committed(self, table: str) -> int:
        """Rows of ``table`` that are complete (read fresh from the store)."""
        group = zarr.open_group(str(self.path / table), mode="r", zarr_format=3)
        value = group.attrs[COMMITTED_ATTR]
        if not isinstance(value, int):
            raise RecorderError(f"{self.path}: {table}.{COMMITTED_ATTR} is {value!r}, not an int")
        return value

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
        out: dict[str, npt.NDArray[Any]] = {}
        for name in names:
            out[name] = np.asarray(_array(group, name)[start:stop])
        return out

    def dataset(self, table: str) -> xr.Dataset:
        """A table as a lazy (dask) xarray Dataset cut to its committed rows.

        Each array is cut on its own before the Dataset is assembled: after a crash the
        arrays of a table may have been grown to different lengths (growth happens
        before rows are written), which ``xarray.open_zarr`` on the group would refuse.
        """
        n = self.committed(table)
        group = self._group(table)
        data_vars = {}
        for name, arr in sorted(group.arrays()):
            if not isinstance(arr.metadata, ArrayV3Metadata):
                raise RecorderError(f"{self.path}: {table}/{name} is not a zarr v3 array")
            dims = tuple(str(d) for d in arr.metadata.dimension_names or ())
            data_vars[name] = (dims, da.from_zarr(arr)[:n])
        return xr.Dataset(data_vars)

    @property
    def n_images(self) -> int:
        """Image tiles that are complete."""
        return self.committed("images")

    def image(self, index: int) -> tuple[Image, dict[str, Any]]:
        """Tile ``index`` and its attributes (``t0_ns``, ``t1_ns``, ``metrics``)."""
        if not 0 <= index < self.n_images:
            raise RecorderError(f"{self.path}: image {index} not committed ({self.n_images} are)")
        group = self._group(f"images/tile_{index:06d}")
        attrs = dict(group.attrs)
        image = Image(
            data=np.asarray(_array(group, "data")[...]),
            axis0_m=np.asarray(_array(group, "axis0_m")[...]),
            axis1_m=np.asarray(_array(group, "axis1_m")[...]),
            frame=str(attrs["frame"]),
        )
        return image, attrs

    def ins_bytes(self, index: int | None = None) -> bytes:
        """Raw INS bytes: chunk ``index`` as read, or all committed bytes in order."""
        if index is None:
            return self.read("ins_bytes")["byte"].tobytes()
        row = self.read("ins_raw", start=index, stop=index + 1)
        if row["offset"].shape[0] == 0:
            raise RecorderError(f"{self.path}: raw INS chunk {index} not committed")
        off, length = int(row["offset"][0]), int(row["length"][0])
        return self.read("ins_bytes", start=off, stop=off + length)["byte"].tobytes()


def open_store(path: str | Path) -> RunStore:
    """Open a run store read-only (see :class:`RunStore`)."""
    return RunStore(path)
