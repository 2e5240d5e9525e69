"""Ground reprocessing with dask: wall time against workers and block size.

Run as ``.venv/bin/python -m bench.bench_batch [--scale 0.05] [--pulses 3000] [--separate]``.

A ku-vehicle run is simulated as files (``sarmoco sim --out``), replayed once in one
process (the reference and the baseline), then reprocessed by :func:`run_batch` on a
local cluster of 1 and of 2 worker processes (one thread each, 127.0.0.1) at several
tile counts per imaging block. Each batch store is compared with the single-process
replay (largest relative L2 difference of a tile). The cluster is started before the
clock starts (its start-up is printed apart); worker processes load the numba kernels
from the on-disk cache on their first block. With ``--separate`` the cluster is a
``dask scheduler`` process and ``dask worker`` processes on 127.0.0.1
(:mod:`tests.workloads.dask_cluster`), reached by address as ``sarmoco batch --scheduler`` does.
Each line also gives the seconds the workers spent computing the front end and the
imaging blocks (dask's task stream): the terms of the wall-time model ``F + I / W``.

Throughput is pixel-pulses per CPU second: the pixel-pulses are those of direct
backprojection over the imaged beam (:func:`pixel_pulses`: each pixel of each tile times
the pulses within the beam at its range), the same count for every configuration; the
CPU seconds are the process CPU time of the single-process replay, or the sum over the
worker processes of theirs during the batch (``client.run(time.process_time)``: the
tasks and the worker's own dask work).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import numpy as np
from distributed import get_task_stream

from sarmoco.app.batch import Recording, cluster_client, run_batch
from sarmoco.daemon.config import load_config
from sarmoco.daemon.runner import replay_files
from sarmoco.store.reader import open_store
from tests.workloads.dask_cluster import separate_cluster

PREFIXES = ("front_end", "image_block")
"""Task-name prefixes of a recording's front end and of its imaging blocks."""


def task_seconds(stream: list[dict[str, Any]], prefix: str) -> float:
    """Seconds the workers spent computing the tasks whose key starts with ``prefix``
    (dask's task stream: the ``compute`` spans of each task)."""
    return sum(
        span["stop"] - span["start"]
        for task in stream
        if str(task["key"]).startswith(prefix)
        for span in task["startstops"]
        if span["action"] == "compute"
    )


def pixel_pulses(store: Path, beam_rad: float, height_m: float) -> float:
    """Pixel-pulses of direct backprojection over the imaged beam: for each pixel of each
    tile, the pulses within ``beam_rad`` at its slant range ``sqrt(y² + height_m²)``
    (``y``: its ground range), at the run's mean speed and pulse rate."""
    s = open_store(store)
    t = s.read("pulses", ["t_ns"])["t_ns"]
    vel = s.read("motion", ["vel_ned"])["vel_ned"]
    speed = float(np.nanmean(np.linalg.norm(vel, axis=1)))
    spacing_m = speed * float(np.median(np.diff(t))) * 1e-9
    total = 0.0
    for k in range(s.n_images):
        image = s.image(k)[0]
        slant = np.hypot(image.axis1_m, height_m)
        total += image.axis0_m.size * float(np.sum(slant * beam_rad / spacing_m))
    return total


def cpu_seconds(client: Any) -> float:
    """Process CPU time of every worker of the cluster, summed, s."""
    return float(sum(client.run(time.process_time).values()))


def worst_difference(single: Path, batch: Path) -> float:
    """Largest relative L2 difference of a tile between two stores."""
    a, b = open_store(single), open_store(batch)
    if a.n_images != b.n_images:
        return float("inf")
    worst = 0.0
    for k in range(a.n_images):
        x, y = a.image(k)[0].data, b.image(k)[0].data
        norm = float(np.linalg.norm(x)) or 1.0
        worst = max(worst, float(np.linalg.norm(x - y)) / norm)
    return worst


def main() -> None:
    """Run the bench and print a JSON line per configuration."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.05)
    ap.add_argument("--pulses", type=int, default=3000)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--tiles-per-block", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument(
        "--separate", action="store_true",
        help="a cluster of `dask scheduler` and `dask worker` processes on 127.0.0.1",
    )  # fmt: skip
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        sim = work / "sim"
        subprocess.run(
            [sys.executable, "-m", "sarmoco", "sim", "--preset", "ku-vehicle", "--scale",
             str(args.scale), "--pulses", str(args.pulses), "--motion", "turbulence",
             "--motion-seed", "1", "--ins-grade", "tactical", "--out", str(sim)],
            check=True, capture_output=True,
        )  # fmt: skip
        cfg = load_config(sim / "sarmoco.toml")
        radar, nav = sim / "radar.vrt", sim / "nav.tlog"
        single = work / "single.zarr"
        start, cpu = time.perf_counter(), time.process_time()
        summary = replay_files(cfg, radar, nav, single, progress=False)
        single_s, single_cpu_s = time.perf_counter() - start, time.process_time() - cpu
        work_pp = pixel_pulses(single, cfg.imaging.imaged_beam_rad(), cfg.geometry.height_m)
        print(json.dumps({"single_process_s": round(single_s, 2), "tiles": summary.tiles,
                          "pulses": args.pulses, "scale": args.scale,
                          "pixel_pulses": float(f"{work_pp:.4g}"),
                          "cpu_s": round(single_cpu_s, 2),
                          "pixel_pulses_per_cpu_s": float(f"{work_pp / single_cpu_s:.3g}")}),
              flush=True)  # fmt: skip
        for workers in args.workers:
            start = time.perf_counter()
            with ExitStack() as stack:
                if args.separate:
                    folder = work / f"cluster-{workers}"
                    folder.mkdir()
                    address, _ = stack.enter_context(separate_cluster(folder, workers))
                    client = stack.enter_context(cluster_client(address, workers))
                    client.wait_for_workers(workers, timeout=120)
                else:
                    client = stack.enter_context(cluster_client(None, workers, dashboard=False))
                startup_s = time.perf_counter() - start
                for tiles_per_block in args.tiles_per_block:
                    out = work / f"batch-{workers}-{tiles_per_block}.zarr"
                    start, cpu = time.perf_counter(), cpu_seconds(client)
                    with get_task_stream(client) as stream:
                        run_batch(client, cfg, [Recording(out, radar=radar, nav=nav)],
                                  tiles_per_block, progress=False)  # fmt: skip
                    wall_s = time.perf_counter() - start
                    batch_cpu_s = cpu_seconds(client) - cpu
                    front_s, imaging_s = (task_seconds(stream.data, p) for p in PREFIXES)
                    print(json.dumps({
                        "workers": workers, "tiles_per_block": tiles_per_block,
                        "wall_s": round(wall_s, 2), "cluster_start_s": round(startup_s, 2),
                        "speedup_vs_single": round(single_s / wall_s, 2),
                        "front_end_task_s": round(front_s, 2),
                        "imaging_task_s": round(imaging_s, 2),
                        "cpu_s": round(batch_cpu_s, 2),
                        "pixel_pulses_per_cpu_s": float(f"{work_pp / batch_cpu_s:.3g}"),
                        "worst_tile_rel_l2": worst_difference(single, out),
                    }), flush=True)  # fmt: skip
                    shutil.rmtree(out)


if __name__ == "__main__":
    main()
