"""The ``mimo-array`` scenario: a MIMO downward-looking array flying over a DEM.

Geometry (local NED, m): the platform flies due north at ``altitude_m`` above the NED origin's
plane (``down = -altitude_m``), along the line ``east = 0``, at ``speed_mps``; the array is
across the wing (body y = east when level), its reference point is the INS (no lever arm).
The terrain is a DEM centred on the track: heights up (``-down``) on a regular north/east grid
of spacing ``terrain.spacing_m``. The scene is the DEM's part under the swath: across track
``|east| <= altitude tan(max_look)`` and along track a strip of ``scale`` times the full scene
length (the full scene is square), centred on north 0. Pulses run from one end of the strip to
the other plus the half aperture ``R_far lambda / D`` at either end, and the DEM holds the
terrain that the beam sees from every pulse.

The roll is a constant ``roll_deg`` (the paper's 3 deg) or, with ``roll_series``, that mean plus
a low-pass random process (:class:`~sarmoco.sim.trajectory.SinusoidSum`); pitch and yaw are
zero. The preset file (``presets/mimo-array.toml``) holds the paper's numbers and says which
values are our own.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.errors import ConfigError, DataFileError
from sarmoco.processing.array.geometry import ArrayLayout, mimo_layout
from sarmoco.processing.types import C_MPS, FloatArray, RadarParams
from sarmoco.sim.array_echo import peaks_dem
from sarmoco.sim.scenario import DEFAULT_T0_NS, level_track, radar_table
from sarmoco.sim.trajectory import Trajectory, euler_to_quat
from sarmoco.sim.turbulence import SinusoidSum

ARRAY_PRESET = "mimo-array"
"""Name of the array preset (``sarmoco sim --preset mimo-array``)."""

RANGE_MARGIN_M = 3.0
"""Slant range kept on either side of the terrain's nearest and farthest points, m."""


@dataclass(frozen=True)
class Terrain:
    """A DEM on a regular north/east grid.

    Parameters
    ----------
    height_m : ndarray of float64, shape (n_north, n_east)
        Height above the NED origin's plane (up = -down), m.
    spacing_m : float
        Grid spacing along north and east, m.
    origin_ne_m : (float, float)
        North and east of sample ``[0, 0]``, m.
    """

    height_m: FloatArray
    spacing_m: float
    origin_ne_m: tuple[float, float]


@dataclass(frozen=True)
class ArrayScenario:
    """One simulated array acquisition (module docstring).

    Parameters
    ----------
    radar : RadarParams
        Waveform and receive window shared by every channel.
    layout : ArrayLayout
        Transmitters and receivers in the body frame.
    epc_spacing_m : float
        Virtual-array spacing d, m.
    antenna_length_m : float
        Along-track element length D, m.
    max_look_rad : float
        Largest look angle off the body z axis across track, rad.
    speed_mps, altitude_m : float
        Ground speed (north) and height of the flight above the NED origin's plane, m/s, m.
    terrain : Terrain
        The DEM the echoes come from.
    mean_ground_m : float
        Mean height of the terrain grid, m (the flight is ``altitude_m - mean_ground_m``
        above it: the daemon's ``geometry.height_m``).
    scene_north_m : (float, float)
        Along-track strip imaged and evaluated, north from .. to, m.
    scene_half_width_m : float
        Half the cross-track swath ``altitude tan(max_look)`` (about the track), m.
    track_start_north_m : float
        North of the platform at the first pulse, m.
    n_pulses : int
        Pulses at ``radar.prf_hz``.
    roll_rad : float
        Constant roll, or the mean of the roll series, rad.
    roll_series : SinusoidSum or None
        Roll about the mean (rad) against time since the first pulse; None: constant.
    snr_db : float or None
        Per-sample SNR of a unit scatterer, dB.
    scatterers_per_cell : int
        Scatterers per DEM cell.
    scale : float
        The scale the preset was loaded with.
    t0_ns : int
        GPS time of the first pulse, ns.
    """

    radar: RadarParams
    layout: ArrayLayout
    epc_spacing_m: float
    antenna_length_m: float
    max_look_rad: float
    speed_mps: float
    altitude_m: float
    terrain: Terrain
    mean_ground_m: float
    scene_north_m: tuple[float, float]
    scene_half_width_m: float
    track_start_north_m: float
    n_pulses: int
    roll_rad: float
    roll_series: SinusoidSum | None
    snr_db: float | None
    scatterers_per_cell: int
    scale: float
    t0_ns: int = DEFAULT_T0_NS

    def roll_rad_at(self, t_s: FloatArray) -> FloatArray:
        """True roll at ``t_s`` s after t0, rad (positive: right wing down)."""
        t = np.asarray(t_s, dtype=np.float64)
        roll = np.full(t.shape, self.roll_rad)
        if self.roll_series is not None:
            roll += self.roll_series.derivatives(t, order=0)[0]
        return roll

    def trajectory(self, t_s: FloatArray) -> Trajectory:
        """True kinematics of the array's reference point (= the INS) at ``t_s`` s after t0."""
        t = np.asarray(t_s, dtype=np.float64)
        pos, vel = level_track(t, self.track_start_north_m, self.speed_mps, self.altitude_m)
        euler = np.zeros((t.size, 3))
        euler[:, 0] = self.roll_rad_at(t)
        return Trajectory(t, pos, vel, np.zeros((t.size, 3)), euler_to_quat(euler))

    def truth_dict(self) -> dict[str, Any]:
        """JSON-able description (no arrays but the DEM's axes; the DEM goes in the truth)."""
        return {
            "name": ARRAY_PRESET,
            "scale": self.scale,
            "speed_mps": self.speed_mps,
            "altitude_m": self.altitude_m,
            "mean_ground_m": self.mean_ground_m,
            "max_look_deg": math.degrees(self.max_look_rad),
            "n_tx": self.layout.n_tx,
            "n_rx": self.layout.n_rx,
            "epc_spacing_m": self.epc_spacing_m,
            "antenna_length_m": self.antenna_length_m,
            "scene_north_m": list(self.scene_north_m),
            "scene_half_width_m": self.scene_half_width_m,
            "track_start_north_m": self.track_start_north_m,
            "roll_deg": math.degrees(self.roll_rad),
            "roll_series": self.roll_series is not None,
            "snr_db": self.snr_db,
            "scatterers_per_cell": self.scatterers_per_cell,
            "radar": radar_table(self.radar),
        }


def _read_preset() -> dict[str, Any]:
    text = resources.files("sarmoco.sim").joinpath("presets", f"{ARRAY_PRESET}.toml").read_text()
    return tomllib.loads(text)


def read_dem(path: Path) -> tuple[FloatArray, float]:
    """A DEM file: ``.npz`` with ``height_m`` (n_north, n_east; m, up) and ``spacing_m`` (m).

    Raises
    ------
    DataFileError
        Naming the file and the key when it cannot be read, a key is missing, the heights are
        not a finite 2-D array of at least 2 x 2, or the spacing is not a number > 0.
    """
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: np.asarray(npz[k]) for k in ("height_m", "spacing_m") if k in npz.files}
    except (OSError, ValueError) as exc:
        raise DataFileError(f"--dem {path}: cannot read as .npz: {exc}") from exc
    for key in ("height_m", "spacing_m"):
        if key not in arrays:
            raise DataFileError(f"--dem {path}: no array {key!r} (want height_m and spacing_m)")
    h = arrays["height_m"]
    if h.ndim != 2 or min(h.shape) < 2 or not np.issubdtype(h.dtype, np.number):
        raise DataFileError(f"--dem {path}: height_m shape {h.shape} is not a 2-D grid >= 2 x 2")
    h = h.astype(np.float64)
    if not np.all(np.isfinite(h)):
        raise DataFileError(f"--dem {path}: height_m has non-finite values")
    spacing = arrays["spacing_m"]
    if spacing.size != 1 or not np.issubdtype(spacing.dtype, np.number):
        raise DataFileError(f"--dem {path}: spacing_m {spacing!r} is not one number")
    dx = float(spacing.reshape(-1)[0])
    if not (math.isfinite(dx) and dx > 0.0):
        raise DataFileError(f"--dem {path}: spacing_m {dx!r} is not > 0")
    return h, dx


def _cut(height: FloatArray, spacing: float, n_north: int, n_east: int, where: str) -> FloatArray:
    """The central (n_north, n_east) part of a DEM grid."""
    if height.shape[0] < n_north or height.shape[1] < n_east:
        raise DataFileError(
            f"{where}: a {height.shape[0]} x {height.shape[1]} grid at {spacing:g} m is smaller "
            f"than the {n_north} x {n_east} samples the scene needs"
        )
    i0 = (height.shape[0] - n_north) // 2
    j0 = (height.shape[1] - n_east) // 2
    return np.ascontiguousarray(height[i0 : i0 + n_north, j0 : j0 + n_east])


def _user_dem(dem: Path, spacing_m: float) -> FloatArray:
    """Heights (m) of the DEM file ``dem``, which must be on the preset's grid spacing (m)."""
    user_h, user_dx = read_dem(dem)
    if not math.isclose(user_dx, spacing_m, rel_tol=1e-6):
        raise DataFileError(
            f"--dem {dem}: spacing_m {user_dx:g} m is not the preset's terrain grid "
            f"{spacing_m:g} m (resample it)"
        )
    return user_h


def _gated_radar(rr: dict[str, Any], near_m: float, far_m: float) -> RadarParams:
    """The preset's ``[radar]`` table with a range gate from ``near_m`` to ``far_m`` (slant, m)."""
    fs, tp = float(rr["sample_rate_hz"]), float(rr["pulse_width_s"])
    return RadarParams(
        carrier_hz=float(rr["carrier_hz"]),
        bandwidth_hz=float(rr["bandwidth_hz"]),
        pulse_width_s=tp,
        sample_rate_hz=fs,
        prf_hz=float(rr["prf_hz"]),
        n_samples=2 * math.ceil((2.0 * (far_m - near_m) / C_MPS + tp) * fs / 2.0),
        range_gate_delay_s=2.0 * near_m / C_MPS,
        receive="matched",
        chirp_direction=rr.get("chirp_direction", "up"),
    )


def _range_span(
    altitude_m: float, half_width_m: float, user_h: FloatArray | None
) -> tuple[float, float, float]:
    """Flight altitude (m, raised by a user DEM's mean height), nearest and farthest slant
    range (m) to the terrain within ``half_width_m`` of the track, with the range margin."""
    if user_h is None:
        lo_h, hi_h = -39.2977, 48.6260  # sarmoco.sim.array_echo.PAPER_DEM_RANGE_M
    else:
        altitude_m += float(user_h.mean())
        lo_h, hi_h = float(user_h.min()), float(user_h.max())
    far_m = math.hypot(half_width_m, altitude_m - lo_h) + RANGE_MARGIN_M
    near_m = altitude_m - hi_h - RANGE_MARGIN_M
    if near_m <= 0.0:
        raise DataFileError(f"terrain: its highest point {hi_h:.1f} m reaches the flight")
    return altitude_m, near_m, far_m


def _roll_series(raw: dict[str, Any], seed: int) -> SinusoidSum:
    """The preset's low-pass random roll (rad) about the mean, seeded by ``seed``."""
    return SinusoidSum.coloured(
        math.radians(float(raw["roll_series_rms_deg"])),
        float(raw["roll_series_corner_hz"]),
        np.random.default_rng(np.random.SeedSequence([seed, 13])),
    )


def load_array_preset(
    scale: float = 1.0,
    *,
    roll_deg: float | None = None,
    roll_series: bool = False,
    dem: Path | None = None,
    seed: int = 0,
) -> ArrayScenario:
    """The ``mimo-array`` scenario.

    Parameters
    ----------
    scale : float
        0 < scale <= 1: length of the imaged strip along track over the full (square) scene.
    roll_deg : float, optional
        Constant roll (or the series' mean), deg; default the preset's 3 deg.
    roll_series : bool
        Add the preset's low-pass random roll about the mean.
    dem : Path, optional
        A DEM (:func:`read_dem`) instead of the synthetic terrain; its centre goes under the
        middle of the track, and the flight is raised by the DEM's mean height.
    seed : int
        Seed of the roll series.

    Raises
    ------
    ConfigError
        A scale outside (0, 1] or a roll that is not finite.
    DataFileError
        A DEM that cannot be read or does not cover the scene.
    """
    if not 0.0 < scale <= 1.0:
        raise ConfigError(f"scenario.scale: {scale!r} is not in (0, 1]")
    raw = _read_preset()
    rr, ar, tr = raw["radar"], raw["array"], raw["terrain"]
    roll = float(raw["roll_deg"] if roll_deg is None else roll_deg)
    if not math.isfinite(roll) or abs(roll) >= 45.0:
        raise ConfigError(f"--roll-deg: {roll!r} is not a finite angle below 45 deg")
    max_look = math.radians(float(raw["max_look_deg"]))
    spacing = float(tr["spacing_m"])
    lam = C_MPS / float(rr["carrier_hz"])
    d_len = float(ar["antenna_length_m"])
    speed = float(raw["speed_mps"])

    half_width = float(raw["altitude_m"]) * math.tan(max_look)
    full_length = 2.0 * half_width
    user_h = None if dem is None else _user_dem(dem, spacing)
    altitude, near_m, far_m = _range_span(float(raw["altitude_m"]), half_width, user_h)
    half_ap = far_m * math.tan(math.asin(min(lam / d_len, 0.5)))
    strip = scale * full_length
    ground_along = strip + 4.0 * half_ap
    n_north = math.ceil(ground_along / spacing) + 1
    half_east = half_width + far_m * math.tan(math.radians(abs(roll)))  # the rolled beam's edge
    n_east = math.ceil(2.0 * half_east / spacing)
    n_east += 1 + n_east % 2  # odd: a sample on the track
    if user_h is None:
        n_full = math.ceil((full_length + 4.0 * half_ap) / spacing) + 1
        user_h, dem_name = peaks_dem(n_full, n_east), "terrain"
    else:
        dem_name = f"--dem {dem}"
    height = _cut(user_h, spacing, n_north, n_east, dem_name)
    terrain = Terrain(
        height, spacing, (-0.5 * (n_north - 1) * spacing, -0.5 * (n_east - 1) * spacing)
    )

    radar = _gated_radar(rr, near_m, far_m)
    flight = strip + 2.0 * half_ap
    n_pulses = math.floor(flight / speed * radar.prf_hz) + 1
    epc = float(ar["epc_spacing_m"])
    return ArrayScenario(
        radar=radar,
        layout=mimo_layout(int(ar["n_tx"]), int(ar["n_rx"]), epc),
        epc_spacing_m=epc,
        antenna_length_m=d_len,
        max_look_rad=max_look,
        speed_mps=speed,
        altitude_m=altitude,
        terrain=terrain,
        mean_ground_m=float(height.mean()),
        scene_north_m=(-0.5 * strip, 0.5 * strip),
        scene_half_width_m=half_width,
        track_start_north_m=-0.5 * flight,
        n_pulses=n_pulses,
        roll_rad=math.radians(roll),
        roll_series=_roll_series(raw, seed) if roll_series else None,
        snr_db=None if raw.get("snr_db") is None else float(raw["snr_db"]),
        scatterers_per_cell=int(tr["scatterers_per_cell"]),
        scale=scale,
    )
