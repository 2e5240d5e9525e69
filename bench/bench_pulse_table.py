"""The store's per-pulse tables at a high pulse rate, raw echoes off: CPU per pulse.

Run as ``python -m bench.bench_pulse_table [--seconds 3] [--prf 20000] [--block 200]
[--flush-interval S] [--meta-chunk N] [--motion] [--work DIR]``.

What the daemon's recording thread hands the :class:`~sarmoco.store.recorder.Recorder`
when the raw echoes are not recorded (``thz-spotlight`` at 20 kHz: a recording pass every
10 ms takes about 200 pulses): blocks of ``--block`` pulses of the ``pulses`` table, paced
at ``--prf``, and with ``--motion`` the same rows of the ``motion`` table (what focusing
records for each pulse), then :meth:`~sarmoco.store.recorder.Recorder.flush_due` as the
recording thread calls it after each pass. Prints the process's user and system CPU per
pulse (every thread: zarr's included) and the wall time against the data's. Without
``--flush-interval`` / ``--meta-chunk`` the recorder's own defaults apply.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.store.recorder import Recorder


def run(
    seconds: float, prf_hz: float, block: int, motion: bool, work: Path | None, **kw: Any
) -> dict[str, float]:
    """Record ``seconds`` of pulses at ``prf_hz`` in blocks of ``block``; CPU µs per pulse."""
    folder = Path(tempfile.mkdtemp(prefix="bench-pulse-table-", dir=work))
    try:
        rec = Recorder(folder / "run.zarr", 4096, raw_echoes=False, **kw)
        n_pulses = round(seconds * prf_hz) // block * block
        flush_due = getattr(rec, "flush_due", lambda: None)  # older recorders: every block
        r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        for first in range(0, n_pulses, block):
            ids = np.arange(first, first + block, dtype=np.int64)
            t_ns = ids * round(1e9 / prf_hz)
            rec.append_pulses(t_ns, ids, np.zeros(block, np.int32), np.zeros(block, np.uint32))
            if motion:
                v3, v = np.zeros((block, 3)), np.zeros(block)
                rec.append_motion(ids, t_ns, v3, v3, np.zeros((block, 4)), v, v, v)
            flush_due()
            time.sleep(max(0.0, t0 + (first + block) / prf_hz - time.perf_counter()))
        r1, wall = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter() - t0
        rec.close()
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return {
        "user_us_per_pulse": (r1.ru_utime - r0.ru_utime) / n_pulses * 1e6,
        "system_us_per_pulse": (r1.ru_stime - r0.ru_stime) / n_pulses * 1e6,
        "wall_over_data": wall / (n_pulses / prf_hz),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=3.0, help="seconds of pulses")
    p.add_argument("--prf", type=float, default=20_000.0, help="pulse rate, Hz")
    p.add_argument("--block", type=int, default=200, help="pulses per recording pass")
    p.add_argument("--flush-interval", type=float, help="recorder flush_interval_s")
    p.add_argument("--meta-chunk", type=int, help="recorder meta_chunk_pulses")
    p.add_argument("--motion", action="store_true", help="also the motion table")
    p.add_argument("--work", type=Path, help="folder for the temporary store")
    a = p.parse_args()
    kw: dict[str, Any] = {}
    if a.flush_interval is not None:
        kw["flush_interval_s"] = a.flush_interval
    if a.meta_chunk is not None:
        kw["meta_chunk_pulses"] = a.meta_chunk
    out = run(a.seconds, a.prf, a.block, a.motion, a.work, **kw)
    print(" ".join(f"{k} {v:.2f}" for k, v in out.items()))


if __name__ == "__main__":
    main()
