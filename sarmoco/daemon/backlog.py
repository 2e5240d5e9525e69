"""Recorded pulses waiting to be focused: a bounded queue that skips ahead, never blocks.

The recording path (:meth:`~sarmoco.daemon.pipeline.Pipeline.record`) takes pulses out
of the echo ring, stores them, and puts them here; the focusing path takes them out
through the :class:`~sarmoco.daemon.aligner.Aligner`, which looks at the oldest
(:meth:`FocusBacklog.peek_times`) and takes them (:meth:`FocusBacklog.pop`) as the
echo ring's consumer does. Recording never waits for focusing: when a put would hold
more than ``capacity`` pulses, the oldest pulses not yet looked at are skipped (counted
in :attr:`FocusBacklog.skipped`): the focuser, fallen behind, goes on with the newest
pulses, and its lag stays within ``capacity`` pulses. The pulses a look has seen are
never skipped, so a :meth:`~FocusBacklog.pop` takes exactly what the look saw. A
skipped pulse is stored all the same; a replay of the store focuses it.

A caller that must not skip (a file read at its own pace, a replay) puts no more than
:attr:`FocusBacklog.free` pulses.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, fields

import numpy as np

from sarmoco.daemon.echoring import EchoBatch
from sarmoco.errors import ProcessingError
from sarmoco.processing.types import IntArray


@dataclass(frozen=True)
class RecordedBatch(EchoBatch):
    """Pulses taken out of the echo ring and stored (oldest first).

    Attributes
    ----------
    row : ndarray of int64, shape (P,)
        Row of each pulse in the store's ``pulses`` table.
    """

    row: IntArray

    def part(self, start: int, stop: int) -> RecordedBatch:
        """Pulses ``start .. stop - 1`` (views)."""
        return RecordedBatch(*(getattr(self, f.name)[start:stop] for f in fields(self)))

    @classmethod
    def join(cls, parts: list[RecordedBatch]) -> RecordedBatch:
        """The pulses of ``parts``, one after the other (one part: itself)."""
        if len(parts) == 1:
            return parts[0]
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(cls)))


class FocusBacklog:
    """Bounded queue of recorded pulses for the focusing path (see the module doc).

    Parameters
    ----------
    capacity : int
        Most pulses held (>= 1).

    Attributes
    ----------
    skipped : int
        Pulses skipped because the focuser was ``capacity`` pulses behind.
    """

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ProcessingError(f"FocusBacklog: capacity {capacity} must be >= 1")
        self.capacity = capacity
        self.skipped = 0
        self._parts: deque[RecordedBatch] = deque()
        self._n = 0
        self._seen = 0
        """Oldest pulses a look has seen and no pop has taken yet (never skipped)."""
        self._lock = threading.Lock()

    def __len__(self) -> int:
        """Pulses waiting."""
        with self._lock:
            return self._n

    @property
    def free(self) -> int:
        """Pulses that a put can add without skipping any."""
        with self._lock:
            return self.capacity - self._n

    def oldest_ns(self) -> int | None:
        """Time of the oldest waiting pulse, GPS ns (None: none waits); no look."""
        with self._lock:
            return int(self._parts[0].t_ns[0]) if self._parts else None

    def put(self, batch: RecordedBatch) -> int:
        """Add pulses newer than every pulse held; returns the pulses skipped to make room."""
        if len(batch) == 0:
            return 0
        with self._lock:
            self._parts.append(batch)
            self._n += len(batch)
            over = max(self._n - max(self.capacity, self._seen), 0)
            if over:
                self._remove(self._seen, over)
                self.skipped += over
            return over

    def peek_times(self, max_n: int | None = None) -> IntArray:
        """Times (GPS ns) of the oldest waiting pulses (a copy); they are not skipped
        until taken.

        Parameters
        ----------
        max_n : int, optional
            Look at no more than this many pulses.
        """
        with self._lock:
            n = self._n if max_n is None else min(max_n, self._n)
            self._seen = max(self._seen, n)
            times, have = [], 0
            for part in self._parts:
                if have >= n:
                    break
                take = min(len(part), n - have)
                times.append(part.t_ns[:take])
                have += take
            return np.concatenate(times) if times else np.zeros(0, dtype=np.int64)

    def pop(self, n: int) -> RecordedBatch:
        """Take the ``n`` oldest pulses out (``n`` >= 1).

        Raises
        ------
        ProcessingError
            If fewer than ``n`` pulses wait, or ``n`` < 1.
        """
        with self._lock:
            if not 1 <= n <= self._n:
                raise ProcessingError(f"FocusBacklog.pop: {n} pulses asked, {self._n} waiting")
            taken: list[RecordedBatch] = []
            have = 0
            while have < n:
                part = self._parts.popleft()
                take = min(len(part), n - have)
                taken.append(part.part(0, take))
                if take < len(part):
                    self._parts.appendleft(part.part(take, len(part)))
                have += take
            self._n -= n
            self._seen = max(self._seen - n, 0)
        return RecordedBatch.join(taken)

    def _remove(self, start: int, n: int) -> None:
        """Remove ``n`` pulses from position ``start`` on (lock held); the parts after them
        are not looked at."""
        head: list[RecordedBatch] = []
        pos = 0
        while self._parts and pos < start + n:
            part = self._parts.popleft()
            a, b = pos, pos + len(part)
            pos = b
            lo, hi = max(a, start), min(b, start + n)
            if lo >= hi:
                head.append(part)
                continue
            if lo > a:
                head.append(part.part(0, lo - a))
            if hi < b:
                head.append(part.part(hi - a, b - a))
        self._parts.extendleft(reversed(head))
        self._n -= n
