"""Streaming range-Doppler image formation onto the ground tiles of a straight reference track.

The frequency-domain counterpart of :class:`~sarmoco.processing.imaging.tiles.TileImager`:
it takes the same pulses (motion compensated to the reference track, autofocused and
pre-filtered) and hands out tiles on the same ground grids (:class:`TileLayout`), so
whatever reads tiles reads these. The two-step motion compensation of a range-Doppler
processor is the chain's own: the first step (bulk, to the straight reference track)
and the second (the range-variant residual, per range bin) are applied to each pulse
before this imager (:mod:`sarmoco.processing.mocomp`); the pulses then lie on the
reference track (imaging frame y = z = 0), which is what the range-Doppler algorithm
assumes.

Tiles are formed ``block_tiles`` at a time. Tile ``k`` takes the pulses whose
along-track position is within a half beam footprint of it (as backprojection's beam
culling); a block of tiles ``k .. k + m - 1`` is formed once the pulses reach a half
footprint past its end, from the pulses of ``[k L - h, (k + m) L + h]`` (``h`` the half
footprint at far range plus the interpolation guard). A block's first tile thus waits
``m - 1`` tile lengths of flight past its own last pulse; a *prompt* imager forms every
tile alone (``m = 1``), as soon as the pulses reach a half footprint and the guard past
it, at about 2.5 times the range-Doppler work per tile (the block's two half footprints
are then shared by one tile instead of ``m``: the live image's quickest rung,
:mod:`sarmoco.daemon.livelevel`). Either way a tile's pixels lie a half footprint from both
ends of its block, so it is the same image:

1. the range bins of the tiles' slant-range span (plus the range cell migration and a
   guard) are kept when a pulse arrives;
2. slow time is resampled onto a uniform along-track grid (the chain places pulses at
   their INS along-track positions, which are not uniform; the grid's spacing is the
   pulses' rounded down to :data:`GRID_DIGITS` significant digits): Kaiser-windowed sinc,
   in the band of the Doppler centroid (demodulated, then remodulated); grid points in a
   hole of more than 1.5 spacings, and beyond the first and last pulse, get zeros;
3. the range-Doppler algorithm (:func:`~sarmoco.processing.imaging.rda.focus_block`, its
   filters computed once per block shape: :func:`block_filters`) without azimuth zero
   padding (circular compression: the rows kept lie a half footprint from both block
   ends), its processed band the imaged beam ``|sin theta - sin theta_c| <= sin(theta_b
   / 2)`` (the same pulses a backprojected pixel takes), scaled to backprojection's
   amplitude and phase (stationary phase: a point target peaks at
   ``a sqrt(lambda r0 / 2) / dx exp(-j pi / 4)``, against ``a`` per pulse times the pulses
   in its beam);
4. the (along-track, slant range) image is basebanded (its range carrier
   ``exp(j 4 pi r / lambda)`` and the centroid's along-track frequency off), resampled
   onto each tile's ground grid (slant range ``sqrt(y^2 + H^2)`` of ground range ``y``),
   range first, and remodulated at the pixels: the phases are backprojection's.

Cost per pulse: an FFT and an inverse FFT over the block in slow time, two in range
(secondary range compression), and a 16-tap interpolation for the slow-time resampling
and for the range migration, on the kept range bins; per pixel two 16-tap
interpolations. Backprojection costs per pixel and pulse.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.interp import sinc_interp, sinc_interp_columns
from sarmoco.processing.imaging.rda import RdaFilters, focus_block, rda_filters
from sarmoco.processing.imaging.tiles import Tile, TileLayout
from sarmoco.processing.phasor import phasor
from sarmoco.processing.types import ComplexArray, FloatArray, IntArray

TAPS = 16
"""Length of the interpolation kernels (slow-time resampling, RCMC, onto the tile grid)."""

RANGE_GUARD_BINS = 32
"""Range bins kept beyond each end of the tiles' span (interpolation and SRC filter)."""

GRID_DIGITS = 3
"""Significant digits of the along-track grid spacing (:func:`grid_spacing`)."""

HOLE_SPACINGS = 1.5
"""A stretch between two pulses longer than this many nominal spacings is a hole."""

LEVELS = ((1, 1, 1), (2, 1, 2), (2, 2, 2), (4, 2, 4))
"""Degraded levels of the live image: (pixel spacing factor, swath divisor, presum factor) of
level 0, 1, 2, 3. The presum narrows the processed Doppler band by its factor (azimuth
resolution that much coarser, the block's range-Doppler steps on that many times fewer
rows); the polar format imager takes the pixels and the swath only."""


def degraded(layout: TileLayout, level: int) -> TileLayout:
    """``layout`` at a degraded level of :data:`LEVELS` (pixels coarser, swath narrower
    about the same centre); level 0 is ``layout`` itself."""
    if not 0 <= level < len(LEVELS):
        raise ProcessingError(f"degraded: level {level!r} is not in 0..{len(LEVELS) - 1}")
    if level == 0:
        return layout
    pixel, narrow, _ = LEVELS[level]
    return replace(layout, pixel_m=layout.pixel_m * pixel, swath_m=layout.swath_m / narrow)


def tile_range_bins(layout: TileLayout, axis: FloatArray, squint_rad: float) -> slice:
    """The bins of the uniform slant-range ``axis`` (m) that the tiles of ``layout`` need:
    their slant-range span, seen up to ``squint_rad`` (rad) off broadside at the far edge,
    and :data:`RANGE_GUARD_BINS` each side (at the far end a few more, up to a fast FFT
    length, where the axis has them)."""
    h = layout.height_m
    y_lo = layout.ground_range_m - layout.swath_m / 2.0
    y_hi = layout.ground_range_m + layout.swath_m / 2.0
    r_lo = math.hypot(h, max(y_lo, 0.0))
    r_hi = math.hypot(h, y_hi) / math.cos(squint_rad)
    i0 = max(int(np.searchsorted(axis, r_lo)) - RANGE_GUARD_BINS, 0)
    i1 = min(int(np.searchsorted(axis, r_hi)) + RANGE_GUARD_BINS, axis.size)
    # a few more guard bins, where the axis has them, for a fast FFT length in range
    i1 = min(i0 + scipy.fft.next_fast_len(i1 - i0), axis.size)
    return slice(i0, i1)


def grid_spacing(dx_m: float) -> float:
    """The along-track grid spacing for pulses ``dx_m`` apart, m: ``dx_m`` rounded down to
    :data:`GRID_DIGITS` significant digits (a grid at most that much finer), so that the
    segments of a flight (reference tracks of slightly different speeds) share one grid
    and its filters (:func:`block_filters`)."""
    scale = 10.0 ** (math.floor(math.log10(dx_m)) - GRID_DIGITS + 1)
    return math.floor(dx_m / scale) * scale


# the running block shape at each of the four levels and of prompt tiles, and the last
# blocks of segments
@functools.lru_cache(maxsize=8)
def block_filters(
    n_az: int,
    dx_m: float,
    r_first_m: float,
    dr_m: float,
    n_bins: int,
    wavelength_m: float,
    beamwidth_rad: float,
    centroid_squint_rad: float,
    presum: int = 1,
) -> RdaFilters:
    """Range-Doppler filters of one block shape, computed once for the blocks (and
    segments) that share it: circular azimuth compression over ``n_az`` rows (no zero
    padding), the imaged beam as the processed band, and the output scaled to
    backprojection's amplitude for pulses ``dx_m`` apart and basebanded in range (step 3
    of the module). With ``presum`` > 1, the processed band is ``presum`` times narrower
    about the centroid, and only the ``n_az / presum`` Doppler bins about the centroid are
    kept (``RdaFilters.rows``, ``n_out``): the image comes out on a grid ``presum * dx_m``
    apart.

    Parameters
    ----------
    n_az : int
        Azimuth FFT length (grid rows, padded to a fast length; a multiple of ``presum``).
    dx_m : float
        Along-track grid spacing, m.
    r_first_m, dr_m : float
        Slant range of the first bin and the bin spacing, m.
    n_bins : int
        Range bins.
    wavelength_m : float
        Carrier wavelength, m.
    beamwidth_rad : float
        Processed band as an angle (the imaged beam), rad.
    centroid_squint_rad : float
        Doppler centroid as a squint, rad.
    presum : int
        Presum factor of a degraded level (:data:`LEVELS`); 1: the pulses' band.
    """
    if n_az % presum:
        raise ProcessingError(f"block_filters: {n_az} rows are not a multiple of {presum}")
    r: FloatArray = r_first_m + dr_m * np.arange(n_bins, dtype=np.float64)
    sin_max = np.full(n_bins, math.sin(beamwidth_rad / 2.0) / presum)
    n_out, dx_out = n_az // presum, dx_m * presum
    f = rda_filters(
        n_out, dx_out, r, wavelength_m, sin_max, True, centroid_squint_rad, np.complex64
    )
    # amplitude and phase of backprojection: the stationary-phase factor
    # sqrt(lambda r / 2) / dx exp(-j pi / 4) of the azimuth chirp's spectrum divided out (on
    # the coarser grid, 1 / dx_out; its inverse FFT over n_out rows gains presum back)
    phase = -4.0 * np.pi * r / wavelength_m + np.pi / 4.0
    column = np.sqrt(wavelength_m * r / 2.0) / dx_out * np.exp(1j * phase)
    azimuth = f.azimuth * column.astype(np.complex64)
    if presum == 1:
        return replace(f, azimuth=azimuth)
    # the Doppler bins of the coarse grid (unwrapped about the centroid as the filters'),
    # found among the n_az bins of the pulses' grid: kx = m / (n_az dx_m)
    kx_c = 2.0 * math.sin(centroid_squint_rad) / wavelength_m
    span = 1.0 / dx_out
    kx = np.fft.fftfreq(n_out, dx_out)
    kx = kx_c + (kx - kx_c + span / 2.0) % span - span / 2.0
    fine = np.round(kx * n_az * dx_m).astype(np.int64) % n_az
    return replace(f, n_az=n_az, azimuth=azimuth, rows=fine[f.rows])


class RdaTileImager:
    """Form ground tiles from blocks of pulses with the range-Doppler algorithm.

    Parameters
    ----------
    layout : TileLayout
        Tile geometry (the same as backprojection's; ``beamwidth_rad`` is the processed
        Doppler band as an angle).
    range_axis_m : ndarray, shape (S,)
        Slant range of each range-compressed bin, m (uniform).
    wavelength_m : float
        Carrier wavelength, m.
    centroid_squint_rad : float
        Doppler centroid as the squint of the beam centre from broadside (forward
        positive), rad: the band processed is centred on it. 0: broadside.
    block_tiles : int, optional
        Tiles formed per block; default the fewest whose length reaches a half beam
        footprint (so a block spends at most about a third of its FFT on overlap).
    """

    def __init__(
        self,
        layout: TileLayout,
        range_axis_m: FloatArray,
        wavelength_m: float,
        centroid_squint_rad: float = 0.0,
        block_tiles: int | None = None,
    ) -> None:
        self.layout = layout
        self.wavelength_m = float(wavelength_m)
        self.centroid_squint_rad = float(centroid_squint_rad)
        axis = np.asarray(range_axis_m, dtype=np.float64)
        self._dr = float(axis[1] - axis[0])
        if not self._dr > 0:
            raise ProcessingError("RdaTileImager: the range axis does not increase")
        self._bins = self._range_bins(layout, axis)
        self.range_axis_m = axis[self._bins]
        """Slant range of the bins kept, m."""
        if self.range_axis_m.size < 2:
            raise ProcessingError("RdaTileImager: the tiles lie outside the range window")
        half = layout.half_footprint_m
        self._half = half
        """Along-track reach of the pulses' footprints from their APC, m (the broadside half
        footprint, widened by squinted beams)."""
        self.block_tiles = block_tiles or max(1, math.ceil(half / layout.tile_length_m))
        """Tiles formed per block."""
        self._rc: list[ComplexArray] = []
        self._x: list[FloatArray] = []
        self._t: list[IntArray] = []
        """Pulses held (kept range bins), their along-track positions (m) and times (GPS ns)."""
        self._next: int | None = None
        """Index of the next tile to form (None before the first pulse)."""
        self._dx = 0.0
        """Spacing of the uniform along-track grid, m (0 before two pulses have come):
        :func:`grid_spacing` of the first pulses' median spacing."""
        self._gain = 1.0
        """Grid over pulse spacing: the filters' amplitude is that of pulses on the grid."""
        self.level = 0
        """Degraded level (:data:`LEVELS`) of the tiles formed from now on."""
        self.only: range | None = None
        """Form only these tiles (a block of a batch); None: every tile."""
        self.prompt = False
        """Form each tile alone as soon as the pulses reach a half footprint and the
        interpolation guard past it, instead of :attr:`block_tiles` at a time."""

    def _range_bins(self, layout: TileLayout, axis: FloatArray) -> slice:
        """The bins of ``axis`` that the tiles of ``layout`` need (:func:`tile_range_bins`)."""
        beam = layout.beamwidth_rad / 2.0 + abs(self.centroid_squint_rad)
        return tile_range_bins(layout, axis, beam)

    def add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None = None,
        beam_squint_rad: FloatArray | None = None,
    ) -> list[Tile]:
        """Take a block of pulses; return the tiles it finished.

        The parameters are those of :meth:`~sarmoco.processing.imaging.tiles.TileImager.add`
        (the APCs' x increasing), but for two. ``compensated_dy_m`` is taken for that
        interface only: the per-pixel squint residual of the range-variant compensation is
        a backprojection term and is not applied here (the autofocus, when on, absorbs it).
        ``beam_squint_rad``: the first block's median centre becomes the centroid the band
        is processed about (when none was given), and the pulses each tile takes reach as
        far as any pulse's footprint; default broadside.
        """
        if rc.shape[0] == 0:
            return []
        x = np.asarray(apc_m, dtype=np.float64)[:, 0]
        if beam_squint_rad is not None:
            beam = np.asarray(beam_squint_rad, dtype=np.float64)
            if self._next is None and self.centroid_squint_rad == 0.0:
                self.centroid_squint_rad = float(np.median(beam.mean(axis=1)))
            back, ahead = self.layout.reach_m(beam)
            self._half = max(self._half, float(np.max(-back)), float(np.max(ahead)))
        self._rc.append(np.asarray(rc[:, self._bins], dtype=np.complex64))
        self._x.append(x.copy())
        self._t.append(np.asarray(t_ns, dtype=np.int64).copy())
        length, half = self.layout.tile_length_m, self._half
        if self._next is None:
            self._next = math.floor((float(x[0]) - half) / length)
        if self._dx == 0.0 and sum(a.size for a in self._x) >= 2:
            spacing = float(np.median(np.diff(np.concatenate(self._x))))
            self._dx = grid_spacing(spacing)
            self._gain = self._dx / spacing
        tiles: list[Tile] = []
        reach = half + TAPS * self._dx
        m = 1 if self.prompt else self.block_tiles
        while float(x[-1]) >= (self._next + m) * length + reach:
            tiles += self._form(range(self._next, self._next + m))
        return tiles

    def close(self) -> list[Tile]:
        """Form every tile the held pulses still reach (end of the segment)."""
        if self._next is None or not self._x:
            return []
        x_last = float(self._x[-1][-1])
        last = math.floor((x_last + self._half) / self.layout.tile_length_m)
        tiles = self._form(range(self._next, last + 1)) if last >= self._next else []
        self._rc, self._x, self._t = [], [], []
        return tiles

    def _form(self, block: range) -> list[Tile]:
        """Form the tiles of ``block`` (contiguous) from the pulses held; drop the pulses no
        later tile takes and advance to the tile after the block."""
        length = self.layout.tile_length_m
        reach = self._half + TAPS * self._dx
        rc, x, t = np.concatenate(self._rc), np.concatenate(self._x), np.concatenate(self._t)
        lo, hi = block.start * length - reach, block.stop * length + reach
        rows = np.flatnonzero((x >= lo) & (x <= hi))
        keep = x >= block.stop * length - reach
        self._rc, self._x, self._t = [rc[keep]], [x[keep]], [t[keep]]
        self._next = block.stop
        formed = [k for k in self.layout.formed(block) if self.only is None or k in self.only]
        if rows.size < 2 or not formed or self._dx <= 0.0:
            return []
        layout = degraded(self.layout, self.level)
        bins = self._range_bins(layout, self.range_axis_m)
        image, x_u = self._focus(rc[rows, bins], x[rows], bins, lo, hi, LEVELS[self.level][2])
        tiles = []
        for k in formed:
            grid = layout.grid(k)
            tile = self._tile(grid, k, image, x_u, self.range_axis_m[bins], x[rows], t[rows])
            if tile is not None:
                tiles.append(tile)
        return self.layout.clip(tiles)

    def _focus(
        self, rc: ComplexArray, x: FloatArray, bins: slice, lo: float, hi: float, presum: int
    ) -> tuple[ComplexArray, FloatArray]:
        """Resample pulses ``rc`` (the kept range bins ``bins``; taken over and changed)
        onto the uniform along-track grid over ``[lo, hi]`` (m; zeros beyond the first and
        last pulse and in holes) and focus them, the band ``presum`` times narrower.

        Returns the image (along-track × range bins, scaled to backprojection's amplitude,
        basebanded: the range carrier ``exp(j 4 pi r / lambda)`` and the centroid's
        along-track frequency taken off) and its along-track axis (the grid's, every
        ``presum``-th point), m.
        """
        dx = self._dx
        first = math.ceil(lo / dx)
        x_u: FloatArray = dx * np.arange(first, first + round((hi - lo) / dx) + 1, dtype=np.float64)
        filters = self._block_filters(x_u.size, bins, presum)
        kx_c = 2.0 * math.sin(self.centroid_squint_rad) / self.wavelength_m
        if kx_c:
            rc *= phasor(-2.0 * np.pi * kx_c * x)[:, None]
        # grid rows up to the FFT length: the rows past the grid are the FFT's zero padding
        idx = np.full(filters.n_az, -1.0)  # -1: a zero row
        idx[: x_u.size] = np.interp(x_u, x, np.arange(x.size, dtype=np.float64))
        nxt = np.clip(np.searchsorted(x, x_u), 1, x.size - 1)
        hole = (x[nxt] - x[nxt - 1] > HOLE_SPACINGS * dx) | (x_u < x[0]) | (x_u > x[-1])
        idx[: x_u.size][hole] = -1.0
        uniform = sinc_interp_columns(rc, idx, TAPS)
        if kx_c:
            uniform[: x_u.size] *= phasor(2.0 * np.pi * kx_c * x_u)[:, None]
        x_out = x_u[::presum]
        img = focus_block(uniform, filters, TAPS)[: x_out.size]
        if kx_c:
            img *= phasor(-2.0 * np.pi * kx_c * x_out)[:, None]
        return img, x_out

    def _block_filters(self, rows: int, bins: slice, presum: int = 1) -> RdaFilters:
        """The filters of a block of ``rows`` grid rows and the kept bins ``bins``, the band
        ``presum`` times narrower."""
        r = self.range_axis_m[bins]
        return block_filters(
            presum * scipy.fft.next_fast_len(-(-rows // presum)),
            self._dx,
            float(r[0]),
            self._dr,
            r.size,
            self.wavelength_m,
            self.layout.beamwidth_rad,
            self.centroid_squint_rad,
            presum,
        )

    def _tile(
        self,
        grid: PlaneGrid,
        k: int,
        image: ComplexArray,
        x_u: FloatArray,
        range_m: FloatArray,
        x: FloatArray,
        t: IntArray,
    ) -> Tile | None:
        """Tile ``k`` on ``grid`` resampled from the block's image (along ``x_u`` × slant
        range ``range_m``, m; None: no pulse reaches it)."""
        length, half = self.layout.tile_length_m, self._half
        used = np.flatnonzero((x >= k * length - half) & (x <= (k + 1) * length + half))
        if used.size == 0:
            return None
        dx = float(x_u[1] - x_u[0])
        az = (grid.axis0_m - x_u[0]) / dx
        a0 = max(math.floor(az.min()) - TAPS, 0)
        a1 = min(math.ceil(az.max()) + TAPS + 1, image.shape[0])
        if a1 <= a0:
            return None
        r = np.hypot(grid.axis1_m, self.layout.height_m)
        rg = (r - range_m[0]) / self._dr
        part = sinc_interp(image[a0:a1], rg[None, :], TAPS)
        data = sinc_interp_columns(part, az - a0, TAPS)
        # remodulation exp(j 2 pi (kx_c x + 2 r / lambda)), one factor per axis
        kx_c = 2.0 * math.sin(self.centroid_squint_rad) / self.wavelength_m
        data *= phasor(2.0 * np.pi * kx_c * grid.axis0_m)[:, None]
        data *= (self._gain * phasor(4.0 * np.pi / self.wavelength_m * r))[None, :]
        return Tile(
            k,
            grid,
            data,
            int(t[used[0]]),
            int(t[used[-1]]),
            int(used.size),
        )
