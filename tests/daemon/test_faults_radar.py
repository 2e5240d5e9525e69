"""Hostile radar datagrams through a real ``sarmoco run`` (VITA 49 over UDP, raw sockets).

One daemon takes the 1000 pulses of ``sarmoco sim --out`` (ku-vehicle x0.05) over UDP
from this test, the INS from the ``.tlog``; between them, at one third and two thirds
of the stream, the test sends datagrams no radar should send:

- truncated packets (the first half of a real one), oversized ones (a real packet with
  1000 bytes appended), random bytes (50..1500 of them);
- real packets with a wrong stream ID;
- real packets whose timestamp jumps forward by an hour, backward by an hour, or to zero.

The daemon must stay up, count what it refused (``/status``, ``/metrics``), record every
real pulse once, and exit 0 on SIGTERM with a complete store. Measured: the garbage and
the wrong stream IDs are refused and counted; a pulse an hour or more in the past (or at
time zero) is dropped as late; a pulse an hour ahead is taken and recorded flagged
``NAV_UNUSABLE`` (no INS sample reaches it, it is never focused), and every real pulse
after it is counted as reordered (it is older than the newest seen): a forward jump is
not refused, only flagged.
"""

# ruff: noqa: F811  (the ``sim_files`` fixture is imported, and named as the tests' argument)
from __future__ import annotations

import socket
import struct
from pathlib import Path

import numpy as np

from sarmoco.daemon.flags import NAV_UNUSABLE
from sarmoco.daemon.store import open_store
from tests.daemon.test_daemon_process import N_PULSES, SimFiles, http_get
from tests.daemon.test_daemon_process import sim as sim_files  # noqa: F401  (the fixture)
from tests.daemon.test_faults_host import UdpRun
from tests.daemon.test_faults_wire import wait_idle

HOUR_S = 3600


def _with_time(packet: bytes, seconds: int | None, shift_s: int = 0) -> bytes:
    """``packet`` with its integer-seconds timestamp (word 4) set or shifted; picoseconds 0
    when set."""
    buf = bytearray(packet)
    (old,) = struct.unpack_from(">I", buf, 16)
    if seconds is None:
        struct.pack_into(">I", buf, 16, (old + shift_s) & 0xFFFFFFFF)
    else:
        struct.pack_into(">IQ", buf, 16, seconds, 0)
    return bytes(buf)


def hostile(packets: list[bytes], rng: np.random.Generator) -> dict[str, list[bytes]]:
    """Datagrams of each kind, made from real ``packets``."""
    pick = [packets[int(k)] for k in rng.integers(0, len(packets), 5)]
    return {
        "truncated": [p[: len(p) // 2] for p in pick],
        "oversized": [p + rng.bytes(1000) for p in pick],
        "random": [rng.bytes(int(n)) for n in rng.integers(50, 1500, 5)],
        "wrong_stream_id": [p[:4] + struct.pack(">I", 0xDEADBEEF) + p[8:] for p in pick],
        "time_forward": [_with_time(p, None, HOUR_S) for p in pick[:2]],
        "time_backward": [_with_time(p, None, -HOUR_S) for p in pick[:2]],
        "time_zero": [_with_time(p, 0) for p in pick[:2]],
    }


def test_hostile_radar_datagrams_are_refused_and_counted(
    sim_files: SimFiles, tmp_path: Path
) -> None:
    rng = np.random.default_rng(49)
    bad = hostile(sim_files.packets, rng)
    run = UdpRun(sim_files, tmp_path, tmp_path / "hostile.zarr")
    try:
        run.daemon.started()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for third in (1, 2):
                run.send(third * N_PULSES // 3 - run.sent)
                for datagrams in bad.values():
                    for d in datagrams:
                        tx.sendto(d, ("127.0.0.1", run.radar_port))
        run.send(len(sim_files.packets) - run.sent)
        status = wait_idle(run.port)
        metrics = http_get(run.port, "/metrics")[1]
        assert run.daemon.proc.poll() is None
        assert run.daemon.stop() == 0, run.daemon.log.read_text()[-3000:]
    finally:
        run.daemon.kill_if_running()
    c = status["counters"]
    print({k: v for k, v in c.items() if k.startswith(("radar_", "pipeline_")) and v})
    store = open_store(tmp_path / "hostile.zarr")
    assert store.attrs["complete"] is True
    got = store.read("pulses", ["t_ns", "flags", "echo"])
    real = np.isin(got["t_ns"], sim_files.t_ns)
    forged = got["t_ns"][~real]
    print(f"{real.sum()} real pulses recorded, forged times recorded: {forged}")
    # a forged time is recorded only flagged (no navigation used), never processed
    assert (got["flags"][~real] & np.uint32(NAV_UNUSABLE)).all(), got["flags"][~real]
    assert forged.size <= 2 and (forged > sim_files.t_ns[-1]).all()  # the hour-forward ones
    assert (np.diff(got["t_ns"]) > 0).all()
    n = int(real.sum())
    assert n == N_PULSES, c
    np.testing.assert_array_equal(got["t_ns"][real], sim_files.t_ns[:n])  # each real one once
    np.testing.assert_array_equal(got["echo"][real], sim_files.echo[:n])
    refused = c["radar_parse_errors"] + c["radar_rejected"]
    assert refused >= 2 * (5 + 5 + 5 + 5)  # truncated, oversized, random, wrong stream ID
    assert "sarmoco_radar_rejected_total" in metrics
