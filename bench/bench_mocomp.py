"""Throughput of range compression + INS D_los compensation, full-size ``thz-spotlight`` pulse.

Issue 3, bench 5 (first half): pulses per second of :func:`rangecomp.compress` (dechirp, 4096
complex samples per pulse) followed by :class:`InsMotionCompensator`, next to the cost of the
bare FFTs that chain needs, measured in the same run on the same block:

- range compression of a dechirped pulse needs one length-4096 FFT;
- the envelope step needs two more (forward and inverse) for every pulse it shifts;
- the phase step needs none.

The ratio printed is (measured time) / (time of the bare FFTs it needs); 1.0 would be a chain
that costs nothing but its FFTs. Velocities come from the simulator's turbulence model, so the
share of pulses that the envelope step shifts is the realistic one for that motion.

Run: ``.venv/bin/python bench/bench_mocomp.py [--pulses 2048] [--repeat 5]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np
import pytest
import scipy.fft

from sarmoco.processing import rangecomp
from sarmoco.processing.geometry import reference_track_from_velocity
from sarmoco.processing.mocomp import InsMotionCompensator, LosGeometry
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import MotionSpec, true_trajectory


def _best_time(fn: Callable[[], object], repeat: int) -> float:
    """Best wall time of ``repeat`` calls after one warm-up, s."""
    fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return float(best)


def run(n_pulses: int, repeat: int) -> list[tuple[str, float, float, float]]:
    """Time each stage; rows are (name, seconds per block, pulses/s, ratio to its bare FFTs)."""
    scn = load_preset("thz-spotlight")
    radar = scn.radar
    rng = np.random.default_rng(0)
    shape = (n_pulses, radar.n_samples)
    raw = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    prt_ns = round(1e9 / radar.prf_hz)
    t_ns = scn.t0_ns + np.arange(n_pulses, dtype=np.int64) * prt_ns
    t_ns += rng.integers(-prt_ns // 20, prt_ns // 20, n_pulses)  # non-uniform PRT
    motion = MotionSpec(kind="turbulence", seed=1)
    traj = true_trajectory(scn, (t_ns - scn.t0_ns) * 1e-9, motion)
    track = reference_track_from_velocity(t_ns, traj.vel_ned)
    axis = rangecomp.range_axis_m(radar)

    def geometry(order: int, fraction: float | None) -> LosGeometry:
        return LosGeometry.build(
            radar,
            axis,
            scn.altitude_m,
            scn.center_slant_range_m,
            track.v0_mps,
            order=order,  # type: ignore[arg-type]
            t_center_ns=int(t_ns[n_pulses // 2]),
            envelope_fraction=fraction,
        )

    rc = rangecomp.compress(radar, raw)
    t_fft = _best_time(lambda: scipy.fft.fft(raw, axis=1), repeat)
    rows = [("bare FFT (P x 4096, complex64)", t_fft, 1.0)]
    rows.append(
        (
            "range compression (dechirp)",
            _best_time(lambda: rangecomp.compress(radar, raw), repeat),
            1.0,
        )
    )
    cases = [
        ("D_los 1st order, phase only", geometry(1, None)),
        ("D_los 1st order, envelope > 0.25 cell", geometry(1, 0.25)),
        ("D_los 1st order, envelope every pulse", geometry(1, 0.0)),
        ("D_los 2nd order (beta(r), eq. 29), env > 0.25", geometry(2, 0.25)),
    ]
    for name, geom in cases:
        shifted = np.count_nonzero(
            InsMotionCompensator(track, geom).compensate(rc, t_ns, traj.vel_ned)[1].range_shift_m
        )
        n_fft = 1.0 + 2.0 * shifted / n_pulses

        def chain(geom: LosGeometry = geom) -> object:
            comp = InsMotionCompensator(track, geom)
            return comp.compensate(rangecomp.compress(radar, raw), t_ns, traj.vel_ned)

        rows.append(
            (f"rangecomp + {name} [{shifted}/{n_pulses} shifted]", _best_time(chain, repeat), n_fft)
        )
    return [(name, sec, n_pulses / sec, sec / (n * t_fft)) for name, sec, n in rows]


def report(rows: list[tuple[str, float, float, float]], n_pulses: int) -> str:
    """The table as text."""
    lines = [
        f"thz-spotlight full-size pulse: 4096 complex samples, block of {n_pulses} pulses",
        f"{'stage':<78} {'ms/block':>9} {'pulses/s':>10} {'/ bare FFTs':>11}",
    ]
    lines += [f"{n:<78} {1e3 * s:9.1f} {p:10.0f} {r:11.2f}" for n, s, p, r in rows]
    return "\n".join(lines)


@pytest.mark.bench
def test_bench_mocomp() -> None:
    """Full-size run (``pytest bench -m bench``): prints the table."""
    print(report(run(2048, 3), 2048))


def main() -> None:
    """Command-line entry."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pulses", type=int, default=2048)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(report(run(args.pulses, args.repeat), args.pulses))


if __name__ == "__main__":
    main()
