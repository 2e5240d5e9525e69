"""The ingest path at thz-spotlight's rate, stage by stage, in one run.

Run as ``python -m bench.bench_ingest [--seconds 10] [--record-seconds 60] [--work DIR]``.

1. **socket and decode**: a second process sends thz-spotlight pulses (4096 int16 I/Q,
   16 KiB payloads) over UDP loopback at 20 kHz; the radar source receives them in batches
   (``recvmmsg``) and decodes them into an int16 ring. Printed: pulses received of those
   sent, and the reader's CPU per pulse in the receive system calls and in decoding
   (:func:`bench.bench_drivers.radar_udp`); then the same with one ``recv_into`` per
   datagram; then decoding alone, on batches of 40 and 128 packets already received.
2. **recorder against the disk**: the disk's sequential write rate (as ``dd bs=16M
   conv=fdatasync``, 2 GiB), and the daemon's recorder offered simulated thz-spotlight
   echoes at 20 kHz for ``--record-seconds``, each echo compression, the pulses it could
   not store counted (:mod:`bench.bench_recording`).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
from pathlib import Path

from bench import bench_drivers, bench_recording


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds of UDP pulses")
    ap.add_argument(
        "--record-seconds", type=float, default=60.0, help="seconds offered to the recorder"
    )
    ap.add_argument("--work", type=Path, default=None, help="where the stores go (then removed)")
    args = ap.parse_args(argv)
    pps = bench_drivers.TARGET_PPS
    print(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for batched in (True, False):
        r = bench_drivers.radar_udp(pps, args.seconds, batched)
        print(
            f"socket + decode ({'recvmmsg' if batched else 'recv_into per datagram'}), "
            f"{pps} pulses/s for {args.seconds:.0f} s: {r.received}/{r.sent} received; CPU "
            f"per pulse: receive {r.receive_us:.1f} µs, decode {r.decode_us:.1f} µs, "
            f"together {r.receive_us + r.decode_us:.1f} µs"
        )
    for batch in (40, 128):
        decode_us, copy_us = bench_drivers.decode_only(batch)
        print(
            f"decode alone, batches of {batch} packets already received: {decode_us:.1f} µs "
            f"of CPU per pulse, {copy_us:.1f} µs of it the byte-swapping copy"
        )
    work = Path(tempfile.mkdtemp(prefix="sarmoco-bench-ingest-", dir=args.work))
    try:
        bench_recording.report(work, args.record_seconds, list(bench_recording.ECHO_COMPRESSION))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
