"""The recorder's writer thread (sarmoco.daemon.writer): order, back-pressure, failures.

Its durability under power loss and SIGKILL is tested with the other recorder crash tests
(test_faults_power.py, parametrised over the writer thread).
"""

from __future__ import annotations

import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from sarmoco.daemon.flags import PulseFlag
from sarmoco.daemon.recorder import Recorder
from sarmoco.daemon.store import open_store
from sarmoco.daemon.writer import OrderedWriter
from sarmoco.errors import RecorderError
from tests.daemon import crash_writer as cw
from tests.daemon.test_recorder import _check_committed


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
