"""The ku-vehicle autofocus table: navigation only, COA baseline, two-step, PGA.

The command line of :mod:`tests.workloads.ku_vehicle` (the workload, shared with the tests)::

    .venv/bin/python -m bench.ku_vehicle_table [--scale 0.3] [--range-orders] [--streaming]
"""

from __future__ import annotations

import argparse

import pytest

from tests.workloads.ku_vehicle import (
    Case,
    format_range_orders,
    format_table,
    range_orders,
    run_case,
    streaming_vs_offline,
    wide_low_case,
)


@pytest.mark.bench
def test_ku_vehicle_table_full() -> None:
    """Full-scale table (bench only)."""
    print(format_table(run_case(Case(scale=1.0))))


def main() -> None:
    """Command line: print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.3)
    ap.add_argument("--seed", type=int, default=Case.motion_seed, help="motion seed")
    ap.add_argument("--cross-track-rms", type=float, default=Case.cross_track_rms_m)
    ap.add_argument(
        "--range-orders", action="store_true", help="acceptance 3: κ order 1 vs 2, wide/low"
    )
    ap.add_argument(
        "--streaming", action="store_true", help="streaming against offline on the table case"
    )
    args = ap.parse_args()
    if args.streaming:
        res = streaming_vs_offline(Case(scale=args.scale, motion_seed=args.seed))
        print("near/centre/far: truth phase residual after a line (rad rms), offline / stream")
        for key in ("offline", "stream", "diff", "dx_off", "dx_st"):
            print(f"{key:<8}" + "".join(f"{v:>9.3f}" for v in res[key]))
        return
    if args.range_orders:
        print(format_range_orders(range_orders(wide_low_case(args.scale, args.seed))))
        return
    case = Case(scale=args.scale, motion_seed=args.seed, cross_track_rms_m=args.cross_track_rms)
    print(format_table(run_case(case)))


if __name__ == "__main__":
    main()
