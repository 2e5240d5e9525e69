"""North-up images: a ground image along a crabbed track resampled onto north/east.

Point targets are simulated under a squinted beam (the antenna fixed to a body crabbed
8° against a track heading 35°): range-compressed sinc pulses with the exact two-way
phase, backprojected onto the track's ground grid and, as the reference, directly onto a
north/east grid of the same spacing. The north-up image of the first must be the second:
the same complex pixels, so the same response and position, whatever the carrier.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing.beam import centre_squint_rad
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import Image
from sarmoco.products.northup import NorthUpImage, north_up

LAM, V, H, PRF = 0.02, 17.5, 450.0, 200.0
BEAM = math.radians(1.909)
CRAB = math.radians(8.0)
HEADING = math.radians(35.0)
R0 = 900.0
DR, RHO = 0.208, 0.25
STEP = 0.05
TARGETS_X = (0.0, 9.0)  # along track, m


def _scene() -> tuple[RangeLines, np.ndarray, np.ndarray, float]:
    """Lines, APCs and targets (NED, m) of the crabbed pass, and the beam centre's squint."""
    yg = math.sqrt(R0**2 - H**2)
    e0 = np.array([math.cos(HEADING), math.sin(HEADING), 0.0])
    e1 = np.array([-math.sin(HEADING), math.cos(HEADING), 0.0])
    axis = math.cos(CRAB) * e0 + math.sin(CRAB) * e1
    psi = float(
        centre_squint_rad(np.array([math.cos(CRAB), math.sin(CRAB), 0.0]), math.acos(H / R0))
    )
    targets = np.array([x * e0 + (yg + dy) * e1 + np.array([0.0, 0.0, H])
                        for x, dy in zip(TARGETS_X, (0.0, 3.0), strict=True)])  # fmt: skip
    n = 900
    s = TARGETS_X[0] - R0 * math.sin(psi) - 12.0 + V * np.arange(n) / PRF
    apc = s[:, None] * e0[None, :]
    r_axis = 860.0 + DR * np.arange(400)
    rc = np.zeros((n, r_axis.size), np.complex64)
    for tgt in targets:
        d = tgt - apc
        r = np.linalg.norm(d, axis=1)
        lit = np.abs(d @ axis) <= r * math.sin(BEAM / 2)
        echo = np.sinc((r_axis[None, :] - r[:, None]) / RHO) * np.exp(
            -4j * np.pi * r[:, None] / LAM
        )
        rc += np.where(lit[:, None], echo, 0).astype(np.complex64)
    return RangeLines.upsample(rc, r_axis), apc, targets, psi


@dataclass(frozen=True)
class Focused:
    image: Image
    """The scene on the track's ground grid."""
    axes: tuple[np.ndarray, np.ndarray]
    """That grid's unit axes (NED)."""
    refs: list[Image]
    """Each target's neighbourhood formed directly on north/east."""
    targets: np.ndarray
    squint_rad: float
    """The beam centre's squint."""


@pytest.fixture(scope="module")
def focused() -> Focused:
    lines, apc, targets, psi = _scene()
    yg = math.sqrt(R0**2 - H**2)
    ax0 = STEP * np.arange(-160, 340) + STEP / 2
    track = PlaneGrid(ax0, yg + STEP * np.arange(-160, 220), (0.0, 0.0, H), HEADING)
    along = np.zeros((track.axis0_m.size, track.axis1_m.size), np.complex64)
    backproject_into(along, lines, apc, LAM, track)
    refs = []
    for tgt in targets:
        n, e = np.round(tgt[:2] / STEP).astype(int)
        box = PlaneGrid(
            STEP * np.arange(n - 60, n + 61), STEP * np.arange(e - 60, e + 61), (0, 0, H)
        )
        ref = np.zeros((box.axis0_m.size, box.axis1_m.size), np.complex64)
        backproject_into(ref, lines, apc, LAM, box)
        refs.append(Image(ref, box.axis0_m, box.axis1_m, "ground"))
    image = Image(along, track.axis0_m, track.axis1_m, "ground")
    return Focused(image, track.unit_vectors, refs, targets, psi)


def _window(nu: NorthUpImage, ref: Image) -> Image:
    """The north-up image's pixels on the reference's grid (the same lattice)."""
    i0 = round((ref.axis0_m[0] - nu.north_m[0]) / STEP)
    j0 = round((ref.axis1_m[0] - nu.east_m[0]) / STEP)
    n0, n1 = ref.data.shape
    assert np.allclose(nu.north_m[i0 : i0 + n0], ref.axis0_m)
    assert np.allclose(nu.east_m[j0 : j0 + n1], ref.axis1_m)
    return Image(nu.data[i0 : i0 + n0, j0 : j0 + n1], ref.axis0_m, ref.axis1_m, "ground")


def test_north_up_image_is_the_image_formed_on_north_east(focused: Focused) -> None:
    """Every reference pixel within 0.1 % (complex, rms; the interpolation leaves 1e-4) and
    each target's response as the direct focus gives it: PSLR within 0.01 dB, IRW within
    0.1 %, peak within 2 mm."""
    nu = north_up(focused.image, np.zeros(3), *focused.axes, H, LAM, focused.squint_rad)
    for ref, tgt in zip(focused.refs, focused.targets, strict=True):
        got = _window(nu, ref)
        assert np.linalg.norm(got.data - ref.data) / np.linalg.norm(ref.data) < 1e-3
        want = point_target_metrics(ref, (tgt[0], tgt[1]), 1.0, through_peak=True)
        have = point_target_metrics(got, (tgt[0], tgt[1]), 1.0, through_peak=True)
        for a, b in ((want.axis0, have.axis0), (want.axis1, have.axis1)):
            assert b.pslr_db == pytest.approx(a.pslr_db, abs=0.01)
            assert b.irw_m == pytest.approx(a.irw_m, rel=0.001)
        assert have.position_error_m is not None and want.position_error_m is not None
        assert math.dist(have.position_error_m, want.position_error_m) < 0.002
        assert math.hypot(*have.position_error_m) < 0.02


def test_the_carrier_beyond_the_pixel_rate_needs_the_beam_squint(focused: Focused) -> None:
    """At 8° of crab the along-track carrier (2 sin psi / lambda, -12.1 cycles/m) lies beyond
    half the 20 /m pixel rate: without the squint the amplitude is still right, the phase
    between the pixels is not."""
    assert 2 * math.sin(focused.squint_rad) / LAM < -0.5 / STEP
    nu = north_up(focused.image, np.zeros(3), *focused.axes, H, LAM, None)
    ref = focused.refs[0]
    got = _window(nu, ref)
    norm = np.linalg.norm(ref.data)
    assert np.linalg.norm(np.abs(got.data) - np.abs(ref.data)) / norm < 0.01
    assert np.linalg.norm(got.data - ref.data) / norm > 0.5


def test_unequal_spacing_is_refused() -> None:
    image = Image(np.zeros((4, 4), np.complex64), np.arange(4) * 0.1, np.arange(4) * 0.2, "ground")
    with pytest.raises(ProcessingError, match="spacing"):
        north_up(image, np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), H, LAM)
