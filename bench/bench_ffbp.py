"""FFBP against direct backprojection: speed-up and image error.

Presets (``ku-vehicle``, ``thz-spotlight``, ``ku-microuav`` at ``--scale``): point targets
across the swath, ideal straight flight, no noise, autofocus off, run through
the daemon's :class:`~sarmoco.daemon.focuser.Focuser` once; the pulses it hands to the
tile imager (compensated, pre-filtered, with their eq. 29 ΔY) are kept and imaged onto the
same tiles by a direct :class:`~sarmoco.processing.imaging.tiles.TileImager` and by one with
``imaging.method = "ffbp"`` at each budget. Reported per budget: imaging CPU time of
both on one thread (best of ``--repeat``, after a warm-up that compiles the kernels; CPU
time, since the machines these run on are shared and their wall time is not), the speed-up, the
relative L2 error over all tiles, and the largest PSLR change (azimuth, range) and IRW
change over the targets.

GOTCHA (AFRL, pass 1 HH, the two 1-degree files in ``../shared/data/gotcha``): the phase
history as provided, range-compressed, onto a 500 x 500 grid of 0.2 m at the scene centre
(the quicklook's), direct against FFBP without beam culling, per-pulse reference range;
L2 over the image, PSLR change of the brightest scatterer, entropy of both.

Run: ``.venv/bin/python -m bench.bench_ffbp [--scale 0.2] [--budgets 0.1 0.3 1.0]
[--repeat 2] [--skip-gotcha]`` (a few minutes on two cores).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.drivers.gotcha import read_gotcha
from sarmoco.processing.imaging import PlaneGrid, compressed_from_phase_history, facing_heading
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.ffbp import ffbp_into
from sarmoco.processing.imaging.tiles import Tile, TileImager, TileLayout
from sarmoco.processing.metrics import image_entropy, point_target_metrics
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, Image, IntArray
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import Target, load_preset

PRESETS = ("ku-vehicle", "thz-spotlight", "ku-microuav")
GOTCHA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "gotcha"
PIXEL_M = {"thz-spotlight": 0.04}
"""Pixel spacing where the daemon's default (0.1 m) would not sample the resolution."""


@dataclass
class Row:
    """One comparison: where, budget, times (s) and image error."""

    name: str
    budget_rad: float
    size: str
    direct_s: float
    ffbp_s: float
    l2: float
    l2_targets: float
    d_pslr_db: tuple[float, float]
    irw_change: float

    def markdown(self) -> str:
        return (
            f"| {self.name} | {self.size} | {self.budget_rad:g} | {self.direct_s:.2f} | "
            f"{self.ffbp_s:.2f} | {self.direct_s / self.ffbp_s:.1f}x | "
            f"{self.l2:.4f} / {self.l2_targets:.4f} | "
            f"{self.d_pslr_db[0]:+.2f} / {self.d_pslr_db[1]:+.2f} | {100 * self.irw_change:.2f} |"
        )


HEADER = (
    "| data | pulses x pixels | budget (rad) | direct (CPU s) | FFBP (CPU s) | speed-up | "
    "rel. L2 all / near targets | max PSLR change az / rg (dB) | max IRW change (%) |\n"
    "|---|---|---|---|---|---|---|---|---|"
)


def _best(fn: Callable[[], object], repeat: int) -> float:
    """Least CPU time of ``repeat`` calls, s (the kernels run on one thread: :func:`main`)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return float(best)


class _Keep:
    """A tile sink that keeps the pulses the tile imager would get."""

    def __init__(self, imager: TileImager, _track: object) -> None:
        self.imager = imager
        self.blocks: list[tuple[ComplexArray, IntArray, FloatArray, FloatArray | None]] = []

    def add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None = None,
    ) -> list[Tile]:
        dy = None if compensated_dy_m is None else compensated_dy_m.copy()
        self.blocks.append((rc.copy(), t_ns.copy(), apc_m.copy(), dy))
        return []

    def close(self) -> list[Tile]:
        return []


def _tiles(keep: _Keep, budget_rad: float | None) -> list[Tile]:
    """The kept pulses imaged by a fresh tile imager like the daemon's."""
    im = keep.imager
    imager = TileImager(im.layout, im.range_axis_m, im.wavelength_m, ffbp_budget_rad=budget_rad)
    tiles: list[Tile] = []
    for rc, t, apc, dy in keep.blocks:
        tiles += imager.add(rc, t, apc, dy)
    return sorted(tiles + imager.close(), key=lambda t: t.index)


def _window(tiles: list[Tile], x: float, y: float, half_m: float = 1.5) -> Image:
    a0 = np.concatenate([t.grid.axis0_m for t in tiles])
    data = np.concatenate([t.data for t in tiles])
    a1 = tiles[0].grid.axis1_m
    i = np.flatnonzero(np.abs(a0 - x) <= half_m)
    j = np.flatnonzero(np.abs(a1 - y) <= half_m)
    return Image(data[i[0] : i[-1] + 1, j[0] : j[-1] + 1], a0[i], a1[j], "ground")


def _l2(ref: list[ComplexArray], got: list[ComplexArray]) -> float:
    """Relative L2 error of the pixels ``got`` against ``ref``."""
    a, b = (np.concatenate([x.ravel() for x in xs]) for xs in (ref, got))
    return float(np.linalg.norm(b - a) / np.linalg.norm(a))


def _errors(ref: Image, got: Image, at: tuple[float, float]) -> tuple[tuple[float, float], float]:
    """PSLR change (azimuth, range) and largest IRW change (fraction) of the target at ``at``."""
    m = [point_target_metrics(img, at, 0.5) for img in (ref, got)]
    d = (m[1].axis0.pslr_db - m[0].axis0.pslr_db, m[1].axis1.pslr_db - m[0].axis1.pslr_db)
    irw = max(
        abs(m[1].axis0.irw_m / m[0].axis0.irw_m - 1), abs(m[1].axis1.irw_m / m[0].axis1.irw_m - 1)
    )
    return d, irw


def preset_rows(name: str, scale: float, budgets: list[float], repeat: int) -> list[Row]:
    """Speed-up and image error of FFBP in the daemon's tile imager on one preset."""
    c = load_preset(name, scale).scene_center_ned
    sw = load_preset(name, scale).swath_m
    targets = tuple(Target((c[0], c[1] + f * sw, 0.0)) for f in (-0.35, 0.0, 0.35))
    scn = load_preset(name, scale, snr_db=None, targets=targets)
    run = simulate(scn, MotionSpec(kind="ideal"), "ideal")
    imaging: dict[str, object] = {"swath_m": 1.1 * sw}
    if name in PIXEL_M:
        imaging["pixel_m"] = PIXEL_M[name]
    cfg = scenario_config(scn, autofocus={"enabled": False}, imaging=imaging)
    kept: list[_Keep] = []

    def sink(imager: TileImager, track: object) -> _Keep:
        kept.append(_Keep(imager, track))
        return kept[-1]

    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:256].mean(axis=0), sink=sink)
    echo = np.asarray(run.echo)
    for a in range(0, run.t_ns.size, cfg.imaging.block_pulses):
        b = slice(a, a + cfg.imaging.block_pulses)
        focuser.push(echo[b], run.t_ns[b], run.vel_ned[b])
    focuser.finish()
    if len(kept) != 1:
        raise RuntimeError(f"{name}: {len(kept)} segments, expected one straight track")
    keep, track = kept[0], focuser.track
    n_p = sum(b[0].shape[0] for b in keep.blocks)
    direct = _tiles(keep, None)
    t_direct = _best(lambda: _tiles(keep, None), repeat)
    layout: TileLayout = keep.imager.layout
    n_pix = sum(t.data.size for t in direct)
    at = []
    for tgt in run.targets_ned:
        d = tgt - run.apc_ned[0]
        at.append((float(d @ track.x_hat), float(d @ track.y_hat)))
    rows = []
    for budget in budgets:
        got = _tiles(keep, budget)
        t_ffbp = _best(lambda b=budget: _tiles(keep, b), repeat)  # type: ignore[misc]
        l2 = _l2([t.data for t in direct], [t.data for t in got])
        near = _l2([_window(direct, *p).data for p in at], [_window(got, *p).data for p in at])
        errs = [_errors(_window(direct, *p), _window(got, *p), p) for p in at]
        d_az = max((e[0][0] for e in errs), key=abs)
        d_rg = max((e[0][1] for e in errs), key=abs)
        size = f"{n_p} x {n_pix} ({len(direct)} tiles of {layout.tile_length_m:g} m)"
        rows.append(
            Row(
                f"{name} x{scale:g}",
                budget,
                size,
                t_direct,
                t_ffbp,
                l2,
                near,
                (d_az, d_rg),
                max(e[1] for e in errs),
            )
        )
        print(rows[-1].markdown(), flush=True)
    return rows


def gotcha_rows(budgets: list[float], repeat: int) -> list[Row]:
    """Speed-up and image error of FFBP on GOTCHA pass 1 HH (2 degrees), 500 x 500 at 0.2 m."""
    d = read_gotcha(sorted(GOTCHA.glob("data_3dsar_pass1_az00*_HH.mat")))
    grid = PlaneGrid.centred(
        (0.0, 0.0, 0.0), 500, 500, 0.2, 0.2, facing_heading(d.apc_m, (0.0, 0.0, 0.0))
    )
    rc, r_axis, fc = compressed_from_phase_history(d.phase_history, d.freq_hz)
    lam = C_MPS / fc
    lines = RangeLines.upsample(rc, r_axis)
    dr = float(r_axis[1] - r_axis[0])
    shape = (500, 500)

    def direct() -> ComplexArray:
        out = np.zeros(shape, np.complex64)
        backproject_into(out, lines, d.apc_m, lam, grid, d.r0_m)
        return out

    def ffbp(budget: float) -> ComplexArray:
        out = np.zeros(shape, np.complex64)
        ffbp_into(out, lines, dr, d.apc_m, lam, grid, budget, ref_range_m=d.r0_m)
        return out

    ref = direct()
    t_direct = _best(direct, repeat)
    ref_img = Image(ref, grid.axis0_m, grid.axis1_m, "ground")
    peak = np.unravel_index(np.argmax(np.abs(ref)), shape)
    at = (float(grid.axis0_m[peak[0]]), float(grid.axis1_m[peak[1]]))
    rows = []
    for budget in budgets:
        got = ffbp(budget)
        t_ffbp = _best(lambda b=budget: ffbp(b), repeat)  # type: ignore[misc]
        l2 = _l2([ref], [got])
        i, j = (
            np.abs(ax - c) <= 1.5 for ax, c in zip((grid.axis0_m, grid.axis1_m), at, strict=True)
        )
        near = _l2([ref[np.ix_(i, j)]], [got[np.ix_(i, j)]])
        (d_az, d_rg), irw = _errors(ref_img, Image(got, grid.axis0_m, grid.axis1_m, "ground"), at)
        size = (
            f"{d.apc_m.shape[0]} x {ref.size} (entropy {image_entropy(ref):.3f} -> "
            f"{image_entropy(got):.3f})"
        )
        rows.append(
            Row(
                "GOTCHA pass 1 HH 2 deg",
                budget,
                size,
                t_direct,
                t_ffbp,
                l2,
                near,
                (d_az, d_rg),
                irw,
            )
        )
        print(rows[-1].markdown(), flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scale", type=float, default=0.2)
    ap.add_argument("--budgets", type=float, nargs="+", default=[0.1, 0.3, 1.0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--presets", nargs="*", default=list(PRESETS))
    ap.add_argument("--skip-gotcha", action="store_true")
    args = ap.parse_args()
    numba.set_num_threads(1)
    print(HEADER, flush=True)
    rows: list[Row] = []
    for name in args.presets:
        rows += preset_rows(name, args.scale, args.budgets, args.repeat)
    if not args.skip_gotcha:
        rows += gotcha_rows(args.budgets, args.repeat)


if __name__ == "__main__":
    main()
