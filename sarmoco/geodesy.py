"""WGS-84: geodetic ↔ ECEF (Earth-centred, Earth-fixed) and local NED about a geodetic point.

Shared by the drivers (an SBG position as local NED), the simulator (the positions an INS
reports), the processing (georeferencing a reference track and an image grid) and the
exports. Latitudes and longitudes are degrees, heights and coordinates metres.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

WGS84_A_M = 6_378_137.0
"""WGS-84 semi-major axis, m."""
WGS84_E2 = 6.694_379_990_14e-3
"""WGS-84 first eccentricity squared."""


def geodetic_to_ecef(lla: FloatArray) -> FloatArray:
    """Latitude, longitude (deg), height (m), shape (..., 3) → ECEF x, y, z (m), same shape."""
    lla = np.asarray(lla, dtype=np.float64)
    lat, lon, h = np.radians(lla[..., 0]), np.radians(lla[..., 1]), lla[..., 2]
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - WGS84_E2) + h) * np.sin(lat),
        ],
        axis=-1,
    )


def ecef_to_geodetic(xyz: FloatArray) -> FloatArray:
    """ECEF x, y, z (m), shape (..., 3) → latitude, longitude (deg), height (m).

    Fixed-point iteration on the latitude (converged below 1e-12 rad within 6 passes for
    points from the Earth's centre region to orbit heights; 10 are run).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(10):
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = p / np.cos(lat) - n
    return np.stack([np.degrees(lat), np.degrees(np.arctan2(y, x)), h], axis=-1)


def ned_rotation(lat_deg: float, lon_deg: float) -> FloatArray:
    """Matrix (3, 3) whose rows are the north, east and down unit vectors in ECEF at a point:
    ``v_ned = R @ v_ecef`` and ``v_ecef = R.T @ v_ned``."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array(
        [
            [-sl * co, -sl * so, cl],
            [-so, co, 0.0],
            [-cl * co, -cl * so, -sl],
        ]
    )


def geodetic_to_ned(lla: FloatArray, origin: tuple[float, float, float]) -> FloatArray:
    """Geodetic points (..., 3) → NED (m) in the tangent frame at ``origin`` (lat, lon deg, h m)."""
    delta = geodetic_to_ecef(lla) - geodetic_to_ecef(np.asarray(origin))
    return np.asarray(delta @ ned_rotation(origin[0], origin[1]).T)


def ned_to_ecef(ned: FloatArray, origin: tuple[float, float, float]) -> FloatArray:
    """NED (m, ..., 3) in the tangent frame at ``origin`` (lat, lon deg, h m) → ECEF (m)."""
    rot = ned_rotation(origin[0], origin[1])
    return np.asarray(geodetic_to_ecef(np.asarray(origin)) + np.asarray(ned) @ rot)


def ned_to_geodetic(ned: FloatArray, origin: tuple[float, float, float]) -> FloatArray:
    """NED (m, ..., 3) in the tangent frame at ``origin`` (lat, lon deg, h m) → latitude,
    longitude (deg) and height (m), same shape: the inverse of :func:`geodetic_to_ned`.

    Exact on the ellipsoid (through ECEF): the tangent plane leaves the surface with
    distance (a point 900 m east lies 6.4 cm above the ellipsoid, and 6.8 cm south of the
    latitude the flat-Earth formulas give at 47° N).
    """
    return ecef_to_geodetic(ned_to_ecef(ned, origin))


def tangent_origin(lla: FloatArray, ned: FloatArray) -> FloatArray:
    """The point (lat, lon deg, h m) about whose tangent frame the geodetic point ``lla``
    (3,) lies at ``ned`` (3,), m: the origin of a local frame from one position given both
    ways. Fixed-point iteration (the frame's tilt between candidate origins is second order:
    3 passes reach 1e-9 m within 10 km)."""
    lla, ned = np.asarray(lla, dtype=np.float64), np.asarray(ned, dtype=np.float64)
    origin = ned_to_geodetic(-ned, (float(lla[0]), float(lla[1]), float(lla[2])))
    for _ in range(3):
        o = (float(origin[0]), float(origin[1]), float(origin[2]))
        origin = ned_to_geodetic(geodetic_to_ned(lla, o) - ned, o)
    return np.asarray(origin)
