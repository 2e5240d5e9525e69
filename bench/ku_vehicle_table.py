"""Issue 4 acceptance 1-3: the ku-vehicle table (navigation only, COA baseline, two-step, PGA).

Scenario: ``ku-vehicle`` (scaled) with turbulence large enough that uncorrected targets spread
over several range cells, navigated by GPS only (≈2 m absolute, 0.3 m noise, 10 Hz). GPS
positions are far too noisy to compensate cross-track motion at a fraction of a 0.2 m cell, so
"navigation only" is the straight reference track fitted to the GPS positions (speed, heading,
origin) and nothing else. The rows:

- ``nav only``: backprojection on that track;
- ``baseline``: the paper's comparison, contrast optimisation, phase step only (no envelope);
- ``two-step``: map drift, envelope step then second-order phase step (docs/methods.md §3);
- ``two-step+PGA``: followed by PGA on the corrected pulses.

Every image is a backprojection on a small ground grid around each target (IMAGING's
``backproject``), axis 0 north (azimuth), axis 1 east (ground range); PSLR and IRW come from
``processing.metrics``. IRW theory: range ``0.886 c/2B / sin β`` on the ground, azimuth
``0.886 λ / (4 sin(θ/2))`` of the stripmap beam θ.

Acceptance 3 (``--range-orders``): the two-step method with a first- and a second-order κ range
model on a wide-swath, low-altitude variant (:func:`wide_low_case`).

Run: ``.venv/bin/python -m bench.ku_vehicle_table [--scale 0.3] [--seed 2] [--range-orders]``;
the test ``tests/processing/autofocus/test_ku_vehicle.py`` runs a smaller case.
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
