"""Autofocus CPU time per second of full-size ku-vehicle data at its real PRF.

Simulates ``ku-vehicle`` at scale 1 (PRF 1 kHz, full swath, the table's motion and GPS
navigation), range-compresses it, and times (process CPU time, all threads) per second of
data, i.e. as a fraction of real time: the streaming two-step autofocus fed in blocks of 256
pulses (what the daemon runs, corrected pulses out), the offline form with
``Corrections.apply``, and PGA. The compiled kernels are warmed up on the first 0.5 s
before timing (a running daemon pays that once).

Run: ``.venv/bin/python -m bench.bench_autofocus [--seconds 2.0]`` from the repository root.
"""

from __future__ import annotations

import argparse
import time

import pytest

from sarmoco.app.simconfig import autofocus_table
from sarmoco.processing import rangecomp
from sarmoco.processing.autofocus import (
    AutofocusConfig,
    AutofocusGeometry,
    SlidingSubapertureAutofocus,
    autofocus_offline,
)
from sarmoco.processing.autofocus.pga import pga_stripmap
from sarmoco.processing.geometry import fit_reference_track
from sarmoco.sim.run import simulate
from tests.workloads.ku_vehicle import Case, motion_spec, scenario


def measure(seconds: float) -> dict[str, float]:
    """CPU seconds of the two-step autofocus and of PGA per second of data."""
    case = Case(scale=1.0)
    scn = scenario(case)
    motion = motion_spec(case)
    n = min(scn.n_pulses, round(seconds * scn.radar.prf_hz))
    run = simulate(scn, motion, "gps", n_pulses=n)
    rc = rangecomp.compress(scn.radar, run.echo)
    range_m = rangecomp.range_axis_m(scn.radar)
    nav = run.ins.nav
    assert nav.pos_ned is not None
    track = fit_reference_track(nav.t_ns, nav.pos_ned)
    geom = AutofocusGeometry(
        scn.radar.wavelength_m, track.v0_mps, -float(track.origin_ned[2]), scn.center_slant_range_m
    )
    data_s = n / scn.radar.prf_hz
    cfg = AutofocusConfig(**autofocus_table(scn))  # the scene's, as the simulator writes it
    warm = round(0.5 * scn.radar.prf_hz)
    autofocus_offline(rc[:warm], run.t_ns[:warm], range_m, geom, cfg)[0].apply(rc[:warm], range_m)
    t0 = time.process_time()
    engine = SlidingSubapertureAutofocus(geom, range_m, cfg)
    for i in range(0, n, 256):
        engine.push(rc[i : i + 256], run.t_ns[i : i + 256])
    engine.flush()
    t1 = time.process_time()
    corr, _ = autofocus_offline(rc, run.t_ns, range_m, geom, cfg)
    focused = corr.apply(rc, range_m)
    t2 = time.process_time()
    t_s = (run.t_ns - run.t_ns[0]) * 1e-9
    pga_stripmap(focused, t_s, range_m, geom.speed_mps, geom.wavelength_m)
    t3 = time.process_time()
    return {
        "pulses": float(n),
        "bins": float(rc.shape[1]),
        "prf_hz": scn.radar.prf_hz,
        "streaming_cpu_per_s": (t1 - t0) / data_s,
        "offline_cpu_per_s": (t2 - t1) / data_s,
        "pga_cpu_per_s": (t3 - t2) / data_s,
    }


@pytest.mark.bench
def test_bench_autofocus() -> None:
    """Print the fraction of real time (bench only)."""
    print(measure(2.0))


def main() -> None:
    """Command line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=2.0)
    res = measure(ap.parse_args().seconds)
    print(
        f"{res['pulses']:.0f} pulses x {res['bins']:.0f} bins at PRF {res['prf_hz']:.0f} Hz, "
        "CPU s per s of data (fraction of real time): two-step streaming "
        f"{res['streaming_cpu_per_s']:.3f}, offline {res['offline_cpu_per_s']:.3f}, "
        f"PGA {res['pga_cpu_per_s']:.3f}"
    )


if __name__ == "__main__":
    main()
