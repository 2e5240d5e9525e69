"""The recorder's writer thread (sarmoco.store.writer): order, back-pressure, failures.

Its durability under power loss and SIGKILL is tested with the other recorder crash tests
(test_faults_power.py, parametrised over the writer thread).
"""

from __future__ import annotations

import asyncio
import shutil
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from zarr.core.buffer import Buffer
from zarr.core.sync import sync as zarr_sync

from sarmoco.errors import RecorderError
from sarmoco.store.flags import PulseFlag
from sarmoco.store.reader import open_store
from sarmoco.store.recorder import Recorder, _SyncingStore
from sarmoco.store.writer import OrderedWriter
from tests.store import crash_writer as cw
from tests.store.test_recorder import _check_committed


def test_writes_run_in_order_on_the_writer_thread_and_a_full_queue_blocks() -> None:
    writer = OrderedWriter("test", depth=3)
    gate = threading.Event()
    done: list[tuple[int, str]] = []

    def write(k: int) -> None:
        if k == 0:
            gate.wait(10.0)
        done.append((k, threading.current_thread().name))

    for k in range(4):  # the first runs (and waits at the gate), three wait in the queue
        writer.submit(write, k)
    blocked = threading.Thread(target=writer.submit, args=(write, 4))
    blocked.start()
    blocked.join(0.3)
    assert blocked.is_alive()  # the fifth waits for room: back-pressure
    gate.set()
    blocked.join(10.0)
    writer.drain()
    assert done == [(k, "test") for k in range(5)]
    writer.close()
    with pytest.raises(RecorderError, match="closed"):
        writer.submit(write, 5)


def test_a_failed_write_stops_the_writes_after_it_and_is_raised_by_every_later_call() -> None:
    writer = OrderedWriter("test", depth=8)
    done: list[int] = []

    def write(k: int) -> None:
        if k == 2:
            raise RecorderError("recorder: /x: cannot write 'pulses/echo/c/0': No space")
        done.append(k)

    for k in range(5):
        writer.submit(write, k)
    with pytest.raises(RecorderError, match="No space"):
        writer.drain()
    assert done == [0, 1]  # 3 and 4 were dropped: nothing is written after a hole
    with pytest.raises(RecorderError, match="No space"):
        writer.submit(write, 6)
    writer.close()
    with pytest.raises(RecorderError, match="No space"):
        writer.raise_error()


def test_depth_zero_writes_at_once_on_the_callers_thread() -> None:
    writer = OrderedWriter("test", depth=0)
    names: list[str] = []
    writer.submit(lambda: names.append(threading.current_thread().name))
    assert names == [threading.current_thread().name] and not writer.threaded
    with pytest.raises(RecorderError, match="depth"):
        OrderedWriter("test", depth=-1)


def _record(path: Path, writer_queue: int) -> None:
    """Rounds of every table, flags set on written pulses, the caller's arrays reused."""
    rec = Recorder(path, cw.N_SAMPLES, "int16", chunk_pulses=32, writer_queue=writer_queue)
    cw.write_rounds(rec, 60.0, rounds=8)
    rows = cw.pulse_rows(np.arange(rec.pulses.rows, rec.pulses.rows + 3, dtype=np.int64))
    flags = rows["flags"].copy()
    rec.append_pulses(rows["t_ns"], rows["pulse_id"], rows["channel"], flags, rows["echo"])
    flags[:] = 99  # the caller reuses its array: what was handed over is recorded
    rec.flag_pulses([rec.pulses.rows - 2], PulseFlag.TURN)  # a row the thread may not have
    rec.close()


def test_threaded_recorder_writes_the_same_store(tmp_path: Path) -> None:
    stores = {}
    for depth in (0, 4):
        _record(tmp_path / f"q{depth}.zarr", depth)
        stores[depth] = open_store(tmp_path / f"q{depth}.zarr")
    threaded = stores[4]
    upto = {t: threaded.committed(t) for t in threaded.tables()} | {"images": threaded.n_images}
    upto["pulses"] -= 3  # the last 3 are not the generator's (flags changed)
    assert _check_committed(threaded, upto)["pulses"] > 0
    for table in stores[0].tables():
        a, b = stores[0].read(table), stores[4].read(table)
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=f"{table}/{name}")
    assert threaded.n_images == stores[0].n_images > 0
    n = threaded.committed("pulses")
    want = cw.pulse_rows(np.arange(n - 3, n, dtype=np.int64))["flags"]
    want[1] |= PulseFlag.TURN
    np.testing.assert_array_equal(threaded.read("pulses")["flags"][-3:], want)


def test_a_failed_write_on_the_thread_is_raised_by_a_later_call_and_by_close(
    tmp_path: Path,
) -> None:
    path = tmp_path / "gone.zarr"
    rec = Recorder(path, cw.N_SAMPLES, "int16", writer_queue=4)
    cw.write_rounds(rec, 60.0, rounds=2)
    rec.sync()
    shutil.rmtree(path)  # the store's directory vanishes under the writer thread
    rows = cw.pulse_rows(np.arange(rec.pulses.rows, rec.pulses.rows + 2, dtype=np.int64))
    rec.append_pulses(rows["t_ns"], rows["pulse_id"], rows["channel"], rows["flags"], rows["echo"])
    deadline = time.monotonic() + 30.0
    with pytest.raises(RecorderError, match="directory was removed"):
        while time.monotonic() < deadline:
            rec.set_metrics({"k": 1})
            time.sleep(0.01)
    with pytest.raises(RecorderError, match="directory was removed"):
        rec.close()
    rec.close()  # closed once


def test_a_failure_after_the_last_call_is_there_to_see_and_the_hook_runs_first() -> None:
    """A caller that makes no more calls sees the thread's failure without one (the live
    runner's health check); ``on_failure`` runs on the writer thread before it is kept."""
    seen: list[tuple[str, bool]] = []
    writer: OrderedWriter

    def on_failure() -> None:
        seen.append((threading.current_thread().name, writer.failure is None))

    writer = OrderedWriter("test", depth=4, on_failure=on_failure)
    writer.submit(lambda: None)
    assert writer.failure is None
    writer.submit(_refuse)
    deadline = time.monotonic() + 10.0
    while writer.failure is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert "No space" in str(writer.failure)
    assert seen == [("test", True)]
    writer.close()


def _refuse() -> None:
    raise RecorderError("recorder: /x: cannot write 'pulses/echo/c/0': No space")


@pytest.mark.parametrize("writer_queue", [0, 4])
def test_a_failed_write_leaves_no_zarr_task_running(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, writer_queue: int
) -> None:
    """When a failed write reaches the caller no write it started still runs on zarr's loop.

    One column's chunk is refused at once, another's 0.3 s later: zarr's gather returns at
    the first failure and the second, finishing later, would be an exception retrieved only
    by a callback that does not run if the loop stops first (at interpreter exit: asyncio's
    "Task exception was never retrieved" after the daemon's last word, CI8).
    """
    real_set = _SyncingStore.set

    async def refusing_set(self: _SyncingStore, key: str, value: Buffer) -> None:
        if key.startswith(("pulses/t_ns/c/", "pulses/flags/c/")):
            await asyncio.sleep(0.3 if "flags" in key else 0.0)
            raise RecorderError(f"recorder: refused {key!r}: No space left on device")
        await real_set(self, key, value)

    rec = Recorder(tmp_path / "r.zarr", cw.N_SAMPLES, "int16", writer_queue=writer_queue)
    monkeypatch.setattr(_SyncingStore, "set", refusing_set)
    rows = cw.pulse_rows(np.arange(4, dtype=np.int64))
    with pytest.raises(RecorderError, match="t_ns"):  # the first failure, once
        rec.append_pulses(
            rows["t_ns"], rows["pulse_id"], rows["channel"], rows["flags"], rows["echo"]
        )
        rec.close()
    assert zarr_sync(_other_tasks()) == []


def test_a_failed_close_leaves_no_zarr_task_running(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same for the close's own zarr calls: trimming the arrays deletes their chunks past
    the committed rows concurrently; one refused at once, the others 0.3 s later (CI run
    bt5 here: asyncio logged five such "Future exception was never retrieved" at exit)."""
    real_delete = _SyncingStore.delete

    async def refusing_delete(self: _SyncingStore, key: str) -> None:
        if key.startswith("pulses/t_ns/c/"):
            await asyncio.sleep(0.0 if key.endswith("/2") else 0.3)
            raise RecorderError(f"recorder: refused {key!r}: Read-only file system")
        await real_delete(self, key)

    rec = Recorder(tmp_path / "r.zarr", cw.N_SAMPLES, "int16", chunk_pulses=2)
    rows = cw.pulse_rows(np.arange(3, dtype=np.int64))
    rec.append_pulses(rows["t_ns"], rows["pulse_id"], rows["channel"], rows["flags"], rows["echo"])
    monkeypatch.setattr(_SyncingStore, "delete", refusing_delete)
    with pytest.raises(RecorderError, match="c/2'"):
        rec.close()
    assert zarr_sync(_other_tasks()) == []


async def _other_tasks() -> list[asyncio.Task[Any]]:
    current = asyncio.current_task()
    return [t for t in asyncio.all_tasks() if t is not current]


@pytest.mark.parametrize("writer_queue", [0, 4])
def test_a_root_attribute_after_the_store_was_removed_does_not_recreate_it(
    tmp_path: Path, writer_queue: int
) -> None:
    """The removed-store check held for every file but the root's metadata, so a root
    attribute update (or a new table's group) after ``rm -rf`` of the store made a new
    store there, and the writes after it went on unreported (test_faults_host, writer thread)."""
    path = tmp_path / "gone.zarr"
    rec = Recorder(path, cw.N_SAMPLES, "int16", writer_queue=writer_queue)
    cw.write_rounds(rec, 60.0, rounds=1)
    rec.sync()
    shutil.rmtree(path)
    with pytest.raises(RecorderError, match="directory was removed"):
        rec.set_attribute("late", {"k": 1})
        rec.close()
    assert not path.exists()


@pytest.mark.parametrize("writer_queue", [0, 4])
def test_a_store_made_again_by_a_write_that_raced_its_removal_is_not_taken_for_it(
    tmp_path: Path, writer_queue: int
) -> None:
    """A write checked just before ``mv`` of the store lets zarr make its folders again, the
    root's metadata with them (a root attribute update); the writes after it went on into
    that new skeleton unreported (test_faults_host in a loaded CI run: healthy 60 s after)."""
    path = tmp_path / "gone.zarr"
    rec = Recorder(path, cw.N_SAMPLES, "int16", writer_queue=writer_queue)
    cw.write_rounds(rec, 60.0, rounds=1)
    rec.sync()
    path.rename(tmp_path / "trash")
    path.mkdir()  # what the racing write left: the name, and the root's metadata
    shutil.copy(tmp_path / "trash" / "zarr.json", path / "zarr.json")
    with pytest.raises(RecorderError, match="directory was removed"):
        cw.write_rounds(rec, 60.0, rounds=1)
        rec.sync()
        rec.close()


def test_without_the_thread_a_failure_stands_until_a_write_succeeds() -> None:
    """The caller's call raises it; the caller's health reads it until a write succeeds
    (a pass of the daemon with nothing to write must not report the store healthy)."""
    writer = OrderedWriter("test", depth=0)
    with pytest.raises(RecorderError, match="No space"):
        writer.submit(_refuse)
    assert "No space" in str(writer.failure)
    writer.raise_error()  # the next write is tried (the disk may have room again)
    writer.submit(lambda: None)
    assert writer.failure is None
