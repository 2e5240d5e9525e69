"""Streaming backprojection onto ground tiles laid along a straight reference track.

The imaging frame is that of docs/methods.md §1 (x along the reference track, y toward
the illuminated side, z down; origin at the reference APC at its start time).
Tile ``k`` covers ``k L <= x < (k + 1) L`` and the ground-range band
``y_c ± W/2`` on the flat ground ``z = H``. A pixel takes the pulses that see
it within their beam: within half the azimuth beamwidth θ of broadside, or within a
per-pulse interval of squint ``[psi_lo, psi_hi]`` from the plane normal to the track
(a squinted beam; beam culling of
:func:`~sarmoco.processing.imaging.backprojection.backproject_into`), so a pulse
at along-track position ``x_p`` reaches the tiles that meet its footprint
``x_p + rho tan(psi_lo) <= x <= x_p + rho tan(psi_hi)`` over the swath's ``rho`` (the
distance from the track); a tile is finished, and handed out, once the latest pulse's
footprint has passed its end, so memory stays bounded however long the run. Each
block of pulses is upsampled in range once (in chunks of ``RANGE_CHUNK_PULSES``) and
accumulated in place into every tile it reaches.

Segments that overlap at a cut (:mod:`sarmoco.processing.segments`) each image only
their side of the cut line: :attr:`TileLayout.keep` holds half-planes of the ground;
pixels outside stay zero (set when the tile is handed out) and a tile wholly outside
is neither formed nor handed out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.coarse import (
    MARGIN,
    MAX_IMAGES,
    CoarseImage,
    add_upsampled,
    along_band,
    band_fits,
    coarse_factors,
    coarse_grid,
)
from sarmoco.processing.imaging.ffbp import ffbp_into
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.types import BoolArray, ComplexArray, FloatArray, Image, IntArray

RANGE_CHUNK_PULSES = 128
"""Pulses upsampled in range at a time (bounds the memory of a large block)."""


@dataclass(frozen=True)
class TileLayout:
    """Where the tiles lie.

    Parameters
    ----------
    height_m : float
        Height H of the reference track above the flat ground, m.
    ground_range_m : float
        Ground-range (imaging-frame y) of the tile centres, m.
    swath_m : float
        Ground-range width W of a tile, m.
    tile_length_m : float
        Along-track length L of a tile, m.
    pixel_m : float
        Pixel spacing on both axes, m.
    beamwidth_rad : float
        Azimuth beamwidth θ: a pixel takes the pulses within θ/2 of its broadside, rad.
    keep : tuple of (a, b, c)
        Half-planes ``a x + b y < c`` (imaging-frame x, y of the pixels, m; c in m) of the
        ground this segment images; pixels outside any stay zero. Default: all.
    """

    height_m: float
    ground_range_m: float
    swath_m: float
    tile_length_m: float
    pixel_m: float
    beamwidth_rad: float
    keep: tuple[tuple[float, float, float], ...] = ()

    def __post_init__(self) -> None:
        for name in ("swath_m", "tile_length_m", "pixel_m", "beamwidth_rad"):
            if not getattr(self, name) > 0:
                raise ProcessingError(f"TileLayout.{name}: {getattr(self, name)!r} is not > 0")

    @property
    def half_footprint_m(self) -> float:
        """Half the along-track beam footprint at the far edge of the swath, m."""
        far = math.hypot(self.height_m, self.ground_range_m + self.swath_m / 2.0)
        return far * math.tan(self.beamwidth_rad / 2.0)

    def broadside_rad(self, n: int) -> FloatArray:
        """Squint intervals ``[-θ/2, θ/2]`` of ``n`` pulses with the beam broadside, rad, (n, 2)."""
        half = self.beamwidth_rad / 2.0
        return np.tile(np.array([-half, half]), (n, 1))

    def reach_m(self, beam_squint_rad: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Along-track extent of each pulse's footprint on the swath, relative to the APC, m.

        Parameters
        ----------
        beam_squint_rad : ndarray, shape (P, 2)
            Squint interval of each pulse's beam from the plane normal to the track, rad.

        Returns
        -------
        back, ahead : ndarray, shape (P,)
            The least and the greatest ``rho tan(psi)`` over the swath's near and far
            edges (``rho`` from the track to the ground) and the interval's ends, m.
        """
        y = self.ground_range_m + np.array([-0.5, 0.5]) * self.swath_m
        rho = np.hypot(self.height_m, y)
        tan = np.tan(np.asarray(beam_squint_rad, dtype=np.float64))
        back = np.minimum(rho[0] * tan[:, 0], rho[1] * tan[:, 0])
        ahead = np.maximum(rho[0] * tan[:, 1], rho[1] * tan[:, 1])
        return back, ahead

    def grid(self, k: int) -> PlaneGrid:
        """Pixel grid of tile ``k`` in the imaging frame (axis 0 = x, axis 1 = y)."""
        n0 = max(2, round(self.tile_length_m / self.pixel_m))
        n1 = max(2, round(self.swath_m / self.pixel_m))
        ax0 = (k * self.tile_length_m + (np.arange(n0) + 0.5) * self.pixel_m).astype(np.float64)
        ax1 = (self.ground_range_m + (np.arange(n1) - n1 / 2.0 + 0.5) * self.pixel_m).astype(
            np.float64
        )
        return PlaneGrid(ax0, ax1, (0.0, 0.0, self.height_m), 0.0, "ground")

    def kept(self, grid: PlaneGrid) -> BoolArray:
        """Pixels (axis 0 × axis 1) of ``grid`` inside every :attr:`keep` half-plane."""
        inside = np.ones((grid.axis0_m.size, grid.axis1_m.size), dtype=bool)
        for a, b, c in self.keep:
            inside &= a * grid.axis0_m[:, None] + b * grid.axis1_m[None, :] < c
        return inside

    def clip(self, tiles: list[Tile]) -> list[Tile]:
        """Finished tiles with the pixels outside :attr:`keep` zeroed (in place), those
        wholly outside left out (``keep`` may have changed since a tile opened: a cut)."""
        if not self.keep:
            return tiles
        out = []
        for tile in tiles:
            inside = self.kept(tile.grid)
            tile.data[~inside] = 0.0
            if inside.any():
                out.append(tile)
        return out

    def formed(self, tiles: range) -> range:
        """The tiles of ``tiles`` (contiguous) with a pixel inside :attr:`keep` (contiguous:
        each half-plane's boundary crosses the strip of tiles once)."""
        inside = [k for k in tiles if self.kept(self.grid(k)).any()] if self.keep else tiles
        return range(inside[0], inside[-1] + 1) if len(inside) else range(0)


@dataclass
class Tile:
    """A tile being accumulated: its index, grid, pixels, time span (GPS ns) and pulse count.

    ``n_pulses`` counts the pulses backprojected into the tile, i.e. after any
    azimuth pre-filter's decimation. ``coarse`` holds the blocks formed on coarser grids
    (:mod:`sarmoco.processing.imaging.coarse`) until the tile is handed out.
    """

    index: int
    grid: PlaneGrid
    data: ComplexArray
    t0_ns: int
    t1_ns: int
    n_pulses: int = 0
    coarse: list[CoarseImage] = field(default_factory=list)

    def image(self) -> Image:
        """The tile as an :class:`Image` (frame ``ground``, axes in imaging-frame metres)."""
        return Image(self.data, self.grid.axis0_m, self.grid.axis1_m, self.grid.frame)


class TileImager:
    """Backproject blocks of pulses onto the tiles their beam covers.

    Parameters
    ----------
    layout : TileLayout
        Tile geometry.
    range_axis_m : ndarray, shape (S,)
        Slant range of each range-compressed bin, m (uniform).
    wavelength_m : float
        Carrier wavelength, m.
    only : range, optional
        Form only these tiles (a block of a batch; the others the pulses reach are
        skipped). Default every tile.
    ffbp_budget_rad : float, optional
        Form the tiles by fast factorised backprojection
        (:func:`~sarmoco.processing.imaging.ffbp.ffbp_into`) with this phase-error budget,
        rad; None: direct backprojection. The pulses are then held until ``RANGE_CHUNK_PULSES``
        are there (one factorisation over each chunk), so tiles finish up to that many
        pulses later.

    Where the tiles' pixels are finer than the image's band, blocks are formed on a
    coarser grid and interpolated onto the tile's when it is handed out
    (:mod:`sarmoco.processing.imaging.coarse`; :attr:`factors` says how much coarser).
    """

    def __init__(
        self,
        layout: TileLayout,
        range_axis_m: FloatArray,
        wavelength_m: float,
        only: range | None = None,
        ffbp_budget_rad: float | None = None,
    ) -> None:
        self.layout = layout
        self.only = only
        self.ffbp_budget_rad = ffbp_budget_rad
        self.range_axis_m = np.asarray(range_axis_m, dtype=np.float64)
        self.wavelength_m = float(wavelength_m)
        far = math.atan2(layout.ground_range_m + layout.swath_m / 2.0, layout.height_m)
        self.factors = coarse_factors(
            layout.pixel_m,
            layout.beamwidth_rad,
            self.wavelength_m,
            float(self.range_axis_m[1] - self.range_axis_m[0]),
            far,
        )
        """Coarsening, along track and across, of the grids blocks may be formed on."""
        self._open: dict[int, Tile] = {}
        self._first_open = -(2**62)
        """Tiles below this index were handed out and are never reopened."""
        self._held: list[
            tuple[ComplexArray, IntArray, FloatArray, FloatArray | None, FloatArray]
        ] = []
        """With FFBP: pulses not yet imaged (fewer than ``RANGE_CHUNK_PULSES``)."""

    def add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None = None,
        beam_squint_rad: FloatArray | None = None,
    ) -> list[Tile]:
        """Backproject a block and return the tiles it finished.

        Parameters
        ----------
        rc : ndarray of complex, shape (P, S)
            Motion-compensated, autofocused range-compressed pulses.
        t_ns : ndarray of int64, shape (P,)
            Pulse times, GPS ns, increasing across calls.
        apc_m : ndarray, shape (P, 3)
            APC of each pulse in the imaging frame (the reference track), m.
        compensated_dy_m : ndarray, shape (P,), optional
            Cross-track APC displacement ΔY (imaging y) the pulses were compensated for
            per range bin (second order, docs/methods.md §2), m: each pixel then gets the
            squint residual of eq. 29 removed
            (:func:`~sarmoco.processing.imaging.backprojection.backproject_into`).
        beam_squint_rad : ndarray, shape (P, 2), optional
            Squint interval of each pulse's beam from the plane normal to the track (a
            squinted beam), rad (positive: ahead). Default: ``±θ/2`` (broadside).
        """
        if rc.shape[0] == 0:
            return []
        beam = (
            self.layout.broadside_rad(rc.shape[0])
            if beam_squint_rad is None
            else np.asarray(beam_squint_rad, dtype=np.float64)
        )
        if beam.shape != (rc.shape[0], 2):
            raise ProcessingError(f"TileImager: beam {beam.shape} for {rc.shape[0]} pulses")
        if self.ffbp_budget_rad is None:
            return self._add(rc, t_ns, apc_m, compensated_dy_m, beam)
        dy = None if compensated_dy_m is None else np.array(compensated_dy_m)
        self._held.append((np.array(rc), np.array(t_ns), np.array(apc_m), dy, beam.copy()))
        n = sum(h[0].shape[0] for h in self._held)
        if n < RANGE_CHUNK_PULSES:
            return []
        return self._add(*self._release(n - n % RANGE_CHUNK_PULSES))

    def _release(
        self, n: int
    ) -> tuple[ComplexArray, IntArray, FloatArray, FloatArray | None, FloatArray]:
        """The first ``n`` held pulses (FFBP), the rest kept."""
        held, self._held = self._held, []
        rc, t_ns, apc_m = (np.concatenate([h[k] for h in held]) for k in range(3))
        beam = np.concatenate([h[4] for h in held])
        dy = None if any(h[3] is None for h in held) else np.concatenate([h[3] for h in held])
        if n < rc.shape[0]:
            rest = None if dy is None else dy[n:]
            self._held = [(rc[n:], t_ns[n:], apc_m[n:], rest, beam[n:])]
        return rc[:n], t_ns[:n], apc_m[:n], None if dy is None else dy[:n], beam[:n]

    def _add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None,
        beam: FloatArray,
    ) -> list[Tile]:
        """Backproject a block now; the tiles it finished."""
        x = apc_m[:, 0]
        back, ahead = self.layout.reach_m(beam)
        length = self.layout.tile_length_m
        first = max(math.floor(float((x + back).min()) / length), self._first_open)
        last = math.floor(float((x + ahead).max()) / length)
        for k in self.layout.formed(range(first, last + 1)):
            if k not in self._open and (self.only is None or k in self.only):
                grid = self.layout.grid(k)
                shape = (grid.axis0_m.size, grid.axis1_m.size)
                self._open[k] = Tile(k, grid, np.zeros(shape, np.complex64), int(t_ns[0]), 0)
        for start in range(0, rc.shape[0], RANGE_CHUNK_PULSES):
            chunk = slice(start, start + RANGE_CHUNK_PULSES)
            dy = None if compensated_dy_m is None else compensated_dy_m[chunk]
            self._backproject(rc[chunk], t_ns[chunk], apc_m[chunk], dy, beam[chunk])
        return self._pop_below(math.floor(float(x[-1] + back[-1]) / length))

    def _backproject(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None,
        beam: FloatArray,
    ) -> None:
        x = apc_m[:, 0]
        back, ahead = self.layout.reach_m(beam)
        length = self.layout.tile_length_m
        lines: RangeLines | None = None
        for k, tile in self._open.items():
            sel = np.flatnonzero((x + ahead >= k * length) & (x + back <= (k + 1) * length))
            if sel.size == 0:
                continue
            if lines is None:
                lines = RangeLines.upsample(rc, self.range_axis_m)
            out, grid = self._target(tile, beam[sel])
            if self.ffbp_budget_rad is None:
                backproject_into(
                    out,
                    lines,
                    apc_m,
                    self.wavelength_m,
                    grid,
                    pulses=sel,
                    compensated_dy_m=compensated_dy_m,
                    beam_squint_rad=beam,
                )
            else:
                ffbp_into(
                    out,
                    lines,
                    float(self.range_axis_m[1] - self.range_axis_m[0]),
                    apc_m,
                    self.wavelength_m,
                    grid,
                    self.ffbp_budget_rad,
                    pulses=sel,
                    compensated_dy_m=compensated_dy_m,
                    beam_squint_rad=beam,
                )
            tile.n_pulses += sel.size
            tile.t1_ns = int(t_ns[sel[-1]])

    def _target(self, tile: Tile, beam: FloatArray) -> tuple[ComplexArray, PlaneGrid]:
        """Where a block of squint intervals ``beam`` is formed in ``tile``: the coarsest
        image whose carrier its band fits, a new one coarser than those, or the tile's own
        grid."""
        band = along_band(beam, self.wavelength_m)
        fits = [image for image in tile.coarse if image.takes(band)]
        best = max(fits, key=lambda image: math.prod(image.factor), default=None)
        held = 1 if best is None else math.prod(best.factor)
        m0, m1 = self.factors
        room = len(tile.coarse) < MAX_IMAGES and min(tile.data.shape) >= 4 * MARGIN * max(m0, m1)
        centre, step = sum(band) / 2.0, float(tile.grid.axis0_m[1] - tile.grid.axis0_m[0])
        for factor in ((m0, m1), (1, m1)):
            if room and math.prod(factor) > held and band_fits(band, centre, factor[0] * step):
                grid = coarse_grid(tile.grid, factor)
                shape = (grid.axis0_m.size, grid.axis1_m.size)
                image = CoarseImage(centre, factor, grid, np.zeros(shape, np.complex64))
                tile.coarse.append(image)
                return image.data, image.grid
        return (best.data, best.grid) if best is not None else (tile.data, tile.grid)

    def close(self) -> list[Tile]:
        """Hand out every tile still open (end of the run), after the pulses held for FFBP."""
        n = sum(h[0].shape[0] for h in self._held)
        tiles = self._add(*self._release(n)) if n else []
        return tiles + self._pop_below(2**62)

    def _pop_below(self, index: int) -> list[Tile]:
        keys = sorted(k for k in self._open if k < index)
        self._first_open = max(self._first_open, index)
        tiles = [self._open.pop(k) for k in keys]
        for tile in tiles:
            for image in tile.coarse:
                add_upsampled(tile.data, tile.grid, image, self.wavelength_m)
            tile.coarse.clear()
        return self.layout.clip(tiles)
