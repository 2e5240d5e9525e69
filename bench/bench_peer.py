"""Peer benchmark: one phase history formed by FastSAR and by sarmoco's imagers, in one run.

A ku-vehicle point-target scene (``--scale``, ideal INS, no autofocus needed) is simulated
(``sarmoco sim --out``), replayed into a store (``sarmoco replay``) and exported as CPHD
(``sarmoco export --cphd``): the one file every imager here reads. Then, on one thread and
on the same ground grid (``--size`` x ``--size`` pixels of ``--pixel-m``, axis 0 along
track, axis 1 along the mean look direction, centred on the scene reference point):

* FastSAR (PyPI ``fastsar``, an optional bench-only dependency: ``pip install fastsar``)
  reads the CPHD with its own reader (``fastsar.io.read_cphd``) and forms the image by
  exact backprojection (``algorithm="bp"``) and by factorised backprojection
  (``algorithm="ffbp"``), its C++/OpenMP ``cpu`` backend, ``OMP_NUM_THREADS=1``;
* sarmoco reads it with :func:`sarmoco.products.cphd.read_cphd` and forms it by direct
  backprojection (:func:`~sarmoco.processing.imaging.backprojection.backproject_into`) and
  by FFBP (:func:`~sarmoco.processing.imaging.ffbp.ffbp_into`, phase budget ``--budget``),
  numba on one thread.

No window on any of them (FastSAR ``window=False``; sarmoco's phase-history path has
none), so the point-target figures compare like with like. Reported per imager: CPU
seconds (``time.process_time``, best of ``--repeat`` after a warm-up that compiles the
kernels; each timing covers range compression to image), pixel-pulses per CPU second, the
relative L2 difference from sarmoco's direct image, and the worst PSLR (dB) and IRW (m)
over the targets along each axis (:func:`~sarmoco.processing.metrics.point_target_metrics`).
With ``--sicd`` the store's SICD (``sarmoco export --sicd``) is also handed to FastSAR's
reader, which takes its image grid from it.

Run: ``.venv/bin/python -m bench.bench_peer [--scale 0.1] [--size 600] [--repeat 2]
[--budget 0.3] [--sicd] [--json]`` (about two minutes on two cores at scale 0.1).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numba
import numpy as np

from sarmoco.geodesy import geodetic_to_ecef
from sarmoco.processing.imaging import PlaneGrid, compressed_from_phase_history
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.ffbp import ffbp_into
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import C_MPS, ComplexArray, Image
from sarmoco.products.cphd import FxPhaseHistory, grid_heading, read_cphd

MARGIN_M = 3.0
"""Least distance from a target to the grid's edge, m."""


@dataclass(frozen=True)
class Row:
    """One imager's figures."""

    imager: str
    cpu_s: float
    pixel_pulses_per_cpu_s: float
    l2_vs_direct: float
    pslr_db: tuple[float, float]
    irw_m: tuple[float, float]

    def markdown(self) -> str:
        """A row of the measurements table."""
        return (
            f"| {self.imager} | {self.cpu_s:.3f} | {self.pixel_pulses_per_cpu_s:.3g} | "
            f"{self.l2_vs_direct:.4f} | {self.pslr_db[0]:.2f} / {self.pslr_db[1]:.2f} | "
            f"{self.irw_m[0]:.4f} / {self.irw_m[1]:.4f} |"
        )


def sarmoco(*args: str) -> None:
    """Run the ``sarmoco`` command line of this environment (fails loudly)."""
    subprocess.run([sys.executable, "-m", "sarmoco", *args], check=True, capture_output=True)


def scene_files(work: Path, scale: float, sicd: bool) -> tuple[Path, Path | None, dict[str, Any]]:
    """Simulate, replay and export the scene; the CPHD, the SICD (or None) and the truth."""
    sim = work / "sim"
    sarmoco("sim", "--preset", "ku-vehicle", "--scale", str(scale), "--ins-grade", "ideal",
            "--out", str(sim))  # fmt: skip
    store = work / "run.zarr"
    sarmoco("replay", "--config", str(sim / "sarmoco.toml"), "--radar", str(sim / "radar.vrt"),
            "--nav", str(sim / "nav.tlog"), "--out", str(store))  # fmt: skip
    cphd, sicd_path = work / "scene.cphd", (work / "scene.nitf" if sicd else None)
    extra = ["--sicd", str(sicd_path)] if sicd_path is not None else []
    sarmoco("export", str(store), "--cphd", str(cphd), *extra)
    return cphd, sicd_path, json.loads((sim / "truth.json").read_text())


def target_grid(
    ph: FxPhaseHistory, truth: dict[str, Any], size: int, pixel_m: float
) -> tuple[PlaneGrid, list[tuple[float, float]]]:
    """A ``size`` x ``size`` grid (scene frame, centred on the IARP, axis 1 along the mean
    look direction) and the targets' (axis 0, axis 1) positions on it, m.

    Raises
    ------
    ValueError
        A target lies within :data:`MARGIN_M` of the grid's edge or beyond (``size`` odd).
    """
    if size % 2:
        raise ValueError(f"--size {size}: give an even size (the imagers centre it alike)")
    heading = grid_heading(ph)
    e0 = np.array([np.cos(heading), np.sin(heading)])
    e1 = np.array([-np.sin(heading), np.cos(heading)])
    enu = ph.scene(geodetic_to_ecef(np.array([t["lla"] for t in truth["targets"]])))
    at = [(float(p[:2] @ e0), float(p[:2] @ e1)) for p in enu]
    if np.max(np.abs(at)) > size / 2 * pixel_m - MARGIN_M:
        raise ValueError(f"targets at {at} m: a {size}-pixel grid of {pixel_m} m misses some")
    return PlaneGrid.centred((0.0, 0.0, 0.0), size, size, pixel_m, pixel_m, heading), at


def best_cpu_s(form: Callable[[], ComplexArray], repeat: int) -> tuple[float, ComplexArray]:
    """Smallest CPU time of ``repeat`` calls after a warm-up call, and the image."""
    image = form()
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        image = form()
        times.append(time.process_time() - t0)
    return min(times), image


def worst_metrics(
    image: ComplexArray, grid: PlaneGrid, at: list[tuple[float, float]]
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Worst (largest) PSLR (dB) and IRW (m) over the targets, along axis 0 and axis 1."""
    img = Image(image, grid.axis0_m, grid.axis1_m, "ground")
    m = [point_target_metrics(img, p, 0.5) for p in at]
    pslr = (max(x.axis0.pslr_db for x in m), max(x.axis1.pslr_db for x in m))
    irw = (max(x.axis0.irw_m for x in m), max(x.axis1.irw_m for x in m))
    return pslr, irw


def run(
    scale: float, size: int, pixel_m: float, budget: float, repeat: int, sicd: bool
) -> dict[str, Any]:
    """Form the scene with each imager; the figures (JSON-able)."""
    os.environ["OMP_NUM_THREADS"] = "1"  # before FastSAR loads its OpenMP kernels
    numba.set_num_threads(1)
    import fastsar
    from fastsar import io as fio

    with tempfile.TemporaryDirectory() as tmp:
        cphd, sicd_path, truth = scene_files(Path(tmp), scale, sicd)
        ph = read_cphd(cphd)
        peer, meta = fio.read_cphd(str(cphd), meta=True)
        from_sicd = None
        if sicd_path is not None:
            with_sicd = fio.read_cphd(str(cphd), sicd=str(sicd_path))
            from_sicd = {k: with_sicd[k] for k in ("nx", "ny", "spx", "spy")}
    grid, at = target_grid(ph, truth, size, pixel_m)
    n0, n1 = grid.axis0_m.size, grid.axis1_m.size
    pulses = ph.signal.shape[0]
    # the grid's axes in FastSAR's local frame (rows of meta["R"], origin its SRP)
    e0, e1 = grid.unit_vectors
    rot = np.asarray(meta["R"])
    e_peer = [rot @ (ph.ecef(e) - ph.ecef(np.zeros(3))) for e in (e0, e1)]
    origin_offset_m = float(np.linalg.norm(ph.ecef(np.zeros(3)) - np.asarray(meta["origin"])))
    apc = ph.scene(ph.apc_ecef_m)
    ref = ph.ref_range_m

    def lines() -> tuple[RangeLines, float, float]:
        rc, r_axis, fc = compressed_from_phase_history(ph.signal, ph.freq_hz)
        return RangeLines.upsample(rc, r_axis), float(r_axis[1] - r_axis[0]), C_MPS / fc

    def direct() -> ComplexArray:
        rl, _, lam = lines()
        out = np.zeros((n0, n1), np.complex64)
        backproject_into(out, rl, apc, lam, grid, ref)
        return out

    def ffbp() -> ComplexArray:
        rl, dr, lam = lines()
        out = np.zeros((n0, n1), np.complex64)
        ffbp_into(out, rl, dr, apc, lam, grid, budget, ref_range_m=ref)
        return out

    def peer_form(algorithm: str) -> Callable[[], ComplexArray]:
        def form() -> ComplexArray:
            return np.asarray(
                fastsar.form_image(
                    peer["S"],
                    peer["ant"],
                    peer["fmin"],
                    peer["df"],
                    n0,
                    n1,
                    pixel_m,
                    pixel_m,
                    e_peer[0],
                    e_peer[1],
                    algorithm=algorithm,
                    backend="cpu",
                    window=False,
                )
            )

        return form

    imagers = {
        "sarmoco direct": direct,
        f"sarmoco FFBP ({budget} rad)": ffbp,
        "FastSAR exact (bp)": peer_form("bp"),
        "FastSAR factorised (ffbp)": peer_form("ffbp"),
    }
    rows, reference = [], None
    for name, form in imagers.items():
        cpu_s, image = best_cpu_s(form, repeat)
        if reference is None:
            reference = image
        l2 = float(np.linalg.norm(image - reference) / np.linalg.norm(reference))
        pslr, irw = worst_metrics(image, grid, at)
        rows.append(Row(name, cpu_s, n0 * n1 * pulses / cpu_s, l2, pslr, irw))
        print(rows[-1].markdown(), flush=True)
    return {
        "scale": scale,
        "pulses": pulses,
        "grid": [n0, n1],
        "pixel_m": pixel_m,
        "pixel_pulses": n0 * n1 * pulses,
        "targets": len(at),
        "srp_vs_iarp_m": origin_offset_m,
        "fastsar_version": fastsar.__version__,
        "fastsar_grid_from_our_sicd": from_sicd,
        "rows": [asdict(r) for r in rows],
    }


def main() -> None:
    """Run the bench; a markdown table (and ``--json``: the figures as one JSON line)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.1)
    ap.add_argument("--size", type=int, default=600, help="grid pixels per side (even)")
    ap.add_argument("--pixel-m", type=float, default=0.1)
    ap.add_argument("--budget", type=float, default=0.3, help="sarmoco FFBP phase budget, rad")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--sicd", action="store_true", help="also hand our SICD to FastSAR")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    print("| imager | CPU s | pixel-pulses / CPU s | L2 vs direct | PSLR dB (az / rg) | "
          "IRW m (az / rg) |\n|---|---|---|---|---|---|")  # fmt: skip
    figures = run(args.scale, args.size, args.pixel_m, args.budget, args.repeat, args.sicd)
    print(
        f"{figures['pulses']} pulses x {figures['grid'][0]} x {figures['grid'][1]} pixels "
        f"({figures['pixel_pulses']:.3g} pixel-pulses), {figures['targets']} targets, "
        f"FastSAR {figures['fastsar_version']}; its SRP {figures['srp_vs_iarp_m']:.2e} m from "
        f"our IARP; its grid from our SICD: {figures['fastsar_grid_from_our_sicd']}"
    )
    if args.json:
        print(json.dumps(figures))


if __name__ == "__main__":
    main()
