"""A dask cluster started apart from the job, as a user starts one on a machine.

``dask scheduler`` and ``dask worker`` run as separate processes of this environment, every
one bound to 127.0.0.1 (the scheduler's HTTP server and each worker's too); the scheduler
writes its address to a scheduler file. Used by ``bench.bench_batch --separate`` and by the
test of ``sarmoco batch --scheduler`` that kills a worker mid-job.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sarmoco.app.batch import LOOPBACK

DASK = Path(sys.executable).with_name("dask")
"""The dask command line of this environment (``dask scheduler``, ``dask worker``)."""


@contextmanager
def separate_cluster(folder: Path, workers: int) -> Iterator[tuple[str, list[int]]]:
    """A ``dask scheduler`` process and ``workers`` ``dask worker`` processes (a nanny and
    one single-threaded worker each) on 127.0.0.1; the scheduler's address and the
    process ids. Their output goes to ``folder/cluster.log``; they are stopped on exit."""
    info = folder / "scheduler.json"
    log = (folder / "cluster.log").open("w")
    procs = [
        subprocess.Popen(
            [str(DASK), "scheduler", "--host", LOOPBACK, "--port", "0",
             "--dashboard-address", f"{LOOPBACK}:0", "--scheduler-file", str(info)],
            stdout=log, stderr=log,
        )
    ]  # fmt: skip
    try:
        deadline = time.monotonic() + 30
        while not info.exists() or not info.read_text().strip():
            if time.monotonic() > deadline or procs[0].poll() is not None:
                raise RuntimeError(f"dask scheduler did not start (see {folder}/cluster.log)")
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        procs += [
            subprocess.Popen(
                [str(DASK), "worker", address, "--host", LOOPBACK, "--nthreads", "1",
                 "--nworkers", "1", "--dashboard-address", f"{LOOPBACK}:0",
                 "--name", f"worker-{k}"],
                stdout=log, stderr=log,
            )
            for k in range(workers)
        ]  # fmt: skip
        yield address, [proc.pid for proc in procs]
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        log.close()
