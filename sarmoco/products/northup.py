"""North-up complex images: a focused ground image resampled onto a north/east grid.

The tiles lie on their reference track's ground grid (axis 0 along the track, axis 1
ground range), which turns with the course flown. :func:`north_up` puts the same complex
image on a grid whose axes are north and east, so that positions read off it are NED
coordinates whatever the course.

A focused image is not band-limited at its pixel spacing: each pixel carries the two-way
phase of the line of sight, ``exp(j 4 pi R / lambda)``, whose gradient (tens of cycles per
metre across range, and ``2 sin psi / lambda`` along track under a squint ``psi``) aliases
on any practical grid. The resampling therefore removes that carrier, interpolates the
slowly varying remainder (cubic B-spline) and puts the carrier back at the new pixels:

    phi(a, c) = phi_a(a) + (4 pi / lambda) cos(psi) sqrt(c^2 + h^2)

with ``a``, ``c`` the pixel's along-track and ground-range coordinates, ``h`` the depth of
the ground below the reference track and ``phi_a`` the integral of the along-track carrier
``2 pi f(a)``. ``f`` is measured from the image itself (lag-one correlation along track,
per block of rows, the Doppler centroid's spatial frequency), its ambiguity by the sampling
rate resolved with the beam's squint where it is known, so the phase of the result is that
of the image at the new pixels, not only its amplitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.ndimage import spline_filter

from sarmoco.daemon.config import parse_config
from sarmoco.errors import ProcessingError
from sarmoco.processing.beam import (
    PER_METRE,
    accc_correlation,
    doppler_hz,
    resolve_ambiguity,
    squint_sine,
)
from sarmoco.processing.types import ComplexArray, FloatArray, Image
from sarmoco.products.georeference import beam_squint_rad, ned_frame, segment_images
from sarmoco.store.reader import open_store
from sarmoco.store.recorder import write_north_up

CARRIER_ROWS = 128
"""Rows of the image per along-track carrier estimate."""


@dataclass(frozen=True)
class NorthUpImage:
    """A complex image on a north/east grid.

    Attributes
    ----------
    data : ndarray of complex64, shape (N, E)
        Pixels; zero outside the source image's footprint.
    north_m, east_m : ndarray of float64, shapes (N,), (E,)
        Pixel-centre coordinates, m, in the frame of the source's ``origin_ned``.
    """

    data: ComplexArray
    north_m: FloatArray
    east_m: FloatArray


def along_track_carrier(
    image: Image, depth_m: float, wavelength_m: float, squint_rad: float | None = None
) -> FloatArray:
    """The image's along-track carrier at each row (axis 0), cycles per metre.

    Per block of :data:`CARRIER_ROWS` rows, the ACCC of the range-demodulated rows
    (:func:`~sarmoco.processing.beam.accc_correlation`, the rows as pulses at one per pixel
    spacing), unwrapped along track and interpolated to every row.

    Parameters
    ----------
    image : Image
        Ground image, axis 0 along track, axis 1 ground range from the track (m).
    depth_m : float
        Depth of the ground below the reference track, m.
    wavelength_m : float
        Carrier wavelength, m.
    squint_rad : float, optional
        Squint of the beam centre (positive ahead) that formed the image: picks the carrier
        among those the row spacing cannot tell apart. None: the one nearest zero.
    """
    a, c = image.axis0_m, image.axis1_m
    step = float(a[1] - a[0])
    k = 4.0 * np.pi / wavelength_m
    base = image.data * np.exp(-1j * k * np.hypot(c, depth_m)).astype(np.complex64)[None, :]
    parts = np.array_split(np.arange(a.size - 1), max(1, (a.size - 1) // CARRIER_ROWS))
    acc = np.array([accc_correlation(base[p[0] : p[-1] + 2]) for p in parts])
    centre = np.array([a[p].mean() for p in parts]) + step / 2.0
    power = np.abs(acc)
    if not power.max() > 0:
        return np.zeros(a.size)
    lit = power > 1e-3 * power.max()
    cycles = np.unwrap(np.angle(acc[lit])) / (2.0 * np.pi * step)  # continuous along track
    per_row = np.interp(a, centre[lit], cycles)
    expected = 0.0 if squint_rad is None else float(doppler_hz(PER_METRE, wavelength_m, squint_rad))
    weights = power[lit]
    mean = float(np.sum(weights * cycles) / np.sum(weights))
    return np.asarray(per_row + resolve_ambiguity(mean, expected, 1.0 / step) - mean)


def north_up(
    image: Image,
    origin_ned: FloatArray,
    e0_ned: FloatArray,
    e1_ned: FloatArray,
    depth_m: float,
    wavelength_m: float,
    squint_rad: float | None = None,
) -> NorthUpImage:
    """Resample a ground image onto a north/east grid of its own pixel spacing.

    Parameters
    ----------
    image : Image
        Ground image: pixel ``(i, j)`` at ``origin + axis0[i] e0 + axis1[j] e1`` on the
        ground ``depth_m`` below the reference track (the line through ``origin`` along
        ``e0``); equal spacing on both axes.
    origin_ned, e0_ned, e1_ned : ndarray, shape (3,)
        The grid's origin (NED, m) and its horizontal unit axes (NED).
    depth_m : float
        Depth of the ground below the reference track, m.
    wavelength_m : float
        Carrier wavelength, m.
    squint_rad : float, optional
        Squint of the beam centre that formed the image, rad (:func:`along_track_carrier`).

    Raises
    ------
    ProcessingError
        The image's axes are not equally spaced, or its unit axes are not horizontal and
        orthonormal.
    """
    a, c = np.asarray(image.axis0_m, np.float64), np.asarray(image.axis1_m, np.float64)
    step = float(a[1] - a[0])
    if not np.isclose(c[1] - c[0], step, rtol=1e-6):
        raise ProcessingError(f"north_up: pixel spacing {step} m along, {c[1] - c[0]} m across")
    e0, e1 = (np.asarray(e, np.float64)[:2] for e in (e0_ned, e1_ned))
    if not np.allclose([e0 @ e0, e1 @ e1, e0 @ e1], [1.0, 1.0, 0.0], atol=1e-9):
        raise ProcessingError("north_up: e0, e1 are not orthonormal horizontal axes")
    k = 4.0 * np.pi / wavelength_m
    carrier = along_track_carrier(image, depth_m, wavelength_m, squint_rad)
    mean_sine = float(squint_sine(float(np.mean(carrier)), PER_METRE, wavelength_m))
    cos_psi = float(np.sqrt(max(0.0, 1.0 - mean_sine**2)))
    phi_a = 2.0 * np.pi * cumulative_trapezoid(carrier, dx=step, initial=0.0)

    # the carrier is separable: one exponential per row times one per column
    along_turn = np.exp(-1j * phi_a).astype(np.complex64)
    across_turn = np.exp(-1j * k * cos_psi * np.hypot(c, depth_m)).astype(np.complex64)
    carrier_free = image.data * along_turn[:, None] * across_turn[None, :]
    coef = np.empty((2, *carrier_free.shape))
    for part, plane in zip((carrier_free.real, carrier_free.imag), coef, strict=True):
        spline_filter(part, order=3, output=plane, mode="mirror")
    o = np.asarray(origin_ned, np.float64)[:2]
    corners = np.array([o + x * e0 + y * e1 for x in (a[0], a[-1]) for y in (c[0], c[-1])])
    lo = np.floor(corners.min(axis=0) / step) * step
    hi = np.ceil(corners.max(axis=0) / step) * step
    north = lo[0] + step * np.arange(round((hi[0] - lo[0]) / step) + 1)
    east = lo[1] + step * np.arange(round((hi[1] - lo[1]) / step) + 1)
    out = np.zeros((north.size, east.size), np.complex64)
    frame = np.array([a[0], c[0], step, north[0] - o[0], east[0] - o[1], k * cos_psi, depth_m])
    _resample(coef, np.stack([e0, e1]), frame, phi_a, out)
    return NorthUpImage(out, north, east)


@numba.njit(parallel=True, cache=True, fastmath=False)
def _resample(
    coef: FloatArray, axes: FloatArray, frame: FloatArray, phi_a: FloatArray, out: ComplexArray
) -> None:  # pragma: no cover - compiled
    """Cubic B-spline interpolation of the carrier-free image at every output pixel inside
    its footprint, the carrier put back: ``out[r, q] = value * exp(j phi)``.

    ``coef`` (2, n_a, n_c): spline coefficients of the real and imaginary parts (mirror
    boundary); ``axes`` (2, 2): e0, e1 (north, east); ``frame``: first along and across
    coordinate, spacing, output's first north and east relative to the image origin (m),
    ``k cos psi`` (rad/m), depth (m); ``phi_a`` (n_a,): along-track carrier phase per row.
    """
    a0, c0, step, n0, e0, k_cos, depth = frame
    n_a, n_c = coef.shape[1], coef.shape[2]
    for r in numba.prange(out.shape[0]):
        dn = n0 + r * step
        for q in range(out.shape[1]):
            de = e0 + q * step
            along = dn * axes[0, 0] + de * axes[0, 1]
            across = dn * axes[1, 0] + de * axes[1, 1]
            i = (along - a0) / step
            j = (across - c0) / step
            if i < 0.0 or j < 0.0 or i > n_a - 1 or j > n_c - 1:
                continue
            i0, j0 = int(i), int(j)
            wi, wj = _bspline(i - i0), _bspline(j - j0)
            re, im = 0.0, 0.0
            for u in range(4):
                ii = _mirror(i0 - 1 + u, n_a)
                for v in range(4):
                    jj = _mirror(j0 - 1 + v, n_c)
                    w = wi[u] * wj[v]
                    re += w * coef[0, ii, jj]
                    im += w * coef[1, ii, jj]
            i1 = min(i0 + 1, n_a - 1)
            ph = phi_a[i0] + (i - i0) * (phi_a[i1] - phi_a[i0])
            ph += k_cos * np.sqrt(across * across + depth * depth)
            cs, sn = np.cos(ph), np.sin(ph)
            out[r, q] = complex(re * cs - im * sn, re * sn + im * cs)


@numba.njit(cache=True, inline="always")
def _bspline(t: float) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """Cubic B-spline weights of the samples at -1, 0, 1, 2 for a point ``t`` in [0, 1)."""
    t2, t3 = t * t, t * t * t
    return (
        (1.0 - t) ** 3 / 6.0,
        (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
        (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
        t3 / 6.0,
    )


@numba.njit(cache=True, inline="always")
def _mirror(i: int, n: int) -> int:  # pragma: no cover - compiled
    """Index ``i`` reflected into 0..n-1 about the end samples (scipy's ``mirror`` mode)."""
    if i < 0:
        return -i
    if i >= n:
        return 2 * (n - 1) - i
    return i


@dataclass(frozen=True)
class NorthUpWritten:
    """One north-up image written into a store.

    Attributes
    ----------
    segment : int
        Reference-track segment (group ``north_up/image_KK``).
    shape : tuple of int
        Pixels (north, east).
    frame : str
        The NED frame and origin of its coordinates.
    """

    segment: int
    shape: tuple[int, int]
    frame: str

    def __str__(self) -> str:
        rows, cols = self.shape
        return f"north-up image {self.segment} of {rows} x {cols} pixels, {self.frame}"


@dataclass(frozen=True)
class NorthUpImages:
    """What :func:`write_north_up_images` did to a store.

    Attributes
    ----------
    images : list of NorthUpWritten
        The images written.
    not_written : str
        Why none was written where the configuration asks for them ("" otherwise).
    """

    images: list[NorthUpWritten]
    not_written: str = ""

    def lines(self) -> list[str]:
        """One line per image written, or the reason none was."""
        if self.not_written:
            return [f"north-up image not written: {self.not_written}"]
        return [str(image) for image in self.images]


UNNAMED_ORIGIN = (
    "the INS named no origin for its positions (no EKF origin, no local positions), so "
    "north/east would be about a point of the daemon's choosing; the tiles and the exports "
    "(geodetic) hold the geometry"
)
"""Why a store gets no north-up image although ``imaging.north_up`` is on."""


def write_north_up_images(path: str | Path) -> NorthUpImages:
    """Resample each reference-track segment of the store at ``path`` onto a north/east
    grid and write it into the store (:data:`~sarmoco.store.schema.NORTH_UP_GROUP`).

    The coordinates are NED about the origin the INS named for its positions
    (:func:`~sarmoco.products.georeference.ned_frame`: its EKF origin, or the origin of its
    local positions); each image's ``frame`` attribute says which. Nothing is written when
    the run's configuration turns it off (``imaging.north_up``), nor when the INS named no
    origin (a geodetic-only INS, or none): north and east about the first fix or the first
    antenna position would be coordinates no one else shares. Segments imaged off the
    ground plane are left out.

    Raises
    ------
    RecorderError
        The store cannot be read or written.
    """
    store = open_store(path)
    cfg = parse_config(store.attrs["config"])
    if not cfg.imaging.north_up:
        return NorthUpImages([])
    frame = ned_frame(store)
    if not frame.stated:
        return NorthUpImages([], UNNAMED_ORIGIN)
    depth = cfg.geometry.height_m
    written = []
    for k, seg in enumerate(segment_images(store)):
        if seg.image.frame != "ground":
            continue
        look = math.atan2(float(np.mean(seg.image.axis1_m)), depth)
        squint = beam_squint_rad(store, seg.track, cfg, look)
        image = north_up(
            seg.image,
            seg.track.origin_ned + frame.offset_ned_m,
            seg.track.x_hat,
            seg.track.y_hat,
            depth,
            cfg.radar.wavelength_m,
            squint,
        )
        attrs = {"frame": frame.description, "segment_tiles": list(seg.tiles)}
        write_north_up(path, k, image.data, image.north_m, image.east_m, attrs)
        written.append(NorthUpWritten(k, image.data.shape, frame.description))
    return NorthUpImages(written)
