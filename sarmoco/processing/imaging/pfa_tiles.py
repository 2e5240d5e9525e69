"""Streaming polar format image formation onto the ground tiles of a straight reference track.

The spotlight counterpart of :class:`~sarmoco.processing.imaging.rda_tiles.RdaTileImager`:
it takes the same pulses (motion compensated per pulse to the reference track,
autofocused, pre-filtered) and hands out tiles on the same ground grids
(:class:`TileLayout`). Each tile is a small spotlight scene of its own: its centre
``c_k`` (the middle of tile ``k`` on the ground) is the motion-compensation point, and
its aperture is the pulses that see ``c_k`` within ``aperture_rad / 2`` of the beam's
centroid squint, ``x_p`` in ``x_k - rho tan(psi_c) ± rho tan(aperture / 2)`` (``rho``
the distance from the track to ``c_k``). A tile is formed once the pulses reach the end
of its aperture; pulses no later tile takes are dropped, so memory stays bounded.

Per tile:

1. the range-compressed lines (the slant-range bins the tiles need) are taken to the
   frequency domain (one FFT per pulse) and deramped to the tile centre:
   ``ph_p(f) = RC_p(f) exp(-j 4 pi (f - f_c) r_0 / c) exp(+j 4 pi f R_c,p / c)``
   (``r_0`` the first bin's range, ``R_c,p`` the APC-to-centre range), the phase history
   of :mod:`~sarmoco.processing.imaging.pfa` within the radar's band;
2. the polar raster is resampled onto a rectangle of spatial frequencies
   (:func:`~sarmoco.processing.imaging.pfa.polar_to_rect`), spaced so that two FFTs
   (zero padded to the scene the pulses see after the pre-filter, so nothing wraps onto
   the tile) give pixels at the tile's spacing;
3. the planar-wavefront distortion is undone: a point at ground offset
   ``(dx, dy)`` from the centre lies in the polar format image at ``a0'``, the slope of
   its deramped phase across the aperture (about ``dx rho_c / rho_t``), and
   ``a1' ~ (R_t - R_c) / g_r`` averaged over the aperture (``g_r`` the cosine of the
   grazing angle); the image (basebanded) is read there (separable 16-tap interpolation, along
   range then along track), so targets land on the pixels backprojection puts them on,
   with its phase; the amplitude is scaled to backprojection's (``a`` per pulse times
   the pulses of the aperture).

Validity (:func:`~sarmoco.processing.imaging.pfa.validity_radius_m`): the residual
quadratic phase stays below ``pi / 2`` within ``2 rho_c sqrt(R_c / lambda)`` of the centre;
a tile reaches ``hypot(L, W) / 2`` from it (``thz-spotlight``: 72 m against 320 m).

Resolution: along track ``lambda / (2 aperture)`` (0.886 of it at -3 dB, unweighted), in
range ``c / (2 B cos(grazing))`` on the ground, both limited to the pixel spacing (a
degraded level keeps only the spectrum its coarser pixels hold).

Cost per tile: an FFT per pulse of the aperture over the kept bins, two 16-tap
resamplings of the phase history, two FFTs of the padded tile and two 16-tap
interpolations per pixel: per sample, not per pixel and pulse.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.fft

from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.interp import sinc_interp
from sarmoco.processing.imaging.pfa import pfa_support, polar_to_rect
from sarmoco.processing.imaging.rda_tiles import TAPS, degraded, tile_range_bins
from sarmoco.processing.imaging.tiles import Tile, TileLayout
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, IntArray

PIXEL_BAND = 0.8
"""Share of the band ``2 pi / pixel`` (rad/m) the image's spectrum may fill on each axis:
the spectrum a level's pixels hold (the rest is cut, coarsening the resolution to them)."""


class PfaTileImager:
    """Form ground tiles from blocks of pulses with the polar format algorithm.

    Parameters
    ----------
    layout : TileLayout
        Tile geometry (the same as backprojection's); ``beamwidth_rad`` is the band the
        pulses were pre-filtered to (the scene they see).
    range_axis_m : ndarray, shape (S,)
        Slant range of each range-compressed bin, m (uniform).
    wavelength_m : float
        Carrier wavelength, m.
    bandwidth_hz : float
        Transmitted bandwidth, Hz: the band of the phase history kept.
    aperture_rad : float
        Angle each tile's aperture spans, rad (sets the along-track resolution).
    centroid_squint_rad : float, optional
        Doppler centroid as the squint of the beam centre from broadside (forward
        positive), rad: the apertures are centred on it. 0: broadside.
    """

    def __init__(
        self,
        layout: TileLayout,
        range_axis_m: FloatArray,
        wavelength_m: float,
        bandwidth_hz: float,
        aperture_rad: float,
        centroid_squint_rad: float = 0.0,
    ) -> None:
        if not (bandwidth_hz > 0 and 0 < aperture_rad < math.pi / 2):
            raise ProcessingError(
                f"PfaTileImager: bandwidth {bandwidth_hz!r} Hz, aperture {aperture_rad!r} rad"
            )
        self.layout = layout
        self.wavelength_m = float(wavelength_m)
        self.bandwidth_hz = float(bandwidth_hz)
        self.aperture_rad = float(aperture_rad)
        self.centroid_squint_rad = float(centroid_squint_rad)
        axis = np.asarray(range_axis_m, dtype=np.float64)
        self._dr = float(axis[1] - axis[0])
        if not self._dr > 0:
            raise ProcessingError("PfaTileImager: the range axis does not increase")
        reach = layout.beamwidth_rad / 2.0 + abs(self.centroid_squint_rad)
        self.range_axis_m = axis[tile_range_bins(layout, axis, reach)]
        """Slant range of the bins kept, m."""
        if self.range_axis_m.size < 2:
            raise ProcessingError("PfaTileImager: the tiles lie outside the range window")
        self._bins = tile_range_bins(layout, axis, reach)
        self._rho = math.hypot(layout.height_m, layout.ground_range_m)
        """Distance from the track to the tile centres, m."""
        self._rc: list[ComplexArray] = []
        self._apc: list[FloatArray] = []
        self._t: list[IntArray] = []
        """Pulses held (kept range bins), their APCs (imaging frame, m) and times (GPS ns)."""
        self._next: int | None = None
        """Index of the next tile to form (None before the first pulse)."""
        self.level = 0
        """Degraded level (:data:`~sarmoco.processing.imaging.rda_tiles.LEVELS`) of the
        tiles formed from now on."""
        self.only: range | None = None
        """Form only these tiles (a block of a batch); None: every tile."""

    def aperture_m(self, k: int) -> tuple[float, float]:
        """Along-track interval of the APCs that form tile ``k`` (imaging x, m)."""
        centre = (k + 0.5) * self.layout.tile_length_m
        shift = self._rho * math.tan(self.centroid_squint_rad)
        half = self._rho * math.tan(self.aperture_rad / 2.0)
        return centre - shift - half, centre - shift + half

    def add(
        self,
        rc: ComplexArray,
        t_ns: IntArray,
        apc_m: FloatArray,
        compensated_dy_m: FloatArray | None = None,
        beam_squint_rad: FloatArray | None = None,
    ) -> list[Tile]:
        """Take a block of pulses; return the tiles whose apertures it completed.

        Arguments as for :meth:`~sarmoco.processing.imaging.tiles.TileImager.add`, with
        the APCs' x increasing. The squint residual of the range-variant compensation
        (``compensated_dy_m``) is a backprojection term, not applied here. With
        ``beam_squint_rad`` the first block's median squint centres the apertures (when no
        centroid was given); broadside without.
        """
        if rc.shape[0] == 0:
            return []
        apc = np.asarray(apc_m, dtype=np.float64)
        if beam_squint_rad is not None and self._next is None and self.centroid_squint_rad == 0.0:
            beam = np.asarray(beam_squint_rad, dtype=np.float64)
            self.centroid_squint_rad = float(np.median(beam.mean(axis=1)))
        self._rc.append(np.asarray(rc[:, self._bins], dtype=np.complex64))
        self._apc.append(apc.copy())
        self._t.append(np.asarray(t_ns, dtype=np.int64).copy())
        length = self.layout.tile_length_m
        if self._next is None:  # the first tile whose aperture ends after the first pulse
            self._next = math.ceil((float(apc[0, 0]) - self.aperture_m(0)[1]) / length)
        tiles: list[Tile] = []
        while float(apc[-1, 0]) >= self.aperture_m(self._next)[1]:
            tiles += self._form(self._next, self._next + 1)
        return tiles

    def close(self) -> list[Tile]:
        """Form every tile whose aperture the held pulses reach (end of the segment)."""
        held = np.concatenate(self._apc) if self._apc else np.zeros((0, 3))
        if self._next is None or held.shape[0] == 0:
            self._rc, self._apc, self._t = [], [], []
            return []
        x_last = float(held[-1, 0])
        tiles: list[Tile] = []
        while self.aperture_m(self._next)[0] <= x_last:
            tiles += self._form(self._next, self._next + 1)
        self._rc, self._apc, self._t = [], [], []
        return tiles

    def _form(self, k: int, after: int) -> list[Tile]:
        """Form tile ``k`` from the pulses held; keep those tile ``after`` still takes."""
        rc, apc, t = np.concatenate(self._rc), np.concatenate(self._apc), np.concatenate(self._t)
        lo, hi = self.aperture_m(k)
        x = apc[:, 0]
        rows = np.flatnonzero((x >= lo) & (x <= hi))
        keep = x >= self.aperture_m(after)[0]
        self._rc, self._apc, self._t = [rc[keep]], [apc[keep]], [t[keep]]
        self._next = after
        if rows.size < 2 or not self.layout.formed(range(k, k + 1)):
            return []
        if self.only is not None and k not in self.only:
            return []
        layout = degraded(self.layout, self.level)
        grid = layout.grid(k)
        try:
            data = self._image(rc[rows], apc[rows], layout, grid)
        except ProcessingError:  # too few pulses for a polar raster (the ends of a segment)
            return []
        tile = Tile(k, grid, data, int(t[rows[0]]), int(t[rows[-1]]), int(rows.size))
        return self.layout.clip([tile])

    def _phase_history(
        self, rc: ComplexArray, r0_m: float, apc: FloatArray, centre: FloatArray
    ) -> tuple[ComplexArray, FloatArray]:
        """Step 1: the pulses' phase history (bins from slant range ``r0_m``) deramped to
        ``centre`` (m) within the band, and its frequencies (Hz, ascending)."""
        n = scipy.fft.next_fast_len(rc.shape[1])
        spectrum = scipy.fft.fft(rc, n, axis=1, workers=1)
        f_c = C_MPS / self.wavelength_m
        df = C_MPS / (2.0 * n * self._dr)
        m = np.arange(-(n // 2), n - n // 2)
        band = np.abs(m * df) <= self.bandwidth_hz / 2.0
        m = m[band]
        if m.size < 2:
            raise ProcessingError("PfaTileImager: the range bins hold no band")
        freq = f_c + m * df
        r_c = np.linalg.norm(apc - centre[None, :], axis=1)
        phase = (4.0 * np.pi / C_MPS) * (freq[None, :] * r_c[:, None] - (m * df)[None, :] * r0_m)
        ph = spectrum[:, m % n] * np.exp(1j * phase).astype(np.complex64)
        return ph, freq

    def _image(
        self, rc: ComplexArray, apc: FloatArray, layout: TileLayout, grid: PlaneGrid
    ) -> ComplexArray:
        """Steps 1-3 of the module: the pixels of ``grid`` (a tile of ``layout``, the level's)
        from the pulses of its aperture."""
        pix = layout.pixel_m
        x_c, y_c = float(np.mean(grid.axis0_m)), layout.ground_range_m
        centre = np.array([x_c, y_c, layout.height_m])
        reach = self.layout.beamwidth_rad / 2.0 + abs(self.centroid_squint_rad)
        bins = tile_range_bins(layout, self.range_axis_m, reach)
        r = self.range_axis_m[bins]
        ph, freq = self._phase_history(rc[:, bins], float(r[0]), apc, centre)
        frame = PlaneGrid(np.array([0.0, 1.0]), np.array([0.0, 1.0]), (x_c, y_c, layout.height_m))
        sup = pfa_support(freq, apc, frame)
        # FFT lengths: the scene the pulses see (along track: the pre-filtered beam's
        # footprint about the aperture; in range: the bins), so nothing wraps onto the tile
        y = np.sqrt(np.maximum(r**2 - layout.height_m**2, 0.0)) - y_c
        shift = self._rho * math.tan(self.centroid_squint_rad)
        half = self._rho * math.tan(self.aperture_rad / 2.0)
        along = abs(shift) + half + self.layout.half_footprint_m
        n0 = scipy.fft.next_fast_len(math.ceil((2 * along + layout.tile_length_m) / pix) + 2 * TAPS)
        n1 = scipy.fft.next_fast_len(math.ceil(2 * float(np.max(np.abs(y))) / pix) + 2 * TAPS)
        kc = _samples(sup.kc_lo, sup.kc_hi, 2.0 * np.pi / (n0 * pix), pix)
        kr = _samples(sup.kr_lo, sup.kr_hi, 2.0 * np.pi / (n1 * pix), pix)
        g = polar_to_rect(ph, freq, apc, frame, kr, kc, TAPS)
        # where each pixel's point lies in the polar format image (step 3): a0' at the
        # tile's pixels; a1' at the image's rows (apparent a0) and the pixels' columns
        dx, dy = (grid.axis0_m - x_c)[:, None], (grid.axis1_m - y_c)[None, :]
        a0, a1_pix = _apparent(apc, centre, dx, dy)
        b0 = float(np.min(a0)) - TAPS * pix
        m0 = min(math.ceil((float(np.max(a0)) - b0) / pix) + TAPS + 1, n0)
        scale0 = _apparent(apc, centre, np.ones(1), dy)[0]  # a0' per m of dx, (1, columns)
        rows_x = (b0 + pix * np.arange(m0))[:, None] / scale0
        _, a1 = _apparent(apc, centre, rows_x, dy)
        b1 = float(np.min(a1)) - TAPS * pix
        m1 = min(math.ceil((float(np.max(a1)) - b1) / pix) + TAPS + 1, n1)
        # the image basebanded, I(b0, b1) exp(-j (kr_m b1 - kc_m b0)) with I = sum G(kr, kc)
        # exp(-j (kc b0 - kr b1)) and (kc_m, kr_m) the middle of the rectangle, on the FFT
        # grids from (b0, b1): its spectrum about zero, so it interpolates
        kc_m, kr_m = 0.5 * (kc[0] + kc[-1]), 0.5 * (kr[0] + kr[-1])
        i_c, i_r = np.arange(kc.size), np.arange(kr.size)
        u, v = np.arange(m0) * pix + b0, np.arange(m1) * pix + b1
        g *= np.exp(-1j * (kc[1] - kc[0]) * b0 * i_c)[None, :].astype(np.complex64)
        img = scipy.fft.fft(g, n0, axis=1, workers=1)[:, :m0]
        img *= np.exp(-1j * (kc[0] - kc_m) * u)[None, :].astype(np.complex64)
        img = np.ascontiguousarray(img.T)
        img *= np.exp(1j * (kr[1] - kr[0]) * b1 * i_r)[None, :].astype(np.complex64)
        img = scipy.fft.ifft(img, n1, axis=1, workers=1)[:, :m1] * n1
        img *= np.exp(1j * (kr[0] - kr_m) * v)[None, :].astype(np.complex64)
        # read it where the pixels' points lie, range first; the carrier back on
        part = sinc_interp(img, (a1 - b1) / pix, TAPS)
        data = sinc_interp(np.ascontiguousarray(part.T), ((a0 - b0) / pix).T, TAPS).T
        data *= np.exp(1j * (kr_m * a1_pix - kc_m * a0)).astype(np.complex64)
        scale = rc.shape[0] * 2.0 * self.bandwidth_hz * self._dr / (C_MPS * kr.size * kc.size)
        return np.ascontiguousarray(data * scale, dtype=np.complex64)


def _samples(lo: float, hi: float, step: float, pixel_m: float) -> FloatArray:
    """Uniform spatial frequencies ``step`` apart over ``[lo, hi]`` (rad/m), narrowed about
    its centre to what pixels ``pixel_m`` apart hold (:data:`PIXEL_BAND` of ``2 pi / pixel``)."""
    width = min(hi - lo, PIXEL_BAND * 2.0 * np.pi / pixel_m)
    n = max(2, math.floor(width / step) + 1)
    mid = 0.5 * (lo + hi)
    return mid + step * (np.arange(n, dtype=np.float64) - (n - 1) / 2.0)


def _apparent(
    apc: FloatArray, centre: FloatArray, dx: FloatArray, dy: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Where the points at ground offsets ``(dx, dy)`` (axis 0, axis 1; arrays that
    broadcast together) from ``centre`` (m) lie in the polar format image of pulses at
    ``apc`` (m): ``(a0', a1')``, of the broadcast shape, m.

    The deramped phase ``-k (R_t - R_c)`` of a point is ``kc a0' - kr a1'`` to first order:
    ``a0'`` is its slope over the aperture per unit of ``g_c`` (first to last pulse), and
    ``a1' = mean(R_t - R_c + g_c a0') / mean(g_r)`` over the aperture (Simpson's rule on the
    first, middle and last pulse), so that the point's peak has the phase of
    backprojection's.
    """
    delta, g_r, g_c = [], [], []
    for p in (apc[0], apc[apc.shape[0] // 2], apc[-1]):
        d = centre - p
        r_c = math.sqrt(float(d @ d))
        r_t = np.sqrt((d[0] + dx) ** 2 + (d[1] + dy) ** 2 + d[2] ** 2)
        delta.append(r_t - r_c)
        g_r.append(float(d[1]) / r_c)  # -u . e1, u from the centre to the APC
        g_c.append(float(-d[0]) / r_c)
    a0 = -(delta[2] - delta[0]) / (g_c[2] - g_c[0])
    weights = (1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0)
    num = sum(w * (d + c * a0) for w, d, c in zip(weights, delta, g_c, strict=True))
    den = sum(w * r for w, r in zip(weights, g_r, strict=True))
    return np.asarray(a0), np.asarray(num / den)
