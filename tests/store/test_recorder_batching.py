"""The recorder's writes at a high pulse rate: no chunk read back, rows gathered in memory
for ``flush_interval_s``, larger chunks for the per-pulse columns other than the echoes."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder, _SyncingStore, meta_chunk_pulses

PRF_HZ = 20_000.0
"""The pulse rate of thz-spotlight: a recording pass every 10 ms takes 200 pulses."""
INTERVAL_S = 1.0
"""The flush interval of the batching test, s (a margin for a loaded machine)."""


def _count_calls(monkeypatch: pytest.MonkeyPatch, method: str) -> list[str]:
    """Keys of every call of ``_SyncingStore.<method>`` from now on."""
    keys: list[str] = []
    real = getattr(_SyncingStore, method)

    async def counted(self: _SyncingStore, key: str, *args: Any, **kwargs: Any) -> Any:
        keys.append(key)
        return await real(self, key, *args, **kwargs)

    monkeypatch.setattr(_SyncingStore, method, counted)
    return keys


def _append(rec: Recorder, first: int, n: int) -> None:
    ids = np.arange(first, first + n, dtype=np.int64)
    rec.append_pulses(ids * 50_000, ids, np.zeros(n, np.int32), (ids % 5).astype(np.uint32))


def test_blocks_that_end_inside_chunks_never_read_a_chunk_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Blocks of 37 pulses into chunks of 16 (echoes) and 64 (the rest): each partial chunk
    is written whole, padded, from the rows kept in memory, so zarr reads nothing."""
    rec = Recorder(tmp_path / "r.zarr", 8, "int16", chunk_pulses=16, meta_chunk_pulses=64)
    reads = _count_calls(monkeypatch, "get")
    for k in range(6):
        ids = np.arange(37 * k, 37 * (k + 1), dtype=np.int64)
        echo = np.broadcast_to(ids[:, None, None], (37, 8, 2)).astype(np.int16)
        rec.append_pulses(ids, ids, np.zeros(37, np.int32), np.zeros(37, np.uint32), echo)
    assert reads == []
    assert open_store(tmp_path / "r.zarr").committed("pulses") == 222
    rec.close()
    got = open_store(tmp_path / "r.zarr").read("pulses")
    np.testing.assert_array_equal(got["pulse_id"], np.arange(222))
    np.testing.assert_array_equal(got["echo"][:, 3, 1], np.arange(222))


def test_meta_chunks_hold_a_fifth_of_a_second_of_pulses() -> None:
    assert meta_chunk_pulses(256, PRF_HZ) == 4096
    assert meta_chunk_pulses(256, 1000.0) == 256
    assert meta_chunk_pulses(32, 500.0) == 128


def test_rows_wait_for_the_flush_interval_and_flags_reach_the_rows_held(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Half a second at 20 kHz in recording passes of 200 pulses with a flush interval of
    1 s (a margin for a loaded machine): a handful of chunk files instead of a few per
    pass, none when no row came; rows held are not committed until written, and a flag set
    on rows held (or already written) is stored."""
    path = tmp_path / "r.zarr"
    rec = Recorder(
        path, 4096, raw_echoes=False, flush_interval_s=INTERVAL_S,
        meta_chunk_pulses=meta_chunk_pulses(256, PRF_HZ),
    )  # fmt: skip
    writes = _count_calls(monkeypatch, "set")
    t0, passes = time.monotonic(), 50
    _append(rec, 0, 200)
    assert open_store(path).committed("pulses") == 0  # held: not written yet
    rec.flag_pulses([3, 150], 0x40)
    for k in range(1, passes):
        time.sleep(max(0.0, t0 + k * 0.01 - time.monotonic()))
        _append(rec, 200 * k, 200)
        rec.flush_due()
    rec.flag_pulses([7, 9_999], 0x80)
    time.sleep(INTERVAL_S)
    rec.flush_due()
    assert open_store(path).committed("pulses") == 200 * passes
    chunk_files = [k for k in writes if "/c/" in k]
    assert len(chunk_files) < passes, writes  # written every pass: 4 files a pass
    writes.clear()
    for _ in range(2):
        time.sleep(INTERVAL_S / 2)
        rec.flush_due()
    assert writes == []  # nothing new: nothing written again
    rec.close()
    flags = open_store(path).read("pulses", ["flags"])["flags"]
    want = (np.arange(200 * passes) % 5).astype(np.uint32)
    want[[3, 150]] |= 0x40
    want[[7, 9_999]] |= 0x80
    np.testing.assert_array_equal(flags, want)
