"""Compile the package's numba kernels into the checkout's cache before the suite starts.

``make test`` runs this first. Every kernel is ``cache=True``: the first process to call
it compiles it and writes the cache beside the module, the later ones load it. In a fresh
clone the cache is empty, and every process that calls a kernel before the first has
written it compiles it again: the first phase's workers start several replays and
simulations at once, and a fresh clone's first phase took 1095 s of CPU where a warm
checkout's took 961 s (docs/measurements/test-suite.md). Here each kernel is compiled
once: the daemon's warm-up (direct and fast-factorised backprojection, interpolation,
pre-filter, autofocus splice) in this process, and beside it a small simulation and its
replay (the simulator's echo kernel, the signatures a replay calls, the north-up image).

Run as ``python -m tests.prewarm``; exits non-zero when a kernel fails to compile.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from sarmoco.processing.autofocus import splice
from sarmoco.processing.imaging import backprojection, ffbp, interp, presum

SCENE = ("--preset", "ku-vehicle", "--scale", "0.05")
"""The simulated scene replayed beside the warm-up (the suite's most common one)."""


def _simulate_and_replay(out: Path, failed: list[str]) -> None:
    """``sarmoco sim`` of :data:`SCENE` into ``out``, then ``sarmoco replay`` of its files;
    a failure's message goes to ``failed``."""
    py = [sys.executable, "-m", "sarmoco"]
    files = ["--radar", str(out / "radar.vrt"), "--nav", str(out / "nav.tlog")]
    for cmd in (
        [*py, "sim", *SCENE, "--out", str(out)],
        [*py, "replay", "--config", str(out / "sarmoco.toml"), *files,
         "--out", str(out / "run.zarr"), "--quiet"],
    ):  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            failed.append(f"{' '.join(cmd[2:4])}: {done.stderr.strip()[-2000:]}")
            return


def main() -> int:
    """Warm every kernel; print the seconds it took. Non-zero when something failed."""
    start = time.perf_counter()
    failed: list[str] = []
    with tempfile.TemporaryDirectory(prefix="sarmoco-prewarm-") as tmp:
        beside = threading.Thread(target=_simulate_and_replay, args=(Path(tmp), failed))
        beside.start()
        for module in (backprojection, ffbp, interp, presum, splice):
            module.warm_up()
        beside.join()
    for message in failed:
        print(f"prewarm: {message}", file=sys.stderr)
    print(f"numba kernels compiled or loaded in {time.perf_counter() - start:.1f} s")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
