"""Report of an array run: its DEMs against the true terrain (the paper's Table 2).

``sarmoco report RUN.zarr --truth DIR/truth.json --json`` compares each DEM product of the
store (``compensated``: roll compensated; ``uncompensated``: imaged as if the wing were
level) with the true terrain (:class:`TrueTerrain`, read by the command from a simulated
run's ``truth.json``):

- registration: the store's DEMs sit in a frame whose origin is the INS reference point at
  the first imaged pulse, ``geometry.height_m`` above the height datum
  (:mod:`sarmoco.daemon.array_pipeline`); the truth's reference point at that pulse time
  moves the truth into that frame, north, east and height (the INS gives no absolute
  position, as for the single-channel tiles; the sim's ``geometry.height_m`` is the flight
  above the terrain's mean, so the datum is that mean);
- the truth is cut to the scene (its imaged strip along track, the swath
  ``|east| <= scene_half_width_m`` across) and the statistics of imaged minus true height
  are :func:`sarmoco.processing.array.dem.evaluate_dem`'s: mean, standard deviation, the
  share of cells within half a height resolution cell ``c / 4B`` (the paper's bar), the
  range [min, max], and the coverage (the share of the scene's cells the DEM has a
  height for);
- a plot ``dem.png``: the true DEM, the imaged (compensated) DEM, and both differences.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from matplotlib.figure import Figure

from sarmoco.errors import DataFileError, ProcessingError, RecorderError
from sarmoco.processing.array.dem import DemStats, evaluate_dem, truth_on_product
from sarmoco.processing.array.imaging3d import DemProduct
from sarmoco.processing.types import FloatArray
from sarmoco.store.reader import RunStore

DEM_PRODUCTS = {"dem": "compensated", "dem_uncompensated": "uncompensated"}
"""Report key of each DEM product of the store."""
PLOT_FILE = "dem.png"


@dataclass(frozen=True)
class TrueTerrain:
    """The true terrain of a scene and the true track of the reference point over it.

    Attributes
    ----------
    height_m : ndarray, shape (n_north, n_east)
        True heights (up) above the terrain's mean, m.
    spacing_m : float
        Spacing of the height samples, north and east, m.
    origin_ne_m : tuple of 2 float
        North and east of sample ``[0, 0]`` in the scene's local NED frame, m.
    scene_north_m : tuple of 2 float
        The imaged strip along track: first and last north, m.
    scene_half_width_m : float
        Half width of the imaged swath across track (``|east|``), m.
    t_ns : ndarray of int64, shape (P,)
        GPS times of the track's samples on the store's time base, ns, increasing.
    pos_ned : ndarray, shape (P, 3)
        True reference point positions at those times, the scene's local NED frame, m.
    source : str
        Where the truth was read from, for messages (e.g. ``--truth PATH``).
    """

    height_m: FloatArray
    spacing_m: float
    origin_ne_m: tuple[float, float]
    scene_north_m: tuple[float, float]
    scene_half_width_m: float
    t_ns: npt.NDArray[np.int64]
    pos_ned: FloatArray
    source: str


@dataclass(frozen=True)
class TruthDem:
    """The true terrain of the scene, in the frame of one DEM product.

    Attributes
    ----------
    height_m : ndarray, shape (n_north, n_east)
        True heights (up) over the scene (the truth's strip along track, the swath across)
        above the product's datum, m.
    north_m, east_m : ndarray
        The samples' north and east in the product's frame (registered), m.
    """

    height_m: FloatArray
    north_m: FloatArray
    east_m: FloatArray


def truth_for(dem: DemProduct, truth: TrueTerrain) -> TruthDem:
    """The truth's scene registered onto ``dem``'s frame by the first imaged pulse."""
    h = truth.height_m
    dx = truth.spacing_m
    n0, e0 = truth.origin_ne_m
    north = n0 + dx * np.arange(h.shape[0])
    east = e0 + dx * np.arange(h.shape[1])
    lo, hi = truth.scene_north_m
    rows = (north >= lo) & (north <= hi)
    cols = np.abs(east) <= truth.scene_half_width_m
    pulses_t = truth.t_ns
    pulses_pos = truth.pos_ned
    since = (pulses_t - pulses_t[0]).astype(np.float64)
    t0 = float(dem.track.t0_ns - pulses_t[0])
    off = [np.interp(t0, since, pulses_pos[:, i]) - dem.track.origin_ned[i] for i in range(3)]
    # NED down of the DEM's frame = the truth's minus off[2]: heights (up) plus off[2]
    return TruthDem(h[np.ix_(rows, cols)] + off[2], north[rows] - off[0], east[cols] - off[1])


@dataclass(frozen=True)
class DemSummary:
    """One DEM product of the store against the truth.

    Attributes
    ----------
    stats : DemStats
        Its statistics over the scene.
    blocks : (int, int)
        The product's ΔR2 sub-blocks along k_x and k_y.
    """

    stats: DemStats
    blocks: tuple[int, int]

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: the statistics' fields and ``blocks`` (a two-element list)."""
        return self.stats.as_dict() | {"blocks": list(self.blocks)}


@dataclass(frozen=True)
class DemReport:
    """What :func:`dem_report` measured and drew.

    Attributes
    ----------
    dem : DemSummary
        The roll-compensated DEM.
    dem_uncompensated : DemSummary or None
        The DEM imaged as if the wing were level, when the store recorded it.
    plot : Path
        ``dem.png``.
    """

    dem: DemSummary
    dem_uncompensated: DemSummary | None
    plot: Path

    def products(self) -> dict[str, DemSummary]:
        """The recorded products by report key (the fields :data:`DEM_PRODUCTS` names)."""
        return {key: p for key in DEM_PRODUCTS if (p := getattr(self, key)) is not None}

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: a key per DEM product recorded, then ``plot``."""
        out: dict[str, object] = {key: p.as_dict() for key, p in self.products().items()}
        return out | {"plot": str(self.plot)}


def dem_report(store: RunStore, truth: TrueTerrain, out_dir: Path) -> DemReport:
    """Statistics of every DEM product of ``store`` against the truth, and ``dem.png``.

    Raises
    ------
    RecorderError
        The store holds no compensated DEM (not an array run).
    DataFileError
        The truth shares no cell with the DEM.
    """
    products: dict[str, DemSummary] = {}
    panels: list[tuple[str, DemProduct, FloatArray, FloatArray]] = []
    for key, name in DEM_PRODUCTS.items():
        try:
            dem, resolution = store.dem(name)
        except RecorderError:
            if name == "compensated":
                raise
            continue
        t = truth_for(dem, truth)
        try:
            stats = evaluate_dem(dem, t.height_m, t.north_m, t.east_m, 0.5 * resolution)
        except ProcessingError as exc:
            raise DataFileError(f"{truth.source}: {name} DEM: {exc}") from exc
        products[key] = DemSummary(stats, dem.blocks)
        truth_h = truth_on_product(dem, t.height_m, t.north_m, t.east_m)
        panels.append((name, dem, truth_h, dem.height_m - truth_h))
    out_dir.mkdir(parents=True, exist_ok=True)
    plot = _plot(panels, out_dir / PLOT_FILE)
    return DemReport(products["dem"], products.get("dem_uncompensated"), plot)


def _plot(panels: list[tuple[str, DemProduct, FloatArray, FloatArray]], path: Path) -> Path:
    """True DEM, imaged DEM (compensated) and each product's difference, on imaging axes."""
    name, dem, truth_h, _ = panels[0]
    extent = (float(dem.y_m[0]), float(dem.y_m[-1]), float(dem.x_m[-1]), float(dem.x_m[0]))
    lo, hi = float(np.nanmin(truth_h)), float(np.nanmax(truth_h))
    shown = [
        ("true DEM (m)", truth_h, "terrain", (lo, hi)),
        (f"imaged, {name} (m)", dem.height_m, "terrain", (lo, hi)),
    ]
    for label, _, _, diff in panels:
        lim = (
            max(1.0, float(np.nanpercentile(np.abs(diff), 99))) if np.isfinite(diff).any() else 1.0
        )
        shown.append((f"imaged - true, {label} (m)", diff, "RdBu_r", (-lim, lim)))
    fig = Figure(figsize=(4.0 * len(shown), 4.0), layout="constrained")
    for i, (title, data, cmap, (vmin, vmax)) in enumerate(shown):
        ax = fig.add_subplot(1, len(shown), i + 1)
        im = ax.imshow(data, extent=extent, cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("cross-track y (m)")
        if i == 0:
            ax.set_ylabel("along-track x (m)")
        fig.colorbar(im, ax=ax, shrink=0.8)
    fig.savefig(path, dpi=100)
    return path


def is_array_store(store: RunStore) -> bool:
    """Whether ``store`` was written in array mode (its configuration's ``radar.mode``)."""
    config = store.attrs.get("config", {})
    radar = config.get("radar", {}) if isinstance(config, dict) else {}
    return isinstance(radar, dict) and radar.get("mode") == "array"


@dataclass(frozen=True)
class ArrayRunSummary:
    """The summary of an array run (``report.json``).

    Attributes
    ----------
    store : str
        The store's path.
    complete : bool
        Whether the run closed its store.
    run : dict
        The run's metrics, as the store records them.
    dems : DemReport or None
        The DEMs against the truth, when a truth was given.
    """

    store: str
    complete: bool
    run: dict[str, Any]
    dems: DemReport | None

    def as_dict(self) -> dict[str, object]:
        """The JSON document: ``store``, ``complete``, ``run``, then :meth:`DemReport.as_dict`'s
        keys."""
        out: dict[str, object] = {"store": self.store, "complete": self.complete, "run": self.run}
        return out if self.dems is None else out | self.dems.as_dict()


def write_array_report(
    store: RunStore, out_dir: Path, truth: TrueTerrain | None
) -> ArrayRunSummary:
    """The summary of an array run (``report.json`` in ``out_dir``); with a truth, the DEM
    statistics and plot of :func:`dem_report`."""
    attrs = store.attrs
    summary = ArrayRunSummary(
        store=str(store.path),
        complete=bool(attrs.get("complete", False)),
        run=attrs.get("metrics", {}),
        dems=None if truth is None else dem_report(store, truth, out_dir),
    )
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "report.json").write_text(json.dumps(summary.as_dict(), indent=1))
    return summary


def summary_text(summary: ArrayRunSummary) -> str:
    """A few lines for the terminal: per DEM product its statistics against the truth."""
    lines = [f"{summary.store}: array run, {summary.run.get('pulses_imaged', 0)} pulses imaged"]
    for key, product in ({} if summary.dems is None else summary.dems.products()).items():
        s = product.stats
        lines.append(
            f"{key}: mean {s.mean_m:+.3f} m, std {s.std_m:.3f} m, "
            f"{100 * s.within_half_cell:.2f} % within {s.half_cell_m:.2f} m, "
            f"range [{s.range_m[0]:.2f}, {s.range_m[1]:.2f}] m, "
            f"coverage {100 * s.coverage:.1f} %"
        )
    return "\n".join(lines) + "\n"
