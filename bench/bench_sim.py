"""Wall time of :func:`sarmoco.sim.run.simulate` on the scaled presets (the test suite's size).

A scaled run (``scale`` 0.1, turbulent motion, tactical INS) is what most tests simulate; this
prints how long each preset takes on this machine, best of ``--repeat`` runs. The test
``tests/sim/test_run.py`` checks the run's content only: a wall-clock bar there fails on a
loaded machine without saying anything about the code.

Run: ``.venv/bin/python -m bench.bench_sim [--scale 0.1] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time

from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import PRESETS, load_preset


def simulate_seconds(name: str, scale: float, repeat: int) -> tuple[int, float]:
    """Pulses and best wall time (s) of ``repeat`` simulations of preset ``name``."""
    scn = load_preset(name, scale=scale)
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        simulate(scn, MotionSpec(kind="turbulence", seed=1), "tactical", seed=4)
        best = min(best, time.perf_counter() - t0)
    return scn.n_pulses, best


def main() -> None:
    """Command line: one line per preset."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.1)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    for name in PRESETS:
        pulses, seconds = simulate_seconds(name, args.scale, args.repeat)
        print(f"{name:<16}{pulses:>8} pulses {seconds:>8.2f} s")


if __name__ == "__main__":
    main()
