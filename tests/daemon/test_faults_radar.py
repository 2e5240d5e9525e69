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
time zero) is dropped as late; a pulse an hour ahead (of the INS and of the radar's own
clock) is refused as a time jump (``pipeline_pulses_time_jump``): it is not recorded, and
the real pulses after it are not taken for reordered ones.
"""

# ruff: noqa: F811  (the ``sim_files`` fixture is imported, and named as the tests' argument)
from __future__ import annotations

import json
import socket
import struct
import time
from pathlib import Path

import numpy as np

from sarmoco.store.flags import UNFOCUSABLE, PulseFlag
from sarmoco.store.reader import open_store
from tests.daemon.test_daemon_process import (
    N_PULSES,
    START_TIMEOUT_S,
    Daemon,
    SimFiles,
    daemon_config,
    free_port,
    http_get,
    wait_status,
)
from tests.daemon.test_daemon_process import sim as sim_files  # noqa: F401  (the fixture)
from tests.daemon.test_faults_host import TIMEOUT_STOP_S, UdpRun
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
    print(f"{real.sum()} real pulses recorded, forged times recorded: {got['t_ns'][~real]}")
    assert real.all()  # the hour-forward ones are refused, not recorded
    assert c["pipeline_pulses_time_jump"] == 2 * len(bad["time_forward"])
    assert c["pipeline_pulses_reordered"] == 0  # the real pulses after them are not late
    assert (np.diff(got["t_ns"]) > 0).all()
    n = int(real.sum())
    assert n == N_PULSES, c
    np.testing.assert_array_equal(got["t_ns"][real], sim_files.t_ns[:n])  # each real one once
    np.testing.assert_array_equal(got["echo"][real], sim_files.echo[:n])
    refused = c["radar_parse_errors"] + c["radar_rejected"]
    assert refused >= 2 * (5 + 5 + 5 + 5)  # truncated, oversized, random, wrong stream ID
    assert "sarmoco_radar_rejected_total" in metrics


# -- a radar that changes its context, restarts, stalls ------------------------------------

HALF_RATE = 0.5
"""The sample rate a radar that decimates by two mid-flight announces, of the configured."""
RESTART_SKIP = 60
"""Pulses the sender misses while it restarts (0.34 s at ku-vehicle x0.05's 175 Hz)."""
STALL_S = 3.0
"""How long a stalled TCP peer sends nothing, s."""


def _is_signal(packet: bytes) -> bool:
    return packet[0] >> 4 == 1


def _with_count(packet: bytes, count: int) -> bytes:
    """``packet`` with its 4-bit packet count set to ``count`` (mod 16)."""
    (w0,) = struct.unpack_from(">I", packet)
    return struct.pack(">I", (w0 & ~0xF0000) | ((count & 0xF) << 16)) + packet[4:]


def _with_rate(context: bytes, rate_hz: float) -> bytes:
    """A context packet of the simulator (CIF0 bandwidth, RF reference, sample rate, in
    that order after the 32-byte header and CIF0) announcing another sample rate."""
    return context[:48] + struct.pack(">q", round(rate_hz * (1 << 20))) + context[56:]


def _restarted(packets: list[bytes], context: bytes) -> list[bytes]:
    """``packets`` as a sender that has just restarted sends them: its context first, and
    every stream's packet count from 0."""
    counts = {True: 0, False: 1}  # signal, context (the leading context is count 0)
    out = [_with_count(context, 0)]
    for p in packets:
        out.append(_with_count(p, counts[_is_signal(p)]))
        counts[_is_signal(p)] += 1
    return out


def _pulse_index(packets: list[bytes]) -> list[int]:
    """Index in ``packets`` of each signal packet (pulse ``j`` is ``packets[index[j]]``)."""
    return [i for i, p in enumerate(packets) if _is_signal(p)]


def _radar_counts(c: dict[str, float]) -> dict[str, float]:
    return {k: v for k, v in c.items() if k.startswith(("radar_", "pipeline_")) and v}


def test_context_change_and_sender_restart(sim_files: SimFiles, tmp_path: Path) -> None:
    """Over UDP: at a third of the flight the radar announces half the configured sample
    rate (and keeps saying so in its periodic context packets), at two thirds it restarts:
    it misses :data:`RESTART_SKIP` pulses, sends its context (as configured again) and
    counts its packets from 0, its timestamps going on from the time it is back.

    The pulses under the changed context are recorded flagged ``CONTEXT_MISMATCH`` and not
    focused, the change is counted and logged naming the key; after the restart every pulse
    is recorded, focused again, and the gap counted."""
    packets, index = sim_files.packets, _pulse_index(sim_files.packets)
    third, restart = N_PULSES // 3, 2 * N_PULSES // 3
    a, b, c = index[third], index[restart], index[restart + RESTART_SKIP]
    rate = sim_files.table["radar"]["sample_rate_hz"]
    context = next(p for p in packets if not _is_signal(p))
    changed = [_with_rate(context, HALF_RATE * rate)]
    changed += [p if _is_signal(p) else _with_rate(p, HALF_RATE * rate) for p in packets[a:b]]
    run = UdpRun(sim_files, tmp_path, tmp_path / "context.zarr")
    try:
        run.daemon.started()
        run.send(a)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for k, p in enumerate([*changed, *_restarted(packets[c:], context)]):
                tx.sendto(p, ("127.0.0.1", run.radar_port))
                if k % 50 == 49:
                    time.sleep(0.01)  # bursts well within the socket buffer, as run.send
        status = wait_idle(run.port)
        assert run.daemon.stop() == 0, run.daemon.log.read_text()[-3000:]
    finally:
        run.daemon.kill_if_running()
    counts = status["counters"]
    print(_radar_counts(counts))
    log_text = run.daemon.log.read_text()
    store = open_store(tmp_path / "context.zarr")
    assert store.attrs["complete"] is True
    got = store.read("pulses", ["t_ns", "pulse_id", "flags"])
    sent = np.concatenate([sim_files.t_ns[:restart], sim_files.t_ns[restart + RESTART_SKIP :]])
    np.testing.assert_array_equal(got["t_ns"], sent)  # every pulse sent recorded, once
    mismatch = (got["flags"] & np.uint32(PulseFlag.CONTEXT_MISMATCH)) != 0
    np.testing.assert_array_equal(np.flatnonzero(mismatch), np.arange(third, restart))
    lost_flag = (got["flags"] & np.uint32(PulseFlag.LOST_BEFORE)) != 0
    assert lost_flag[restart]  # the first pulse after the restart
    assert counts["radar_context_changes"] == 1
    assert counts["radar_context_mismatch"] == restart - third
    assert counts["radar_gaps"] >= 1 and counts["pipeline_pulses_time_jump"] == 0
    metrics = store.attrs["metrics"]
    focused = metrics["pulses_processed"]
    # the burst outruns focusing: the pulses it skipped ahead over never reach the motion
    # table, every other one does (mismatched ones too, before focusing began as after);
    # of those none of the mismatched is focused, every other one is
    pushed = np.isin(got["pulse_id"], store.read("motion", ["pulse_id"])["pulse_id"])
    usable = (got["flags"] & np.uint32(UNFOCUSABLE)) == 0
    assert np.count_nonzero(~pushed) == metrics["pulses_focus_skipped"]
    assert focused == np.count_nonzero(usable & pushed)
    assert metrics["pulses_unfocused"] == np.count_nonzero(~usable & pushed)
    fates = ("processed", "unfocused", "focus_skipped", "out_of_order")
    assert sum(metrics[f"pulses_{k}"] for k in fates) == got["t_ns"].size
    assert (
        "radar.sample_rate_hz: configured" in log_text
        and "agrees with the configuration again" in log_text
    )
    print(
        f"context change at pulse {third}: {int(mismatch.sum())} pulses recorded flagged "
        f"CONTEXT_MISMATCH, {focused:.0f} of {got['t_ns'].size} focused; restart "
        f"after pulse {restart} missing {RESTART_SKIP}: radar_gaps {counts['radar_gaps']:.0f}, "
        f"radar_drops {counts['radar_drops']:.0f}, every pulse after it recorded"
    )


def test_stalled_and_restarted_tcp_peer(sim_files: SimFiles, tmp_path: Path) -> None:
    """A TCP radar that sends a third of the flight, then half a packet and nothing for
    :data:`STALL_S`; then closes the connection (it restarts), is connected again, and sends
    from a little later with its packet count from 0; then stalls with the connection open,
    reading nothing. The daemon stays up, ``/status`` answers and shows the stall
    (``radar_age_seconds``), every whole packet sent is recorded once, and SIGTERM during the
    second stall exits 0 within ``TimeoutStopSec``."""
    packets, index = sim_files.packets, _pulse_index(sim_files.packets)
    third = N_PULSES // 3
    a, c = index[third], index[third + RESTART_SKIP]
    context = next(p for p in packets if not _is_signal(p))
    status_port = free_port(socket.SOCK_STREAM)
    with socket.create_server(("127.0.0.1", 0)) as server:
        server.settimeout(START_TIMEOUT_S)
        config = daemon_config(
            sim_files, tmp_path / "tcp.toml",
            radar={"link": f"tcp://127.0.0.1:{server.getsockname()[1]}"},
            status={"http_port": status_port}, recorder={"fsync_interval_s": 0.05},
        )  # fmt: skip
        daemon = Daemon(config, tmp_path / "tcp.zarr")
        try:
            first, _ = server.accept()
            daemon.started()
            with first:
                first.sendall(b"".join(packets[:a]) + packets[a][: len(packets[a]) // 2])
                wait_status(status_port, "counters", "pipeline_pulses_received", third)
                time.sleep(STALL_S)
                stalled = json.loads(http_get(status_port, "/status")[1])
            t_closed = time.monotonic()
            second, _ = server.accept()
            reconnect_s = time.monotonic() - t_closed
            with second:
                second.sendall(b"".join(_restarted(packets[c:], context)))
                n_sent = N_PULSES - RESTART_SKIP
                status = wait_status(status_port, "counters", "pipeline_pulses_received", n_sent)
                assert daemon.proc.poll() is None
                t0 = time.monotonic()
                exit_status = daemon.stop(timeout_s=TIMEOUT_STOP_S)
                stop_s = time.monotonic() - t0
        finally:
            daemon.kill_if_running()
    assert exit_status == 0, daemon.log.read_text()[-3000:]
    counts = status["counters"]
    print(_radar_counts(counts))
    age = stalled["gauges"]["radar_age_seconds"]
    assert STALL_S - 1.5 <= age  # published once a second
    assert stalled["components"]["links"]["ok"], stalled["components"]
    store = open_store(tmp_path / "tcp.zarr")
    assert store.attrs["complete"] is True
    got = store.read("pulses", ["t_ns", "flags"])
    sent = np.concatenate([sim_files.t_ns[:third], sim_files.t_ns[third + RESTART_SKIP :]])
    np.testing.assert_array_equal(got["t_ns"], sent)  # the half packet is not a pulse
    assert counts["radar_gaps"] >= 1
    print(
        f"TCP peer stalled {STALL_S:.0f} s after half a packet: radar_age_seconds "
        f"{age:.1f}, links healthy; reconnected {reconnect_s:.1f} s after it closed; "
        f"{got['t_ns'].size} pulses recorded (all whole ones sent); SIGTERM during the "
        f"second stall: exit 0 in {stop_s:.1f} s"
    )


OTHER_STREAM = 0x0A00_0005
"""A stream ID the simulator does not send (it sends stream 0)."""


def test_only_other_streams_arriving_name_them_and_the_key(
    sim_files: SimFiles, tmp_path: Path
) -> None:
    """A live run configured for a stream the radar does not send, over UDP: the radar
    health turns bad naming the stream IDs that arrived and ``radar.stream_id``, the log
    says the same; nothing of those streams is recorded as pulses."""
    run = UdpRun(sim_files, tmp_path, tmp_path / "other.zarr", radar={"stream_id": OTHER_STREAM})
    try:
        run.daemon.started()
        run.send(len(sim_files.packets) // 4)
        status = run.wait_unhealthy("radar")
        detail = status["components"]["radar"]["detail"]
        assert not status["healthy"]
        assert f"no signal packet of VITA stream {OTHER_STREAM} (radar.stream_id)" in detail
        assert "streams 0 (0x00000000) arrived" in detail and "set radar.stream_id" in detail
        assert status["counters"]["radar_rejected"] > 0
        assert status["counters"].get("pipeline_pulses_received", 0) == 0
        run.daemon.stop()
    finally:
        run.daemon.kill_if_running()
    print(f"radar health: {detail}")
    warned = [r["msg"] for r in run.log() if "skipping the signal packets" in r["msg"]]
    assert len(warned) == 1 and "radar.stream_id" in warned[0], warned
