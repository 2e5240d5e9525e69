"""Backprojection kernel, beam culling, and the tile imager's speed-ups judged on point targets.

The speed-ups of the daemon's image formation (per-pixel beam culling and the
azimuth pre-filter with decimation) must not change how point targets focus:
the tile imager with both is compared with a plain backprojection of every
pulse onto the same pixels (no culling, no pre-filter) on simulated targets at
the scene centre, near and far range and off the aperture centre, with the
imaging frame's heading off the true track by as much as the INS-only
reference track was in the simulated runs. PSLR and ISLR within 0.2 dB, IRW
within 2 %, peak within 1 %, position within 1 cm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from sarmoco.errors import ProcessingError
from sarmoco.processing import rangecomp
from sarmoco.processing.imaging import PlaneGrid, backproject
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.presum import AzimuthPrefilter
from sarmoco.processing.imaging.tiles import Tile, TileImager, TileLayout
from sarmoco.processing.metrics import CutMetrics, point_target_metrics
from sarmoco.processing.types import ComplexArray, FloatArray, Image, IntArray
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import Scenario, Target, load_preset

SQUINT_TOLERANCE_RAD = math.radians(0.3)
"""The daemon's default imaging.squint_tolerance_deg."""

HEADING_ERROR_RAD = -3.3e-3
"""Heading of the imaging frame's x axis from the true track (thz bench replay: -3.28 mrad)."""


def _direct_sum(
    lines: RangeLines, apc: FloatArray, lam: float, grid: PlaneGrid, half_angle: float | None
) -> ComplexArray:
    """Backprojection as written in the module docstring, complex128, pixel by pixel."""
    pix = grid.positions()
    e0, _ = grid.unit_vectors
    out = np.zeros(pix.shape[:2], np.complex128)
    n = lines.data.shape[1]
    for p in range(apc.shape[0]):
        d = pix - apc[p]
        r = np.linalg.norm(d, axis=-1)
        u = (r - lines.r_first_m) / lines.dr_m
        ok = (u >= 0) & (u < n - 1)
        if half_angle is not None:
            along = np.abs(d @ e0)
            ok &= along <= np.tan(half_angle) * np.sqrt(r**2 - along**2)
        j = np.clip(u.astype(np.int64), 0, n - 2)
        f = u - j
        v = lines.data[p, j] * (1 - f) + lines.data[p, j + 1] * f
        out += np.where(ok, v * np.exp(4j * np.pi * r / lam), 0)
    return out


@pytest.mark.parametrize("half_angle", [None, 0.02])
def test_kernel_equals_direct_sum(half_angle: float | None) -> None:
    """Separable geometry, column runs, culling and float32 phase polynomials against float64."""
    rng = np.random.default_rng(0)
    n_p, n_s = 9, 64
    rc = (rng.standard_normal((n_p, n_s)) + 1j * rng.standard_normal((n_p, n_s))).astype(
        np.complex64
    )
    axis = 95.0 + 0.25 * np.arange(n_s)
    lam = 0.0015  # 0.2 THz: phase of 8400 rad/m
    apc = np.column_stack(
        [np.linspace(-1.5, 1.5, n_p), rng.normal(0, 0.05, n_p), -60.0 + rng.normal(0, 0.05, n_p)]
    )
    grid = PlaneGrid.centred((0.3, 80.0, 0.0), 41, 57, 0.11, 0.37, heading_rad=0.05)
    lines = RangeLines.upsample(rc, axis, 4)
    got = np.zeros((41, 57), np.complex64)
    backproject_into(got, lines, apc, lam, grid, beam_half_angle_rad=half_angle)
    want = _direct_sum(lines, apc, lam, grid, half_angle)
    assert np.count_nonzero(want) > 0.2 * want.size
    assert np.max(np.abs(got - want)) < 2e-5 * np.max(np.abs(want))
    if half_angle is not None:
        assert np.count_nonzero(want) < 0.9 * want.size  # the beam did cull pixels
    # a subset of pulses, accumulated in place on what is there
    sub = np.array([1, 4, 7])
    backproject_into(got, lines, apc, lam, grid, pulses=sub, beam_half_angle_rad=half_angle)
    sub_lines = RangeLines(lines.data[sub], lines.r_first_m, lines.dr_m)
    want += _direct_sum(sub_lines, apc[sub], lam, grid, half_angle)
    assert np.max(np.abs(got - want)) < 2e-5 * np.max(np.abs(want))


def test_backproject_into_rejects_bad_arguments() -> None:
    lines = RangeLines.upsample(np.ones((2, 8), np.complex64), np.arange(8.0), 2)
    grid = PlaneGrid.centred((0.0, 0.0, 0.0), 4, 4, 1.0, 1.0)
    apc = np.zeros((2, 3))
    with pytest.raises(ProcessingError):
        backproject_into(np.zeros((4, 4), np.complex128), lines, apc, 0.03, grid)
    with pytest.raises(ProcessingError):
        backproject_into(np.zeros((4, 4), np.complex64), lines, apc[:1], 0.03, grid)
    with pytest.raises(ProcessingError):
        backproject_into(np.zeros((4, 4), np.complex64), lines, apc, 0.03, grid, pulses=[2])
    with pytest.raises(ProcessingError):
        backproject_into(
            np.zeros((4, 4), np.complex64), lines, apc, 0.03, grid, beam_half_angle_rad=2.0
        )


# -- point targets: speed-ups on and off --------------------------------------------------


@dataclass(frozen=True)
class Case:
    scn: Scenario
    rc: ComplexArray
    axis_m: FloatArray
    t_ns: IntArray
    apc_img: FloatArray
    targets_img: FloatArray


def _case(
    preset: str, scale: float, prf_hz: float, offsets: list[tuple[float, float]], heading: float
) -> Case:
    """Ideal straight track; the imaging frame is NED shifted to the first APC and turned
    by ``heading`` (its x axis ``heading`` rad from north toward east)."""
    c = load_preset(preset, scale).scene_center_ned
    targets = tuple(Target((c[0] + dn, c[1] + de, 0.0)) for dn, de in offsets)
    scn = load_preset(preset, scale, snr_db=None, targets=targets, prf_hz=prf_hz)
    run = simulate(scn, MotionSpec(kind="ideal"), "ideal")
    rc = rangecomp.compress(scn.radar, run.echo).astype(np.complex64)
    ch, sh = math.cos(heading), math.sin(heading)
    rot = np.array([[ch, sh, 0.0], [-sh, ch, 0.0], [0.0, 0.0, 1.0]])  # NED -> frame
    origin = run.apc_ned[0]
    return Case(
        scn,
        rc,
        rangecomp.range_axis_m(scn.radar),
        run.t_ns,
        (run.apc_ned - origin) @ rot.T,
        (run.targets_ned - origin) @ rot.T,
    )


def _fast_tiles(case: Case, pixel_m: float, oversampling: float) -> tuple[list[Tile], int]:
    """Tile imager with beam culling and the pre-filter, fed in blocks like the daemon."""
    scn = case.scn
    lam = scn.radar.wavelength_m
    beam = scn.integration_angle_rad + 2 * SQUINT_TOLERANCE_RAD
    layout = TileLayout(
        scn.altitude_m, scn.scene_center_ned[1], 1.1 * scn.swath_m, 10.0, pixel_m, beam
    )
    imager = TileImager(layout, case.axis_m, lam)
    band = 2 * scn.speed_mps * math.sin(beam / 2) / lam
    pre = AzimuthPrefilter(scn.radar.prf_hz, band, oversampling)
    step = (case.apc_img[-1] - case.apc_img[0]) / float(case.t_ns[-1] - case.t_ns[0])

    def apc(t: IntArray) -> FloatArray:  # the straight track, also before and after the pulses
        return case.apc_img[0] + (t - case.t_ns[0])[:, None].astype(np.float64) * step

    tiles: list[Tile] = []
    for a in range(0, case.rc.shape[0], 256):
        rc, t = pre.push(case.rc[a : a + 256], case.t_ns[a : a + 256])
        tiles += imager.add(rc, t, apc(t))
    rc, t = pre.flush()
    tiles += imager.add(rc, t, apc(t))
    return tiles + imager.close(), pre.decimation


def _window(tiles: list[Tile], centre: FloatArray, half_m: float) -> Image:
    """The pixels within ``half_m`` of ``centre`` on both axes, across tile boundaries."""
    tiles = sorted(tiles, key=lambda t: t.index)
    a0 = np.concatenate([t.grid.axis0_m for t in tiles])
    data = np.concatenate([t.data for t in tiles])
    a1 = tiles[0].grid.axis1_m
    i = np.flatnonzero(np.abs(a0 - centre[0]) <= half_m)
    j = np.flatnonzero(np.abs(a1 - centre[1]) <= half_m)
    return Image(data[i[0] : i[-1] + 1, j[0] : j[-1] + 1], a0[i], a1[j], "ground")


def _compare(case: Case, pixel_m: float, oversampling: float, min_decimation: int) -> None:
    tiles, decimation = _fast_tiles(case, pixel_m, oversampling)
    assert decimation >= min_decimation
    lam = case.scn.radar.wavelength_m
    for tgt in case.targets_img:
        fast = _window(tiles, tgt, 1.5)
        grid = PlaneGrid(fast.axis0_m, fast.axis1_m, (0.0, 0.0, tgt[2]), 0.0, "ground")
        ref = backproject(case.rc, case.axis_m, case.apc_img, lam, grid)
        m_ref = point_target_metrics(ref, (tgt[0], tgt[1]), 0.5)
        m_fast = point_target_metrics(fast, (tgt[0], tgt[1]), 0.5)
        assert np.max(np.abs(fast.data)) == pytest.approx(np.max(np.abs(ref.data)), rel=0.01)
        assert m_fast.position_error_m is not None
        assert np.hypot(*m_fast.position_error_m) < 0.01
        cuts: list[tuple[str, CutMetrics, CutMetrics]] = [
            ("azimuth", m_ref.axis0, m_fast.axis0),
            ("range", m_ref.axis1, m_fast.axis1),
        ]
        for name, r, f in cuts:
            msg = f"target {tgt[:2]} {name}: reference {r}, fast {f}"
            assert abs(f.pslr_db - r.pslr_db) <= 0.2, msg
            assert abs(f.islr_db - r.islr_db) <= 0.2, msg
            assert abs(f.irw_m / r.irw_m - 1.0) <= 0.02, msg


@pytest.mark.parametrize("heading", [0.0, HEADING_ERROR_RAD])
def test_spotlight_speedups_keep_point_targets(heading: float) -> None:
    """thz-spotlight (0.2 THz) at its 20 kHz PRF: decimated 13 times."""
    sw = load_preset("thz-spotlight", 0.1).swath_m
    offsets = [(0.0, 0.0), (0.0, -0.4 * sw), (0.0, 0.4 * sw), (1.5, 0.1 * sw)]
    case = _case("thz-spotlight", 0.1, 20_000.0, offsets, heading)
    _compare(case, pixel_m=0.04, oversampling=1.25, min_decimation=13)


def test_stripmap_speedups_keep_point_targets() -> None:
    """ku-vehicle (15 GHz, rect real beam) at a 1 kHz PRF: decimated 7 times."""
    sw = load_preset("ku-vehicle", 0.05).swath_m
    offsets = [(0.0, -0.4 * sw), (0.0, 0.4 * sw)]
    case = _case("ku-vehicle", 0.05, 1000.0, offsets, HEADING_ERROR_RAD)
    _compare(case, pixel_m=0.05, oversampling=1.25, min_decimation=7)


def test_a_tile_does_not_depend_on_the_tiles_open_beside_it() -> None:
    """Each open tile takes every pulse within half a beam footprint of it: the target's
    tile comes out the same imaged alone (``only``) or beside every tile the pulses reach.
    A loop variable once shadowed the half footprint with the half beam angle, so the
    tiles after the first in a block took only the pulses right over them: with 10 %
    radar loss (other blocks) ku-vehicle x0.1 focused to -0.9 dB azimuth PSLR."""
    case = _case("ku-vehicle", 0.05, 175.0, [(0.0, 0.0)], 0.0)
    scn = case.scn
    beam = scn.integration_angle_rad + 2 * SQUINT_TOLERANCE_RAD
    layout = TileLayout(scn.altitude_m, scn.scene_center_ned[1], 1.1 * scn.swath_m, 10.0, 0.1, beam)
    k = math.floor(case.targets_img[0, 0] / layout.tile_length_m)

    def tiles(only: range | None) -> dict[int, Tile]:
        imager = TileImager(layout, case.axis_m, scn.radar.wavelength_m, only=only)
        out = imager.add(case.rc, case.t_ns, case.apc_img) + imager.close()
        return {t.index: t for t in out}

    beside = tiles(None)
    assert min(beside) < k  # a tile before the target's is open with it
    np.testing.assert_array_equal(beside[k].data, tiles(range(k, k + 1))[k].data)
