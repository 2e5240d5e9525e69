"""MIMO downward-looking array: the array paper's Table 2 and more, full size.

Cases (all with the paper's Table 1 system, 2 Tx × 80 Rx, :func:`paper_system`):

- ``synthetic``: the three-peak / two-valley terrain (-39.2977..48.6260 m) on a square of
  ``--width`` metres at 0.5 m, 200 m altitude, roll 3°; imaged before compensation (attitude
  ignored) and after (ΔR1 + ΔR2, 1 × 8 sub-blocks), beside the paper's numbers;
- ``blocks``: the same echoes with 1 × 1 .. 1 × 32 and 2 × 8 sub-blocks, accuracy and imaging
  time (one ``form_dem`` call, wall clock, this machine);
- ``series``: the roll as a time series, 3° + 0.5° sin(2π t / 2 s), the processor given an
  INS roll with 0.01° white noise per pulse (and, for contrast, the constant 3°);
- ``real``: matplotlib's USGS 3-arc-second DEM of the Jacksboro fault, cropped around its
  steepest point, resampled (bicubic) to 0.5 m over ``--real-width`` metres, the platform
  269 m above the crop's highest point (the paper's clearance: 5200 m over 4931.2 m), roll 3°,
  a ``--real-strip`` metre strip across it.

Statistics: imaged minus true height over the strip, 2 m inside the terrain's border
(:func:`sarmoco.processing.array.dem.evaluate_dem`); "within" is |error| <= half the height
resolution c/2B = 0.5 m.

Run: ``.venv/bin/python -m bench.mimo_array [--width 120] [--strip 120] [--real-width 200]
[--real-strip 40] [--cases synthetic,blocks,series,real] [--json OUT.json]``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from matplotlib import cbook
from scipy.interpolate import RectBivariateSpline

from sarmoco.processing.array.dem import DemStats, error_stats, height_errors
from sarmoco.processing.array.geometry import euler_to_quat
from sarmoco.processing.array.imaging3d import Array3dOptions, ArraySystem, form_dem
from sarmoco.processing.array.paper import PAPER_ROLL_DEG, PAPER_SPEED_MPS, paper_system
from sarmoco.sim.array_echo import ArrayStrip, peaks_dem, simulate_strip

SPACING_M = 0.5
PAPER: dict[str, tuple[float, float, float, str]] = {
    # mean (m), std (m), within half a cell (fraction), error range (text)
    "before": (-0.0864, 9.0074, 0.1167, ""),
    "after": (-0.0432, 0.5927, 0.9095, ""),
    "real_before": (-24.05, 49.88, 0.0238, "[-151.56, +133.15]"),
    "real_after": (-0.03, 1.82, 0.8028, "[-9.99, +9.09]"),
}
CLEARANCE_M = 5200.0 - 4931.2
ROLL = math.radians(PAPER_ROLL_DEG)


class Case:
    """A terrain, a system and a simulated strip over it."""

    def __init__(
        self,
        height: np.ndarray,
        altitude_m: float,
        strip: tuple[float, float],
        roll: float | Callable[[np.ndarray], np.ndarray],
        seed: int = 1,
    ) -> None:
        n0, n1 = height.shape
        self.height = height
        self.north = np.arange(n0, dtype=np.float64) * SPACING_M
        self.east = (np.arange(n1, dtype=np.float64) - (n1 - 1) / 2.0) * SPACING_M
        self.system: ArraySystem = paper_system(
            float(height.min()), float(height.max()), altitude_m=altitude_m
        )
        self.strip_range = strip
        self.ground = float(np.mean(height))
        t0 = time.perf_counter()
        self.strip: ArrayStrip = simulate_strip(
            self.system.radar, self.system.layout, self.system.antenna_length_m,
            self.system.max_look_rad, PAPER_SPEED_MPS, height, SPACING_M,
            (float(self.north[0]), float(self.east[0])), altitude_m, strip, roll, seed=seed,
        )  # fmt: skip
        self.sim_s = time.perf_counter() - t0

    def run(self, quat: np.ndarray | None = None, **opts: object) -> tuple[DemStats, float]:
        """Image (``quat`` default: the truth) and score over the strip; (stats, seconds)."""
        s = self.strip
        options = Array3dOptions(ground_height_m=self.ground, **opts)  # type: ignore[arg-type]
        t0 = time.perf_counter()
        product = form_dem(
            s.echoes, s.t_ns, s.pos_ned, s.quat if quat is None else quat, self.system, options
        )
        wall = time.perf_counter() - t0
        err, in_truth = height_errors(product, self.height, self.north, self.east, margin_m=2.0)
        north = product.points_ned()[..., 0]
        lo, hi = self.strip_range
        in_strip = in_truth & (north >= lo) & (north <= hi)
        return error_stats(
            np.where(in_strip, err, np.nan), in_strip, 0.5 * self.system.height_resolution_m
        ), wall


def _row(name: str, st: DemStats, wall: float | None = None) -> str:
    lo, hi = st.range_m
    cells = (
        f"| {name} | {st.mean_m:+.4f} | {st.std_m:.4f} | {100 * st.within_half_cell:.2f} % "
        f"| [{lo:+.2f}, {hi:+.2f}] | {st.n_cells} | {100 * st.coverage:.1f} % |"
    )
    return cells + (f" {wall:.1f} |" if wall is not None else "")


def _paper_row(label: str, key: str, timed: bool) -> str:
    mean, std, within, span = PAPER[key]
    row = f"| {label} | {mean:+.4f} | {std:.4f} | {100 * within:.2f} % | {span} | | |"
    return row + (" |" if timed else "")


HEAD = "| image | mean (m) | std (m) | within 0.5 m | error range (m) | cells | coverage |"
SEP = "|---|---|---|---|---|---|---|"


def synthetic(args: argparse.Namespace, out: dict[str, object]) -> Case:
    n = round(args.width / SPACING_M) + 1
    h = peaks_dem(n, n)
    lo = (args.width - args.strip) / 2.0
    case = Case(h, 200.0, (lo, lo + args.strip), ROLL)
    shape = case.strip.echoes.shape
    print(f"\n## synthetic terrain, roll 3°: {shape} echoes, sim {case.sim_s:.0f} s")
    before, tb = case.run(compensate_attitude=False)
    after, ta = case.run()
    print(HEAD + " time (s) |\n" + SEP + "---|")
    print(_paper_row("paper, before", "before", True))
    print(_paper_row("paper, after", "after", True))
    print(_row("ours, before (attitude ignored)", before, tb))
    print(_row("ours, after (ΔR1 + ΔR2, 1×8)", after, ta))
    out["synthetic"] = {
        "before": before.as_dict(),
        "after": after.as_dict(),
        "shape": case.strip.echoes.shape,
    }
    return case


def blocks(case: Case, args: argparse.Namespace, out: dict[str, object]) -> None:
    print("\n## sub-blocks (same echoes)\n" + HEAD + " imaging (s) |\n" + SEP + "---|")
    rows = {}
    for spec in args.blocks.split(","):
        m, n = (int(v) for v in spec.split("x"))
        st, wall = case.run(blocks=(m, n))
        print(_row(f"{m}×{n}", st, wall))
        rows[spec] = {**st.as_dict(), "imaging_s": wall}
    out["blocks"] = rows


def series(args: argparse.Namespace, out: dict[str, object]) -> None:
    n = round(args.width / SPACING_M) + 1
    h = peaks_dem(n, n)
    lo = (args.width - args.strip) / 2.0

    def truth(t_s: np.ndarray) -> np.ndarray:
        return ROLL + math.radians(0.5) * np.sin(2.0 * math.pi * t_s / 2.0)

    case = Case(h, 200.0, (lo, lo + args.strip), truth, seed=2)
    t_s = (case.strip.t_ns - case.strip.t_ns[0]) * 1e-9
    rng = np.random.default_rng(7)
    ins = truth(t_s) + math.radians(0.01) * rng.standard_normal(t_s.size)
    zero = np.zeros_like(t_s)
    print(f"\n## roll series 3° + 0.5° sin(2πt/2 s), INS noise 0.01°: sim {case.sim_s:.0f} s")
    print(HEAD + "\n" + SEP)
    before, _ = case.run(compensate_attitude=False)
    with_ins, _ = case.run(quat=euler_to_quat(ins, zero, zero))
    constant, _ = case.run(quat=euler_to_quat(np.full_like(t_s, ROLL), zero, zero))
    print(_row("before (attitude ignored)", before))
    print(_row("after, INS roll series", with_ins))
    print(_row("after, constant 3° assumed", constant))
    out["series"] = {
        "before": before.as_dict(),
        "ins": with_ins.as_dict(),
        "constant": constant.as_dict(),
    }


def jacksboro(width_m: float) -> tuple[np.ndarray, dict[str, float]]:
    """The crop of the Jacksboro DEM around its steepest point, resampled to 0.5 m."""
    d: Any = cbook.get_sample_data("jacksboro_fault_dem.npz")
    elev = np.asarray(d["elevation"], dtype=np.float64)[::-1]  # rows south -> north
    lat0 = float(d["ymax"])  # the file's ymax is the southern edge (36.446)
    dlat = float(d["dy"])
    dn = dlat * 111_320.0
    de = float(d["dx"]) * 111_320.0 * math.cos(math.radians(lat0 + dlat * elev.shape[0] / 2))
    g0, g1 = np.gradient(elev, dn, de)
    slope = np.hypot(g0, g1)
    pad = 4
    inner = slope[pad:-pad, pad:-pad]
    i, j = np.unravel_index(np.argmax(inner), inner.shape)
    i, j = i + pad, j + pad
    rows = np.arange(i - pad, i + pad + 1)
    cols = np.arange(j - pad, j + pad + 1)
    spline = RectBivariateSpline((rows - i) * dn, (cols - j) * de, elev[np.ix_(rows, cols)])
    n = round(width_m / SPACING_M) + 1
    ax = (np.arange(n) - (n - 1) / 2.0) * SPACING_M
    h = spline(ax, ax)
    info = {"sample_north_m": dn, "sample_east_m": de, "max_slope": float(slope[i, j])}
    return np.asarray(h, dtype=np.float64), info


def real(args: argparse.Namespace, out: dict[str, object]) -> None:
    h, info = jacksboro(args.real_width)
    lo = (args.real_width - args.real_strip) / 2.0
    altitude = float(h.max()) + CLEARANCE_M
    case = Case(h, altitude, (lo, lo + args.real_strip), ROLL, seed=3)
    print(
        f'\n## real terrain: Jacksboro 3" DEM ({info["sample_north_m"]:.1f} m × '
        f"{info['sample_east_m']:.1f} m samples), {args.real_width:.0f} m square at 0.5 m, "
        f"{h.min():.1f}..{h.max():.1f} m, platform at {altitude:.1f} m, roll 3°; "
        f"{case.strip.echoes.shape} echoes, sim {case.sim_s:.0f} s"
    )
    before, _ = case.run(compensate_attitude=False)
    after, _ = case.run()
    print(HEAD + "\n" + SEP)
    print(_paper_row("paper SRTM, before", "real_before", False))
    print(_paper_row("paper SRTM, after", "real_after", False))
    print(_row("ours, before", before))
    print(_row("ours, after (1×8)", after))
    out["real"] = {
        "before": before.as_dict(),
        "after": after.as_dict(),
        "terrain": info,
        "height_range_m": [float(h.min()), float(h.max())],
        "altitude_m": altitude,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=float, default=120.0, help="synthetic terrain side, m")
    ap.add_argument("--strip", type=float, default=116.0, help="synthetic strip length, m")
    ap.add_argument("--real-width", type=float, default=200.0)
    ap.add_argument("--real-strip", type=float, default=40.0)
    ap.add_argument("--blocks", default="1x1,1x2,1x4,1x8,1x16,1x32,2x8")
    ap.add_argument("--cases", default="synthetic,blocks,series,real")
    ap.add_argument("--json", default=None, help="write the numbers here")
    args = ap.parse_args()
    cases = set(args.cases.split(","))
    out: dict[str, object] = {"args": vars(args)}
    if cases & {"synthetic", "blocks"}:
        case = synthetic(args, out)
        if "blocks" in cases:
            blocks(case, args, out)
        del case
    if "series" in cases:
        series(args, out)
    if "real" in cases:
        real(args, out)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(out, fh, indent=1, default=str)


if __name__ == "__main__":
    main()
