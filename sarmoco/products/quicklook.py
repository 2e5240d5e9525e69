"""Quicklook PNGs for an operator: the image in dB, the motion solution, autofocus estimates.

Drawn with matplotlib's object API (``Figure``, no pyplot state, no display), in the
intensity scale of :mod:`sarmoco.grayscale`. Axes are in metres and seconds.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from sarmoco.grayscale import DYNAMIC_RANGE_DB, intensity_db


def _nice_length(span_m: float) -> float:
    """A 1-2-5 length close to a fifth of ``span_m`` (for the scale bar), m."""
    target = span_m / 5.0
    exponent = np.floor(np.log10(target))
    for mult in (1.0, 2.0, 5.0, 10.0):
        if mult * 10**exponent >= target:
            return float(mult * 10**exponent)
    return float(10 ** (exponent + 1))


def plot_image(
    data: npt.NDArray[np.generic],
    axis0_m: npt.NDArray[np.float64],
    axis1_m: npt.NDArray[np.float64],
    path: Path,
    title: str,
    axis_names: tuple[str, str] = ("along-track x (m)", "cross-track / range (m)"),
) -> Path:
    """Write a complex image as a dB quicklook with metre axes and a scale bar.

    Parameters
    ----------
    data : ndarray, shape (n0, n1)
        Complex or magnitude image; axis 0 is plotted vertically.
    axis0_m, axis1_m : ndarray
        Pixel-centre coordinates, m.
    path : Path
        PNG to write.
    title : str
        Figure title.
    axis_names : tuple of str
        Labels of axis 0 and axis 1.
    """
    power = np.abs(np.asarray(data)) ** 2
    peak = float(power.max()) if power.size and power.max() > 0 else 1.0
    db = 10.0 * np.log10(np.maximum(power / peak, 10 ** (-DYNAMIC_RANGE_DB / 10)))
    fig = Figure(figsize=(7, 6), dpi=110)
    ax = fig.subplots()
    extent = (float(axis1_m[0]), float(axis1_m[-1]), float(axis0_m[0]), float(axis0_m[-1]))
    im = ax.imshow(
        db,
        origin="lower",
        extent=extent,
        cmap="gray",
        vmin=-DYNAMIC_RANGE_DB,
        vmax=0.0,
        aspect="equal",
        interpolation="nearest",
    )
    fig.colorbar(im, ax=ax, label="intensity (dB re peak)")
    bar = _nice_length(extent[1] - extent[0])
    x0 = extent[0] + 0.05 * (extent[1] - extent[0])
    y0 = extent[2] + 0.05 * (extent[3] - extent[2])
    ax.plot([x0, x0 + bar], [y0, y0], color="yellow", linewidth=3)
    ax.text(x0 + bar / 2, y0, f"{bar:g} m", color="yellow", ha="center", va="bottom")
    ax.set_xlabel(axis_names[1])
    ax.set_ylabel(axis_names[0])
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    return path


def plot_series(
    t_s: npt.NDArray[np.float64],
    series: Mapping[str, npt.NDArray[np.float64]],
    path: Path,
    title: str,
) -> Path:
    """Plot named time series one panel each (label carries the unit), against time in s.

    Parameters
    ----------
    t_s : ndarray
        Time axis, s from the start of the run.
    series : mapping of str to ndarray
        Panel label (with unit, e.g. ``"d_los (m)"``) to values, same length as ``t_s``; a
        series of fewer than 50 points is drawn with markers.
    path : Path
        PNG to write.
    title : str
        Figure title.
    """
    return _stacked({label: {"": (t_s, v)} for label, v in series.items()}, path, title, 2.0)


def plot_overlays(
    panels: Mapping[str, Mapping[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]],
    path: Path,
    title: str,
) -> Path:
    """Several named curves per panel, each on its own time axis, one panel per quantity.

    Parameters
    ----------
    panels : mapping of str to mapping of str to (ndarray, ndarray)
        Panel label (with unit) to curve name to (time s, values); a curve of fewer than
        50 points is drawn with markers (e.g. one value per autofocus subaperture).
    path : Path
        PNG to write.
    title : str
        Figure title.
    """
    return _stacked(panels, path, title, 2.3)


def _stacked(
    panels: Mapping[str, Mapping[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]],
    path: Path,
    title: str,
    panel_in: float,
) -> Path:
    """Panels stacked on a shared time axis (s), ``panel_in`` inches tall each; curves with
    an empty name get no legend entry."""
    n = max(len(panels), 1)
    fig = Figure(figsize=(8, panel_in * n + 0.8), dpi=100)
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)
    for ax, (label, curves) in zip(axes[:, 0], panels.items(), strict=False):
        for name, (t, v) in curves.items():
            style = "o-" if len(t) < 50 else "-"
            ax.plot(t, v, style, linewidth=0.9, markersize=3, label=name or None)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        if any(curves):
            ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].set_title(title)
    fig.tight_layout()
    fig.savefig(path)
    return path


def plot_panels(
    panels: Mapping[str, npt.NDArray[np.generic]],
    axis0_m: npt.NDArray[np.float64],
    axis1_m: npt.NDArray[np.float64],
    path: Path,
    title: str,
) -> Path:
    """Write images of one grid side by side on one dB scale (re the brightest pixel of all).

    Parameters
    ----------
    panels : mapping of str to ndarray, each shape (n0, n1)
        Panel title to complex (or magnitude) image; axis 0 (along track) is vertical.
    axis0_m, axis1_m : ndarray
        Pixel-centre coordinates shared by the panels, m.
    path : Path
        PNG to write.
    title : str
        Figure title.
    """
    peak = max(float(np.max(np.abs(p)) ** 2) for p in panels.values()) or 1.0
    fig = Figure(figsize=(3.2 * len(panels) + 1.2, 4.2), dpi=110)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    extent = (float(axis1_m[0]), float(axis1_m[-1]), float(axis0_m[0]), float(axis0_m[-1]))
    im = None
    for ax, (name, data) in zip(axes, panels.items(), strict=True):
        im = ax.imshow(intensity_db(data, peak), origin="lower", extent=extent, cmap="gray",
                       vmin=-DYNAMIC_RANGE_DB, vmax=0.0, aspect="equal",
                       interpolation="nearest")  # fmt: skip
        ax.set_title(name)
        ax.set_xlabel("ground range y (m)")
    axes[0].set_ylabel("along-track x (m)")
    if im is not None:
        fig.colorbar(im, ax=list(axes), label="intensity (dB re brightest panel)")
    fig.suptitle(title)
    fig.savefig(path)
    return path


def plot_cuts(
    cuts: Mapping[str, Mapping[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.generic]]]],
    ideal: Mapping[str, tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]],
    path: Path,
    title: str,
) -> Path:
    """Cuts through a point target, one panel per direction, against the ideal response.

    Parameters
    ----------
    cuts : mapping of str to mapping of str to (ndarray, ndarray)
        Direction (panel title, e.g. ``"azimuth x (m)"``) to curve name to (coordinate m,
        complex or magnitude samples).
    ideal : mapping of str to (ndarray, ndarray)
        Direction to (coordinate m, amplitude re peak) of the ideal response.
    path : Path
        PNG to write.
    title : str
        Figure title.
    """
    fig = Figure(figsize=(10, 3.8), dpi=100)
    axes = fig.subplots(1, len(cuts), squeeze=False)[0]
    for ax, (direction, curves) in zip(axes, cuts.items(), strict=True):
        peak = max(float(np.max(np.abs(v)) ** 2) for _, v in curves.values()) or 1.0
        for name, (x, v) in curves.items():
            ax.plot(x, intensity_db(v, peak), linewidth=1.0, label=name)
        x, amp = ideal[direction]
        ax.plot(x, intensity_db(amp, 1.0), "k--", linewidth=0.9, label="ideal sinc")
        ax.set_xlabel(direction)
        ax.set_ylim(-DYNAMIC_RANGE_DB, 1.0)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("intensity (dB re peak)")
    axes[0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path)
    return path
