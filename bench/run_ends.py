"""Ends of runs with the autofocus on (docs/measurements/flights.md).

The command line of :mod:`tests.workloads.run_ends` (the workload, shared with the tests)::

    .venv/bin/python -m bench.run_ends [--seeds 0 1 2] [--uniform] [--no-autofocus]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from tests.workloads.run_ends import one


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--uniform", action="store_true", help="mocomp.along_track off")
    parser.add_argument("--no-autofocus", action="store_true")
    args = parser.parse_args()
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            start, middle, end = one(seed, not args.uniform, not args.no_autofocus, Path(tmp))
        print(f"seed {seed}: start {start}  middle {middle}  end {end} dB", flush=True)


if __name__ == "__main__":
    main()
