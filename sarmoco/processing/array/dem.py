"""Evaluation of an imaged DEM against the true terrain (the array paper's Table 2).

The imaged DEM minus the truth, over the cells where both exist: mean, standard deviation,
the share of cells whose error is within half a resolution cell, and the error range. The
cell is the paper's height resolution, the slant-range resolution c / 2B (1 m at 150 MHz,
so the bar is |error| <= 0.5 m): near nadir height is measured by range.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from sarmoco.errors import ProcessingError
from sarmoco.processing.array.imaging3d import DemProduct
from sarmoco.processing.types import FloatArray


@dataclass(frozen=True)
class DemStats:
    """Error statistics of an imaged DEM (imaged minus true height), m.

    Parameters
    ----------
    mean_m, std_m : float
        Mean and standard deviation of the error, m.
    within_half_cell : float
        Fraction (0..1) of compared cells with |error| <= ``half_cell_m``.
    range_m : (float, float)
        Smallest and largest error, m.
    half_cell_m : float
        Half the height resolution used as the bar, m.
    n_cells : int
        Number of cells compared.
    coverage : float
        Fraction of the product's cells inside the truth that carry a height.
    """

    mean_m: float
    std_m: float
    within_half_cell: float
    range_m: tuple[float, float]
    half_cell_m: float
    n_cells: int
    coverage: float

    def as_dict(self) -> dict[str, object]:
        """JSON-ready dict (``range_m`` as a two-element list)."""
        out = asdict(self)
        out["range_m"] = list(self.range_m)
        return out


def truth_on_product(
    product: DemProduct, truth_height_m: FloatArray, north_m: FloatArray, east_m: FloatArray
) -> FloatArray:
    """True heights at the product's cells, (n_x, n_y), bilinear; NaN outside the truth grid.

    Parameters
    ----------
    product : DemProduct
        The imaged DEM (its cells are placed in NED through its track).
    truth_height_m : ndarray, shape (n_north, n_east)
        True heights (up), m.
    north_m, east_m : ndarray, shape (n_north,), (n_east,)
        Increasing NED north and east of the truth samples, m.
    """
    h = np.asarray(truth_height_m, dtype=np.float64)
    if h.shape != (np.size(north_m), np.size(east_m)):
        raise ProcessingError(
            f"truth_on_product: truth shape {h.shape} does not match axes "
            f"({np.size(north_m)}, {np.size(east_m)})"
        )
    interp = RegularGridInterpolator(
        (np.asarray(north_m, dtype=np.float64), np.asarray(east_m, dtype=np.float64)),
        h, bounds_error=False, fill_value=np.nan,
    )  # fmt: skip
    return np.asarray(interp(product.points_ned()), dtype=np.float64)


def height_errors(
    product: DemProduct,
    truth_height_m: FloatArray,
    north_m: FloatArray,
    east_m: FloatArray,
    margin_m: float = 0.0,
) -> tuple[FloatArray, np.ndarray]:
    """Imaged minus true height per product cell, and where the truth exists.

    Parameters
    ----------
    product, truth_height_m, north_m, east_m
        As :func:`truth_on_product`.
    margin_m : float
        Cells closer than this to the truth's border count as outside it, m (the terrain's
        edge is a cliff to the zero-reflectivity outside).

    Returns
    -------
    errors : ndarray of float64, shape (n_x, n_y)
        Imaged minus true height, m; NaN where either is missing.
    in_truth : ndarray of bool, shape (n_x, n_y)
        Cells inside the truth (less the margin).
    """
    truth = truth_on_product(product, truth_height_m, north_m, east_m)
    if margin_m > 0.0:
        ne = product.points_ned()
        n0, n1 = float(np.min(north_m)) + margin_m, float(np.max(north_m)) - margin_m
        e0, e1 = float(np.min(east_m)) + margin_m, float(np.max(east_m)) - margin_m
        inside = (ne[..., 0] >= n0) & (ne[..., 0] <= n1) & (ne[..., 1] >= e0) & (ne[..., 1] <= e1)
        truth = np.where(inside, truth, np.nan)
    return np.asarray(product.height_m - truth, dtype=np.float64), np.isfinite(truth)


def error_stats(errors: FloatArray, in_truth: np.ndarray, half_cell_m: float) -> DemStats:
    """The statistics of the finite cells of ``errors`` (coverage against ``in_truth``).

    Raises
    ------
    ProcessingError
        If no cell is finite.
    """
    both = np.isfinite(errors) & in_truth
    if not np.any(both):
        raise ProcessingError("DEM evaluation: the imaged DEM and the truth share no cell")
    err = errors[both]
    return DemStats(
        mean_m=float(np.mean(err)),
        std_m=float(np.std(err)),
        within_half_cell=float(np.mean(np.abs(err) <= half_cell_m)),
        range_m=(float(np.min(err)), float(np.max(err))),
        half_cell_m=float(half_cell_m),
        n_cells=int(err.size),
        coverage=float(err.size / np.count_nonzero(in_truth)),
    )


def evaluate_dem(
    product: DemProduct,
    truth_height_m: FloatArray,
    north_m: FloatArray,
    east_m: FloatArray,
    half_cell_m: float,
    margin_m: float = 0.0,
) -> DemStats:
    """Imaged minus true height over the cells where both exist (module docstring).

    Parameters
    ----------
    product : DemProduct
        The imaged DEM.
    truth_height_m, north_m, east_m
        The truth (see :func:`truth_on_product`).
    half_cell_m : float
        Half the height resolution, m (``ArraySystem.height_resolution_m / 2``).
    margin_m : float
        Cells closer than this to the truth's border are left out, m.

    Raises
    ------
    ProcessingError
        If no cell can be compared.
    """
    errors, in_truth = height_errors(product, truth_height_m, north_m, east_m, margin_m)
    return error_stats(errors, in_truth, half_cell_m)
