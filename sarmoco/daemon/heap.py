"""Give the memory that focusing freed back to the system.

The focusing chain allocates and frees arrays of tens of megabytes for every block (a
block of raw pulses, a range-Doppler block, its filters). glibc's malloc serves such
arrays from its heap once the first one freed has raised its mmap threshold to its size
(up to 32 MiB), and keeps the pages of freed chunks that lie below a chunk still in use:
the daemon's resident memory then climbs to the largest set of temporaries ever alive at
once in each thread's arena, and stays there. :class:`HeapTrim` hands those free pages
back (``malloc_trim(0)``: every arena) at most once per interval, from the focusing loop.
Where the C library has no ``malloc_trim`` (not glibc) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import math
import time
from collections.abc import Callable

TRIM_INTERVAL_S = 1.0
"""Least wall time between two trims, s (a trim of a heap of a gigabyte takes milliseconds)."""


def _malloc_trim() -> Callable[[int], int] | None:
    """The C library's ``malloc_trim`` (None where it has none)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
    except OSError:
        return None
    trim: Callable[[int], int] | None = getattr(libc, "malloc_trim", None)
    return trim


class HeapTrim:
    """Return the heap's free pages to the system, at most once per ``interval_s``.

    Parameters
    ----------
    interval_s : float
        Least wall time between two trims, s.
    clock : callable, optional
        Monotonic clock, s (tests pass their own).

    Attributes
    ----------
    trims : int
        Trims done.
    """

    def __init__(
        self, interval_s: float = TRIM_INTERVAL_S, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.interval_s = float(interval_s)
        self._clock = clock
        self._trim = _malloc_trim()
        self._last = -math.inf
        self.trims = 0

    @property
    def available(self) -> bool:
        """Whether the C library can trim (glibc)."""
        return self._trim is not None

    def maybe_trim(self) -> bool:
        """Trim if the interval has passed since the last trim; whether it trimmed."""
        now = self._clock()
        if self._trim is None or now - self._last < self.interval_s:
            return False
        self._last = now
        self._trim(0)
        self.trims += 1
        return True
