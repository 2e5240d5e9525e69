"""Quicklook of the AFRL GOTCHA 2-deg phase history: docs/img/gotcha.png.

Backprojection and polar format of the same 100 m x 100 m ground grid (axis 1
along the mean look direction), each in dB over 50 dB, with its image entropy;
the entropy with the provider's autofocus solution applied is printed too.

Run: ``.venv/bin/python bench/gotcha_quicklook.py`` (about 10 s).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from sarmoco.drivers.gotcha import GotchaPass, read_gotcha
from sarmoco.processing.imaging import (
    PlaneGrid,
    backproject,
    compressed_from_phase_history,
    facing_heading,
    polar_format,
)
from sarmoco.processing.metrics import image_entropy
from sarmoco.processing.types import C_MPS, Image

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data" / "gotcha"
OUT = ROOT / "docs" / "img" / "gotcha.png"
DYNAMIC_RANGE_DB = 50.0


def _bp(d: GotchaPass, grid: PlaneGrid, autofocus: bool) -> Image:
    ph, ref = d.phase_history, d.r0_m
    if autofocus:
        ph = ph * np.exp(1j * d.af_ph_correct_rad)[:, None]
        ref = d.r0_m + d.af_r_correct_m
    rc, r_axis, fc = compressed_from_phase_history(ph, d.freq_hz)
    return backproject(rc, r_axis, d.apc_m, C_MPS / fc, grid, ref_range_m=ref)


def main() -> None:
    d = read_gotcha(sorted(DATA.glob("data_3dsar_pass1_az00*_HH.mat")))
    grid = PlaneGrid.centred(
        (0.0, 0.0, 0.0), 500, 500, 0.2, 0.2, facing_heading(d.apc_m, (0.0, 0.0, 0.0))
    )
    images = {
        "backprojection": _bp(d, grid, autofocus=False),
        "polar format": polar_format(d.phase_history, d.freq_hz, d.apc_m, grid),
    }
    h_af = image_entropy(_bp(d, grid, autofocus=True).data)
    fig = Figure(figsize=(12, 5.6), dpi=100)
    axes = fig.subplots(1, 2)
    for ax, (name, img) in zip(axes, images.items(), strict=True):
        power = np.abs(img.data.astype(np.complex128)) ** 2
        db = 10 * np.log10(np.maximum(power / power.max(), 10 ** (-DYNAMIC_RANGE_DB / 10)))
        extent = (img.axis1_m[0], img.axis1_m[-1], img.axis0_m[0], img.axis0_m[-1])
        im = ax.imshow(db, origin="lower", extent=extent, cmap="gray", vmin=-DYNAMIC_RANGE_DB)
        ax.set_title(f"GOTCHA pass 1 HH, 2° — {name}\nentropy {image_entropy(img.data):.3f}")
        ax.set_xlabel("ground range (m, away from the radar)")
        ax.set_ylabel("cross range (m)")
        fig.colorbar(im, ax=ax, label="dB re peak", shrink=0.85)
    fig.tight_layout()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT)
    h_bp = image_entropy(images["backprojection"].data)
    print(f"wrote {OUT}; backprojection entropy {h_bp:.3f} as provided, {h_af:.3f} with data.af")


if __name__ == "__main__":
    main()
