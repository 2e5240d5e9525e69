"""Backprojection on a grid coarser than the tiles', where the pixels are finer than the band.

A tile's cost is pixels × pulses. Asked for pixels several times finer than the
resolution, direct backprojection spends most of it on samples the image's band does not
need. The image of a block of pulses holds, about the line of sight's carrier, a band of
spatial frequencies bounded across the track by the range samples (``sin(look) / dr``
cycles/m in ground range) and along it by the pulses' squint interval
``[psi_lo, psi_hi]`` (``2 sin(psi) / lambda`` cycles/m: a pixel takes no pulse outside it).
With the carrier removed, that band is sampled well enough on a grid a few times coarser
(:func:`coarse_factors`, per axis); the tile imager forms such blocks there and
interpolates the sum onto the tile's grid once, when the tile is handed out.

The carrier of a coarse image is that of its blocks' squint ``psi_c``:

    phi(a, c) = (4 pi / lambda) (sin(psi_c) a + cos(psi_c) sqrt(c^2 + h^2))

(``a`` along track, ``c`` ground range from the track, ``h`` the track's height). A block
joins a coarse image only when its band, about that carrier, lies within
:data:`USABLE` cycles per coarse sample; a block that fits none (a squint that has moved
on, a beam widened while its pointing is uncertain) starts another coarse image, up to
:data:`MAX_IMAGES` per tile: coarse on both axes where its band allows, else across the
track only (the range band does not widen with the beam), else it goes to the tile's own
grid. The interpolation is the
Kaiser-windowed sinc of :mod:`sarmoco.processing.imaging.interp` with :data:`TAPS` taps,
and each coarse grid reaches :data:`MARGIN` samples beyond the tile on every side, so
that the samples near a tile's edge have the kernel's full support.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sarmoco.processing.beam import PER_METRE, doppler_hz, squint_sine
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.imaging.interp import sinc_interp, sinc_interp_columns
from sarmoco.processing.types import ComplexArray, FloatArray

TAPS = 32
"""Interpolation kernel length, coarse samples."""

MARGIN = TAPS // 2
"""Coarse samples beyond each edge of the tile."""

USABLE = 0.42
"""Largest spatial frequency about the carrier a coarse image holds, cycles per coarse
sample (the kernel's error on a tone stays below 5e-4 up to there)."""

BAND_USE = 0.25
"""Share of a coarse sample's cycles that the nominal band (the layout's beam, the range
samples) may take when the factor is chosen; the rest is room for the carrier to move."""

MAX_FACTOR = 4
"""Largest coarsening of either axis."""

MAX_IMAGES = 3
"""Coarse images per tile (each one interpolation when the tile is handed out)."""


def coarse_factors(
    pixel_m: float,
    beam_rad: float,
    wavelength_m: float,
    range_bin_m: float,
    far_look_rad: float,
) -> tuple[int, int]:
    """How many times coarser than ``pixel_m`` blocks may be formed along track and across
    (1: not at all).

    Parameters
    ----------
    pixel_m : float
        The tiles' pixel spacing, m.
    beam_rad : float
        The squint interval's nominal width (the layout's beam), rad.
    wavelength_m : float
        Carrier wavelength, m.
    range_bin_m : float
        Spacing of the range-compressed samples, slant range, m.
    far_look_rad : float
        Look angle (from the vertical) of the swath's far edge, rad.
    """
    along = float(doppler_hz(PER_METRE, wavelength_m, beam_rad / 2.0))  # cycles/m either side
    across = 0.5 * math.sin(far_look_rad) / range_bin_m

    def factor(half: float) -> int:
        return max(1, min(MAX_FACTOR, int(BAND_USE / (half * pixel_m))))

    return factor(along), factor(across)


def along_band(beam_squint_rad: FloatArray, wavelength_m: float) -> tuple[float, float]:
    """Lowest and highest along-track frequency a block's pulses put into the image,
    cycles/m, from their squint intervals (P, 2), rad."""
    edges = [np.min(beam_squint_rad[:, 0]), np.max(beam_squint_rad[:, 1])]
    lo, hi = doppler_hz(PER_METRE, wavelength_m, np.array(edges))
    return float(lo), float(hi)


def band_fits(band: tuple[float, float], centre: float, step_m: float) -> bool:
    """Whether an along-track band (cycles/m) lies within :data:`USABLE` cycles per sample of
    spacing ``step_m`` about the carrier ``centre`` (cycles/m)."""
    return max(abs(band[0] - centre), abs(band[1] - centre)) * step_m <= USABLE


@dataclass
class CoarseImage:
    """Blocks of one tile formed on a coarser grid about one carrier.

    Attributes
    ----------
    centre : float
        Along-track carrier, cycles/m (``2 sin(psi_c) / lambda``).
    factor : tuple of int
        Coarsening along track and across (:func:`coarse_grid`).
    grid : PlaneGrid
        The coarse grid.
    data : ndarray of complex64
        The sum of its blocks' backprojections.
    """

    centre: float
    factor: tuple[int, int]
    grid: PlaneGrid
    data: ComplexArray

    def takes(self, band: tuple[float, float]) -> bool:
        """Whether a block of along-track band ``band`` (cycles/m) fits this carrier."""
        return band_fits(band, self.centre, float(self.grid.axis0_m[1] - self.grid.axis0_m[0]))


def coarse_grid(fine: PlaneGrid, factor: tuple[int, int]) -> PlaneGrid:
    """The grid ``factor`` times coarser than ``fine`` along each axis, through its first
    pixel and, along a coarsened axis, :data:`MARGIN` samples beyond it on either side."""
    axes = []
    for ax, f in zip((fine.axis0_m, fine.axis1_m), factor, strict=True):
        margin = MARGIN if f > 1 else 0
        n = -(-ax.size // f) + 2 * margin
        axes.append(ax[0] + f * float(ax[1] - ax[0]) * (np.arange(n) - margin))
    return PlaneGrid(axes[0], axes[1], fine.origin_m, fine.heading_rad, fine.frame)


def add_upsampled(
    out: ComplexArray, fine: PlaneGrid, coarse: CoarseImage, wavelength_m: float
) -> None:
    """Add a coarse image, interpolated onto ``fine``, to ``out`` (in place).

    The grids lie on the plane ``origin_m[2]`` below the track, axis 1 the distance from it
    (:class:`~sarmoco.processing.imaging.tiles.TileLayout`).
    """
    k = 4.0 * np.pi / wavelength_m
    sine = float(squint_sine(coarse.centre, PER_METRE, wavelength_m))
    cosine = math.sqrt(max(0.0, 1.0 - sine * sine))
    depth = float(fine.origin_m[2])

    def phasors(grid: PlaneGrid, sign: float) -> tuple[ComplexArray, ComplexArray]:
        along = np.exp(sign * 1j * k * sine * grid.axis0_m)
        across = np.exp(sign * 1j * k * cosine * np.hypot(grid.axis1_m, depth))
        return along.astype(np.complex64), across.astype(np.complex64)

    rows, cols = phasors(coarse.grid, -1.0)
    value: ComplexArray = coarse.data * rows[:, None] * cols[None, :]
    f0, f1 = coarse.factor
    if f0 > 1:
        value = sinc_interp_columns(value, MARGIN + np.arange(fine.axis0_m.size) / f0, TAPS)
    if f1 > 1:
        at = MARGIN + np.arange(fine.axis1_m.size) / f1
        value = sinc_interp(value, at[None, :], TAPS)
    rows, cols = phasors(fine, 1.0)
    out += value * rows[:, None] * cols[None, :]
