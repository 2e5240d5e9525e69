"""CPU time of the daemon's stages: its threads' clocks, from ``/proc/self/task`` (Linux).

Each stage of a live run is one thread or a few, known by their names:

``receive``
    The radar reader (``radar``): socket, decode, the write into the echo ring.
``record``
    The recording thread (``recording``): echo ring to store calls, the INS log.
``write``
    The store's writes: the recorder's writer thread (``recorder …``) and zarr's I/O
    loop and workers (``zarr_io``, ``asyncio_…``).
``focus``
    The focusing loop (the main thread) and the threads that are no Python thread
    (numba's and the FFT's worker pools, which only focusing uses).
``other``
    The rest: INS reader, health, status server, and threads that have ended.

Where ``/proc`` is missing (not Linux) every stage reads 0.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

STAGES = ("receive", "record", "write", "focus", "other")
"""The stages, in the order of the data."""

_BY_NAME = (("radar", "receive"), ("recording", "record"), ("recorder ", "write"),
            ("zarr_io", "write"), ("asyncio_", "write"))  # fmt: skip
"""Python thread name (or its start) → stage."""


_seen: dict[int, str] = {}
"""Stage of every Python thread seen alive (by native id): one that has just ended keeps
its stage while its task is still listed."""
_seen_lock = threading.Lock()
"""Held while :data:`_seen` is read or changed (status requests come on many threads)."""


def _stage_of(name: str) -> str:
    for start, stage in _BY_NAME:
        if name == start or (start.endswith(("_", " ")) and name.startswith(start)):
            return stage
    return "other"


def _cpu_s(stat: Path) -> float:
    """User + system CPU time in a ``stat`` file of ``/proc``, s (0 when it is gone)."""
    try:
        text = stat.read_text()
    except OSError:
        return 0.0
    fields = text[text.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stage_cpu_seconds() -> dict[str, float]:
    """CPU seconds spent so far by each of :data:`STAGES` (this process), s."""
    proc = Path("/proc/self")
    out = dict.fromkeys(STAGES, 0.0)
    if not proc.is_dir():
        return out
    main = threading.main_thread().native_id
    with _seen_lock:
        for thread in threading.enumerate():
            if thread.native_id is not None and thread.native_id != main:
                _seen[thread.native_id] = _stage_of(thread.name)
        listed = set()
        for task in (proc / "task").iterdir():
            listed.add(int(task.name))
            out[_seen.get(int(task.name), "focus")] += _cpu_s(task / "stat")
        for tid in _seen.keys() - listed:
            _seen.pop(tid, None)
    out["other"] += max(_cpu_s(proc / "stat") - sum(out.values()), 0.0)  # ended threads
    return out
