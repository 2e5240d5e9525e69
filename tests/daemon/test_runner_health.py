"""A store write that fails on the recorder's writer thread after the processing loop's
last call to the recorder (the last pulses recorded, nothing more to write) reaches the
processing health, the error counter and the log once, and the exit status at the stop.

Before, such a failure waited for a call that never came: with ``recorder.writer_queue``
on, test_faults_host's disk-full and removed-store checks saw /status healthy for 60 s.
(The same checks with real file systems, both ways, are in test_faults_host.py.)
"""

from __future__ import annotations

import logging
import shutil
import time
from pathlib import Path

import pytest

from sarmoco.errors import RecorderError
from tests.daemon.idle_run import idle_run


def test_a_failure_after_the_last_write_is_reported_once_and_stays(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    run = idle_run(tmp_path, writer_queue=4)
    try:
        assert run._process() == 0
        assert run.health.components()["processing"]["ok"]
        run.recorder.sync()  # the queued writes done: none is renaming a file in the store
        shutil.rmtree(run.path)  # the store vanishes
        run.recorder.set_attribute("late", {"k": 1})  # written, and refused, on the thread
        deadline = time.monotonic() + 10.0
        while run.recorder.write_failure is None and time.monotonic() < deadline:
            time.sleep(0.01)
        with caplog.at_level(logging.ERROR, logger="sarmoco"):
            for _ in range(3):  # passes with nothing to write
                run._process()
        processing = run.health.components()["processing"]
        assert not processing["ok"] and "directory was removed" in processing["detail"]
        assert run.counters.snapshot()["counters"]["processing_errors"] == 1
        assert [r.getMessage() for r in caplog.records] == ["processing error, block skipped"]
    finally:
        with pytest.raises(RecorderError, match="directory was removed"):  # exit status 2
            run.shut_down()


def test_link_health_follows_the_links_without_a_processing_pass(tmp_path: Path) -> None:
    """The links' and the INS's health are kept on their own thread: with no processing
    pass at all (as during a long one through a backlog), /status still sees the INS go
    from never heard to fresh to stale. Set between passes, a 0.4 s CAN bus fault showed
    in no /status read while passes took up to 0.9 s."""
    run = idle_run(tmp_path)

    def ins_after(seconds: float) -> dict[str, object]:
        time.sleep(seconds)
        return run.health.components()["ins"]

    try:
        first = ins_after(0.5)
        assert not first["ok"] and "inf s old" in str(first["detail"]), first
        assert run.health.components()["links"]["ok"]
        run.st.last_nav_mono = time.monotonic()  # what the INS reader does with a sample
        assert ins_after(0.5)["ok"]
        assert run.counters.snapshot()["gauges"]["ins_age_seconds"] < 2.0
        run.st.last_nav_mono = time.monotonic() - 10.0
        stale = ins_after(0.5)
        assert not stale["ok"] and "10." in str(stale["detail"]), stale
    finally:
        run.shut_down()
