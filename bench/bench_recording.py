"""Raw echo recording: can the zarr recorder store ``thz-spotlight`` pulses at the radar's rate?

Run as ``python -m bench.bench_recording [--seconds 60] [--work DIR]``.

The THz paper's radar delivers 4096 int16 I/Q samples at 20 kHz: 328 MB/s. This prints,
in one run, on the disk that holds ``--work``:

1. **the disk's sequential write rate**: 2 GiB in 16 MiB writes, then ``fdatasync`` (what
   ``dd bs=16M count=128 conv=fdatasync`` measures);
2. **lossless compressors on simulated echoes**: ratio and single-thread CPU rate of each
   candidate on blocks of the simulated ``thz-spotlight`` run at mid-aperture, scaled to
   int16 as the simulator's radar sends them;
3. **the recorder at the radar's rate**: those echoes offered in blocks of :data:`BLOCK`
   pulses at 20 kHz (paced) to the daemon's :class:`~sarmoco.store.recorder.Recorder` (fsync every
   second) on a writer thread, through a queue that holds the echo ring's seconds of
   pulses; a block that finds the queue full is not stored and is counted (as the daemon's
   ring counts the pulses it drops). For each echo compression: MB/s of echoes stored per
   wall second against the radar's rate and against the disk's.
"""

from __future__ import annotations

import argparse
import os
import queue
import shutil
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numcodecs
import numpy as np

from sarmoco.daemon.ingest import RING_SECONDS
from sarmoco.daemon.runner import RECORD_POLL_S
from sarmoco.sim.echostream import EchoStream
from sarmoco.sim.emit_radar import int16_scale
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.store.recorder import Recorder
from sarmoco.store.schema import ECHO_COMPRESSION

N_SAMPLES = 4096
PRF_HZ = 20_000.0
BLOCK = round(RECORD_POLL_S * PRF_HZ)
"""Pulses per offer: what one pass of the daemon's recording loop stores at 20 kHz (200,
so that blocks end inside the recorder's 256-pulse chunks, as the daemon's do)."""
NEEDED_MB_S = PRF_HZ * N_SAMPLES * 4 / 1e6
"""Rate of the THz paper's radar, MB/s of int16 I/Q."""
DD_BLOCK = 16 << 20
DD_BYTES = 2 << 30
CODECS: dict[str, Any] = {
    "zstd level 0 (zarr's default)": numcodecs.Zstd(level=0),
    "zstd level 1": numcodecs.Zstd(level=1),
    "blosc lz4 + shuffle": numcodecs.Blosc("lz4", 5, numcodecs.Blosc.SHUFFLE),
    "blosc lz4 + bitshuffle": numcodecs.Blosc("lz4", 5, numcodecs.Blosc.BITSHUFFLE),
    "blosc zstd 1 + bitshuffle": numcodecs.Blosc("zstd", 1, numcodecs.Blosc.BITSHUFFLE),
}
"""Candidates measured on the echoes (``lz4-bitshuffle`` of the recorder is the fourth)."""


def disk_rate(work: Path) -> float:
    """MB/s of 2 GiB written in 16 MiB blocks and fdatasync'd in ``work`` (``dd``'s way)."""
    path = work / "dd.bin"
    block = bytes(DD_BLOCK)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        t0 = time.perf_counter()
        for _ in range(DD_BYTES // DD_BLOCK):
            os.write(fd, block)
        os.fdatasync(fd)
        wall = time.perf_counter() - t0
    finally:
        os.close(fd)
        path.unlink()
    return DD_BYTES / 1e6 / wall


def simulated_blocks(n_blocks: int = 4) -> list[np.ndarray]:
    """Blocks of ``BLOCK`` simulated thz-spotlight echoes from mid-aperture, int16 I/Q
    ``(BLOCK, N_SAMPLES, 2)``, scaled as the simulator's radar scales them for the wire."""
    scn = load_preset("thz-spotlight")
    echo = simulate(scn, MotionSpec(kind="ideal"), "ideal", stream_echo=True).echo
    assert isinstance(echo, EchoStream)
    scale = int16_scale(echo)
    mid = len(echo) // echo.block_pulses // 2
    blocks = []
    for b in range(mid - n_blocks // 2, mid - n_blocks // 2 + n_blocks):
        rows = echo.block(b)[:BLOCK].view(np.float32) * scale
        iq = np.clip(np.rint(rows), -32768, 32767).astype(np.int16)
        blocks.append(iq.reshape(BLOCK, N_SAMPLES, 2))
    return blocks


def codec_table(blocks: list[np.ndarray]) -> list[tuple[str, float, float]]:
    """(name, compression ratio, single-thread CPU MB/s) of each of :data:`CODECS`."""
    numcodecs.blosc.set_nthreads(1)
    rows = []
    for name, codec in CODECS.items():
        t0 = time.process_time()
        packed = sum(len(codec.encode(b)) for b in blocks)
        cpu = time.process_time() - t0
        raw = sum(b.nbytes for b in blocks)
        rows.append((name, raw / packed, raw / 1e6 / cpu))
    return rows


def record_at_radar_rate(
    path: Path, blocks: list[np.ndarray], seconds: float, echo_compression: str
) -> tuple[float, int, int, tuple[float, float]]:
    """Offer ``seconds`` of pulses at the radar's rate to a recorder on a writer thread.

    Returns
    -------
    tuple
        MB/s of echoes stored per wall second (from the first offer to the last write), the
        pulses stored, the pulses not stored (their block found the queue full), and the
        process's user and system CPU per block stored, ms (the pacing costs next to none).
    """
    n_blocks = max(1, round(seconds * PRF_HZ / BLOCK))
    q: queue.Queue[int | None] = queue.Queue(maxsize=max(1, round(RING_SECONDS * PRF_HZ / BLOCK)))
    dropped = 0
    with Recorder(path, N_SAMPLES, "int16", echo_compression=echo_compression) as rec:

        def writer() -> None:
            while (k := q.get()) is not None:
                t = (np.arange(BLOCK) + k * BLOCK) * 50_000
                rec.append_pulses(
                    t, t // 50_000, np.zeros(BLOCK, np.int32), np.zeros(BLOCK, np.uint32),
                    blocks[k % len(blocks)],
                )  # fmt: skip

        thread = threading.Thread(target=writer)
        thread.start()
        cpu0 = os.times()
        t0 = time.perf_counter()
        for k in range(n_blocks):
            due = t0 + k * BLOCK / PRF_HZ
            time.sleep(max(0.0, due - time.perf_counter()))
            try:
                q.put_nowait(k)
            except queue.Full:
                dropped += BLOCK
        q.put(None)
        thread.join()
        rec.sync()
        wall = time.perf_counter() - t0
        cpu1 = os.times()
    stored = n_blocks * BLOCK - dropped
    per_block = 1e3 * BLOCK / max(stored, 1)
    cpu = ((cpu1.user - cpu0.user) * per_block, (cpu1.system - cpu0.system) * per_block)
    return stored * N_SAMPLES * 4 / 1e6 / wall, stored, dropped, cpu


def report(work: Path, seconds: float, compressions: list[str]) -> None:
    """Print the disk's rate, the codecs on simulated echoes and the recorder offered
    ``seconds`` of pulses at the radar's rate with each of ``compressions``, in ``work``."""
    disk = disk_rate(work)
    print(
        f"disk: {disk:.0f} MB/s sequential (2 GiB in 16 MiB writes + fdatasync, {work}); "
        f"the radar needs {NEEDED_MB_S:.0f} MB/s"
    )
    blocks = simulated_blocks()
    print(f"compression of simulated thz-spotlight echoes ({len(blocks) * BLOCK} pulses):")
    for name, ratio, mb_s in codec_table(blocks):
        print(f"  {name:28s} ratio {ratio:5.3f}, {mb_s:6.0f} MB/s of CPU (one thread)")
    for comp in compressions:
        load0 = os.getloadavg()[0]
        rate, stored, dropped, (user, sys) = record_at_radar_rate(
            work / f"{comp}.zarr", blocks, seconds, comp
        )
        shutil.rmtree(work / f"{comp}.zarr", ignore_errors=True)
        print(
            f"recorder, echo_compression {comp!r}, {seconds:.0f} s offered at {PRF_HZ:.0f} Hz: "
            f"{rate:.0f} MB/s stored ({rate / NEEDED_MB_S:.2f} x the radar, {rate / disk:.2f} x "
            f"the disk); {stored} pulses stored, {dropped} not stored (counted); CPU per "
            f"{BLOCK}-pulse block {user:.1f} ms user + {sys:.1f} ms system; load "
            f"{load0:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
        )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="seconds of radar data to offer")
    ap.add_argument("--work", type=Path, default=None, help="where the stores go (then removed)")
    ap.add_argument(
        "--compression",
        nargs="*",
        default=list(ECHO_COMPRESSION),
        choices=list(ECHO_COMPRESSION),
        help="echo compressions to record with",
    )
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="sarmoco-bench-rec-", dir=args.work))
    try:
        report(work, args.seconds, args.compression)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
