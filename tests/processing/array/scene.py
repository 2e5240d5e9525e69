"""Scaled array-paper scenes shared by the array tests: terrain, strip, echoes, truth."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from sarmoco.processing.array.dem import DemStats, evaluate_dem, truth_on_product
from sarmoco.processing.array.imaging3d import Array3dOptions, ArraySystem, DemProduct, form_dem
from sarmoco.processing.array.paper import PAPER_SPEED_MPS, paper_system
from sarmoco.sim.array_echo import level_strip, peaks_dem, synthesize_array, terrain_scatterers

SPACING_M = 0.5


@dataclass
class Scene:
    """Echoes of a strip over a DEM and everything needed to image and score it."""

    system: ArraySystem
    height_m: np.ndarray
    north_m: np.ndarray
    east_m: np.ndarray
    t_ns: np.ndarray
    pos_ned: np.ndarray
    quat: np.ndarray
    echoes: np.ndarray
    strip_north_m: tuple[float, float]

    def image(
        self,
        quat: np.ndarray | None = None,
        compensate_attitude: bool = True,
        blocks: tuple[int, int] = (1, 8),
    ) -> DemProduct:
        """The DEM imaged with ``quat`` (default: the true attitude), default options otherwise."""
        att = self.quat if quat is None else quat
        opt = Array3dOptions(compensate_attitude=compensate_attitude, blocks=blocks)
        return form_dem(self.echoes, self.t_ns, self.pos_ned, att, self.system, opt)

    def errors(self, product: DemProduct) -> np.ndarray:
        """Imaged minus true height on the product grid inside the strip, NaN elsewhere."""
        truth = truth_on_product(product, self.height_m, self.north_m, self.east_m)
        north = product.points_ned()[..., 0]
        lo, hi = self.strip_north_m
        edge = float(np.max(np.abs(self.east_m))) - 2.0
        keep = (north >= lo) & (north <= hi) & (np.abs(product.points_ned()[..., 1]) <= edge)
        return np.where(keep, product.height_m - truth, np.nan)

    def stats(self, product: DemProduct) -> DemStats:
        """The paper's statistics over the whole product (2 m off the terrain's border)."""
        return evaluate_dem(
            product, self.height_m, self.north_m, self.east_m,
            self.system.height_resolution_m / 2.0, margin_m=2.0,
        )  # fmt: skip


def band_bias(scene: Scene, product: DemProduct, y_min: float, y_max: float, side: int) -> float:
    """Mean height error of the cells with y_min <= side * y < y_max (side ±1), m."""
    err = scene.errors(product)
    y = side * product.y_m
    sel = (y >= y_min) & (y < y_max)
    e = err[:, sel]
    return float(np.nanmean(e))


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
    rng = np.random.default_rng(seed)
    targets, amp = terrain_scatterers(h, SPACING_M, (north[0], east[0]), 2, rng)
    half_ap = aperture_m(system, altitude_m) / 2.0
    x0 = width_m / 2.0 - strip_m / 2.0
    keep = (targets[:, 0] >= x0 - half_ap) & (targets[:, 0] <= x0 + strip_m + half_ap)
    n_p = n_pulses(system, altitude_m, strip_m)
    roll = roll_rad(np.arange(n_p) / system.radar.prf_hz) if callable(roll_rad) else roll_rad
    t, pos, quat = level_strip(
        n_p, system.radar.prf_hz, PAPER_SPEED_MPS, altitude_m, x0 - half_ap, roll
    )
    echoes = synthesize_array(
        system.radar, system.layout, pos, quat, targets[keep], amp[keep],
        system.antenna_length_m, system.max_look_rad,
    )  # fmt: skip
    return Scene(system, h, north, east, t, pos, quat, echoes, (x0, x0 + strip_m))


def aperture_m(system: ArraySystem, altitude_m: float) -> float:
    """Along-track extent over which a point on the terrain is seen, m (main lobe, far edge)."""
    far = altitude_m / math.cos(system.max_look_rad) + 10.0
    return 2.0 * far * system.radar.wavelength_m / system.antenna_length_m


def n_pulses(system: ArraySystem, altitude_m: float, strip_m: float) -> int:
    """Pulses of a strip plus one aperture."""
    step = PAPER_SPEED_MPS / system.radar.prf_hz
    return int((strip_m + aperture_m(system, altitude_m)) / step) + 1
