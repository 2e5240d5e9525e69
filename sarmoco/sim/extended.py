"""The extended demo scene: distributed clutter shaded like real terrain, plus corner reflectors.

The clutter's reflectivity is a hillshade (``matplotlib.colors.LightSource``, sun from the
north-west at 45 deg) of the USGS DEM of the Jacksboro fault that matplotlib ships as sample
data, laid over a square patch of ground centred on the scene centre (track frame: DEM rows
along track x, columns across it in ground range y). Scatterers sit on a regular grid,
``SPACING_RESOLUTIONS`` of the azimuth resolution apart, with amplitude
``CLUTTER_AMPLITUDE * sqrt(reflectivity)`` (reflectivity: the hillshade to the power
``SHADE_POWER``) and a uniformly random phase. Corner reflectors (:data:`REFLECTORS`)
are point targets at the centre and near the corners of the patch; the aperture, PRF and
range window are those of the preset for the reflectors and the patch's corners.

Echoes of so many scatterers (tens of thousands) are synthesised by binning: per pulse,
each lit scatterer adds ``a exp(-j 4 pi R / lambda)`` (exact stop-and-hop range) to a delay
grid ``UPSAMPLING`` times finer than the sample rate, which is then convolved with the
transmitted chirp's baseband replica and decimated to the samples. This is the
``matched`` closed form of :mod:`sarmoco.sim.echo` with the envelope delay rounded to the
fine grid (at most ``1 / (2 UPSAMPLING f_s)``, 1.0 cm of range at 900 MHz); the carrier
phase is exact. Only the ``matched`` receive chain is supported.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numba
import numpy as np
from matplotlib import cbook
from matplotlib.colors import LightSource
from scipy.signal import fftconvolve

from sarmoco.errors import ConfigError
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, RadarParams
from sarmoco.sim.scenario import Clutter, Scenario, Target, load_preset

SCENES = ("points", "extended")
"""``sarmoco sim --scene``: the preset's point targets, or :func:`extended_scenario`."""

PATCH_SWATH_FRACTION = 0.9
"""Side of the square clutter patch, fraction of the (scaled) swath."""

SPACING_RESOLUTIONS = 1.0
"""Clutter grid spacing, in azimuth resolutions (one scatterer per resolution cell: each
pixel is dominated by its own scatterer, so the speckle stays mild)."""

CLUTTER_AMPLITUDE = 0.07
"""Amplitude of a scatterer of reflectivity 1 (a unit point target is a corner reflector)."""

REFLECTORS = ((0.0, 0.0, 1.4), (-0.35, -0.35, 1.0), (0.35, -0.35, 1.0), (-0.35, 0.35, 1.0),
              (0.35, 0.35, 1.0))  # fmt: skip
"""Corner reflectors: (x, y) offsets from the patch centre in patch sides, amplitude."""

UPSAMPLING = 8
"""Delay grid of the clutter synthesis, samples per receive sample."""

DEM_FILE = "jacksboro_fault_dem.npz"
"""matplotlib sample data: USGS 3-arc-second DEM, int16 elevation (m), spacing in degrees."""

VERTICAL_EXAGGERATION = 2.0
"""Hillshade vertical exaggeration (the terrain is gentle at 90 m spacing)."""

DEM_CROP = 0.5
"""Side of the DEM square laid over the patch, fraction of the DEM's shorter side (centred
on the DEM: the fault valley and the ridges beside it)."""

SHADE_POWER = 2.0
"""Reflectivity is the hillshade to this power (more contrast between lit and shaded slopes)."""

CLUTTER_SEED = 16
"""Seed of the scatterers' random phases."""


def hillshade(shape: tuple[int, int]) -> FloatArray:
    """The DEM's hillshade in [0, 1], resampled (nearest) to ``shape`` (rows, columns).

    A centred square of :data:`DEM_CROP` of the DEM is used, so the picture is not
    stretched on a square patch.
    """
    dem = np.load(cbook.get_sample_data(DEM_FILE, asfileobj=False))
    elevation = dem["elevation"].astype(np.float64)
    side = round(DEM_CROP * min(elevation.shape))
    r0, c0 = ((n - side) // 2 for n in elevation.shape)
    elevation = elevation[r0 : r0 + side, c0 : c0 + side]
    lat_rad = math.radians(0.5 * float(dem["ymin"] + dem["ymax"]))
    dy_m = 111_200.0 * float(dem["dy"])
    dx_m = dy_m * math.cos(lat_rad)
    shade = LightSource(azdeg=315, altdeg=45).hillshade(
        elevation, vert_exag=VERTICAL_EXAGGERATION, dx=dx_m, dy=dy_m
    )
    rows = np.minimum((np.arange(shape[0]) + 0.5) * side / shape[0], side - 1).astype(int)
    cols = np.minimum((np.arange(shape[1]) + 0.5) * side / shape[1], side - 1).astype(int)
    return np.asarray(shade[np.ix_(rows, cols)], dtype=np.float64)


def extended_scenario(name: str, scale: float = 1.0, **overrides: Any) -> Scenario:
    """A preset flown over the extended scene (see the module docstring).

    Parameters
    ----------
    name, scale, **overrides
        As for :func:`~sarmoco.sim.scenario.load_preset` (``targets`` may not be given:
        the corner reflectors are the scene's point targets).

    Returns
    -------
    Scenario
        With ``targets`` the corner reflectors and ``clutter`` the patch (NED).

    Raises
    ------
    ConfigError
        ``targets`` overridden, or a receive chain other than ``matched``.
    """
    if "targets" in overrides:
        raise ConfigError("scenario.targets: the extended scene places its own reflectors")
    base = load_preset(name, scale, **overrides)
    if base.radar.receive != "matched":
        raise ConfigError(
            f"scenario.receive: the extended scene needs 'matched', not {base.radar.receive!r}"
        )
    side = PATCH_SWATH_FRACTION * base.swath_m
    ground_c = math.sqrt(base.center_slant_range_m**2 - base.altitude_m**2)
    reflectors = tuple(
        Target((fx * side, ground_c + fy * side, 0.0), complex(a)) for fx, fy, a in REFLECTORS
    )
    corners = tuple(
        Target((fx * side / 2, ground_c + fy * side / 2, 0.0), 0j)
        for fx in (-1.0, 1.0)
        for fy in (-1.0, 1.0)
    )
    # aperture, PRF and range window from the reflectors and the patch's corners
    scn = load_preset(name, scale, targets=reflectors + corners, **overrides)
    scn = replace(scn, targets=scn.targets[: len(reflectors)])
    spacing = SPACING_RESOLUTIONS * scn.azimuth_resolution_m
    n = int(side / spacing)
    offsets = np.asarray((np.arange(n) - (n - 1) / 2.0) * spacing, dtype=np.float64)
    x, y = np.meshgrid(offsets, ground_c + offsets, indexing="ij")
    reflectivity = hillshade((n, n)) ** SHADE_POWER
    phase = np.random.default_rng(CLUTTER_SEED).uniform(0.0, 2.0 * math.pi, (n, n))
    track = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    clutter = Clutter(
        pos_ned=track @ scn.track_to_ned.T,
        amplitude=(CLUTTER_AMPLITUDE * np.sqrt(reflectivity) * np.exp(1j * phase)).ravel(),
        x_m=offsets,
        y_m=ground_c + offsets,
        reflectivity=reflectivity,
    )
    return replace(scn, clutter=clutter)


def load_scene(scene: str, name: str, scale: float = 1.0, **overrides: Any) -> Scenario:
    """``scene`` (one of :data:`SCENES`) with the preset ``name``.

    Raises
    ------
    ConfigError
        Unknown scene, or what the scene's loader raises.
    """
    if scene == "points":
        return load_preset(name, scale, **overrides)
    if scene == "extended":
        return extended_scenario(name, scale, **overrides)
    raise ConfigError(f"scenario.scene: {scene!r} is not one of {', '.join(SCENES)}")


@numba.njit(cache=True)
def _bin_kernel(
    grid: np.ndarray,
    apc: np.ndarray,
    pos: np.ndarray,
    amp: np.ndarray,
    x_hat: np.ndarray,
    sin_half: float,
    first_delay_s: float,
    grid_hz: float,
    wavelength: float,
) -> None:
    n_p, n_k, n_g = apc.shape[0], pos.shape[0], grid.shape[1]
    for p in range(n_p):
        for k in range(n_k):
            dx = pos[k, 0] - apc[p, 0]
            dy = pos[k, 1] - apc[p, 1]
            dz = pos[k, 2] - apc[p, 2]
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            if abs(dx * x_hat[0] + dy * x_hat[1] + dz * x_hat[2]) > sin_half * r:
                continue  # outside the rect beam
            m = round((2.0 * r / C_MPS - first_delay_s) * grid_hz)
            if 0 <= m < n_g:
                ph = -4.0 * math.pi * r / wavelength
                grid[p, m] += amp[k] * complex(math.cos(ph), math.sin(ph))


def clutter_echo(
    radar: RadarParams,
    apc_ned: FloatArray,
    clutter: Clutter,
    x_hat_ned: FloatArray,
    half_beam_rad: float | None,
    batch: int = 64,
) -> ComplexArray:
    """Raw ``matched`` echoes of the clutter (module docstring), without noise.

    Parameters
    ----------
    radar : RadarParams
        Waveform and receive chain (``matched``; I/Q conjugation applied when set).
    apc_ned : ndarray of float64, shape (P, 3)
        True APC at each pulse, NED, m.
    clutter : Clutter
        The scatterers.
    x_hat_ned : ndarray of float64, shape (3,)
        Axis of the stripmap beam's cone (``Scenario.beam_axis_ned``: the track direction
        when nothing squints the beam), NED unit vector.
    half_beam_rad : float or None
        Half the stripmap beam (as ``Scenario.illumination``); None: every scatterer lit.
    batch : int
        Pulses convolved at once (memory).

    Returns
    -------
    ndarray of complex64, shape (P, radar.n_samples)

    Raises
    ------
    ConfigError
        A receive chain other than ``matched``.
    """
    if radar.receive != "matched":
        raise ConfigError(
            f"radar.receive: clutter synthesis needs 'matched', not {radar.receive!r}"
        )
    grid_hz = UPSAMPLING * radar.sample_rate_hz
    u = np.arange(math.ceil(radar.pulse_width_s * grid_hz)) / grid_hz
    replica = np.exp(
        1j * math.pi * radar.signed_chirp_rate_hz_per_s * (u - radar.pulse_width_s / 2) ** 2
    )
    lead = replica.size  # grid bins before the gate: echoes whose tail reaches sample 0
    first_delay_s = radar.range_gate_delay_s - lead / grid_hz
    n_grid = lead + radar.n_samples * UPSAMPLING
    sin_half = 2.0 if half_beam_rad is None else math.sin(half_beam_rad)
    apc = np.ascontiguousarray(apc_ned, dtype=np.float64)
    pos = np.ascontiguousarray(clutter.pos_ned, dtype=np.float64)
    amp = np.ascontiguousarray(clutter.amplitude, dtype=np.complex128)
    x_hat = np.ascontiguousarray(x_hat_ned, dtype=np.float64)
    echo = np.empty((apc.shape[0], radar.n_samples), dtype=np.complex64)
    take = lead + UPSAMPLING * np.arange(radar.n_samples)
    for start in range(0, apc.shape[0], batch):
        rows = slice(start, min(start + batch, apc.shape[0]))
        grid = np.zeros((rows.stop - start, n_grid), dtype=np.complex128)
        _bin_kernel(grid, apc[rows], pos, amp, x_hat, sin_half, first_delay_s, grid_hz,
                    radar.wavelength_m)  # fmt: skip
        echo[rows] = fftconvolve(grid, replica[None, :], axes=1)[:, take]
    if radar.iq_conjugate:
        np.conjugate(echo, out=echo)
    return echo
