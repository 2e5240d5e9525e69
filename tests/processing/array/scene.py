"""Scaled array-paper scenes shared by the array tests: terrain, strip, echoes, truth."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sarmoco.processing.array.dem import DemStats, error_stats, height_errors
from sarmoco.processing.array.imaging3d import Array3dOptions, ArraySystem, DemProduct, form_dem
from sarmoco.processing.array.paper import PAPER_SPEED_MPS, paper_system
from sarmoco.sim.array_echo import ArrayStrip, peaks_dem, simulate_strip

SPACING_M = 0.5


@dataclass
class Scene:
    """Echoes of a strip over a DEM and everything needed to image and score it."""

    system: ArraySystem
    height_m: np.ndarray
    north_m: np.ndarray
    east_m: np.ndarray
    strip: ArrayStrip
    strip_north_m: tuple[float, float]

    @property
    def t_ns(self) -> np.ndarray:
        """Pulse times, GPS ns."""
        return self.strip.t_ns

    def image(
        self,
        quat: np.ndarray | None = None,
        compensate_attitude: bool = True,
        blocks: tuple[int, int] = (1, 8),
    ) -> DemProduct:
        """The DEM imaged with ``quat`` (default: the true attitude), default options otherwise."""
        s = self.strip
        att = s.quat if quat is None else quat
        opt = Array3dOptions(compensate_attitude=compensate_attitude, blocks=blocks)
        return form_dem(s.echoes, s.t_ns, s.pos_ned, att, self.system, opt)

    def errors(self, product: DemProduct) -> tuple[np.ndarray, np.ndarray]:
        """Imaged minus true height inside the strip, 2 m off the terrain's border, and the
        cells of the strip inside the truth."""
        err, in_truth = height_errors(
            product, self.height_m, self.north_m, self.east_m, margin_m=2.0
        )
        north = product.points_ned()[..., 0]
        lo, hi = self.strip_north_m
        in_strip = in_truth & (north >= lo) & (north <= hi)
        return np.where(in_strip, err, np.nan), in_strip

    def stats(self, product: DemProduct) -> DemStats:
        """The paper's statistics over the strip."""
        return error_stats(*self.errors(product), self.system.height_resolution_m / 2.0)


def band_bias(scene: Scene, product: DemProduct, y_min: float, y_max: float, side: int) -> float:
    """Mean height error of the cells with y_min <= side * y < y_max (side ±1), m."""
    err = scene.errors(product)[0]
    y = side * product.y_m
    sel = (y >= y_min) & (y < y_max)
    return float(np.nanmean(err[:, sel]))


def simulate(
    n_rx: int,
    width_m: float,
    strip_m: float,
    roll_rad: float | Callable[[np.ndarray], np.ndarray],
    height_scale: float = 1.0,
    altitude_m: float = 200.0,
    seed: int = 1,
) -> Scene:
    """A strip of ``strip_m`` across the middle of a ``width_m`` square peaks terrain.

    ``roll_rad`` is the true roll, rad: a constant, or a function of the time since the first
    pulse (s) giving one value per pulse.
    """
    n = round(width_m / SPACING_M) + 1
    h = peaks_dem(n, n) * height_scale
    north = np.arange(n) * SPACING_M
    east = (np.arange(n) - (n - 1) / 2.0) * SPACING_M
    system = paper_system(float(h.min()), float(h.max()), altitude_m=altitude_m, n_rx=n_rx)
    x0 = width_m / 2.0 - strip_m / 2.0
    strip = simulate_strip(
        system.radar, system.layout, system.antenna_length_m, system.max_look_rad,
        PAPER_SPEED_MPS, h, SPACING_M, (north[0], east[0]), altitude_m,
        (x0, x0 + strip_m), roll_rad, seed=seed,
    )  # fmt: skip
    return Scene(system, h, north, east, strip, (x0, x0 + strip_m))
