"""Buffers of the streaming autofocus: pulses appended and dropped without copying, and
per-subaperture values that can be forgotten."""

from __future__ import annotations

from typing import Generic, TypeVar

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import ComplexArray


class RowBuffer:
    """Pulses (rows) appended at the end and dropped from the front; the kept rows are copied
    only when the storage grows (to twice what is kept), not on every append."""

    def __init__(self, n_cols: int) -> None:
        self._buf: ComplexArray = np.zeros((0, n_cols), dtype=np.complex64)
        self._start = 0
        self._stop = 0

    @property
    def rows(self) -> ComplexArray:
        """The kept rows (a view)."""
        return self._buf[self._start : self._stop]

    def __len__(self) -> int:
        return self._stop - self._start

    def append(self, rows: ComplexArray) -> None:
        n = rows.shape[0]
        if self._stop + n > self._buf.shape[0]:
            kept = len(self)
            grown = np.empty((max(2 * (kept + n), 256), self._buf.shape[1]), dtype=np.complex64)
            grown[:kept] = self.rows
            self._buf, self._start, self._stop = grown, 0, kept
        self._buf[self._stop : self._stop + n] = rows
        self._stop += n

    def drop(self, n: int) -> None:
        self._start += min(n, len(self))


T = TypeVar("T")


class History(Generic[T]):
    """Per-subaperture values by absolute subaperture number j; the oldest can be forgotten
    (a run of hours keeps only those the buffered pulses still need, not one per hop)."""

    def __init__(self) -> None:
        self.first = 0
        """Number of the oldest value kept."""
        self._items: list[T] = []

    def __len__(self) -> int:
        """Number of values ever appended (one past the newest j)."""
        return self.first + len(self._items)

    def __getitem__(self, j: int) -> T:
        if j < 0:
            return self._items[j]
        if j < self.first:
            raise ProcessingError(f"autofocus history: subaperture {j} was forgotten")
        return self._items[j - self.first]

    def append(self, value: T) -> None:
        self._items.append(value)

    def since(self, j0: int, j1: int | None = None) -> list[T]:
        """Values j0 .. j1 - 1 (to the newest when j1 is None); j0 at least :attr:`first`."""
        if j0 < self.first:
            raise ProcessingError(f"autofocus history: subaperture {j0} was forgotten")
        stop = None if j1 is None else j1 - self.first
        return self._items[j0 - self.first : stop]

    def forget_before(self, j: int) -> None:
        """Drop the values of subapertures before j."""
        n = max(0, min(j - self.first, len(self._items)))
        del self._items[:n]
        self.first += n
