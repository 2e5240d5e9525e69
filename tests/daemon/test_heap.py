"""The daemon hands the heap pages focusing freed back to the system."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from sarmoco.daemon.heap import HeapTrim

FREED_IN_THE_HEAP = """
import numpy as np
from sarmoco.daemon.heap import HeapTrim

MIB = 2**20

def rss_mib():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) / 1024.0 for line in f if line.startswith("VmRSS:"))

heap = HeapTrim(interval_s=0.0)
temporaries = [np.ones(20 * MIB // 8) for _ in range(10)]
held = np.ones(MIB // 8)
del temporaries
before = rss_mib()
trimmed = heap.maybe_trim()
print(heap.available, trimmed, before, rss_mib(), held.size)
"""
"""In a fresh interpreter with glibc's mmap threshold at 64 MiB (:data:`HEAP_ENV`): ten
20 MiB temporaries taken from the heap below an array still in use, and freed; prints
whether the trim is available and done, and the RSS before and after it, MiB."""

HEAP_ENV = {"MALLOC_MMAP_THRESHOLD_": str(64 * 2**20)}
"""Where glibc serves 20 MiB arrays: from the heap, as a running daemon's once the first large
array it freed has raised the dynamic threshold (up to 32 MiB). Set here, the heap's state
does not hang on what the interpreter happened to allocate first (a freed 25 MiB array
raised it on one machine and not on another)."""


def test_the_pages_of_freed_block_temporaries_go_back_to_the_system() -> None:
    """As a focusing pass leaves the heap (:data:`FREED_IN_THE_HEAP`): the freed
    temporaries stay resident until the trim, which hands them back."""
    out = subprocess.run(
        [sys.executable, "-c", FREED_IN_THE_HEAP],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, **HEAP_ENV},
    ).stdout.split()
    if out[0] != "True":
        pytest.skip("the C library has no malloc_trim (not glibc)")
    before, after = float(out[2]), float(out[3])
    assert out[1] == "True"
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
