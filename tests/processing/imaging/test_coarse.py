"""Tiles asked for pixels finer than the band: blocks formed on a coarser grid.

Point targets under a beam squinted by a 4° crab (an antenna fixed to the body), 0.05 m
pixels against 0.25 m of resolution: the tile imager forms the blocks on a grid twice as
coarse on both axes and interpolates onto the tiles. Over the first two blocks the beam
points where a body without crab would point it, not where the attitude says, and their
pixels take a beam widened by 4.5° on each side (the pointing uncertain): more band than
any coarse grid holds, so those blocks are formed on the tiles' own grid. The tiles must be
those formed wholly on the tiles' own grid: the same complex pixels about each target (one
of them 0.3 m from a tile's edge), so the same response and position.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sarmoco.processing.beam import centre_squint_rad, squint_interval_rad
from sarmoco.processing.imaging.coarse import (
    CoarseImage,
    add_upsampled,
    coarse_factors,
    coarse_grid,
)
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.tiles import Tile, TileImager, TileLayout
from sarmoco.processing.metrics import point_target_metrics
from tests.processing.imaging.test_squint import BEAM, DR, LAM, PRF, R0, RHO, TOL, H, V, _axis

YG = math.sqrt(R0**2 - H**2)
TARGETS = ((30.0, YG), (39.7, YG + 4.0))  # the second 0.3 m before tile 1 ends (x = 40 m)
OFF_DEG = -4.0
"""Over the first two blocks the beam points this much (of crab) off what the attitude says."""
WIDENED = math.radians(4.5)
"""Those blocks take a beam this much wider on each side, as while the pointing is
uncertain: more band than a coarse grid holds."""


def _tiles(factors: tuple[int, int] | None) -> dict[int, Tile]:
    axis = _axis(4.0, 1.0)
    psi_c = float(centre_squint_rad(axis, math.acos(H / R0)))
    n = 1400
    t = (np.arange(n) - n / 2) / PRF
    apc = np.column_stack([35.0 - R0 * math.sin(psi_c) + V * t, np.zeros(n), np.zeros(n)])
    r_axis = 860.0 + DR * np.arange(400)
    rc = np.zeros((n, r_axis.size), np.complex64)
    for x, y in TARGETS:
        d = np.array([x, y, H]) - apc
        r = np.linalg.norm(d, axis=1)
        off = np.arange(n) // 128 <= 1
        pointed = np.where(off[:, None], _axis(4.0 + OFF_DEG, 1.0)[None, :], axis[None, :])
        lit = np.abs(np.sum(d * pointed, axis=1)) <= r * math.sin(BEAM / 2)
        echo = np.sinc((r_axis[None, :] - r[:, None]) / RHO) * np.exp(
            -4j * np.pi * r[:, None] / LAM
        )
        rc += np.where(lit[:, None], echo, 0).astype(np.complex64)
    layout = TileLayout(H, YG, 16.0, 20.0, 0.05, BEAM + 2 * TOL)
    looks = np.arctan2(YG + np.array([-8.0, 8.0]), H)
    lo, hi = squint_interval_rad(axis, BEAM / 2 + TOL, looks)
    imager = TileImager(layout, r_axis, LAM, only=range(1, 3))
    if factors is not None:
        imager.factors = factors
    t_ns = np.round(t * 1e9).astype(np.int64)
    tiles = []
    for b in range(0, n, 128):  # blocks as the focuser hands them over
        s = slice(b, b + 128)
        wide = WIDENED if b // 128 <= 1 else 0.0  # a beam whose pointing is uncertain
        beam = np.tile([lo - wide, hi + wide], (rc[s].shape[0], 1))
        tiles += imager.add(rc[s], t_ns[s], apc[s], None, beam)
    return {tile.index: tile for tile in tiles + imager.close()}


@pytest.fixture(scope="module")
def formed() -> tuple[dict[int, Tile], dict[int, Tile]]:
    return _tiles(None), _tiles((1, 1))


def test_the_layout_asks_for_blocks_twice_as_coarse() -> None:
    """0.05 m pixels against a band of ±2.2 cycles/m (beam 2.5°, range bins 0.208 m): twice
    as coarse on both axes; 0.1 m pixels: none."""
    far = math.atan2(YG + 8.0, H)
    assert coarse_factors(0.05, BEAM + 2 * TOL, LAM, DR, far) == (2, 2)
    assert coarse_factors(0.1, BEAM + 2 * TOL, LAM, DR, far) == (1, 1)


def test_coarse_blocks_give_the_tiles_of_the_fine_grid(
    formed: tuple[dict[int, Tile], dict[int, Tile]],
) -> None:
    """About each target (±3 m) the pixels within 5e-3 (complex, rms; -46 dB) of the fine
    grid's: what differs is the part of the image that no band holds, where a pixel's
    beam (culling) starts or ends a pulse (2e-3 to 4e-3 here; the interpolation's own
    error is 5e-4 at most). The target inside the tile is measured alike: PSLR within
    0.01 dB, IRW within 0.1 %, the peak within 1 mm (its aperture, half of it under the
    misplaced beam, has sidelobes of -2 dB either way)."""
    coarse, fine = formed
    for x, y in TARGETS:
        k = int(x // 20.0)
        a, b = coarse[k].image(), fine[k].image()
        rows = np.abs(a.axis0_m - x) < 3.0
        cols = np.abs(a.axis1_m - y) < 3.0
        pa, pb = a.data[np.ix_(rows, cols)], b.data[np.ix_(rows, cols)]
        assert np.linalg.norm(pa - pb) / np.linalg.norm(pb) < 5e-3
    x, y = TARGETS[0]
    ma = point_target_metrics(coarse[1].image(), (x, y), 1.0, through_peak=True)
    mb = point_target_metrics(fine[1].image(), (x, y), 1.0, through_peak=True)
    for one, other in ((ma.axis0, mb.axis0), (ma.axis1, mb.axis1)):
        assert one.pslr_db == pytest.approx(other.pslr_db, abs=0.01)
        assert one.irw_m == pytest.approx(other.irw_m, rel=0.001)
    assert ma.position_error_m is not None and mb.position_error_m is not None
    assert math.dist(ma.position_error_m, mb.position_error_m) < 0.001


def test_a_coarse_image_interpolates_a_squinted_tone() -> None:
    """A plane wave at the carrier of a 5° squint plus 0.4 cycles per coarse sample along
    track, sampled on the coarse grid: interpolated onto the fine grid within 1e-3."""
    fine = PlaneGrid(0.025 + 0.05 * np.arange(200), YG + 0.05 * np.arange(160), (0.0, 0.0, H))
    grid = coarse_grid(fine, (2, 2))
    centre = 2 * math.sin(math.radians(-5.0)) / LAM
    k = 4 * math.pi / LAM
    f_along = centre + 0.4 / 0.1

    def wave(g: PlaneGrid) -> np.ndarray:
        cosine = math.sqrt(1 - (centre * LAM / 2) ** 2)
        along = np.exp(2j * np.pi * f_along * g.axis0_m)
        across = np.exp(1j * k * cosine * np.hypot(g.axis1_m, H))
        return (along[:, None] * across[None, :]).astype(np.complex64)

    out = np.zeros((200, 160), np.complex64)
    add_upsampled(out, fine, CoarseImage(centre, (2, 2), grid, wave(grid)), LAM)
    assert np.abs(out - wave(fine)).max() < 1e-3
