"""The MIMO array through the user's three commands, at any scale (the end-to-end path).

Cases, each ``sarmoco sim --preset mimo-array --scale S ... --out DIR``, ``sarmoco replay``,
``sarmoco report --truth --json``:

- ``constant``: the paper's roll of 3 deg over the three-peak terrain;
- ``series``: ``--roll-series`` (3 deg + a 0.5 deg rms, 2 Hz corner random series, known to
  the processor only from the INS stream);
- ``real``: ``--dem`` with matplotlib's USGS 3-arc-second DEM of the Jacksboro fault, a
  600 m square around its steepest point resampled (bicubic) to the preset's 0.5 m grid
  (the sim flies 200 m above its mean height).

Prints one row per case and image (before = level, after = roll compensated) with the CPU
and wall time of the three commands; ``--json OUT`` keeps every report.

Run: ``.venv/bin/python -m bench.array_commands [--scale 1] [--cases constant,series,real]
[--out DIR] [--json OUT.json]``.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import cbook
from scipy.interpolate import RectBivariateSpline

SPACING_M = 0.5
"""The preset's terrain grid, m."""
REAL_SIZE_M = 600.0
"""Side of the Jacksboro square resampled for ``real``, m."""
EARTH_M_PER_DEG = 111_320.0


def jacksboro_npz(path: Path) -> Path:
    """A ``--dem`` file: the Jacksboro DEM around its steepest point at 0.5 m (m, up)."""
    dem = np.load(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False))
    z = np.asarray(dem["elevation"], dtype=np.float64)
    lat = 0.5 * (float(dem["ymin"]) + float(dem["ymax"]))
    dy_m = float(dem["dy"]) * EARTH_M_PER_DEG
    dx_m = float(dem["dx"]) * EARTH_M_PER_DEG * math.cos(math.radians(lat))
    north = dy_m * np.arange(z.shape[0])
    east = dx_m * np.arange(z.shape[1])
    gn, ge = np.gradient(z, dy_m, dx_m)
    margin = math.ceil(REAL_SIZE_M / min(dx_m, dy_m))
    slope = np.hypot(gn, ge)[margin:-margin, margin:-margin]
    i, j = np.unravel_index(int(np.argmax(slope)), slope.shape)
    c_n, c_e = north[i + margin], east[j + margin]
    n_out = int(REAL_SIZE_M / SPACING_M) + 1
    grid = SPACING_M * np.arange(n_out) - REAL_SIZE_M / 2.0
    spline = RectBivariateSpline(north, east, z, kx=3, ky=3)
    height = spline(c_n + grid, c_e + grid)
    np.savez(path, height_m=height, spacing_m=SPACING_M)
    return path


def _sarmoco(*argv: str) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "sarmoco", *argv], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise SystemExit(f"sarmoco {' '.join(argv)} failed:\n{done.stderr}")
    return done.stdout


def run_case(root: Path, scale: float, extra: list[str]) -> dict[str, Any]:
    """The three commands for one case; the report plus CPU and wall seconds."""
    sim, store = root / "sim", root / "run.zarr"
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    _sarmoco("sim", "--preset", "mimo-array", "--scale", str(scale), *extra, "--out", str(sim))
    _sarmoco(
        "replay", "--config", str(sim / "sarmoco.toml"), "--radar", str(sim / "radar.vrt"),
        "--nav", str(sim / "nav.tlog"), "--out", str(store),
    )  # fmt: skip
    report: dict[str, Any] = json.loads(
        _sarmoco("report", str(store), "--truth", str(sim / "truth.json"), "--json")
    )
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    report["cpu_s"] = (cpu1.ru_utime + cpu1.ru_stime) - (cpu0.ru_utime + cpu0.ru_stime)
    report["wall_s"] = time.perf_counter() - t0
    return report


def main() -> None:
    """Run the cases and print the table."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scale", type=float, default=1.0)
    p.add_argument("--cases", default="constant,series,real")
    p.add_argument("--out", type=Path, default=Path("array-bench-out"))
    p.add_argument("--json", type=Path)
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    extras = {
        "constant": [],
        "series": ["--roll-series"],
        "real": ["--dem", str(jacksboro_npz(args.out / "jacksboro.npz"))],
    }
    results = {}
    print("| case | image | mean m | std m | within ½ cell | range m | coverage | CPU s | wall s |")
    print("|---|---|---|---|---|---|---|---|---|")
    for case in args.cases.split(","):
        r = run_case(args.out / case, args.scale, extras[case])
        results[case] = r
        for key, label in (("dem_uncompensated", "level"), ("dem", "compensated")):
            s = r[key]
            print(
                f"| {case} ×{args.scale:g} | {label} | {s['mean_m']:+.3f} | {s['std_m']:.3f} | "
                f"{100 * s['within_half_cell']:.2f} % | {s['range_m'][0]:+.2f} … "
                f"{s['range_m'][1]:+.2f} | {100 * s['coverage']:.1f} % | {r['cpu_s']:.0f} | "
                f"{r['wall_s']:.0f} |",
                flush=True,
            )
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
