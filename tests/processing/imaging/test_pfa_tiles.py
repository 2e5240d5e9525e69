"""The polar format tile former: point targets against theory and against backprojection.

thz-spotlight ×0.1 at the paper's 20 kHz PRF, ideal straight track, no noise, a run long
enough for the tile's whole aperture; the pulses range compressed, pre-filtered and
decimated as in the daemon and fed to :class:`PfaTileImager` in blocks. Targets at the
tile centre, at both swath edges and off the centre along track (all well within the
polar format's valid scene radius, 320 m here). Per target and axis: PSLR within 0.3 dB of
an unweighted sinc's -13.26 dB, IRW within 2 % of ``0.886 * 2 pi / extent`` of the
spectral rectangle kept (:func:`pfa_support` of the tile's aperture; along track
``lambda / (2 aperture)``), position within 1 cm; the complex peak within 3 % of
backprojection's (amplitude) and 0.1 rad (phase).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sarmoco.processing import rangecomp
from sarmoco.processing.imaging import PlaneGrid, backproject, pfa_support
from sarmoco.processing.imaging.pfa_tiles import PfaTileImager
from sarmoco.processing.imaging.presum import AzimuthPrefilter
from sarmoco.processing.imaging.tiles import Tile, TileLayout
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import FloatArray
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import Target, load_preset
from sarmoco.sim.trajectory import MotionSpec
from tests.processing.imaging.test_tiles import SQUINT_TOLERANCE_RAD, _window

SINC_PSLR_DB = -13.26
"""Peak sidelobe of an unweighted sinc, dB."""


@pytest.fixture(scope="module", params=[(0.1, 20_000.0), (1.0, 2_000.0)], ids=["x0.1", "x1"])
def run(request: pytest.FixtureRequest) -> dict[str, object]:
    """Pulses of thz-spotlight over 0.45 s (27 m: tile 1 at 10-20 m has its whole
    aperture), the tiles the imager formed, the targets: ×0.1 at the paper's PRF, and the
    full swath (targets 58 m from the tile centre: the planar-wavefront distortion moves
    them by 0.6 m) at a tenth of it (still 1.6 times the pre-filter's band)."""
    scale, prf_hz = request.param
    base = load_preset("thz-spotlight", scale)
    sw, c = base.swath_m, base.scene_center_ned
    offsets = [(1.5, 0.0), (1.5, -0.45 * sw), (1.5, 0.45 * sw), (4.5, 0.1 * sw), (-0.5, -0.2 * sw)]
    targets = tuple(Target((c[0] + dn, c[1] + de, 0.0)) for dn, de in offsets)
    scn = load_preset(
        "thz-spotlight", scale, snr_db=None, targets=targets, prf_hz=prf_hz, aperture_s=0.45
    )
    sim = simulate(scn, MotionSpec(kind="ideal"), "ideal")
    rc = rangecomp.compress(scn.radar, sim.echo).astype(np.complex64)
    axis = rangecomp.range_axis_m(scn.radar)
    apc = sim.apc_ned - sim.apc_ned[0]  # the imaging frame: NED from the first APC
    lam = scn.radar.wavelength_m
    beam = scn.integration_angle_rad + 2 * SQUINT_TOLERANCE_RAD
    layout = TileLayout(scn.altitude_m, c[1], 1.1 * sw, 10.0, 0.04, beam)
    band = 2 * scn.speed_mps * math.sin(beam / 2) / lam
    pre = AzimuthPrefilter(scn.radar.prf_hz, band, 1.25)
    imager = PfaTileImager(layout, axis, lam, scn.radar.bandwidth_hz, scn.integration_angle_rad)
    t0 = sim.t_ns[0]
    step = (apc[-1] - apc[0]) / float(sim.t_ns[-1] - t0)
    tiles: list[Tile] = []
    for a in range(0, rc.shape[0], 256):
        out, t = pre.push(rc[a : a + 256], sim.t_ns[a : a + 256])
        tiles += imager.add(out, t, apc[0] + (t - t0).astype(np.float64)[:, None] * step)
    tiles += imager.close()
    decimated = apc[:: pre.decimation]
    return {
        "scn": scn, "rc": rc, "axis": axis, "apc": apc, "tiles": tiles, "imager": imager,
        "targets": sim.targets_ned - sim.apc_ned[0], "decimated": decimated,
    }  # fmt: skip


def _theory_irw(run: dict[str, object], k: int, target: FloatArray) -> tuple[float, float]:
    """IRW along track and in ground range of the spectral rectangle tile ``k`` keeps, m."""
    imager = run["imager"]
    assert isinstance(imager, PfaTileImager)
    apc = run["decimated"]
    assert isinstance(apc, np.ndarray)
    lo, hi = imager.aperture_m(k)
    rows = apc[(apc[:, 0] >= lo) & (apc[:, 0] <= hi)]
    scn = run["scn"]
    f_c, b = scn.radar.carrier_hz, scn.radar.bandwidth_hz  # type: ignore[attr-defined]
    freq = np.linspace(f_c - b / 2, f_c + b / 2, 64)
    grid = PlaneGrid(np.array([0.0, 1.0]), np.array([0.0, 1.0]), tuple(target))
    return pfa_support(freq, rows, grid).irw_m


def test_pfa_tiles_focus_to_theory(run: dict[str, object]) -> None:
    tiles = run["tiles"]
    assert isinstance(tiles, list) and tiles
    lam = run["scn"].radar.wavelength_m  # type: ignore[attr-defined]
    for tgt in run["targets"]:  # type: ignore[attr-defined]
        k = math.floor(tgt[0] / 10.0)
        assert k in [t.index for t in tiles]
        img = _window(tiles, tgt, 1.5)
        m = point_target_metrics(img, (tgt[0], tgt[1]), 0.5)
        assert m.position_error_m is not None
        assert np.hypot(*m.position_error_m) < 0.01, f"target {tgt[:2]}: {m.position_error_m}"
        irw = _theory_irw(run, k, tgt)
        for name, cut, want in (("azimuth", m.axis0, irw[0]), ("range", m.axis1, irw[1])):
            msg = f"target {tgt[:2]} {name}: {cut}, theory IRW {want:.4f} m"
            print(msg)
            assert cut.pslr_db <= SINC_PSLR_DB + 0.3, msg
            assert cut.irw_m == pytest.approx(want, rel=0.02), msg
        # amplitude and phase at the peak: backprojection of the aperture's pulses (the
        # pre-filter's DC gain is its decimation, so the decimated pulses sum alike)
        i = int(np.argmin(np.abs(img.axis0_m - tgt[0])))
        j = int(np.argmin(np.abs(img.axis1_m - tgt[1])))
        pixel = PlaneGrid(img.axis0_m[i : i + 2], img.axis1_m[j : j + 2], (0.0, 0.0, tgt[2]))
        apc, rc, imager = run["apc"], run["rc"], run["imager"]
        assert isinstance(apc, np.ndarray) and isinstance(rc, np.ndarray)
        assert isinstance(imager, PfaTileImager)
        lo, hi = imager.aperture_m(k)
        rows = (apc[:, 0] >= lo) & (apc[:, 0] <= hi)
        ref = backproject(rc[rows], run["axis"], apc[rows], lam, pixel).data[0, 0]  # type: ignore[arg-type]
        got = img.data[i, j]
        assert abs(got) == pytest.approx(abs(ref), rel=0.03), f"target {tgt[:2]}"
        assert abs(np.angle(got / ref)) < 0.1, f"target {tgt[:2]}"
        print(f"target {tgt[:2]}: peak / backprojection {got / ref:.4f}")


def test_close_after_every_pulse_was_used_forms_nothing_more() -> None:
    """Pulses that end between one tile's aperture and the next: the first tile takes them
    all, none are held, and the segment closes with no more tiles (it raised)."""
    layout = TileLayout(1000.0, 1118.0, 13.0, 10.0, 0.04, 0.015)
    axis = 1400.0 + 0.1 * np.arange(2048)
    imager = PfaTileImager(layout, axis, 1.5e-3, 1.1e9, 4.7e-3)
    lo, hi = imager.aperture_m(0)
    assert hi + 1.0 < imager.aperture_m(1)[0]
    x = np.linspace(lo - 1.0, hi + 1.0, 200)
    apc = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    rc = np.zeros((200, 2048), np.complex64)
    imager.add(rc, np.arange(200, dtype=np.int64), apc)
    assert imager.close() == []
