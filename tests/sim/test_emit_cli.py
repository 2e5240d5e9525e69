"""`sarmoco sim --serve` as a process: its JSON line, then the drivers connect as the daemon."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import numpy as np
import pytest

from sarmoco.app.demo import free_udp_port
from sarmoco.drivers.can_source import CanSource
from sarmoco.drivers.mavlink import MavlinkSource
from sarmoco.drivers.radar import RadarSource, RadarTcpSource, RadarUdpSource
from sarmoco.drivers.samples import EchoPacket, Sample, VelocitySample
from sarmoco.drivers.sbg import SbgSerialSource
from sarmoco.drivers.source import Source
from sarmoco.drivers.vita49 import VitaDecoder
from sarmoco.errors import DriverError

SCENARIO = ["--preset", "thz-spotlight", "--scale", "0.02", "--motion", "turbulence"]


SIM = [sys.executable, "-m", "sarmoco", "sim"]


def serve(
    tmp_path: Path,
    radar: str,
    ins: str,
    open_ins: Callable[[dict[str, Any]], Source],
    open_radar: Callable[[dict[str, Any], VitaDecoder], RadarSource],
) -> tuple[list[EchoPacket], list[Sample], dict[str, Any], dict[str, Any], int]:
    """Serve the scenario, read both links as the daemon does; (pulses, INS samples, truth,
    the simulator's last line, the largest time bound the INS source stated while samples
    came, ns: 0 for a source that states none)."""
    truth_path = tmp_path / "truth.json"
    live = ["--serve", "--radar", radar, "--ins", ins, "--truth", str(truth_path)]
    timing = ["--lead", "0.5", "--linger", "0.3", "--wait", "30"]
    argv = [*SIM, *SCENARIO, *live, *timing]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        line = json.loads(proc.stdout.readline())
        assert line["event"] == "listening" and line["pid"] == proc.pid
        n = line["radar"]["n_samples"]
        dec = VitaDecoder(n, line["radar"]["payload"])
        rsrc = open_radar(line["radar"], dec)
        nsrc = open_ins(line["ins"][0])
        rows = np.zeros((line["n_pulses"] + 8, n), np.complex64)
        pulses: list[EchoPacket] = []
        samples: list[Sample] = []
        ins_open, bound_ns = True, 0
        while ins_open and proc.poll() is None:
            try:
                got = nsrc.poll(0.01)
            except DriverError:  # the simulator closed its end of the pty: hang-up
                ins_open = False
                continue
            samples += got
            if got and isinstance(nsrc, MavlinkSource):
                bound_ns = max(bound_ns, nsrc.time_bound_ns)
            pulses += rsrc.read_into(rows[len(pulses) :], 0.0)
        with contextlib.suppress(DriverError):
            samples += nsrc.poll(0.05)
        pulses += rsrc.read_into(rows[len(pulses) :], 0.05)
        done = json.loads(proc.stdout.readline())
        proc.wait(10)
        # python-can's slcan shutdown writes "C" to the adapter, gone with the simulator
        with contextlib.suppress(can.CanError):
            nsrc.close()
        rsrc.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0 and done["event"] == "done"
    return pulses, samples, json.loads(truth_path.read_text()), done, bound_ns


def check(
    pulses: list[EchoPacket], samples: list[Sample], truth: dict[str, Any], tol_ns: int
) -> None:
    shift = truth["wire"]["shift_ns"]
    assert shift != 0  # a live run happens now on the host clock
    assert [p.t_gps_ns - shift for p in pulses] == truth["pulses"]["t_ns"]
    vel = [s for s in samples if isinstance(s, VelocitySample)]
    t_true = np.array(truth["ins"]["t_ns"]) + shift
    idx = np.clip(np.searchsorted(t_true, [s.t_gps_ns - tol_ns for s in vel]), 0, t_true.size - 1)
    assert len(vel) > 10
    assert np.abs(np.array([s.t_gps_ns for s in vel]) - t_true[idx]).max() <= tol_ns
    v_true = np.array(truth["ins"]["vel_ned"])[idx]
    np.testing.assert_allclose([s.vel_ned for s in vel], v_true, atol=0.005)


def test_mavlink_udp_and_radar_udp(tmp_path: Path) -> None:
    rport, mport = free_udp_port(), free_udp_port()
    """The INS time stamps come from TIMESYNC over loopback: each is within the bound the
    source stated (half its slowest admitted round trip; a loaded host's are milliseconds)."""
    pulses, samples, truth, done, bound_ns = serve(
        tmp_path, f"udp://127.0.0.1:{rport}", f"mavlink:udpout:127.0.0.1:{mport}",
        lambda d: MavlinkSource(d["connect"]),
        lambda d, dec: RadarUdpSource("127.0.0.1", rport, dec),
    )  # fmt: skip
    assert done["links"]["ins1"]["answered"]["TIMESYNC"] > 0
    print(f"TIMESYNC: largest stated bound {bound_ns / 1e6:.3f} ms")
    assert 0 < bound_ns < 20_000_000
    check(pulses, samples, truth, tol_ns=bound_ns)


def test_sbg_pty_and_radar_tcp(tmp_path: Path) -> None:
    def radar(d: dict[str, Any], dec: VitaDecoder) -> RadarSource:
        host, port = d["connect"].removeprefix("tcp://").split(":")
        return RadarTcpSource(host, int(port), dec)

    pulses, samples, truth, _, _ = serve(
        tmp_path, "tcp://127.0.0.1:0", "sbg:pty", lambda d: SbgSerialSource(d["connect"]), radar
    )
    check(pulses, samples, truth, tol_ns=1_000)


@pytest.mark.parametrize("bus", ["slcan-pty", "socketcand:0"])
def test_sbg_can_and_radar_udp(tmp_path: Path, bus: str) -> None:
    rport = free_udp_port()
    extra: dict[str, Any] = {"sleep_after_open": 0} if "slcan" in bus else {}
    pulses, samples, truth, _, _ = serve(
        tmp_path, f"udp://127.0.0.1:{rport}", f"sbg-can:{bus}",
        lambda d: CanSource.open(**d["connect"], **extra),
        lambda d, dec: RadarUdpSource("127.0.0.1", rport, dec),
    )  # fmt: skip
    check(pulses, samples, truth, tol_ns=1_000)
