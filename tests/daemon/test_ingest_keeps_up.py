"""Recording never waits for focusing: a slow focuser costs no pulse and no navigation.

``sarmoco sim --serve`` plays ku-vehicle x0.05 in real time over real sockets on
127.0.0.1 (VITA 49/UDP, MAVLink/UDP) into a live run in this process whose focuser is
made four times slower than real time, holding the GIL while it spins (the worst case
for threads). Every pulse sent must be stored, none flagged without navigation; the
focuser skips ahead (counted in ``/status`` and the store's metrics), and a replay of
the store focuses every pulse.
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
from sarmoco.daemon.focuser import Focuser, FocusOutput
from sarmoco.daemon.runner import _LiveRun, replay_store
from sarmoco.sim.scenario import load_preset
from sarmoco.store.flags import NAV_UNUSABLE
from sarmoco.store.reader import open_store

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
