"""Weighted least squares on the line rates of one subaperture (docs/methods.md §3 steps 2 and 3).

Envelope step: ``Δγ_i = (2/λ)(a_y sin β_i + a_z cos β_i)``. In the frame of docs/methods.md §1 (y to
the scene, z down) the APC deviation shortens the range by d_los, the echo gains the phase
``+4π d_los/λ`` and the rate ``(2/λ) d''_los``; the sign is checked against a simulated target
in the tests (the paper prints the opposite sign for its own axes). Note that over flat ground
``cos β = H/R``, so an along-track speed error (rate ``∝ 1/R``) is indistinguishable from a_z.

Phase step: ``Δγ(Δd) = κ0 + κ1 Δd + κ2 Δd²`` with ``Δd = R - R_c``.
"""

from __future__ import annotations

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.types import FloatArray


def look_angle(range_m: FloatArray, depth_m: float) -> FloatArray:
    """Off-nadir look angle β of slant range r over flat ground, ``cos β = H / r``, rad."""
    r = np.asarray(range_m, dtype=float)
    if np.any(r < depth_m):
        raise ProcessingError(f"look_angle: slant range {r.min():.3f} m is below depth {depth_m} m")
    return np.asarray(np.arccos(depth_m / r), dtype=float)


def weighted_lstsq(
    design: FloatArray, rates: FloatArray, weights: FloatArray, reject_sigma: float = 3.0
) -> tuple[FloatArray, float]:
    """Solve ``X = (Hᵀ W H)⁻¹ Hᵀ W D`` (minimum norm if rank deficient).

    After a first solve, lines whose residual exceeds ``reject_sigma`` robust standard
    deviations (1.4826 MAD) are given zero weight and the system is solved again.

    Returns the solution and the weighted RMS residual of the kept lines (units of ``rates``).
    """
    w = np.clip(np.asarray(weights, dtype=float), 0.0, None)
    if w.sum() <= 0 or design.shape[0] != rates.shape[0]:
        raise ProcessingError(
            f"weighted_lstsq: {design.shape[0]} rows, {rates.shape[0]} rates, "
            f"weight sum {w.sum():.3g}: nothing to fit"
        )
    for _ in range(2):
        sw = np.sqrt(w)
        x = np.linalg.lstsq(design * sw[:, None], rates * sw, rcond=None)[0]
        res = rates - design @ x
        kept = np.abs(res[w > 0])
        spread = 1.4826 * float(np.median(kept)) if kept.size > design.shape[1] + 1 else np.inf
        outlier = np.abs(res) > reject_sigma * max(spread, 1e-12)
        if not np.any(outlier & (w > 0)):
            break
        w = np.where(outlier, 0.0, w)
    return x, float(np.sqrt(np.sum(w * res**2) / w.sum()))


def acceleration_design(range_m: FloatArray, depth_m: float, wavelength_m: float) -> FloatArray:
    """Rows ``(2/λ)[sin β_i, cos β_i]`` mapping (a_y, a_z) in m/s² to rate errors in Hz/s."""
    beta = look_angle(range_m, depth_m)
    return (2.0 / wavelength_m) * np.column_stack([np.sin(beta), np.cos(beta)])


def fit_accelerations(
    range_m: FloatArray,
    rates: FloatArray,
    weights: FloatArray,
    depth_m: float,
    wavelength_m: float,
) -> tuple[tuple[float, float], float]:
    """Cross-track accelerations (a_y, a_z), m/s², and the weighted RMS residual, Hz/s."""
    x, res = weighted_lstsq(acceleration_design(range_m, depth_m, wavelength_m), rates, weights)
    return (float(x[0]), float(x[1])), res


def fit_range_polynomial(
    range_m: FloatArray,
    rates: FloatArray,
    weights: FloatArray,
    ref_range_m: float,
    order: int,
) -> tuple[FloatArray, float]:
    """κ0..κ2 of the rate error against ``Δd = R - R_c`` (orders above ``order`` are zero).

    The order is lowered until at least two more lines than coefficients are used: an exact
    quadratic through three noisy lines swings the rate by several Hz/s at the swath edges
    (measured on a three-target scene, where it made the focus worse than no autofocus).
    """
    if order not in (0, 1, 2):
        raise ProcessingError(f"fit_range_polynomial: order {order!r} is not 0, 1 or 2")
    dd = np.asarray(range_m, dtype=float) - ref_range_m
    usable = min(order, int(np.count_nonzero(np.asarray(weights) > 0)) - 3)
    kappa = np.zeros(3)
    usable = max(usable, 0)
    design = np.column_stack([dd**p for p in range(usable + 1)])
    x, res = weighted_lstsq(design, rates, weights)
    kappa[: usable + 1] = x
    return kappa, res
