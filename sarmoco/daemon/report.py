"""``sarmoco report STORE``: quicklook PNGs and a metrics summary of a recorded run.

Writes into the output folder:

- ``image.png``: the image strip (tiles side by side along track) in dB, metre axes,
  scale bar;
- ``motion.png``: the INS motion solution per pulse (d_los, phase, range shift);
- ``autofocus.png``: autofocus estimates per subaperture (a_y, a_z, κ0), when recorded;
- ``report.json`` and ``report.txt``: run totals, per-tile entropy and contrast, and the
  point-target measures (PSLR, ISLR, IRW) of the brightest isolated scatterers (corner
  reflectors, or the simulator's targets).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.daemon.quicklook import plot_image, plot_series
from sarmoco.daemon.store import RunStore, open_store
from sarmoco.errors import ProcessingError, RecorderError
from sarmoco.processing.metrics import image_contrast, image_entropy, point_target_metrics
from sarmoco.processing.types import Image

BRIGHT_POINTS = 5
"""How many of the brightest scatterers are measured."""

POINT_SEPARATION_M = 5.0
"""Minimum distance between two measured scatterers, m."""

POINT_CONTRAST_DB = 20.0
"""A scatterer is measured only if its peak stands this far above the image's median
magnitude (noise and clutter peaks, whose PSLR means nothing, stand ~10 dB above it), dB."""


def strip(store: RunStore) -> Image | None:
    """The recorded tiles joined along track (axis 0); None without tiles.

    Tiles of one reference-track segment are in that track's frame; segments follow each
    other in time, each shifted along axis 0 to start where the one before ended (so the
    first segment keeps its own coordinates, and a single-segment run is unchanged).
    """
    segments: dict[int, list[Image]] = {}
    for k in range(store.n_images):
        image, attrs = store.image(k)
        segments.setdefault(int(attrs.get("reference_track", {}).get("t0_ns", 0)), []).append(image)
    if not segments:
        return None
    parts: list[tuple[Image, float]] = []
    end = -np.inf
    for t0 in sorted(segments):
        tiles = sorted(segments[t0], key=lambda im: float(im.axis0_m[0]))
        first = float(tiles[0].axis0_m[0])
        shift = 0.0 if not parts else end - first + abs(float(np.diff(tiles[0].axis0_m[:2])[0]))
        parts += [(t, shift) for t in tiles]
        end = float(tiles[-1].axis0_m[-1]) + shift
    return Image(
        np.concatenate([t.data for t, _ in parts], axis=0),
        np.concatenate([t.axis0_m + s for t, s in parts]),
        parts[0][0].axis1_m,
        parts[0][0].frame,
    )


def bright_points(image: Image, n: int = BRIGHT_POINTS) -> list[dict[str, float]]:
    """Point-target measures of the ``n`` brightest isolated scatterers.

    A candidate pixel is measured only if it is the maximum of the window of
    ``POINT_SEPARATION_M`` around it (a sidelobe of a brighter neighbour is not), stands
    ``POINT_CONTRAST_DB`` above the image's median magnitude, and is at least
    ``POINT_SEPARATION_M`` from a scatterer already measured.
    """
    mag = np.abs(image.data)
    dx, dy = image.spacing_m
    half0, half1 = round(POINT_SEPARATION_M / abs(dx)), round(POINT_SEPARATION_M / abs(dy))
    floor = float(np.median(mag)) * 10 ** (POINT_CONTRAST_DB / 20)
    found: list[dict[str, float]] = []
    order = np.argsort(mag, axis=None)[::-1]
    taken: list[tuple[float, float]] = []
    for flat in order[: 200 * n]:
        i, j = (int(k) for k in np.unravel_index(int(flat), mag.shape))
        if mag[i, j] < floor:
            break
        x, y = float(image.axis0_m[i]), float(image.axis1_m[j])
        if any(np.hypot(x - a, y - b) < POINT_SEPARATION_M for a, b in taken):
            continue
        rows = slice(max(i - half0, 0), i + half0 + 1)
        cols = slice(max(j - half1, 0), j + half1 + 1)
        if mag[rows, cols].max() > mag[i, j]:
            continue
        taken.append((x, y))
        sub = Image(image.data[rows, cols], image.axis0_m[rows], image.axis1_m[cols], image.frame)
        try:
            m = point_target_metrics(sub)
        except ProcessingError:
            continue
        found.append(
            {
                "x_m": m.axis0.peak_m,
                "y_m": m.axis1.peak_m,
                "peak_db": float(20 * np.log10(mag[i, j] / mag.max())),
                "pslr_az_db": m.axis0.pslr_db,
                "islr_az_db": m.axis0.islr_db,
                "irw_az_m": m.axis0.irw_m,
                "pslr_rg_db": m.axis1.pslr_db,
                "islr_rg_db": m.axis1.islr_db,
                "irw_rg_m": m.axis1.irw_m,
            }
        )
        if len(found) == n:
            break
    return found


def write_report(store_path: Path, out_dir: Path) -> dict[str, Any]:
    """Write the quicklooks and the summary of a store; returns the summary.

    Raises
    ------
    RecorderError
        If the store cannot be opened or holds no pulses.
    """
    store = open_store(store_path)
    out_dir.mkdir(parents=True, exist_ok=True)
    attrs = store.attrs
    summary: dict[str, Any] = {
        "store": str(store_path),
        "complete": bool(attrs.get("complete", False)),
        "run": attrs.get("metrics", {}),
        "versions": attrs.get("versions", {}),
        "pulses_committed": store.committed("pulses"),
    }
    if summary["pulses_committed"] == 0:
        raise RecorderError(f"{store_path}: no committed pulses")
    image = strip(store)
    if image is not None:
        plot_image(image.data, image.axis0_m, image.axis1_m, out_dir / "image.png",
                   f"{store_path.name}: backprojection, ground plane",
                   ("along-track x (m)", "ground range y (m)"))  # fmt: skip
        summary["image"] = {
            "shape": list(image.data.shape),
            "pixel_m": list(image.spacing_m),
            "entropy": image_entropy(image.data),
            "contrast": image_contrast(image.data),
            "points": bright_points(image),
        }
    if store.committed("motion"):
        m = store.read("motion", ["t_ns", "d_los_m", "phase_rad", "range_shift_m"])
        t = (m["t_ns"] - m["t_ns"][0]) * 1e-9
        plot_series(t, {"d_los (m)": m["d_los_m"], "phase (rad)": m["phase_rad"],
                        "range shift (m)": m["range_shift_m"]},
                    out_dir / "motion.png", "INS motion solution per pulse")  # fmt: skip
        summary["motion"] = {
            "d_los_rms_m": float(np.sqrt(np.mean(m["d_los_m"] ** 2))),
            "d_los_peak_to_peak_m": float(np.ptp(m["d_los_m"])),
        }
    if "autofocus" in store.tables() and store.committed("autofocus"):
        a = store.read("autofocus", ["t_center_s", "a_y_mps2", "a_z_mps2", "kappa"])
        plot_series(a["t_center_s"], {"a_y (m/s²)": a["a_y_mps2"], "a_z (m/s²)": a["a_z_mps2"],
                                       "κ0 (Hz/s)": a["kappa"][:, 0]},
                    out_dir / "autofocus.png", "autofocus estimates per subaperture")  # fmt: skip
        summary["autofocus"] = {"subapertures": int(a["t_center_s"].shape[0])}
    (out_dir / "report.json").write_text(json.dumps(summary, indent=2, default=float))
    (out_dir / "report.txt").write_text(_text(summary))
    return summary


def _text(summary: dict[str, Any]) -> str:
    run = summary.get("run", {})
    state = "complete" if summary["complete"] else "INCOMPLETE"
    lines = [
        f"store            {summary['store']} ({state})",
        f"pulses           {summary['pulses_committed']} recorded, "
        f"{run.get('pulses_processed', '?')} focused, "
        f"{run.get('pulses_nav_flagged', '?')} flagged for navigation",
        f"INS samples      {run.get('nav_samples', '?')}",
    ]
    if "motion" in summary:
        mo = summary["motion"]
        lines.append(f"d_los            rms {mo['d_los_rms_m']:.3f} m, "
                     f"peak-to-peak {mo['d_los_peak_to_peak_m']:.3f} m")  # fmt: skip
    if "image" in summary:
        im = summary["image"]
        lines.append(f"image            {im['shape'][0]} x {im['shape'][1]} px, entropy "
                     f"{im['entropy']:.3f}, contrast {im['contrast']:.3f}")  # fmt: skip
        lines.append("brightest points  x (m)    y (m)   PSLR az/rg (dB)   IRW az/rg (m)")
        for p in im["points"]:
            lines.append(
                f"                 {p['x_m']:7.2f} {p['y_m']:8.2f}   {p['pslr_az_db']:6.2f} "
                f"{p['pslr_rg_db']:6.2f}     {p['irw_az_m']:.3f} {p['irw_rg_m']:.3f}"
            )
    return "\n".join(lines) + "\n"
