"""A squinted beam (antenna fixed to a crabbed body) focused on point targets.

The echoes are simulated here: a rectangular beam, a cone about the crabbed array axis
(``|asin(u · a)| <= θ/2``), range-compressed sinc pulses with the exact two-way phase.
Imaged with the squint intervals that :mod:`sarmoco.processing.beam` gives for that axis,
the target reaches the unweighted-sinc limits; with the beam taken broadside (the crab
ignored) it does not. The pre-filter, centred on the (aliased) Doppler centroid, keeps
the band and rejects what lies outside it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sarmoco.processing.beam import (
    accc_centroid_hz,
    accc_coherence,
    accc_correlation,
    array_axis_body,
    centre_squint_rad,
    doppler_hz,
    resolve_ambiguity,
    squint_interval_rad,
)
from sarmoco.processing.imaging.presum import AzimuthPrefilter
from sarmoco.processing.imaging.tiles import TileImager, TileLayout
from sarmoco.processing.metrics import point_target_metrics

LAM, V, H, PRF = 0.02, 17.5, 450.0, 200.0
BEAM = math.radians(1.909)
TOL = math.radians(0.3)
R0 = 900.0
DR, RHO = 0.208, 0.25  # range bin and range resolution, m


def _axis(crab_deg: float, side: float) -> np.ndarray:
    """Array axis in the imaging frame of a body yawed by ``crab_deg`` toward the right."""
    c = math.radians(crab_deg)
    return np.array([math.cos(c), side * math.sin(c), 0.0])


def _focus(crab_deg: float, side: float, squinted: bool):
    yg = math.sqrt(R0**2 - H**2)
    axis = _axis(crab_deg, side)
    psi_c = float(centre_squint_rad(axis, math.acos(H / R0)))
    n = 1200
    t = (np.arange(n) - n / 2) / PRF
    tgt = np.array([30.0, yg, H])
    apc = np.column_stack([30.0 - R0 * math.sin(psi_c) + V * t, np.zeros(n), np.zeros(n)])
    d = tgt - apc
    r = np.linalg.norm(d, axis=1)
    lit = np.abs(d @ axis) <= r * math.sin(BEAM / 2)
    r_axis = 860.0 + DR * np.arange(400)
    rc = np.where(
        lit[:, None],
        np.sinc((r_axis[None, :] - r[:, None]) / RHO) * np.exp(-4j * np.pi * r[:, None] / LAM),
        0,
    ).astype(np.complex64)
    layout = TileLayout(H, yg, 16.0, 20.0, 0.05, BEAM + 2 * TOL)
    beam = None
    if squinted:
        looks = np.arctan2(yg + np.array([-8.0, 8.0]), H)
        lo, hi = squint_interval_rad(axis, BEAM / 2 + TOL, looks)
        beam = np.tile([lo, hi], (n, 1))
    imager = TileImager(layout, r_axis, LAM)
    tiles = imager.add(rc, np.round(t * 1e9).astype(np.int64), apc, None, beam) + imager.close()
    tile = next((k for k in tiles if k.index == 1), None)
    return lit.sum(), tile, (30.0, yg)


@pytest.mark.parametrize(
    ("crab_deg", "side"), [(12.0, 1.0), (-12.0, 1.0), (4.0, -1.0), (-8.0, -1.0)]
)
def test_squinted_beam_focuses_to_theory(crab_deg: float, side: float) -> None:
    lit, tile, where = _focus(crab_deg, side, squinted=True)
    assert lit > 250
    assert tile is not None
    m = point_target_metrics(tile.image(), where, 1.0)
    theory = 0.886 * LAM / (4 * math.sin(BEAM / 2))
    assert m.axis0.pslr_db <= -13.0
    assert m.axis0.irw_m <= 1.03 * theory
    assert m.axis1.pslr_db <= -13.0


def test_ignoring_the_crab_loses_the_target() -> None:
    """The beam taken broadside to the track: the pixels take none of the pulses that saw
    the target (at most a trace of a stray pulse's sidelobes)."""
    _, focused, _ = _focus(8.0, 1.0, squinted=True)
    _, ignored, _ = _focus(8.0, 1.0, squinted=False)
    assert focused is not None
    peak = np.abs(focused.data).max()
    assert ignored is None or np.abs(ignored.data).max() < 0.01 * peak


def test_prefilter_keeps_the_aliased_band_about_the_centroid() -> None:
    """At 4° crab the centroid (-106 Hz) lies beyond PRF / 2: a tone inside its band passes
    (gain D), one outside is stopped."""
    axis = _axis(4.0, 1.0)
    f_dc = float(doppler_hz(V, LAM, centre_squint_rad(axis, math.radians(60.0))))
    assert f_dc < -PRF / 2
    assert AzimuthPrefilter(PRF, 20.0, 1.25).decimation == 4
    t_ns = np.round(np.arange(800) / PRF * 1e9).astype(np.int64)
    gains = []
    for f in (f_dc + 10.0, f_dc + 60.0):
        pre = AzimuthPrefilter(PRF, 20.0, 1.25)
        pre.centroid_hz = f_dc
        x = np.exp(2j * np.pi * f * t_ns * 1e-9)[:, None].astype(np.complex64)
        out, t_out = pre.push(x, t_ns)
        mid = slice(out.shape[0] // 4, 3 * out.shape[0] // 4)
        want = np.exp(2j * np.pi * f * t_out[mid] * 1e-9)
        gains.append(np.mean(out[mid, 0] / want))
    assert abs(gains[0] - pre.decimation) < 0.02 * pre.decimation
    assert abs(gains[1]) < 0.01 * pre.decimation


def test_accc_measures_an_aliased_centroid() -> None:
    f_true = -106.0
    t = np.arange(512) / PRF
    rng = np.random.default_rng(1)
    echo = np.exp(2j * np.pi * f_true * t)[:, None] * np.ones((1, 8))
    echo = echo + 0.3 * (rng.standard_normal(echo.shape) + 1j * rng.standard_normal(echo.shape))
    measured = accc_centroid_hz(echo, PRF)
    assert abs(measured - (f_true + PRF)) < 1.0
    assert abs(resolve_ambiguity(measured, -90.0, PRF) - f_true) < 1.0
    noise = rng.standard_normal(echo.shape) + 1j * rng.standard_normal(echo.shape)
    assert accc_coherence(echo, accc_correlation(echo)) > 0.8
    assert accc_coherence(noise, accc_correlation(noise)) < 0.1


def test_mount_squint_turns_the_array_axis_forward() -> None:
    right = array_axis_body(math.radians(10.0), "right")
    left = array_axis_body(math.radians(10.0), "left")
    assert right[1] < 0 < left[1]
    assert float(centre_squint_rad(right, math.radians(60.0))) > 0
