"""Backprojection's per-pixel squint residual (eq. 29, docs/methods.md §2) against a float64 sum.

The kernel adds ``k ΔY_p (sqrt(dx^2 + dy^2) - dy) / R`` to each pixel's phase, ``(dx, dy)``
the pixel's offset from the APC along the grid axes and ``R`` its range: checked here on a
rotated grid with APCs off the plane's axes, at 0.2 THz (k = 8400 rad/m) where the term is
several radians. The focusing it buys is tested through the daemon in tests/daemon/test_eq29.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging import PlaneGrid
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.types import ComplexArray, FloatArray

LAMBDA_M = 0.0015


def _direct_sum(
    lines: RangeLines, apc: FloatArray, grid: PlaneGrid, dy_m: FloatArray
) -> ComplexArray:
    """docs/methods.md §2's per-pixel residual, pixel by pixel in complex128."""
    pix = grid.positions()
    e0, e1 = grid.unit_vectors
    k = 4 * np.pi / LAMBDA_M
    out = np.zeros(pix.shape[:2], np.complex128)
    n = lines.data.shape[1]
    for p in range(apc.shape[0]):
        d = pix - apc[p]
        r = np.linalg.norm(d, axis=-1)
        dx, dy = d @ e0, d @ e1
        u = (r - lines.r_first_m) / lines.dr_m
        ok = (u >= 0) & (u < n - 1)
        j = np.clip(u.astype(np.int64), 0, n - 2)
        f = u - j
        v = lines.data[p, j] * (1 - f) + lines.data[p, j + 1] * f
        phase = k * r + k * dy_m[p] * (np.hypot(dx, dy) - dy) / r
        out += np.where(ok, v * np.exp(1j * phase), 0)
    return out


def _case() -> tuple[RangeLines, FloatArray, PlaneGrid, FloatArray]:
    rng = np.random.default_rng(3)
    n_p, n_s = 9, 64
    rc = rng.standard_normal((n_p, n_s, 2)).astype(np.float32).view(np.complex64)[..., 0]
    apc = np.column_stack(
        [np.linspace(-9.0, 9.0, n_p), rng.normal(0, 0.05, n_p), -60.0 + rng.normal(0, 0.05, n_p)]
    )
    grid = PlaneGrid.centred((0.3, 80.0, 0.0), 41, 57, 0.11, 0.37, heading_rad=0.05)
    lines = RangeLines.upsample(rc, 95.0 + 0.25 * np.arange(n_s, dtype=np.float64), 4)
    return lines, apc, grid, rng.normal(0.0, 0.5, n_p)


def test_kernel_removes_the_squint_residual_per_pixel() -> None:
    lines, apc, grid, dy = _case()
    got = np.zeros((41, 57), np.complex64)
    backproject_into(got, lines, apc, LAMBDA_M, grid, compensated_dy_m=dy)
    want = _direct_sum(lines, apc, grid, dy)
    assert np.max(np.abs(got - want)) < 2e-5 * np.max(np.abs(want))
    without = _direct_sum(lines, apc, grid, np.zeros_like(dy))
    assert np.max(np.abs(without - want)) > 0.3 * np.max(np.abs(want))  # the term is not small
    flipped = _direct_sum(lines, apc, grid, -dy)
    assert np.max(np.abs(flipped - want)) > 0.3 * np.max(np.abs(want))


@pytest.mark.parametrize("bad", [np.zeros(8), np.full(9, np.nan)])
def test_kernel_refuses_a_bad_displacement(bad: FloatArray) -> None:
    lines, apc, grid, _ = _case()
    out = np.zeros((41, 57), np.complex64)
    with pytest.raises(ProcessingError, match="compensated_dy_m"):
        backproject_into(out, lines, apc, LAMBDA_M, grid, compensated_dy_m=bad)
