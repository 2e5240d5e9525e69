"""Throughput of range compression + INS D_los compensation, full-size ``thz-spotlight`` pulse.

Pulses per second of :func:`rangecomp.compress` (dechirp, 4096
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
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.trajectory import true_trajectory


def _paired_times(
    fn: Callable[[], object], ref: Callable[[], object], repeat: int
) -> tuple[float, float]:
    """Best wall times of ``fn`` and ``ref``, called alternately ``repeat`` times, s.

    Alternating the stage with the bare FFT it is compared to keeps the ratio honest on a
    machine whose load changes during the run.
    """
    fn()
    ref()
    best_fn, best_ref = np.inf, np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        ref()
        t1 = time.perf_counter()
        fn()
        t2 = time.perf_counter()
        best_ref, best_fn = min(best_ref, t1 - t0), min(best_fn, t2 - t1)
    return float(best_fn), float(best_ref)


def run(n_pulses: int, repeat: int) -> list[tuple[str, float, float, float]]:
    """Time each stage; rows are (name, s per block, FFTs it needs per pulse, cost in FFTs)."""
    scn = load_preset("thz-spotlight")
    radar = scn.radar
    rng = np.random.default_rng(0)
    shape = (n_pulses, radar.n_samples)
    raw = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    prt_ns = round(1e9 / radar.prf_hz)
    t_ns = scn.t0_ns + np.arange(n_pulses, dtype=np.int64) * prt_ns
    t_ns += rng.integers(-prt_ns // 20, prt_ns // 20, n_pulses)  # non-uniform PRT
    motion = MotionSpec(kind="turbulence", seed=1)
    traj = true_trajectory(scn, np.asarray((t_ns - scn.t0_ns) * 1e-9, dtype=np.float64), motion)
    track = reference_track_from_velocity(t_ns, traj.vel_ned)
    axis = rangecomp.range_axis_m(radar)

    def geometry(order: int, fraction: float | None) -> LosGeometry:
        return LosGeometry.build(
            radar,
            axis,
            scn.altitude_m,
            scn.center_slant_range_m,
            order=order,  # type: ignore[arg-type]
            envelope_fraction=fraction,
        )

    rc = rangecomp.compress(radar, raw)

    def bare_fft() -> object:
        return scipy.fft.fft(raw, axis=1)

    rows = [
        ("bare FFT (P x 4096, complex64)", bare_fft, 1.0),
        ("range compression (dechirp)", lambda: rangecomp.compress(radar, raw), 1.0),
    ]
    cases = [
        ("D_los 1st order, phase only", geometry(1, None)),
        ("D_los 1st order, envelope > 0.25 cell", geometry(1, 0.25)),
        ("D_los 1st order, envelope every pulse", geometry(1, 0.0)),
        ("D_los 2nd order (beta(r)), env > 0.25", geometry(2, 0.25)),
    ]
    for name, geom in cases:
        _, sol = InsMotionCompensator(track, geom).compensate(rc, t_ns, traj.vel_ned)
        n_env = 2.0 * np.count_nonzero(sol.range_shift_m) / n_pulses

        def alone(geom: LosGeometry = geom) -> object:
            return InsMotionCompensator(track, geom).compensate(rc, t_ns, traj.vel_ned)

        def chain(geom: LosGeometry = geom) -> object:
            comp = InsMotionCompensator(track, geom)
            return comp.compensate(rangecomp.compress(radar, raw), t_ns, traj.vel_ned)

        label = f"{name} [{n_env / 2:.0%} shifted]"
        rows.append((f"  {label} alone", alone, n_env))
        rows.append((f"rangecomp + {label}", chain, 1.0 + n_env))
    out = []
    for name, fn, n_fft in rows:
        sec, t_fft = _paired_times(fn, bare_fft, repeat)
        out.append((name, sec, n_fft, sec / t_fft))
    return out


def report(rows: list[tuple[str, float, float, float]], n_pulses: int) -> str:
    """The table as text: cost in units of one bare FFT pass, and over the FFTs it needs."""
    lines = [
        f"thz-spotlight full-size pulse: 4096 complex samples, block of {n_pulses} pulses",
        f"{'stage':<66} {'ms/block':>8} {'pulses/s':>9} {'FFTs':>5} {'cost':>5} {'ratio':>6}",
    ]
    for name, sec, n_fft, cost in rows:
        ratio = f"{cost / n_fft:6.2f}" if n_fft > 0 else f"{'-':>6}"
        lines.append(
            f"{name:<66} {1e3 * sec:8.1f} {n_pulses / sec:9.0f} {n_fft:5.2f} {cost:5.2f} {ratio}"
        )
    lines.append(
        "FFTs: bare FFT passes the stage needs; cost: its time in bare-FFT passes (timed"
        " alternately with it); ratio = cost / FFTs"
    )
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
