"""Recording never waits for focusing: a slow focuser costs no pulse and no navigation.

``sarmoco sim --serve`` plays ku-vehicle x0.05 in real time over real sockets on
127.0.0.1 (VITA 49/UDP, MAVLink/UDP) into a live run in this process whose focuser is
made four times slower than real time, holding the GIL while it spins (the worst case
for threads). Every pulse sent must be stored, none flagged without navigation; the
focuser skips ahead (counted in ``/status`` and the store's metrics), and a replay of
the store focuses every pulse.

A file run (``.vrt`` radar file and ``.tlog`` INS log, both read as fast as the disk
allows) whose recording thread stalls at its start: the INS log is read no further
ahead than the navigation history can hold for the pulses still in the echo ring, so
none of them loses its navigation.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sarmoco.app.demo import free_udp_port, read_json_line
from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.config import load_config
from sarmoco.daemon.focuser import Focuser, FocusOutput
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import _LiveRun, replay_store
from sarmoco.sim.scenario import load_preset
from sarmoco.store.flags import NAV_UNUSABLE
from sarmoco.store.reader import open_store
from tests.daemon.test_daemon_process import simulate_files

PRESET, SCALE, SECONDS = "ku-vehicle", 0.05, 10.0
SLOWDOWN = 4.0
"""Wall seconds the slowed focuser spends per second of pulses pushed."""


def _slowed(push: Callable[..., FocusOutput], s_per_pulse: float) -> Callable[..., FocusOutput]:
    """``push`` that first spins ``s_per_pulse`` per pulse, holding the GIL."""

    def slow_push(self: Focuser, raw: Any, t_ns: Any, *args: Any, **kwargs: Any) -> FocusOutput:
        end = time.perf_counter() + s_per_pulse * len(t_ns)
        while time.perf_counter() < end:
            pass
        return push(self, raw, t_ns, *args, **kwargs)

    return slow_push


def test_a_slow_focuser_loses_no_pulse_and_leaves_none_without_navigation(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    scn = load_preset(PRESET, SCALE)
    n_pulses = round(SECONDS * scn.radar.prf_hz)
    sim = subprocess.Popen(
        [sys.executable, "-m", "sarmoco", "sim", "--preset", PRESET, "--scale", str(SCALE),
         "--pulses", str(n_pulses), "--motion", "turbulence", "--motion-seed", "1",
         "--ins-grade", "tactical", "--serve",
         "--radar", f"udp://127.0.0.1:{free_udp_port()}",
         "--ins", f"mavlink:udpout:127.0.0.1:{free_udp_port()}"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        hello = read_json_line(sim, "the simulator", 120.0)
        cfg = scenario_config(
            scn,
            radar={"link": hello["radar"]["connect"]},
            ins={"protocol": "mavlink", "link": hello["ins"][0]["connect"]},
            recorder={"directory": str(tmp_path)},
            status={"http_port": 0},
            imaging={"block_pulses": 64},
        )
        with monkeypatch.context() as slow:
            slow.setattr(Focuser, "push", _slowed(Focuser.push, SLOWDOWN / scn.radar.prf_hz))
            run = _LiveRun(cfg, tmp_path / "run.zarr", threading.Event())
            try:
                run.supervise(idle_exit_s=2.0)
            finally:
                run.shut_down()
        assert sim.wait(timeout=60.0) == 0
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait()

    store = open_store(tmp_path / "run.zarr")
    pulses = store.read("pulses", ["t_ns", "flags"])
    assert pulses["t_ns"].size == n_pulses, "pulses lost"
    assert np.all(np.diff(pulses["t_ns"]) > 0)
    assert not np.any(pulses["flags"] & NAV_UNUSABLE), "pulses left without navigation"
    counters = run.counters.snapshot()["counters"]
    assert counters["pipeline_pulses_dropped_ring"] == 0
    assert counters["pipeline_pulses_nav_flagged"] == 0
    skipped = counters["pipeline_pulses_focus_skipped"]
    assert skipped > 0, "the focuser was not slow enough to fall behind"
    assert store.attrs["metrics"]["pulses_focus_skipped"] == skipped
    assert counters["pipeline_pulses_processed"] + skipped == n_pulses

    replay = replay_store(cfg, tmp_path / "run.zarr", tmp_path / "replay.zarr", progress=False)
    assert replay.pulses_processed == n_pulses
    assert replay.pulses_nav_flagged == replay.pulses_focus_skipped == 0


def _stalled_once(record: Callable[..., int], stall_s: float) -> Callable[..., int]:
    """``record`` whose first call first sleeps ``stall_s`` (a recording thread descheduled
    while the file links are read)."""
    stalled = threading.Event()

    def stall_then_record(self: Pipeline, *args: Any, **kwargs: Any) -> int:
        if not stalled.is_set():
            stalled.set()
            time.sleep(stall_s)
        return record(self, *args, **kwargs)

    return stall_then_record


def test_a_file_run_whose_recording_stalls_leaves_no_pulse_without_navigation(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    n_pulses = 3000  # 17 s of pulses: the INS log is longer than half the nav history
    simulate_files(tmp_path, n_pulses)
    cfg = load_config(tmp_path / "sarmoco.toml")
    with monkeypatch.context() as stall:
        stall.setattr(Pipeline, "record", _stalled_once(Pipeline.record, 2.0))
        run = _LiveRun(cfg, tmp_path / "run.zarr", threading.Event())
        try:
            run.supervise(idle_exit_s=4.0)  # longer than the stall
        finally:
            run.shut_down()
    pulses = open_store(tmp_path / "run.zarr").read("pulses", ["t_ns", "flags"])
    assert pulses["t_ns"].size == n_pulses
    assert np.count_nonzero(pulses["flags"] & NAV_UNUSABLE) == 0, "pulses without navigation"
