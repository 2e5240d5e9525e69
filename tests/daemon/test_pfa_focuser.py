"""The spotlight live imager (``imaging.method = "pfa"``) through the daemon's Focuser.

Raw thz-spotlight ×0.1 echoes at the paper's 20 kHz PRF (0.2 THz, turbulent flight with an
ideal INS, no noise, autofocus off) go through :class:`Focuser` in blocks with the
pre-filter first (``imaging.presum_first``): the per-pulse D_los phase at the full rate,
then the presum, range compression, envelope shift and per-bin D_los at the decimated
rate, then the polar format tile former. Each target is judged against theory on the
ground tiles: PSLR within 0.5 dB of the sinc's -13.26 dB, IRW within 5 % of
``0.886 lambda / (4 sin(theta / 2))`` (azimuth, ``theta = imaging.azimuth_beamwidth_deg``,
the tile's aperture) and of ``0.886 c / 2B`` projected to the ground (measured: -13.27 dB,
IRW within 1 %), position within 0.1 m of the target taken from the first APC along the
reference track's axes (measured 7.7 cm in range, not yet explained: the frame's offset
under turbulence, or the chain's).

A simulated spotlight scene's configuration picks the polar format for live runs only
(``imaging.live_method``); replay and batch keep ``imaging.method``.
"""

from __future__ import annotations

import math

import pytest

from sarmoco.app.simconfig import config_table, scenario_config
from sarmoco.daemon.config import live_imaging, parse_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.processing.imaging.pfa_tiles import PfaTileImager
from sarmoco.processing.imaging.tiles import Tile
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import C_MPS
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import Target, load_preset
from sarmoco.sim.trajectory import MotionSpec
from tests.daemon.test_rda_focuser import SINC_PSLR_DB, _window


@pytest.fixture(scope="module")
def spot() -> SimRun:
    scn0 = load_preset("thz-spotlight", 0.1)
    c, sw = scn0.scene_center_ned, scn0.swath_m
    targets = tuple(
        Target((c[0] + dn, c[1] + de, 0.0)) for dn, de in ((9.0, -0.4 * sw), (11.0, 0.4 * sw))
    )
    scn = load_preset(
        "thz-spotlight", 0.1, snr_db=None, targets=targets, prf_hz=20_000.0, aperture_s=0.6
    )
    return simulate(scn, MotionSpec(kind="turbulence", seed=1), "ideal")


def test_pfa_live_imager_focuses_point_targets_as_theory(spot: SimRun) -> None:
    cfg = scenario_config(
        spot.scenario,
        autofocus={"enabled": False},
        mocomp={"segments": False},
        imaging={"method": "pfa", "presum_first": True, "live_degrade": False},
    )
    focuser = Focuser(cfg, int(spot.t_ns[0]), spot.vel_ned[:256].mean(axis=0))
    tiles: list[Tile] = []
    for a in range(0, spot.t_ns.size, cfg.imaging.block_pulses):
        b = slice(a, a + cfg.imaging.block_pulses)
        tiles += focuser.push(spot.echo[b], spot.t_ns[b], spot.vel_ned[b]).tiles
    tiles += focuser.finish().tiles
    assert isinstance(focuser._last.tiles, PfaTileImager)
    scn, track = spot.scenario, focuser.track
    theta = math.radians(cfg.imaging.azimuth_beamwidth_deg)
    irw_az = 0.886 * scn.radar.wavelength_m / (4.0 * math.sin(theta / 2.0))
    for tgt in spot.targets_ned:
        d = tgt - spot.apc_ned[0]
        x, y = float(d @ track.x_hat), float(d @ track.y_hat)
        irw_rg = 0.886 * C_MPS / (2.0 * scn.radar.bandwidth_hz) * math.hypot(y, scn.altitude_m) / y
        m = point_target_metrics(_window(tiles, x, y), (x, y), 0.5)
        for name, cut, irw in (("az", m.axis0, irw_az), ("rg", m.axis1, irw_rg)):
            msg = f"target at y {y:.1f} m, {name}: {cut}, theory IRW {irw:.4f} m"
            print(msg)
            assert abs(cut.pslr_db - SINC_PSLR_DB) <= 0.5, msg
            assert abs(cut.irw_m / irw - 1.0) <= 0.05, msg
        assert m.position_error_m is not None
        assert math.hypot(*m.position_error_m) < 0.1, m.position_error_m


def test_spotlight_scene_picks_the_polar_format_for_live_runs_only() -> None:
    cfg = parse_config(config_table(load_preset("thz-spotlight", 0.1)))
    assert cfg.imaging.live_method == "pfa"
    assert cfg.imaging.method == "direct"  # replay and batch: full-resolution backprojection
    assert live_imaging(cfg).imaging.method == "pfa"
    strip = parse_config(config_table(load_preset("ku-vehicle", 0.1)))
    assert live_imaging(strip) == strip
