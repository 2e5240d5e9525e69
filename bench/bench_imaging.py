"""Backprojection throughput in pixel*pulses/s.

Full-size ``thz-spotlight`` geometry and pulse (4096 range bins, upsampled 8x
before linear interpolation) onto a ground grid around the scene centre. Three
numbers from the same run, each the best of ``--repeat`` after a warm-up:

- the whole :func:`backproject` call (FFT upsampling of the lines + kernel);
- the compiled kernel alone on already upsampled lines;
- the same with the per-pixel eq. 29 squint residual (``compensated_dy_m``, 0.3 m rms ΔY);
- the FFT upsampling alone.

The content of the lines does not change the cost (random samples are used).
The kernel runs on every core (``numba.prange`` over grid rows).

Run: ``.venv/bin/python bench/bench_imaging.py [--pulses 512] [--pixels 512] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numba
import numpy as np
import pytest

from sarmoco.processing import rangecomp
from sarmoco.processing.imaging import PlaneGrid, backproject
from sarmoco.processing.imaging.backprojection import (
    DEFAULT_UPSAMPLE,
    RangeLines,
    backproject_into,
)
from sarmoco.processing.imaging.interp import fft_upsample
from sarmoco.sim.scenario import load_preset


def _best_time(fn: Callable[[], object], repeat: int) -> float:
    """Best wall time of ``repeat`` calls after one warm-up, s."""
    fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return float(best)


def run(n_pulses: int, n_pix: int, repeat: int) -> list[tuple[str, float, float]]:
    """Rows (name, seconds, pixel*pulses/s): whole call, kernel, kernel + eq. 29, upsampling."""
    scn = load_preset("thz-spotlight")
    radar = scn.radar
    rng = np.random.default_rng(0)
    shape = (n_pulses, radar.n_samples)
    rc = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    axis = rangecomp.range_axis_m(radar)
    t_s = np.arange(n_pulses) / radar.prf_hz + scn.aperture_s / 2 - n_pulses / radar.prf_hz / 2
    apc, _ = scn.ideal_track(t_s)
    grid = PlaneGrid.centred(scn.scene_center_ned, n_pix, n_pix, 0.05, 0.05)
    lam = radar.wavelength_m
    lines = RangeLines.upsample(rc, axis, DEFAULT_UPSAMPLE)
    out = np.zeros((n_pix, n_pix), dtype=np.complex64)

    dy = rng.normal(0.0, 0.3, n_pulses)

    def kernel() -> None:
        backproject_into(out, lines, apc, lam, grid)

    def kernel_eq29() -> None:
        backproject_into(out, lines, apc, lam, grid, compensated_dy_m=dy)

    work = float(n_pulses) * n_pix * n_pix
    rows = []
    for name, fn in (
        ("backproject() total", lambda: backproject(rc, axis, apc, lam, grid)),
        ("kernel only", kernel),
        ("kernel + eq. 29 term", kernel_eq29),
        ("FFT upsampling only", lambda: fft_upsample(rc, DEFAULT_UPSAMPLE)),
    ):
        sec = _best_time(fn, repeat)
        rows.append((name, sec, work / sec))
    return rows


def report(rows: list[tuple[str, float, float]], n_pulses: int, n_pix: int) -> str:
    lines = [
        f"backprojection, thz-spotlight full-size pulse (4096 bins, x{DEFAULT_UPSAMPLE}), "
        f"{n_pulses} pulses onto {n_pix} x {n_pix} pixels, {numba.get_num_threads()} threads",
        f"{'stage':<22} {'s':>8} {'Mpixel*pulses/s':>16} {'ns/(pixel*pulse)':>17}",
    ]
    for name, sec, rate in rows:
        lines.append(f"{name:<22} {sec:8.3f} {rate / 1e6:16.1f} {1e9 / rate:17.2f}")
    return "\n".join(lines)


@pytest.mark.bench
def test_bench_backprojection() -> None:
    """Full-size run (``pytest -m bench bench/bench_imaging.py``): prints the table."""
    print(report(run(512, 512, 3), 512, 512))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pulses", type=int, default=512)
    ap.add_argument("--pixels", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(report(run(args.pulses, args.pixels, args.repeat), args.pulses, args.pixels))


if __name__ == "__main__":
    main()
