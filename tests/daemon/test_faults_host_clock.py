"""The host's wall clock stepping under a live run: ``sarmoco sim --serve`` into ``sarmoco run``
over MAVLink/UDP and VITA/UDP (ku-vehicle x0.1, 465 pulses, 2.66 s), the daemon alone under
libfaketime (``LD_PRELOAD``, its wall clock offset by the contents of a file that the test
rewrites mid-run; ``DONT_FAKE_MONOTONIC``: its monotonic clock is the machine's). The
machine's own clock, the simulator's, the radar's GPS time stamps and the autopilot's boot
clock are left alone: only the wall clock the daemon sees steps, as chrony or NTP step it.

While the pulses flow the wall clock steps +10 s, back (-10 s), -1 h, and back (+1 h), 0.35 s
apart. The daemon (TIMESYNC on the monotonic clock, each step judged against the
autopilot's SYSTEM_TIME) ignores each step and says so in its log; no pulse is lost or
flagged, every recorded velocity is the autopilot's at its own time stamp, and the three
targets focus as without the steps (within 1 dB of the sinc's azimuth PSLR).
"""

from __future__ import annotations

import importlib.resources
import json
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.demo import run_loopback
from sarmoco.store.flags import NAV_UNUSABLE
from sarmoco.store.reader import open_store
from tests.daemon.test_faults_ins_link import _free_tcp_port, _stamp_error
from tests.daemon.test_faults_wire import SINC_PSLR_DB

FAKETIME = importlib.resources.files("libfaketime") / "vendor/libfaketime/src/libfaketime.so.1"
"""libfaketime's preload library as the ``libfaketime`` wheel ships it."""
OFFSETS_S = (10, 0, -3600, 0)
"""The daemon's wall clock against the machine's after each step, s: +10 s, -10 s, -1 h,
+1 h."""
FIRST_STEP_S = 0.5
"""When the first step comes after the first pulse is received, s (TIMESYNC and
SYSTEM_TIME have mapped the autopilot's clock by then)."""
STEP_INTERVAL_S = 0.35


def _status(port: int) -> dict[str, object]:
    with socket.create_connection(("127.0.0.1", port), timeout=1.0) as s:
        s.sendall(b"GET /status HTTP/1.0\r\nHost: x\r\n\r\n")
        body = b"".join(iter(lambda: s.recv(65536), b"")).split(b"\r\n\r\n", 1)[1]
    status: dict[str, object] = json.loads(body)
    return status


def test_wall_clock_steps_under_a_live_run(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    offset_file = tmp_path / "faketime"
    offset_file.write_text("+0\n")
    env = {
        "LD_PRELOAD": str(FAKETIME),
        "FAKETIME_TIMESTAMP_FILE": str(offset_file),
        "FAKETIME_NO_CACHE": "1",
        "DONT_FAKE_MONOTONIC": "1",
        # libfaketime's "monotonic fix" (its default on glibc >= 2.30) makes the condition
        # variables' CLOCK_MONOTONIC deadlines lie in the past: the GIL's timed waits then
        # return at once, the threads spin on it in system calls and the INS reader
        # starves (measured here: a third of the velocity samples, no step logged)
        "FAKETIME_FORCE_MONOTONIC_FIX": "0",
    }
    port = _free_tcp_port()
    stepped: list[float] = []
    done = threading.Event()

    def step_when_pulses_flow() -> None:
        while not done.is_set():
            try:
                counters = _status(port).get("counters", {})
                assert isinstance(counters, dict)
                if counters.get("pipeline_pulses_received", 0):
                    break
            except (OSError, ValueError, IndexError):
                pass
            time.sleep(0.05)
        time.sleep(FIRST_STEP_S)
        for offset in OFFSETS_S:
            if done.is_set():
                return
            offset_file.write_text(f"{offset:+d}\n")
            stepped.append(time.monotonic())
            time.sleep(STEP_INTERVAL_S)

    stepper = threading.Thread(target=step_when_pulses_flow, daemon=True)
    stepper.start()
    try:
        summary = run_loopback(tmp_path / "run", 0.1, status={"http_port": port}, daemon_env=env)
    finally:
        done.set()
        stepper.join()
    log = capfd.readouterr().err
    out = tmp_path / "run"
    store = open_store(out / "run.zarr")
    truth = json.loads((out / "truth.json").read_text())
    flags = store.read("pulses", ["flags"])["flags"]
    nav = store.read("nav", ["t_ns", "vel_ned"])
    kin = np.isfinite(nav["vel_ned"]).all(axis=1)
    err = _stamp_error(truth, nav["t_ns"][kin], nav["vel_ned"][kin])
    pslr = [p["pslr_az_db"] for p in summary.image.points[:3]]
    steps_logged = [line for line in log.splitlines() if "host wall clock stepped" in line]
    print(f"wall clock steps {OFFSETS_S} s: {len(stepped)} made, {len(steps_logged)} logged; "
          f"{flags.size} pulses, {(flags & np.uint32(NAV_UNUSABLE) != 0).sum()} flagged; "
          f"{kin.sum()} velocity samples, max |error| {err.max():.4f} m/s; azimuth PSLR "
          f"{pslr} dB")  # fmt: skip
    assert len(stepped) == len(OFFSETS_S)
    assert store.attrs["complete"]
    assert flags.size == len(truth["pulses"]["t_ns"])  # no pulse lost
    assert (flags & np.uint32(NAV_UNUSABLE) == 0).all()  # none without navigation
    assert kin.sum() > 100 and err.max() < 1e-3  # none misplaced: each at its own stamp
    assert all(p <= SINC_PSLR_DB + 1.0 for p in pslr), pslr
    assert len(steps_logged) == len(OFFSETS_S), log
    for line, (before, after) in zip(
        steps_logged, zip((0, *OFFSETS_S[:-1]), OFFSETS_S, strict=True), strict=True
    ):
        assert f"stepped by {after - before:+.3f} s" in line and "the step is ignored" in line
