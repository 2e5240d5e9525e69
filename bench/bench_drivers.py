"""Driver benchmarks: radar VITA 49 over UDP loopback, MAVLink and SBG decode rates.

Run as a script (``python bench/bench_drivers.py --duration 60``) or through
pytest (``pytest -m bench bench/bench_drivers.py``). The radar test sends
``thz-spotlight``-sized pulses (4096 int16 I/Q samples, 16 KiB payload) from a
second process at a paced rate and counts what the driver decodes into a ring;
if pulses are lost it steps the rate down and reports the highest loss-free one,
with the reader's CPU per pulse (in the receive system calls, and in decoding into an
int16 ring, apart) and the socket buffer it got; then again with one system call per
datagram. The drain test sends a
burst while the reader sleeps and times how fast the reader empties the buffer.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import socket
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from sarmoco.drivers import sbg_codec
from sarmoco.drivers.mavlink import MavlinkSource
from sarmoco.drivers.radar import UDP_BATCH_PACKETS, RadarUdpSource
from sarmoco.drivers.sbg import SbgDecoder
from sarmoco.drivers.vita49 import VitaDecoder, encode_signal_packet

N_SAMPLES = 4096
TARGET_PPS = 20_000
TLOG = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mavlink"
TLOG = TLOG / "arduplane_quadplane_sitl.tlog"


def _sender(port: int, pps: int, duration_s: float, start: float) -> None:
    iq = np.zeros(N_SAMPLES, np.complex64)
    packets = [encode_signal_packet(1, 10**18 + k, k, iq) for k in range(16)]
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 << 20)
    addr = ("127.0.0.1", port)
    while time.time() < start:
        time.sleep(0.001)
    t0 = time.perf_counter()
    n_total = int(pps * duration_s)
    sent = 0
    while sent < n_total:
        due = min(n_total, int((time.perf_counter() - t0) * pps) + 1)
        while sent < due:
            try:
                tx.sendto(packets[sent & 15], addr)
                sent += 1
            except BlockingIOError:
                break
        if sent >= due:
            time.sleep(0.0002)
    tx.close()


@dataclass
class RadarIngest:
    """What :func:`radar_udp` measured.

    Attributes
    ----------
    sent, received : int
        Pulses sent and decoded into the ring.
    receive_us, decode_us : float
        The reader's CPU per pulse received, µs: in the system calls that fill the stage
        with datagrams, and in decoding the stage into the ring (headers, counters,
        byte swap into int16 I/Q rows).
    """

    sent: int
    received: int
    receive_us: float
    decode_us: float


def radar_udp(pps: int, duration_s: float, batch_receive: bool = True) -> RadarIngest:
    """Send ``pps × duration_s`` pulses and receive them as the daemon does: batches of
    datagrams (``recvmmsg``, or ``recv_into`` each with ``batch_receive`` False) decoded
    into an int16 ring (the daemon's ring for int16 payloads).

    The CPU is this thread's CPU time in :meth:`RadarUdpSource.read_into` (waits cost
    none), split between the receive calls (:meth:`RadarUdpSource.receive`) and the rest:
    decoding, and waiting for the socket.
    """
    dec = VitaDecoder(N_SAMPLES, "int16")
    src = RadarUdpSource("127.0.0.1", 0, dec, batch_receive=batch_receive)
    print(f"radar udp: socket receive buffer {src.rcvbuf_bytes / 2**20:.0f} MiB")
    ring = np.zeros((UDP_BATCH_PACKETS, N_SAMPLES, 2), np.int16)
    rx_cpu = 0.0
    receive = src.receive

    def timed_receive(first: int, stop: int) -> np.ndarray:
        nonlocal rx_cpu
        t0 = time.thread_time()
        lengths = receive(first, stop)
        rx_cpu += time.thread_time() - t0
        return lengths

    src.receive = timed_receive  # type: ignore[method-assign]
    start = time.time() + 0.3
    proc = mp.get_context("spawn").Process(
        target=_sender, args=(src.address[1], pps, duration_s, start)
    )
    proc.start()
    received = 0
    cpu0 = time.thread_time()
    while proc.is_alive():  # the sender may start late on a loaded machine: wait for its end
        received += len(src.read_into(ring, 0.05))
    proc.join()
    while batch := len(src.read_into(ring, 0.2)):
        received += batch
    dec_cpu = time.thread_time() - cpu0 - rx_cpu
    src.close()
    per = 1e6 / max(received, 1)
    return RadarIngest(int(pps * duration_s), received, rx_cpu * per, dec_cpu * per)


def decode_only(batch: int, repeats: int = 200) -> tuple[float, float]:
    """CPU per pulse of decoding batches of ``batch`` thz-spotlight packets already received
    (no socket) into an int16 ring, and of the byte-swapping copy of their payloads alone, µs.
    """
    dec = VitaDecoder(N_SAMPLES, "int16")
    iq = np.random.default_rng(0).integers(-2000, 2000, (N_SAMPLES, 2)).astype(np.int16)
    packets = [encode_signal_packet(1, 10**18 + 50_000 * k, k, iq) for k in range(batch)]
    stage = np.zeros((batch, dec.max_packet_bytes + 4), np.uint8)
    for i, p in enumerate(packets):
        stage[i, : len(p)] = np.frombuffer(p, np.uint8)
    lengths = np.array([len(p) for p in packets])
    ring = np.zeros((batch, N_SAMPLES, 2), np.int16)
    dec.decode_batch(stage, lengths, ring)
    t0 = time.thread_time()
    for _ in range(repeats):
        dec.decode_batch(stage, lengths, ring)
    t1 = time.thread_time()
    payloads = stage[:, 32 : 32 + 4 * N_SAMPLES].view(">i2")
    for _ in range(repeats):
        np.copyto(ring.reshape(batch, -1), payloads, casting="same_kind")
    t2 = time.thread_time()
    per = 1e6 / (repeats * batch)
    return (t1 - t0) * per, (t2 - t1) * per


def radar_drain(n_pulses: int = 6000) -> tuple[int, int, float]:
    """Send a burst while the reader sleeps, then drain the socket buffer.

    Returns (sent, drained, drained pulses per second of the reader's wall time).
    """
    dec = VitaDecoder(N_SAMPLES, "int16")
    src = RadarUdpSource("127.0.0.1", 0, dec)
    ring = np.zeros((256, N_SAMPLES), np.complex64)
    pps, duration_s = 10**9, n_pulses / 10**9  # as fast as the sender can
    proc = mp.get_context("spawn").Process(
        target=_sender, args=(src.address[1], pps, duration_s, time.time() + 0.3)
    )
    proc.start()
    proc.join()
    got, t0 = 0, time.perf_counter()
    while batch := len(src.read_into(ring, 0.0)):
        got += batch
    rate = got / (time.perf_counter() - t0)
    src.close()
    return int(pps * duration_s), got, rate


def radar_search(duration_s: float, batch_receive: bool = True) -> dict[str, float]:
    """Loss-free rate at the target, or the highest loss-free rate below it; the reader's
    CPU per pulse (receive, decode) at that rate."""
    pps = TARGET_PPS
    while pps >= 500:
        r = radar_udp(pps, duration_s, batch_receive)
        print(
            f"radar udp ({'recvmmsg' if batch_receive else 'recv_into'}): {pps} pulses/s for "
            f"{duration_s} s: {r.received}/{r.sent} received; reader CPU per pulse: receive "
            f"{r.receive_us:.1f} µs, decode {r.decode_us:.1f} µs"
        )
        if r.received == r.sent:
            return {
                "loss_free_pps": pps,
                "mbyte_per_s": pps * (16384 + 32) / 1e6,
                "receive_us": r.receive_us,
                "decode_us": r.decode_us,
            }
        pps = int(pps * 0.7)
    return {"loss_free_pps": 0.0, "mbyte_per_s": 0.0}


def mavlink_rate() -> float:
    """MAVLink messages decoded per second from the SITL tlog."""
    t0 = time.perf_counter()
    with MavlinkSource(str(TLOG)) as src:
        for _ in src.samples():
            pass
        frames = src.counters.frames
    return frames / (time.perf_counter() - t0)


def sbg_rate(n: int = 20_000) -> float:
    """sbgECom frames (EKF_NAV + EKF_QUAT + UTC_TIME mix) decoded per second."""
    frames = []
    status = (sbg_codec.CLOCK_VALID << 1) | (sbg_codec.UTC_INITIALIZED << 6)
    for k in range(n // 2):
        t = 1000 + 5000 * k  # 200 Hz
        if k % 50 == 0:
            sec, ns = divmod(k * 5_000_000, 10**9)
            utc = sbg_codec.UtcTime(t, status, 2024, 5, 1, 12, 0, sec, ns, 302_418_000 + k * 5)
            frames.append(sbg_codec.encode_message(utc))
        nav = sbg_codec.EkfNav(
            t, (30.0, 1.0, 0.1), (0.1,) * 3, (43.0, 1.0, 100.0), 0.0, (1.0,) * 3, 0xF4
        )
        frames.append(sbg_codec.encode_message(nav))
        quat = sbg_codec.EkfQuat(t, (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, 0xF4)
        frames.append(sbg_codec.encode_message(quat))
    stream = b"".join(frames)
    dec = SbgDecoder()
    t0 = time.perf_counter()
    for i in range(0, len(stream), 4096):
        dec.feed(stream[i : i + 4096])
    return dec.counters.frames / (time.perf_counter() - t0)


@pytest.mark.bench
def test_bench_drivers() -> None:
    main(["--duration", "60"])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=60.0, help="seconds per radar rate")
    args = ap.parse_args(argv)
    print(f"radar: {radar_search(args.duration)}")
    print(f"radar, one system call per datagram: {radar_search(args.duration, False)}")
    sent, drained, rate = radar_drain()
    print(f"radar udp backlog: {drained} of a {sent}-pulse burst drained at {rate:.0f} pulses/s")
    print(f"mavlink tlog decode: {mavlink_rate():.0f} messages/s")
    print(f"sbg decode: {sbg_rate():.0f} frames/s")


if __name__ == "__main__":
    main()
