"""A processing pass through a backlog feeds the watchdog after every block it records.

Under load the daemon falls behind and one pass of its loop releases many blocks; if
WATCHDOG=1 went out only between passes, a pass longer than ``WatchdogSec`` would get a
progressing daemon restarted (a 30-minute soak once missed 92 periods so). The
pings go through the real notification socket (:class:`sarmoco.daemon.sdnotify.Notifier`
with a 1 us period, so that none is rate-limited away).
"""

from __future__ import annotations

import socket
from pathlib import Path

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.sdnotify import Notifier
from sarmoco.daemon.status import Counters
from sarmoco.drivers.samples import AttitudeSample, Validity, VelocitySample
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import load_preset

BLOCK = 32
PULSES = 3 * BLOCK + 9


def test_a_backlog_pass_pings_after_each_block(tmp_path: Path) -> None:
    run = simulate(load_preset("ku-vehicle", 0.03), MotionSpec("turbulence", seed=1), "tactical",
                   n_pulses=PULSES)  # fmt: skip
    cfg = scenario_config(run.scenario, radar={"sample_format": "float32"},
                          imaging={"block_pulses": BLOCK})  # fmt: skip
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    listener.bind(str(tmp_path / "notify.sock"))
    listener.settimeout(0.0)
    notifier = Notifier({"NOTIFY_SOCKET": str(tmp_path / "notify.sock"), "WATCHDOG_USEC": "1"})
    nav = run.ins.nav
    with open_recorder(cfg, tmp_path / "run.zarr") as rec:
        pipe = Pipeline(cfg, rec, Counters())
        for k in range(nav.t_ns.size):  # the INS first: every pulse can be aligned
            tk = int(nav.t_ns[k])
            v, q = tuple(nav.vel_ned[k].tolist()), tuple(nav.quat[k].tolist())
            vel = VelocitySample(tk, v, Validity.VELOCITY, "sim", tk)
            pipe.add_nav([vel, AttitudeSample(tk, q, Validity.ATTITUDE, "sim", tk)], None)
        for i, t in enumerate(run.t_ns.tolist()):  # the backlog: no pass while it builds
            slot = pipe.ring.reserve()
            assert slot is not None
            slot.samples[...] = run.echo[i]
            pipe.ring.commit(slot, t, i)
        blocks: list[int] = []

        def on_block() -> None:
            blocks.append(pipe.summary.pulses_processed)
            assert notifier.keepalive()

        released = pipe.process(int(run.t_ns[-1]) + 10**9, on_block=on_block)
        pipe.finish()
    pings = []
    while True:
        try:
            pings.append(listener.recv(64))
        except BlockingIOError:
            break
    listener.close()
    notifier.close()
    assert released == PULSES
    # focusing takes whole blocks: three focused, then the rest recorded and held (focused
    # by finish), each with its ping, in one pass
    full = PULSES - PULSES % BLOCK
    assert blocks == [min(full, BLOCK * (k + 1)) for k in range(len(blocks))]
    assert len(blocks) == 4
    assert pings == [b"WATCHDOG=1"] * len(blocks)
