"""Kernel warm-up before READY=1 (the soak's daemon compiled its numba kernels
at the first block, while the radar ring overflowed and the watchdog went unfed).

After :func:`warm_up_kernels` a focusing run compiles nothing: every kernel it calls
already holds the one specialisation (``dispatcher.signatures``) the run uses. Checked in
a fresh interpreter, where nothing but the warm-up ran before. ``sarmoco run`` warms up
before it sends READY=1, extending the start-up timeout meanwhile.
"""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sarmoco.daemon import warmup
from tests.daemon.idle_run import idle_run

_FOCUS = """
import json, sys
from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.daemon.warmup import warm_up_kernels
from sarmoco.processing.autofocus import splice
from sarmoco.processing.imaging import backprojection, ffbp, presum
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.motionspec import MotionSpec

KERNELS = {"backprojection": backprojection._bp_kernel, "presum": presum._fir_decimate,
           "splice": splice._rotate, "ffbp polar": ffbp._pulses_to_polar,
           "ffbp merge": ffbp._merge, "ffbp grid": ffbp._polar_to_grid}
def signatures():
    return {name: sorted(map(str, k.signatures)) for name, k in KERNELS.items()}

scn = load_preset("thz-spotlight", 0.1, prf_hz=20_000.0)
run = simulate(scn, MotionSpec("turbulence", seed=1), "tactical", n_pulses=3000)
cfg = scenario_config(run.scenario, imaging=json.loads(sys.argv[1]))
warm_up_kernels(cfg)
warm = signatures()
focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[0])
n = 0
for a in range(0, run.t_ns.size, cfg.imaging.block_pulses):
    b = slice(a, a + cfg.imaging.block_pulses)
    n += len(focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b]).tiles)
n += len(focuser.finish().tiles)
print(json.dumps({"warm": warm, "focused": signatures(), "tiles": n,
                  "decimation": focuser.prefilter.decimation}))
"""


@pytest.mark.parametrize(
    ("imaging", "kernels"),
    [
        ({"method": "direct"}, {"backprojection", "presum", "splice"}),
        (
            {"method": "ffbp", "presum_first": True},
            {"backprojection", "presum", "splice", "ffbp polar", "ffbp merge", "ffbp grid"},
        ),
    ],
)
def test_focusing_after_the_warm_up_compiles_nothing(
    imaging: dict[str, object], kernels: set[str]
) -> None:
    out = subprocess.run(
        [sys.executable, "-c", _FOCUS, json.dumps(imaging)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    got = json.loads(out.stdout)
    assert got["tiles"] > 0 and got["decimation"] > 1
    assert got["focused"] == got["warm"]  # the focusing compiled no new specialisation
    assert {name for name, sigs in got["focused"].items() if sigs} == kernels


def _received(sock: socket.socket) -> list[bytes]:
    """The datagrams waiting on ``sock``."""
    got = []
    while True:
        try:
            got.append(sock.recv(4096))
        except BlockingIOError:
            return got


def test_ready_comes_after_the_warm_up(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The live run warms its kernels up, extending the start-up timeout every period,
    and only then sends READY=1 (a last warm-up step looks at what was sent before it)."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    listener.bind(str(tmp_path / "notify.sock"))
    listener.setblocking(False)
    monkeypatch.setenv("NOTIFY_SOCKET", str(tmp_path / "notify.sock"))
    monkeypatch.setattr(warmup, "EXTEND_EVERY_S", 0.05)
    before_ready: list[bytes] = []
    real = warmup.kernel_warm_ups

    def last_step() -> None:
        time.sleep(0.3)  # a long compile: the start-up timeout is extended meanwhile
        before_ready.extend(_received(listener))

    monkeypatch.setattr(warmup, "kernel_warm_ups", lambda cfg: [*real(cfg), last_step])
    run = idle_run(tmp_path)
    run.shut_down()
    after = _received(listener)
    listener.close()
    assert before_ready[0] == b"STATUS=compiling the processing kernels"
    extends = [m for m in before_ready[1:] if m.startswith(b"EXTEND_TIMEOUT_USEC=")]
    assert len(extends) == len(before_ready) - 1 >= 4  # 0.3 s every 0.05 s
    assert not any(m.startswith(b"READY=1") for m in before_ready)
    kinds = [m.split(b"=")[0] for m in after]  # the keeper may send one more before it stops
    assert kinds[kinds.index(b"READY") :] == [b"READY", b"STOPPING"]
    assert set(kinds[: kinds.index(b"READY")]) <= {b"EXTEND_TIMEOUT_USEC"}
