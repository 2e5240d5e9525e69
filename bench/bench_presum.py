"""Presum first or last: CPU cost of the whole chain on full-size ``thz-spotlight`` pulses.

Run as ``python -m bench.bench_presum [--work DIR] [--repeats 2] [--profile]``.

``sarmoco sim --out`` files of the full-size preset (2343 pulses of 4096 samples, PRF
20 kHz, turbulent flight, tactical INS) are replayed in this process
(:func:`~sarmoco.daemon.runner.replay_files`: decode, ring, alignment, focusing,
recording) with ``imaging.presum_first`` off (today's chain: range compression and
INS compensation of every pulse, the pre-filter after the autofocus) and on (the
pre-filter on the raw echoes after the per-pulse D_los phase; everything after it at
the decimated rate). CPU seconds of the process (all its threads) are counted, not
wall time: on a machine shared with other work they say what the chain costs. The
ratio to real time on one core is the data time over that CPU time.

``--profile`` adds the functions that took the most CPU (cProfile timed with the
process CPU clock) for each setting.
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import os
import pstats
import shutil
import tempfile
import time
from pathlib import Path

from bench.bench_daemon import simulate_files
from sarmoco.daemon.config import Config, load_config
from sarmoco.daemon.runner import replay_files


def replay_cpu(cfg: Config, files: Path, profile: bool) -> tuple[int, float, str]:
    """Pulses, process CPU seconds and (``profile``) the top functions of one replay."""
    out = files / f"presum-{time.time_ns()}.zarr"
    prof = cProfile.Profile(time.process_time) if profile else None
    c0 = time.process_time()
    if prof is not None:
        summary = prof.runcall(
            replay_files, cfg, files / "radar.vrt", files / "nav.tlog", out, False
        )
    else:
        summary = replay_files(cfg, files / "radar.vrt", files / "nav.tlog", out, False)
    cpu = time.process_time() - c0
    shutil.rmtree(out)
    text = ""
    if prof is not None:
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(12)
        text = buf.getvalue()
    return summary.pulses_received, cpu, text


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--work",
        type=Path,
        default=Path(tempfile.gettempdir()) / "sarmoco-bench-daemon",
        help="folder for the simulated files (shared with bench_daemon)",
    )
    ap.add_argument("--repeats", type=int, default=2, help="replays per setting (best counts)")
    ap.add_argument("--profile", action="store_true", help="top functions by CPU")
    args = ap.parse_args(argv)
    files = args.work.resolve() / "thz-spotlight-1"
    files.parent.mkdir(parents=True, exist_ok=True)
    base = load_config(simulate_files(files, "thz-spotlight", 1.0))
    replay_cpu(base, files, False)  # warm-up: imports, compiled kernels from the cache
    print(f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores (at start)")
    for presum in (False, True):
        imaging = dataclasses.replace(base.imaging, presum_first=presum)
        cfg = dataclasses.replace(base, imaging=imaging)
        runs = [replay_cpu(cfg, files, False) for _ in range(args.repeats)]
        n, cpu = runs[0][0], min(r[1] for r in runs)
        print(
            f"presum_first {str(presum).lower():5}: {n} pulses, CPU {cpu:.2f} s, "
            f"{cpu / n * 1e3:.3f} ms/pulse, {n / base.radar.prf_hz / cpu:.4f} x real time on "
            f"one core"
        )
        if args.profile:
            print(replay_cpu(cfg, files, True)[2])
    print(f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores (at end)")


if __name__ == "__main__":
    main()
