"""Stripmap PGA of backprojected tiles, broadside and under a squinted beam.

Point targets at several along-track positions and ground ranges of a ku-vehicle-like
geometry (λ = 2 cm, R ≈ 900 m, v = 17.5 m/s, pixel 0.1 m) are range compressed
analytically, given an azimuth phase error per pulse, and backprojected by the daemon's
:class:`TileImager`; :class:`TilePga` refocuses the tiles. Each target sees a different
part of a phase error shorter than an autofocus subaperture (a 5 Hz sinusoid of 1 rad:
paired echoes at ±2.6 m, azimuth PSLR about -5 dB).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.errors import ProcessingError
from sarmoco.processing.imaging.tile_pga import StripPga, TilePga
from sarmoco.processing.imaging.tiles import Tile, TileImager, TileLayout
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import Image
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset

WAVELENGTH_M = 0.02
HEIGHT_M = 100.0
SPEED_MPS = 17.5
PRF_HZ = 175.0
RES_M = 0.2
"""Slant-range resolution (750 MHz), m."""
BEAM_RAD = math.radians(2.863 + 0.6)
LAYOUT = TileLayout(
    height_m=HEIGHT_M,
    ground_range_m=math.sqrt(900.0**2 - HEIGHT_M**2),
    swath_m=33.0,
    tile_length_m=10.0,
    pixel_m=0.1,
    beamwidth_rad=BEAM_RAD,
)
TARGETS = [(22.0, 884.0), (24.5, 890.0), (27.0, 896.0), (25.5, 902.0), (15.0, 893.0)]
"""(x, ground range) of the point targets, m: four in tile 2, one in its neighbour."""


def _tiles(
    phase_error: Callable[[np.ndarray], np.ndarray] | None, squint_rad: float = 0.0
) -> list[Tile]:
    """Tiles 1..3 of the targets, backprojected from pulses carrying ``phase_error`` (rad).

    ``squint_rad``: the beam (``BEAM_RAD`` wide) points that far ahead of the plane normal
    to the track (a crabbed platform); a target echoes only while it is in the beam, and
    the pixels take the pulses of that beam.
    """
    lead = 900.0 * math.tan(squint_rad)
    t = np.arange(-10.0 - lead, 55.0 - lead, SPEED_MPS / PRF_HZ) / SPEED_MPS
    x_p = SPEED_MPS * t
    range_m = 880.0 + np.arange(700, dtype=np.float64) * 0.15
    beam = squint_rad + np.array([-0.5, 0.5]) * BEAM_RAD
    rc = np.zeros((t.size, range_m.size), np.complex64)
    for x, y in TARGETS:
        r = np.sqrt((x - x_p) ** 2 + y**2 + HEIGHT_M**2)
        psi = np.arctan2(x - x_p, math.hypot(y, HEIGHT_M))
        lit = (psi >= beam[0]) & (psi <= beam[1])
        rc += (
            np.sinc((range_m[None, :] - r[:, None]) / RES_M)
            * (lit * np.exp(-4j * np.pi * r / WAVELENGTH_M))[:, None]
        ).astype(np.complex64)
    if phase_error is not None:
        rc *= np.exp(1j * phase_error(t))[:, None].astype(np.complex64)
    imager = TileImager(LAYOUT, range_m, WAVELENGTH_M)
    apc = np.zeros((t.size, 3))
    apc[:, 0] = x_p
    t_ns = np.round(t * 1e9).astype(np.int64)
    tiles = imager.add(rc, t_ns, apc, beam_squint_rad=np.tile(beam, (t.size, 1))) + imager.close()
    return [tile for tile in tiles if 1 <= tile.index <= 3]


def _pslr(tiles: list[Tile]) -> list[float]:
    """Azimuth PSLR of each target of tiles 1..3, dB."""
    out = []
    for x, y in TARGETS:
        tile = next(tl for tl in tiles if tl.grid.axis0_m[0] <= x < tl.grid.axis0_m[-1])
        m = point_target_metrics(tile.image(), (x, y), 0.5)
        out.append(m.axis0.pslr_db)
    return out


def _refocus(tiles: list[Tile], squint_rad: tuple[float, float] | None = None) -> list[Tile]:
    pga = TilePga(StripPga(HEIGHT_M, WAVELENGTH_M, BEAM_RAD / 2.0))
    return pga.push(tiles, squint_rad) + pga.flush(squint_rad)


def _sine(t: np.ndarray) -> np.ndarray:
    return 1.0 * np.sin(2.0 * np.pi * 5.0 * t + 0.3)


def test_pga_refocuses_a_phase_error_shorter_than_a_subaperture() -> None:
    tiles = _tiles(_sine)
    before = _pslr(tiles)
    after = _pslr(_refocus(tiles))
    print("PSLR before", np.round(before, 2), "after", np.round(after, 2))
    assert min(before) > -8.0
    assert max(after) <= -12.5


@pytest.mark.parametrize("seed", [3, 4])
def test_pga_refocuses_random_phase_noise(seed: int) -> None:
    """1 rad rms, a new independent value every 0.1 s (a quarter subaperture), linear between."""
    rng = np.random.default_rng(seed)
    t_knots = np.arange(-2.0, 5.0, 0.1)
    knots = rng.normal(0.0, 1.0, t_knots.size)

    def noise(t: np.ndarray) -> np.ndarray:
        return np.interp(t, t_knots, knots)

    tiles = _tiles(noise)
    before = _pslr(tiles)
    after = _pslr(_refocus(tiles))
    print("PSLR before", np.round(before, 2), "after", np.round(after, 2))
    assert min(before) > -10.0
    assert max(after) <= -12.5


@pytest.mark.parametrize("crab_deg", [-4.0, 6.0])
def test_pga_refocuses_the_tiles_of_a_squinted_beam(crab_deg: float) -> None:
    """A crabbed platform's beam: the tiles' azimuth band lies about 2k sin(crab), beyond
    the pixel's Nyquist wavenumber here (aliased in the image); PGA keeps that band.

    The error is 1 rad at 2 Hz (paired echoes ±1.0 m from the peak): the range walk of
    the squinted beam moves them 0.07-0.11 m in range, within the target's column that
    PGA decompresses (a faster error's paired echoes walk off it).
    """
    squint = math.radians(crab_deg)
    tiles = _tiles(lambda t: np.sin(2.0 * np.pi * 2.0 * t + 0.3), squint)
    before = _pslr(tiles)
    after = _pslr(_refocus(tiles, (squint - BEAM_RAD / 2.0, squint + BEAM_RAD / 2.0)))
    print("PSLR before", np.round(before, 2), "after", np.round(after, 2))
    assert min(before) > -8.0
    assert max(after) <= -12.5


def test_pga_leaves_a_focused_tile_focused() -> None:
    tiles = _tiles(None)
    before = _pslr(tiles)
    after = _pslr(_refocus(tiles))
    print("PSLR before", np.round(before, 2), "after", np.round(after, 2))
    assert np.all(np.array(after) <= np.array(before) + 0.2)


def test_tiles_are_handed_out_in_order_one_behind() -> None:
    tiles = _tiles(None)
    pga = TilePga(StripPga(HEIGHT_M, WAVELENGTH_M, BEAM_RAD / 2.0))
    assert pga.push(tiles[:1]) == []
    assert [t.index for t in pga.push(tiles[1:])] == [1, 2]
    assert [t.index for t in pga.flush()] == [3]
    assert pga.flush() == []


def test_a_coarse_pixel_is_refused() -> None:
    with pytest.raises(ProcessingError, match="coarser"):
        StripPga(HEIGHT_M, WAVELENGTH_M, BEAM_RAD / 2.0).focus(
            np.zeros((64, 8), np.complex64), 0.3, np.full(8, 890.0)
        )


# -- through the daemon's Focuser: ku-vehicle x0.1, ideal track and INS, echoes given the
# 5 Hz error; the chain's pre-filter, along-track time map and tile order included --------


def _daemon_pslr(run: SimRun, pga: bool) -> list[float]:
    """Azimuth PSLR of each target of ``run`` focused by the Focuser (autofocus off), dB."""
    cfg = scenario_config(run.scenario, autofocus={"enabled": False, "pga": pga})
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[0])
    tiles: list[Tile] = []
    for a in range(0, run.t_ns.size, cfg.imaging.block_pulses):
        b = slice(a, a + cfg.imaging.block_pulses)
        tiles += focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b]).tiles
    tiles += focuser.finish().tiles
    indices = [t.index for t in tiles]
    assert indices == sorted(set(indices)) == list(range(indices[0], indices[-1] + 1))
    a0 = np.concatenate([t.grid.axis0_m for t in tiles])
    strip = Image(np.concatenate([t.data for t in tiles]), a0, tiles[0].grid.axis1_m, "ground")
    track = focuser.track
    out = []
    for tg in run.targets_ned:
        x, y, _ = track.rotation @ (tg - run.apc_ned[0])
        out.append(point_target_metrics(strip, (x, y), 0.5).axis0.pslr_db)
    return out


def test_the_daemon_option_refocuses_its_tiles() -> None:
    scn = load_preset("ku-vehicle", 0.1, snr_db=None)
    run = simulate(scn, MotionSpec(kind="ideal"), "ideal")
    t_s = (run.t_ns - run.t_ns[0]) * 1e-9
    run = dataclasses.replace(run, echo=run.echo * np.exp(1j * _sine(t_s))[:, None])
    plain = _daemon_pslr(run, pga=False)
    refocused = _daemon_pslr(run, pga=True)
    print("PSLR without PGA", np.round(plain, 2), "with", np.round(refocused, 2))
    assert min(plain) > -8.0
    assert max(refocused) <= -12.5
