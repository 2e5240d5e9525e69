"""The daemon hands the heap pages focusing freed back to the system."""

from __future__ import annotations

import numpy as np
import pytest

from sarmoco.daemon.heap import HeapTrim

MIB = 2**20


def _rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS in /proc/self/status")


def test_the_pages_of_freed_block_temporaries_go_back_to_the_system() -> None:
    """As a focusing pass leaves the heap: one large array freed (which raises glibc's mmap
    threshold), then ten 20 MiB temporaries taken from the heap below an array still in
    use, and freed. They stay resident until the trim, which hands them back."""
    heap = HeapTrim(interval_s=0.0)
    if not heap.available:
        pytest.skip("the C library has no malloc_trim (not glibc)")
    first = np.ones(25 * MIB // 8)
    del first
    temporaries = [np.ones(20 * MIB // 8) for _ in range(10)]
    held = np.ones(MIB // 8)  # in use above them: the heap's top cannot shrink
    del temporaries
    before = _rss_mib()
    assert heap.maybe_trim()
    after = _rss_mib()
    assert held.sum() == MIB // 8
    assert before - after > 150.0, (before, after)


def test_at_most_one_trim_per_interval() -> None:
    now = [0.0]
    heap = HeapTrim(interval_s=1.0, clock=lambda: now[0])
    if not heap.available:
        pytest.skip("the C library has no malloc_trim (not glibc)")
    assert heap.maybe_trim() and not heap.maybe_trim()
    now[0] = 0.99
    assert not heap.maybe_trim()
    now[0] = 1.0
    assert heap.maybe_trim() and heap.trims == 2
