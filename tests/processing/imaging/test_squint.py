"""A squinted beam (antenna fixed to a crabbed body) focused on point targets.

The echoes are simulated here: a rectangular beam, a cone about the crabbed array axis
(``|asin(u · a)| <= θ/2``), range-compressed sinc pulses with the exact two-way phase.
Imaged with the squint intervals that :mod:`sarmoco.processing.beam` gives for that axis,
the target reaches the unweighted-sinc limits; with the beam taken broadside (the crab
ignored) it does not. The pre-filter, centred on the (aliased) Doppler centroid, keeps
the band and rejects what lies outside it; pixels that take its decimated pulses over
more Doppler than that band image a target's along-track ambiguity as well.
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
    squint_sine,
    within_band,
)
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.grid import PlaneGrid
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
    imager = TileImager(layout, r_axis, LAM, only=range(1, 2))  # the target's tile alone
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


def _prefiltered_ghost(cut_to_band: bool) -> tuple[float, float]:
    """Peak of a target and of its along-track ambiguity, imaged from pre-filtered pulses.

    The beam's centre is 0.87° ahead (echo centroid +26.6 Hz at PRF 200 Hz, the acceptance
    flight 20 s into its log); the pixels' squint interval is widened 2.3° backward, as the
    daemon's is while the attitude puts the beam there and the echoes do not. The
    pre-filter keeps ±38.4 Hz about the echoes' centroid and decimates by 2.
    """
    yg = math.sqrt(R0**2 - H**2)
    psi_c = math.radians(0.87)
    n = 1600
    t_ns = np.round((np.arange(n) - n / 2) / PRF * 1e9).astype(np.int64)
    tgt = np.array([0.0, yg, H])
    apc = np.column_stack([V * t_ns * 1e-9, np.zeros(n), np.zeros(n)])
    d = tgt - apc
    r = np.linalg.norm(d, axis=1)
    lit = np.abs(np.arcsin(d[:, 0] / r) - psi_c) <= BEAM / 2
    r_axis = 860.0 + DR * np.arange(400)
    rc = np.where(
        lit[:, None],
        np.sinc((r_axis[None, :] - r[:, None]) / RHO) * np.exp(-4j * np.pi * r[:, None] / LAM),
        0,
    ).astype(np.complex64)
    pre = AzimuthPrefilter(PRF, 38.4, 1.25)
    pre.centroid_hz = float(doppler_hz(V, LAM, psi_c))
    out, t_out = pre.push(rc, t_ns)
    tail, t_tail = pre.flush()
    out, t_out = np.concatenate([out, tail]), np.concatenate([t_out, t_tail])
    assert pre.decimation == 2
    beam = np.tile(np.radians([0.87 - 0.95 - 2.3, 0.87 + 0.95 + 0.3]), (t_out.size, 1))
    if cut_to_band:
        beam = within_band(beam, pre.passband_hz(t_out), V, LAM)
    lines = RangeLines.upsample(out, r_axis)
    pos = np.column_stack([V * t_out * 1e-9, np.zeros(t_out.size), np.zeros(t_out.size)])
    ghost_m = LAM * R0 * PRF / pre.decimation / (2.0 * V)  # along-track ambiguity, 51.4 m
    peaks = []
    for x0 in (0.0, -ghost_m, ghost_m):
        grid = PlaneGrid(
            x0 + 0.05 * np.arange(-100, 101), yg + 0.05 * np.arange(-10, 11), (0.0, 0.0, H)
        )
        img = np.zeros((grid.axis0_m.size, grid.axis1_m.size), np.complex64)
        backproject_into(img, lines, pos, LAM, grid, beam_squint_rad=beam)
        peaks.append(float(np.abs(img).max()))
    return peaks[0], max(peaks[1:])


def test_pixels_take_no_more_doppler_than_the_prefilter_keeps() -> None:
    """Decimated to 100 Hz, a pulse holds the band and the aliases of its neighbours: a
    pixel 51 m from a target along track that takes pulses over a 5.3° interval
    (160 Hz) sums the target's echo as if it were its own. Cut to the pre-filter's band,
    the ambiguity falls below the image's noise-free sidelobes."""
    target, ghost = _prefiltered_ghost(cut_to_band=False)
    assert 20 * math.log10(ghost / target) > -30.0
    target_cut, ghost_cut = _prefiltered_ghost(cut_to_band=True)
    assert ghost_cut < 10 ** (-50.0 / 20.0) * target_cut
    assert target_cut == pytest.approx(target, rel=0.02)


def test_prefilter_says_which_band_each_output_holds() -> None:
    """The centroid moves between blocks (the echoes' estimate settles): each output's
    band is the one its centre slot was demodulated with, not the latest (pixels cut
    to the latest band lost the edge of the earlier pulses' beam: azimuth IRW 1.40 x
    theory on the acceptance reference)."""
    pre = AzimuthPrefilter(PRF, 38.4, 1.25)
    t_ns = np.round(np.arange(600) / PRF * 1e9).astype(np.int64)
    x = np.ones((600, 2), np.complex64)
    outs = []
    for block, f_dc in ((slice(0, 300), 4.1), (slice(300, 600), -8.7)):
        pre.centroid_hz = f_dc
        outs.append(pre.push(x[block], t_ns[block])[1])
    t_out = np.concatenate(outs)
    band = pre.passband_hz(t_out)
    centre = band.mean(axis=1)
    first_late = int(np.searchsorted(t_out, t_ns[300]))
    assert np.allclose(centre[:first_late], 4.1)
    assert np.allclose(centre[first_late:], -8.7)
    assert np.allclose(band[:, 1] - band[:, 0], 2 * 38.4)


def test_squint_sine_inverts_the_doppler() -> None:
    """``sin ψ = f λ / (2 v)`` back from ``f = 2 v sin ψ / λ`` (Ku band, 17.5 m/s), and a
    Doppler beyond ``2 v / λ`` has no squint (|sine| > 1, left to the caller)."""
    squint = np.radians(np.linspace(-15.0, 15.0, 31))
    f = doppler_hz(17.5, 0.02, squint)
    np.testing.assert_allclose(np.arcsin(squint_sine(f, 17.5, 0.02)), squint, atol=1e-12)
    assert float(squint_sine(2.0 * 17.5 / 0.02 * 1.01, 17.5, 0.02)) > 1.0
