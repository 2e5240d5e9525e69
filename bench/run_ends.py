"""Ends of runs with the autofocus on (docs/measurements/flights.md).

Run as ``.venv/bin/python -m bench.run_ends [--seeds 0 1 2] [--uniform] [--no-autofocus]``.

ku-vehicle ×0.1 flown with the motion of a real ArduPilot flight log (18.5 → 19.5 m/s),
tactical INS, 9 targets (3 along track 15 m apart × 3 ranges; the start group is lit from
the run's first pulses, the end group leaves the beam 0.4 s, one subaperture, before the
last: the log flies faster than the preset's 17.5 m/s), simulated, written as ``.vrt`` and
``.tlog`` and replayed (``mocomp.along_track`` on unless ``--uniform``). Prints the azimuth
PSLR of the start, middle and end targets (each three ranges): the strip's nine brightest
points, as the report measures them.
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
