"""Roll range error: the wavenumber form against the exact geometry, and its split."""

from __future__ import annotations

import math

import numpy as np

from sarmoco.processing.array.geometry import euler_to_quat, mimo_layout
from sarmoco.processing.array.roll import (
    direction_from_wavenumbers,
    epc_deviation,
    range_error_m,
)
from sarmoco.processing.geometry import ReferenceTrack

LAMBDA = 299_792_458.0 / 9.6e9
KR = 4.0 * math.pi / LAMBDA


def _track() -> ReferenceTrack:
    return ReferenceTrack.from_velocity(np.zeros(3), np.array([100.0, 0.0, 0.0]), 0)


def _deviation(roll_rad: float) -> tuple[np.ndarray, np.ndarray]:
    layout = mimo_layout(2, 80, 0.02)
    quat = euler_to_quat(roll_rad, 0.0, 0.0)[None, :]
    dev = epc_deviation(np.array([0]), np.zeros((1, 3)), quat, layout, _track())[0]
    return layout.epc_body_m[:, 1], dev


def _wavenumbers(x: float, y: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local wavenumbers of exp(-j k_r R) along x and y at each element (central differences)."""
    h = 1e-4

    def phase(dx: float, dy: float) -> np.ndarray:
        r = np.sqrt((target[0] - x - dx) ** 2 + (target[1] - y - dy) ** 2 + target[2] ** 2)
        return -KR * r

    kx = (phase(h, 0.0) - phase(-h, 0.0)) / (2 * h)
    ky = (phase(0.0, h) - phase(0.0, -h)) / (2 * h)
    return kx, ky


def test_wavenumber_range_error_matches_exact_geometry() -> None:
    alpha = math.radians(3.0)
    y, dev = _deviation(alpha)
    worst = 0.0
    biggest = 0.0
    for look_deg in (-20.0, -8.0, 0.0, 5.0, 14.0, 20.0):
        for depth in (160.0, 200.0, 240.0):
            for dx in (-3.0, 0.0, 2.5):
                look = math.radians(look_deg)
                target = np.array([dx, depth * math.tan(look), depth])
                # exact: the paper's EPC (x, y cos a, y sin a) against the level one
                moved = np.sqrt(
                    (target[0]) ** 2
                    + (target[1] - y * math.cos(alpha)) ** 2
                    + (target[2] - y * math.sin(alpha)) ** 2
                )
                level = np.sqrt(target[0] ** 2 + (target[1] - y) ** 2 + target[2] ** 2)
                exact = moved - level
                kx, ky = _wavenumbers(0.0, y, target)
                u = direction_from_wavenumbers(kx, ky, KR)
                model = range_error_m(dev, u)
                worst = max(worst, float(np.max(np.abs(model - exact))))
                biggest = max(biggest, float(np.max(np.abs(exact))))
    # ΔR reaches 8 cm at the array's ends (34 rad); the wavenumber form holds it to 30 µm
    assert biggest > 0.08
    assert worst < 3e-5


def test_split_first_part_is_the_nadir_range_error() -> None:
    alpha = math.radians(3.0)
    y, dev = _deviation(alpha)
    nadir = range_error_m(dev, direction_from_wavenumbers(0.0, 0.0, KR))
    np.testing.assert_allclose(nadir, -y * math.sin(alpha), atol=1e-12)
    # ΔR2 at 20°: y [sinθ (1 - cos α) + (1 - cosθ) sin α], 5.8 mm (2.3 rad) at the array's end
    th = math.radians(20.0)
    u = direction_from_wavenumbers(0.0, KR * math.sin(th), KR)
    dr2 = range_error_m(dev, u) - nadir
    paper = y * (math.sin(th) * (1 - math.cos(alpha)) + (1 - math.cos(th)) * math.sin(alpha))
    np.testing.assert_allclose(dr2, paper, atol=1e-12)
    assert float(np.max(np.abs(dr2))) > 5e-3
