"""Phase gradient autofocus of backprojected stripmap tiles (image-domain stripmap PGA).

A stripmap tile (:mod:`sarmoco.processing.imaging.tiles`) is a ground grid, axis 0 = x
along a straight reference track, axis 1 = ground range y, backprojected from pulses
whose APCs lie on the track at ``x_p = v0 (t - t0)``. At a fixed ground range, the slant
range to the track is ``R = sqrt(y² + H²)`` and backprojection is a convolution in x of
the pulses' echo phase history ``d(x_p)`` with the kernel ``c(u) = exp(+j 2k sqrt(u² + R²))``
(``k = 2π/λ``, ``R tan ψ_lo <= u <= R tan ψ_hi`` with beam culling, ``[ψ_lo, ψ_hi]`` the
squint interval of the beam from the plane normal to the track: ``±θ/2`` broadside,
shifted by the crab of a platform in a crosswind). Its spectrum has, by stationary phase,
the phase ``Ψ(k_x) = R sqrt(4k² - k_x²)`` (constants dropped) and a flat magnitude in the
band ``2k sin ψ_lo <= k_x <= 2k sin ψ_hi``, so one column's phase history is recovered
from the image as ``d = IFFT(FFT(I) exp(-j Ψ))``, sampled at the pixel spacing on the
same x axis. The pixel spacing need only sample the band's width: the FFT's wavenumbers
are taken about the band's centre (a squinted band beyond the pixel's Nyquist wavenumber
is aliased in the image, not lost). A phase error ``φ(x_p)`` common to all ranges (an LOS
error the INS and the sliding-subaperture autofocus left) multiplies ``d``; it is removed
by ``exp(-j φ)`` and the column is recompressed with ``exp(+j Ψ)`` within the band.

Estimation (stripmap PGA, after Callow, Hayes & Gough, IEEE JOE 2003, in this
decompression form), per iteration: the peak column of each bright target (one column per
target, ``guard_m`` apart: the columns beside a range peak hold phase histories bent by
range migration) is windowed around its brightest pixel (the window shrinks with the
iterations as in :func:`~sarmoco.processing.autofocus.pga.pga`), decompressed and
dechirped with its own kernel ``c(x_t - x_p)``, which leaves ``exp(j φ(x_p))`` over that
target's aperture only; the phase of the same operation on an ideal focused point (the
kernel's Fresnel ripple near the aperture ends) is removed. Targets at different x see
different parts of ``φ``, so each target's phase differences are taken on the common
``x_p`` axis and its own mean gradient is removed (a phase linear over one aperture only
moves that target, and its sub-pixel offset is such a term) before the maximum-likelihood
sum ``Δφ(n) = arg Σ_i h_i(n)``, ``h_i(n) = g_i*(n) g_i(n+1) exp(-j b_i)``. An update that
lowers the sharpness ``Σ |I|⁴`` of the selected lines is not taken, so a focused tile
comes out unchanged.

Approximations: the stationary-phase kernel for decompression (the phase error varies
slowly against the azimuth chirp); one carrier wavenumber for the whole range band and
one phase error for all ranges of the tile; columns processed independently, although
the response of a pulse near the aperture ends runs across range columns (range
migration over the window: with 1 rad rms errors of 10 Hz bandwidth, correcting the
true phase this way still leaves -13.0 dB azimuth PSLR, not -13.26; under a squinted beam
``ψ`` the range walk moves the paired echoes of an error of ``f`` Hz ``λ R f sin ψ / (2 v)``
off the column, so only errors slow enough to leave them within a range cell are
estimated); the APCs on the
straight track at the pixel spacing (the daemon's along-track time map puts them there).
Phase linear over the whole estimation support is removed (it would shift the image).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy import fft as sfft

from sarmoco.errors import ProcessingError
from sarmoco.keys import key
from sarmoco.processing.imaging.tiles import Tile
from sarmoco.processing.types import BoolArray, ComplexArray, FloatArray, IntArray

MIN_WINDOW_PX = 16
"""Smallest PGA window, pixels along track."""

APERTURE_LEVEL = 0.1
"""A target's phase history is used where its focused reference exceeds this fraction of
its maximum amplitude (inside its aperture)."""

SELECT_DB = 20.0
"""A column is used only if its peak power is this far above the tile's median pixel power."""


@dataclass(frozen=True)
class TilePgaConfig:
    """Settings of tile PGA.

    Each field is a configuration key (:func:`sarmoco.keys.key`): the daemon's
    ``[autofocus]`` section is :class:`~sarmoco.processing.autofocus.settings.AutofocusConfig`
    plus this class plus the daemon's switches, and is handed to :class:`StripPga` as it is.
    """

    pga_iterations: int = key(6, "Tile PGA iterations at most", gt=0)
    pga_window_m: float = key(
        12.0,
        "Along-track width of tile PGA's first window around each target; it must hold the "
        "paired echoes (lambda R f / (2 v) from the peak) of the fastest phase error to remove",
        unit="m",
        gt=0,
    )


@dataclass(frozen=True)
class StripPga:
    """Image-domain stripmap PGA on a ground grid along a straight track.

    Parameters
    ----------
    height_m : float
        Height of the track above the ground plane of the grid, m.
    wavelength_m : float
        Carrier wavelength, m.
    half_beam_rad : float
        Half the azimuth angle the pixels took pulses over (beam culling), rad: the
        broadside squint interval ``±half_beam_rad`` that :meth:`focus` takes by default.
    settings : TilePgaConfig
        ``pga_window_m``: along-track width of the first iteration's window around each
        target, m; it must hold the paired echoes of the fastest phase error to be
        corrected (``λ R f / (2 v)`` from the peak for an error of ``f`` Hz).
        ``pga_iterations``: at most this many iterations.
    n_lines : int
        Range columns (brightest peaks first) used for the estimate.
    tol_rad : float
        Stop when the RMS update over the estimation support is below this, rad.
    guard_m : float
        Two columns used are at least this far apart in ground range, m (ten range
        resolution cells keep a target's range sidelobes above -30 dB out).
    """

    height_m: float
    wavelength_m: float
    half_beam_rad: float
    settings: TilePgaConfig = field(default_factory=TilePgaConfig)
    n_lines: int = 32
    tol_rad: float = 0.02
    guard_m: float = 2.0

    def __post_init__(self) -> None:
        for name in ("wavelength_m", "half_beam_rad", "n_lines"):
            if not getattr(self, name) > 0:
                raise ProcessingError(f"StripPga.{name}: {getattr(self, name)!r} is not > 0")
        for name in ("pga_window_m", "pga_iterations"):
            if not getattr(self.settings, name) > 0:
                raise ProcessingError(
                    f"StripPga.settings.{name}: {getattr(self.settings, name)!r} is not > 0"
                )

    def focus(
        self,
        data: ComplexArray,
        pixel_m: float,
        ground_range_m: FloatArray,
        squint_rad: tuple[float, float] | None = None,
    ) -> tuple[ComplexArray, FloatArray]:
        """Estimate and remove the azimuth phase error of an image strip.

        Parameters
        ----------
        data : ndarray of complex, shape (N0, N1)
            Backprojected strip, axis 0 along track (uniform ``pixel_m``), axis 1 ground
            range (uniform).
        pixel_m : float
            Along-track pixel spacing, m.
        ground_range_m : ndarray, shape (N1,)
            Ground range y of each column, m.
        squint_rad : (float, float), optional
            Squint interval ``(ψ_lo, ψ_hi)`` the pixels took pulses over, from the plane
            normal to the track, rad (positive: ahead); the union over the strip's pulses.
            Default: broadside, ``±half_beam_rad``.

        Returns
        -------
        corrected : ndarray of complex64, shape (N0, N1)
            The strip with ``exp(-j φ)`` applied to its phase history.
        phase : ndarray, shape (N0,)
            Estimated phase error ``φ`` at the along-track positions of the rows, rad
            (zero when nothing was estimated; held at its end values beyond the
            estimation support, and used up to a half aperture beyond the strip).
        """
        n0 = data.shape[0]
        k0 = 4.0 * math.pi / self.wavelength_m
        lo, hi = (-self.half_beam_rad, self.half_beam_rad) if squint_rad is None else squint_rad
        if not -math.pi / 2 < lo < hi < math.pi / 2:
            raise ProcessingError(f"tile PGA: squint interval ({lo}, {hi}) rad is not ordered")
        width = k0 * (math.sin(hi) - math.sin(lo))
        if width * pixel_m > 2.0 * math.pi:
            raise ProcessingError(
                f"tile PGA: pixel {pixel_m} m is coarser than the azimuth band needs "
                f"({2.0 * math.pi / width:.3g} m for λ = {self.wavelength_m} m and a beam "
                f"over squints {lo:.4g} to {hi:.4g} rad)"
            )
        y = np.asarray(ground_range_m, dtype=np.float64)
        slant = np.hypot(y, self.height_m)
        reach = float(slant.max()) * max(abs(math.tan(lo)), abs(math.tan(hi)))
        pad = math.ceil(reach / pixel_m) + 8
        axis = _PaddedAxis(pad, n0, sfft.next_fast_len(n0 + 2 * pad), pixel_m, k0, (lo, hi))
        guard = round(self.guard_m / abs(float(y[1] - y[0])))
        cols = _bright_columns(np.abs(data) ** 2, self.n_lines, guard)
        if cols.size == 0:
            return np.asarray(data, dtype=np.complex64), np.zeros(n0)
        comp = axis.compression(slant[cols])
        hist = axis.decompress(data[:, cols], comp)
        total = self._estimate(hist, slant[cols], comp, axis)
        if not np.any(total):
            return np.asarray(data, dtype=np.complex64), np.zeros(n0)
        out = np.empty(data.shape, dtype=np.complex64)
        corr = np.exp(-1j * total)[:, None]
        for j0 in range(0, y.size, 64):  # 64 columns at a time bound the memory
            sl = slice(j0, min(y.size, j0 + 64))
            comp = axis.compression(slant[sl])
            hist = axis.decompress(data[:, sl], comp) * corr
            out[:, sl] = axis.recompress(hist, comp)[pad : pad + n0]
        return out, total[pad : pad + n0]

    def _estimate(
        self, hist: ComplexArray, rho: FloatArray, comp: ComplexArray, axis: _PaddedAxis
    ) -> FloatArray:
        """Iterated phase error on the padded x_p axis of ``axis``, rad.

        ``hist`` holds the phase histories of the selected columns, ``rho`` their slant
        ranges (m), ``comp`` their :meth:`_PaddedAxis.compression`.
        """
        pad, n0 = axis.pad, axis.n0
        rows = np.arange(axis.n_fft)
        total = np.zeros(axis.n_fft)
        width = max(MIN_WINDOW_PX, round(self.settings.pga_window_m / axis.pixel_m))
        focused = np.asarray(sfft.ifft(np.abs(axis.kernel(rho)) ** 2, axis=0))
        img = axis.recompress(hist, comp)
        for it in range(self.settings.pga_iterations):
            peaks = pad + np.argmax(np.abs(img[pad : pad + n0]), axis=0)
            if it:
                width = max(MIN_WINDOW_PX, min(width, _window_width(img, peaks)))
            half = width // 2
            sel = np.flatnonzero((peaks - half >= pad) & (peaks + half < pad + n0))
            if sel.size == 0:
                break
            win = np.abs(rows[:, None] - peaks[None, sel]) <= half
            u = (peaks[None, sel] - rows[:, None]) * axis.pixel_m
            r = rho[None, sel]
            dechirp = np.exp(1j * axis.wavenum * (u**2 / (np.sqrt(u**2 + r**2) + r)))
            g = axis.decompress(img[:, sel] * win, comp[:, sel]) * dechirp
            # the same for a focused point at the peak: the Fresnel phase ripple of the
            # kernel near the aperture ends, which is not a phase error
            idx = (rows[:, None] - peaks[None, sel]) % axis.n_fft
            ref = np.take_along_axis(focused[:, sel], idx, axis=0) * win
            ref = axis.decompress(ref, comp[:, sel]) * dechirp
            inside = np.abs(ref) > APERTURE_LEVEL * np.abs(ref).max(axis=0)[None, :]
            g = g * np.exp(-1j * np.angle(ref)) * inside
            h = np.conj(g[:-1]) * g[1:]
            h *= np.exp(-1j * np.angle(np.sum(h, axis=0)))[None, :]
            acc = np.sum(h, axis=1)
            support = np.abs(acc) > 1e-6 * float(np.max(np.abs(acc)))
            phi = np.concatenate([[0.0], np.cumsum(np.where(support, np.angle(acc), 0.0))])
            edge = np.concatenate([support, [False]]) | np.concatenate([[False], support])
            phi = _detrend(phi, edge)
            new = axis.recompress(hist * np.exp(-1j * (total + phi))[:, None], comp)
            if _sharpness(new[pad : pad + n0]) <= _sharpness(img[pad : pad + n0]):
                break  # an update that blurs the selected lines is not taken
            total += phi
            img = new
            if float(np.sqrt(np.mean(phi[edge] ** 2))) < self.tol_rad:
                break
        return total


@dataclass(frozen=True)
class _PaddedAxis:
    """The along-track axis padded by ``pad`` rows each side, and the BP kernel on it.

    Row ``n`` is at ``x_0 + (n - pad) * pixel_m`` (``x_0`` the strip's first row); the
    padding holds the phase history of targets up to a half aperture beyond the strip.
    """

    pad: int
    n0: int
    n_fft: int
    pixel_m: float
    wavenum: float
    """Two-way carrier wavenumber K = 4π/λ, rad/m."""
    squint_rad: tuple[float, float]
    """Squint interval (lo, hi) the pixels took pulses over, rad (positive: ahead)."""

    @cached_property
    def kx(self) -> FloatArray:
        """Along-track wavenumber of each FFT bin, rad/m: the one of its aliases within a
        sampling band (``2π / pixel_m`` wide) centred on the beam's band."""
        centre = self.wavenum * float(np.mean(np.sin(self.squint_rad)))
        span = 2.0 * math.pi / self.pixel_m
        kx = 2.0 * math.pi * np.fft.fftfreq(self.n_fft, self.pixel_m)
        return np.asarray(centre + (kx - centre + span / 2.0) % span - span / 2.0, np.float64)

    def compression(self, rho: FloatArray) -> ComplexArray:
        """``exp(j R (sqrt(K² - k_x²) - K))`` per FFT bin and line (lines on axis 1, slant
        ``R``): what :meth:`recompress` applies and :meth:`decompress` takes back."""
        kx2 = self.kx**2
        psi = -kx2 / (np.sqrt(self.wavenum**2 - kx2) + self.wavenum)  # no cancellation
        return np.exp(1j * psi[:, None] * np.asarray(rho)[None, :])

    def decompress(self, lines: ComplexArray, comp: ComplexArray) -> ComplexArray:
        """Phase histories (padded rows) of image lines (strip rows, or padded rows);
        ``comp``: the lines' :meth:`compression`."""
        if lines.shape[0] == self.n0:
            lines = np.concatenate([np.zeros((self.pad, lines.shape[1]), lines.dtype), lines])
        spec = sfft.fft(lines, n=self.n_fft, axis=0)
        return np.asarray(sfft.ifft(spec * np.conj(comp), axis=0))

    def recompress(self, hist: ComplexArray, comp: ComplexArray) -> ComplexArray:
        """Image lines (padded rows) of phase histories, limited to the beam's band;
        ``comp``: the lines' :meth:`compression`.

        Backprojection passes only the beam's band (beam culling); a phase
        correction spreads the band of a phase history, so the band is cut again
        (without this cut, a 1 rad rms phase error corrected with its true value still
        left targets at -12.6 dB azimuth PSLR).
        """
        spec = sfft.fft(hist, axis=0) * comp * self.band[:, None]
        return np.asarray(sfft.ifft(spec, axis=0))

    def kernel(self, rho: FloatArray) -> ComplexArray:
        """Spectrum ``C(k_x)`` of the backprojection kernel of each line (slant ``rho``).

        ``c(u) = exp(j K (sqrt(u² + R²) - R))`` for ``R tan ψ_lo <= u <= R tan ψ_hi`` (beam
        culling), sampled at the pixel spacing on the circular padded axis: the exact kernel, with
        the Fresnel ripple at its band edges that the stationary-phase form lacks.
        """
        n = np.arange(self.n_fft)
        u = np.where(n < (self.n_fft + 1) // 2, n, n - self.n_fft)[:, None] * self.pixel_m
        r = rho[None, :]
        c = np.exp(1j * self.wavenum * (u**2 / (np.sqrt(u**2 + r**2) + r)))
        lo, hi = np.tan(self.squint_rad)
        c *= (u >= r * lo) & (u <= r * hi)
        return np.asarray(sfft.fft(c, axis=0))

    @cached_property
    def band(self) -> BoolArray:
        """FFT bins inside the beam's band ``K sin ψ_lo <= k_x <= K sin ψ_hi``."""
        lo, hi = self.wavenum * np.sin(self.squint_rad)
        return np.asarray((self.kx >= lo) & (self.kx <= hi))


def _bright_columns(power: FloatArray, n_lines: int, guard: int) -> IntArray:
    """Up to ``n_lines`` columns, brightest peak first, at least ``guard`` columns apart.

    A column next to a target's range peak holds its range mainlobe flank or sidelobes,
    whose phase history the range migration bends (0.7 rad over an aperture two columns
    from the peak in the test geometry): only the peak column of each target is taken.
    Columns whose peak is not ``SELECT_DB`` above the median pixel power are never taken.
    """
    peak = power.max(axis=0)
    floor = float(np.median(power)) * 10.0 ** (SELECT_DB / 10.0)
    blocked = np.zeros(peak.size, dtype=bool)
    taken: list[int] = []
    for j in np.argsort(peak)[::-1]:
        if len(taken) >= n_lines or peak[j] <= floor:
            break
        if not blocked[j]:
            taken.append(int(j))
            blocked[max(0, j - guard) : j + guard + 1] = True
    return np.sort(np.array(taken, dtype=np.int64))


def _sharpness(lines: ComplexArray) -> float:
    """Normalised sharpness ``Σ |I|⁴ / (Σ |I|²)²`` of image lines; grows as they focus."""
    power = np.abs(lines) ** 2
    return float(np.sum(power**2) / np.sum(power) ** 2)


def _window_width(img: ComplexArray, peaks: np.ndarray) -> int:
    """Width (rows) of twice the -20 dB extent of the peak-centred non-coherent average."""
    n = img.shape[0]
    idx = (np.arange(n)[:, None] + peaks[None, :]) % n
    avg = np.mean(np.abs(np.take_along_axis(img, idx, axis=0)) ** 2, axis=1)
    above = np.fft.fftshift(avg >= avg[0] * 0.01)
    c = n // 2
    left = c
    while left > 0 and above[left - 1]:
        left -= 1
    right = c
    while right < n - 1 and above[right + 1]:
        right += 1
    return int(2 * (2 * max(c - left, right - c) + 1))


def _detrend(phi: FloatArray, support: np.ndarray) -> FloatArray:
    """``phi`` less its mean and linear trend over ``support``, held flat outside it."""
    n = np.arange(phi.size, dtype=float)
    if np.count_nonzero(support) < 2:
        return np.zeros_like(phi)
    fit = np.polyfit(n[support], phi[support], 1)
    out = phi - np.polyval(fit, n)
    first, last = np.flatnonzero(support)[[0, -1]]
    out[:first] = out[first]
    out[last + 1 :] = out[last]
    return out


@dataclass
class TilePga:
    """Stripmap PGA on the tiles of one :class:`~sarmoco.processing.imaging.tiles.TileImager`.

    Tile edges cut target responses (and the phase history a target leaves in a tile is
    that of a whole aperture, several tiles long), so each tile is focused as the middle
    of the strip it forms with its neighbours: a tile is handed out when the next one
    arrives (one tile of latency), corrected with the phase estimated on the strip
    ``[k-1, k, k+1]`` (the raw neighbours: each tile is corrected once, from raw pixels).
    Tiles that are not contiguous in index are focused without the missing neighbour.

    Parameters
    ----------
    pga : StripPga
        The estimator and its settings.
    """

    pga: StripPga
    _prev: Tile | None = field(default=None, init=False)
    _held: Tile | None = field(default=None, init=False)

    def push(self, tiles: list[Tile], squint_rad: tuple[float, float] | None = None) -> list[Tile]:
        """Take finished tiles (in index order); return the tiles now focused.

        ``squint_rad``: the squint interval the tiles' pixels took pulses over (rad,
        :meth:`StripPga.focus`); default broadside.
        """
        out: list[Tile] = []
        for tile in tiles:
            held = self._held
            if held is not None:
                nxt = tile if tile.index == held.index + 1 else None
                out.append(self._focus(held, nxt, squint_rad))
                self._prev = held if nxt is not None else None
            self._held = tile
        return out

    def flush(self, squint_rad: tuple[float, float] | None = None) -> list[Tile]:
        """Focus and hand out the tile still held (end of the segment or run)."""
        if self._held is None:
            return []
        tile = self._focus(self._held, None, squint_rad)
        self._prev = self._held = None
        return [tile]

    def _focus(self, tile: Tile, nxt: Tile | None, squint_rad: tuple[float, float] | None) -> Tile:
        prev = self._prev if self._prev is not None and self._prev.index == tile.index - 1 else None
        parts = [t for t in (prev, tile, nxt) if t is not None]
        strip = np.concatenate([t.data for t in parts], axis=0)
        axis0 = tile.grid.axis0_m
        pixel = float(axis0[1] - axis0[0])
        focused, _ = self.pga.focus(strip, pixel, tile.grid.axis1_m, squint_rad)
        first = 0 if prev is None else prev.data.shape[0]
        return replace(tile, data=focused[first : first + tile.data.shape[0]])
