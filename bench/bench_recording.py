"""Raw echo recording rate: can the zarr recorder take full-size ``thz-spotlight`` pulses?

Run as ``python -m bench.bench_recording [--seconds 3] [--work DIR]``.

The THz paper's radar delivers 4096 int16 I/Q samples at 20 kHz: 328 MB/s. Blocks of
256 such pulses (noise: zstd gains little on them, as on real echoes) go through
:meth:`Recorder.append_pulses` (the daemon's recorder, fsync every second), twice:

1. **on the calling thread** (as the daemon records today, in its processing loop);
2. **on a writer thread** fed through a queue while the calling thread does the
   work that would share the CPU with it: one ``scipy.fft`` per pulse (the FFT floor
   of the chain). The writer's rate and the FFT thread's are both printed.

Each rate is MB of int16 samples per wall second; the machine's load average is
printed beside them (2 cores, shared with other work).
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

import numpy as np
import scipy.fft

from sarmoco.daemon.recorder import Recorder

N_SAMPLES = 4096
PRF_HZ = 20_000.0
BLOCK = 256
NEEDED_MB_S = PRF_HZ * N_SAMPLES * 4 / 1e6
"""Rate of the THz paper's radar, MB/s of int16 I/Q."""


def _block(rng: np.random.Generator) -> np.ndarray:
    return rng.integers(-2000, 2000, size=(BLOCK, N_SAMPLES, 2), dtype=np.int16)


def _append(rec: Recorder, k: int, samples: np.ndarray) -> None:
    t = (np.arange(BLOCK) + k * BLOCK) * 50_000
    rec.append_pulses(t, t // 50_000, np.zeros(BLOCK, np.int32), np.zeros(BLOCK, np.uint8), samples)


def on_thread(path: Path, n_blocks: int, blocks: list[np.ndarray]) -> float:
    """MB/s of appends on the calling thread."""
    with Recorder(path, N_SAMPLES, "int16") as rec:
        t0 = time.perf_counter()
        for k in range(n_blocks):
            _append(rec, k, blocks[k % len(blocks)])
        wall = time.perf_counter() - t0
    return n_blocks * blocks[0].nbytes / 1e6 / wall


def with_writer_thread(path: Path, n_blocks: int, blocks: list[np.ndarray]) -> tuple[float, float]:
    """MB/s of a writer thread, and pulses/s of FFTs on the calling thread meanwhile."""
    q: queue.Queue[int | None] = queue.Queue(maxsize=8)
    with Recorder(path, N_SAMPLES, "int16") as rec:

        def writer() -> None:
            while (k := q.get()) is not None:
                _append(rec, k, blocks[k % len(blocks)])

        thread = threading.Thread(target=writer)
        x = blocks[0][..., 0] + 1j * blocks[0][..., 1]
        x = x.astype(np.complex64)
        t0 = time.perf_counter()
        thread.start()
        ffts = 0
        for k in range(n_blocks):
            q.put(k)
            scipy.fft.fft(x, axis=1, workers=1)
            ffts += BLOCK
        q.put(None)
        fft_wall = time.perf_counter() - t0
        thread.join()
        wall = time.perf_counter() - t0
    return n_blocks * blocks[0].nbytes / 1e6 / wall, ffts / fft_wall


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=3.0, help="seconds of radar data to write")
    ap.add_argument("--work", type=Path, default=None, help="where the stores go (then removed)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    blocks = [_block(rng) for _ in range(4)]
    n_blocks = max(1, round(args.seconds * PRF_HZ / BLOCK))
    work = Path(tempfile.mkdtemp(prefix="sarmoco-bench-rec-", dir=args.work))
    try:
        load0 = os.getloadavg()[0]
        sync = on_thread(work / "a.zarr", n_blocks, blocks)
        threaded, fft_rate = with_writer_thread(work / "b.zarr", n_blocks, blocks)
        load1 = os.getloadavg()[0]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    mb = n_blocks * blocks[0].nbytes / 1e6
    print(
        f"raw echo recording, {n_blocks * BLOCK} pulses x {N_SAMPLES} int16 I/Q ({mb:.0f} MB); "
        f"needed {NEEDED_MB_S:.0f} MB/s; load {load0:.1f} -> {load1:.1f} on {os.cpu_count()} cores"
    )
    print(f"  on the calling thread   {sync:7.0f} MB/s ({sync / NEEDED_MB_S:.2f} x needed)")
    print(
        f"  writer thread + FFTs    {threaded:7.0f} MB/s ({threaded / NEEDED_MB_S:.2f} x "
        f"needed); FFT thread meanwhile {fft_rate:.0f} pulses/s ({fft_rate / PRF_HZ:.2f} x PRF)"
    )


if __name__ == "__main__":
    main()
