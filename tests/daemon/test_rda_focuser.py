"""The daemon's live imager (``imaging.method = "rda"``) on point targets, and its level rule.

Raw ku-vehicle ×0.05 echoes (15 GHz, rect real beam, turbulent flight with an ideal INS,
no noise, autofocus off) go through :class:`Focuser` in blocks as the pipeline sends
them: INS compensation to the straight reference track and the per-bin residual, the
azimuth pre-filter, then the range-Doppler tile former. Each target is judged against
theory on the ground tiles: PSLR within 0.5 dB of the sinc's -13.26 dB and IRW within
5 % of ``0.886 c / 2B`` (range, projected to the ground) and of
``0.886 lambda / (4 sin(theta / 2))`` (azimuth, ``theta`` the real beam), position within
2 cm. Without range cell migration correction the azimuth PSLR is -9.2 dB; with the
pulses' along-track positions (uneven in gusts) taken as uniform, -10.4 dB.
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.daemon.livelevel import (
    HEADROOM,
    LEVEL_COST,
    PROMPT_COST,
    LiveLevel,
    level_names,
)
from sarmoco.daemon.status import LIVE_PAGE
from sarmoco.errors import ConfigError
from sarmoco.processing.imaging.rda_tiles import LEVELS, RdaTileImager, degraded
from sarmoco.processing.imaging.tiles import Tile, TileLayout
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import C_MPS, Image
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import Target, load_preset

SINC_PSLR_DB = -13.26
"""Peak sidelobe of an unweighted sinc, dB."""


@pytest.fixture(scope="module")
def strip() -> SimRun:
    scn0 = load_preset("ku-vehicle", 0.05)
    c, sw = scn0.scene_center_ned, scn0.swath_m
    targets = tuple(
        Target((c[0] + dn, c[1] + de, 0.0)) for dn, de in ((0, -0.4 * sw), (3, 0.4 * sw))
    )
    scn = load_preset("ku-vehicle", 0.05, snr_db=None, targets=targets)
    return simulate(scn, MotionSpec(kind="turbulence", seed=1), "ideal")


def _focus(run: SimRun, level: int = 0, **imaging: object) -> tuple[list[Tile], Focuser]:
    """Tiles of ``run`` through a focuser (``level``: a degraded level held throughout)."""
    cfg = scenario_config(
        run.scenario, autofocus={"enabled": False}, imaging={"method": "rda", **imaging}
    )
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:256].mean(axis=0))
    tiles: list[Tile] = []
    for a in range(0, run.t_ns.size, cfg.imaging.block_pulses):
        b = slice(a, a + cfg.imaging.block_pulses)
        tiles += focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b]).tiles
        if level and focuser.segment is not None:  # a segment forms no tile in its first block
            focuser.segment.tiles.level = level
    return tiles + focuser.finish().tiles, focuser


def _window(tiles: list[Tile], x: float, y: float, half_m: float = 1.5) -> Image:
    """The pixels within ``half_m`` of ``(x, y)`` on both axes, across tile boundaries."""
    tiles = sorted(tiles, key=lambda t: t.index)
    a0 = np.concatenate([t.grid.axis0_m for t in tiles])
    data = np.concatenate([t.data for t in tiles])
    a1 = tiles[0].grid.axis1_m
    i = np.flatnonzero(np.abs(a0 - x) <= half_m)
    j = np.flatnonzero(np.abs(a1 - y) <= half_m)
    return Image(data[i[0] : i[-1] + 1, j[0] : j[-1] + 1], a0[i], a1[j], "ground")


@pytest.mark.parametrize(
    ("imaging", "prompt"),
    [({"live_budget": 1e6, "live_window_s": 0.01}, True), ({"live_degrade": False}, False)],
    ids=["prompt", "blocks"],
)
def test_live_imager_focuses_point_targets_as_theory(
    strip: SimRun, imaging: dict[str, object], prompt: bool
) -> None:
    """Tiles formed alone as soon as their pulses are in (a live focuser with room), and in
    blocks of tiles (one over its budget, and a replay)."""
    tiles, focuser = _focus(strip, **imaging)
    assert isinstance(focuser._last.tiles, RdaTileImager)
    assert focuser._last.tiles.prompt is prompt
    scn, track = strip.scenario, focuser.track
    lam = scn.radar.wavelength_m
    irw_az = 0.886 * lam / (4.0 * math.sin(scn.integration_angle_rad / 2.0))
    for tgt in strip.targets_ned:
        d = tgt - strip.apc_ned[0]
        x, y = float(d @ track.x_hat), float(d @ track.y_hat)
        h = float(scn.altitude_m)
        irw_rg = 0.886 * C_MPS / (2.0 * scn.radar.bandwidth_hz) * math.hypot(y, h) / y
        m = point_target_metrics(_window(tiles, x, y), (x, y), 0.5)
        for name, cut, irw in (("az", m.axis0, irw_az), ("rg", m.axis1, irw_rg)):
            msg = f"target at y {y:.1f} m, {name}: {cut}, theory IRW {irw:.4f} m"
            print(msg)
            assert abs(cut.pslr_db - SINC_PSLR_DB) <= 0.5, msg
            assert abs(cut.irw_m / irw - 1.0) <= 0.05, msg
        assert m.position_error_m is not None
        assert math.hypot(*m.position_error_m) < 0.02


def test_degraded_level_forms_coarser_narrower_tiles() -> None:
    layout = TileLayout(100.0, 900.0, 300.0, 10.0, 0.1, 0.06)
    assert degraded(layout, 0) is layout
    for level, (pixel, narrow, _) in enumerate(LEVELS):
        d = degraded(layout, level)
        assert d.pixel_m == pytest.approx(0.1 * pixel)
        assert d.swath_m == pytest.approx(300.0 / narrow)
        assert d.ground_range_m == layout.ground_range_m
        g = d.grid(3)
        assert g.axis0_m.size == round(10.0 / d.pixel_m)


def test_presum_level_widens_the_azimuth_response_as_its_band(strip: SimRun) -> None:
    """Level 1 presums by 2: the processed Doppler band, the imaged beam's at level 0
    (wider than the real beam by the squint tolerance), is halved about the centroid. A
    point target's azimuth IRW is then ``0.886 / B`` of that band, its PSLR still the
    sinc's (the band stays a rectangle within the real beam's), its range response and
    position as at level 0, its energy the share of the real beam's band kept."""
    presum = LEVELS[1][2]
    assert presum == 2
    full, _ = _focus(strip)
    half, focuser = _focus(strip, level=1)
    scn, track = strip.scenario, focuser.track
    lam = scn.radar.wavelength_m
    imaged = scenario_config(scn).imaging.imaged_beam_rad()
    sin_band = math.sin(imaged / 2.0) / presum  # half the processed band, as sin(angle)
    irw_az = 0.886 * lam / (4.0 * sin_band)
    kept = sin_band / math.sin(scn.integration_angle_rad / 2.0)  # of the real beam's band
    assert 0.5 < kept < 1.0
    for tgt in strip.targets_ned:
        d = tgt - strip.apc_ned[0]
        x, y = float(d @ track.x_hat), float(d @ track.y_hat)
        m0 = point_target_metrics(_window(full, x, y), (x, y), 0.5)
        m = point_target_metrics(_window(half, x, y), (x, y), 0.5)
        msg = f"y {y:.1f} m: level 1 {m}, level 0 {m0}, theory az IRW {irw_az:.4f} m"
        print(msg)
        assert abs(m.axis0.pslr_db - SINC_PSLR_DB) <= 0.5, msg
        assert abs(m.axis0.irw_m / irw_az - 1.0) <= 0.05, msg
        assert abs(m.axis1.irw_m / m0.axis1.irw_m - 1.0) <= 0.05, msg
        assert m.position_error_m is not None
        assert math.hypot(*m.position_error_m) < 0.02
        # peak a N (N: the pulses of the band kept), IRW 1 / B: energy a² N² / B ∝ the band
        ratio = _energy(_window(half, x, y)) / _energy(_window(full, x, y))
        assert abs(ratio / kept - 1.0) <= 0.05, f"energy ratio {ratio:.3f}, {msg}"


def _energy(image: Image) -> float:
    """Sum of |pixel|² times the pixel area: a point response's energy, whatever the pixels."""
    area = float(np.diff(image.axis0_m)[0] * np.diff(image.axis1_m)[0])
    return float(np.sum(np.abs(image.data) ** 2)) * area


def rule_rung(level: int, prompt: bool) -> int:
    """The rung of :class:`LiveLevel` of a level with tiles prompt or in blocks."""
    return 0 if prompt else level + 1


def _rungs(rule: LiveLevel, data_s: float, busy_s: float, n: int) -> list[tuple[int, bool]]:
    """(level, prompt) after each of ``n`` updates of ``rule`` with the same load."""
    return [(rule.update(data_s, busy_s), rule.prompt) for _ in range(n)]


def test_live_level_rule_steps_up_holds_and_steps_down() -> None:
    rule = LiveLevel(budget=0.8, window_s=5.0)
    assert rule.level == 0 and not rule.prompt  # starts at level 0 in blocks
    # 1.2 s of focusing per s of data: up after one window, then held for another
    rungs = _rungs(rule, 1.0, 1.2, 12)
    assert rungs[:4] == [(0, False)] * 4 and rungs[4] == (1, False)
    assert rungs[5:9] == [(1, False)] * 4 and rungs[9] == (2, False)  # over budget: up
    assert rule.update(0.0, 5.0) == 2  # no data: nothing decided
    # the load expected one level down is the measured cost ratio times this one's
    assert rule.load * LEVEL_COST[1] / LEVEL_COST[2] == pytest.approx(rule._at(rule.rung - 1))
    # 0.3 s per s at level 2 would be 0.3 c1 / c2 at level 1: within 0.7 of the budget;
    # and down to prompt tiles, one rung at a time
    down = _rungs(rule, 1.0, 0.3, 25)
    assert down[-1] == (0, True) and max(level for level, _ in down) <= 2
    steps = [rule_rung(level, prompt) for level, prompt in down]
    assert all(b - a in (-1, 0) for a, b in itertools.pairwise(steps))
    # a load that fits at level 2 but not, with the headroom, at level 1: held at 2
    held = 1.01 * HEADROOM * 0.8 * LEVEL_COST[2] / LEVEL_COST[1]
    stay = LiveLevel(budget=0.8, window_s=1.0)
    stay.rung, stay.load = rule_rung(2, False), held
    assert [stay.update(1.0, held) for _ in range(5)] == [2] * 5
    lower = 0.98 * HEADROOM * 0.8 * LEVEL_COST[2] / LEVEL_COST[1]  # fits at level 1
    assert stay.update(1.0, lower) == 1
    # level 0 in blocks steps down to prompt tiles only where their cost fits
    blocks = LiveLevel(budget=0.8, window_s=1.0)
    blocks.rung, blocks.load = rule_rung(0, False), 1.01 * HEADROOM * 0.8 / PROMPT_COST
    assert _rungs(blocks, 1.0, blocks.load, 5) == [(0, False)] * 5
    assert _rungs(blocks, 1.0, 0.98 * HEADROOM * 0.8 / PROMPT_COST, 1) == [(0, True)]
    top = LiveLevel(budget=0.8, window_s=1.0)
    assert max(top.update(1.0, 10.0) for _ in range(20)) == len(LEVELS) - 1
    # a lowest level (imaging.live_min_level): the rule starts there, in blocks, and never
    # goes below it
    floor = LiveLevel(budget=0.8, window_s=1.0, floor=1)
    assert _rungs(floor, 1.0, 0.01, 10) == [(1, False)] * 10
    assert max(floor.update(1.0, 10.0) for _ in range(20)) == len(LEVELS) - 1
    with pytest.raises(ConfigError):
        LiveLevel(budget=0.8, window_s=1.0, floor=len(LEVELS))


def test_focuser_applies_the_level_to_the_tiles_it_forms(strip: SimRun) -> None:
    """A focuser over its budget forms degraded tiles; with live_degrade off, none."""
    tiles, focuser = _focus(strip, live_budget=1e-6, live_window_s=0.01)
    assert focuser.live is not None and focuser.live.level >= 1
    pixel = scenario_config(strip.scenario).imaging.pixel_m
    spacing = {round(float(np.diff(t.grid.axis0_m)[0]) / pixel) for t in tiles}
    assert spacing - {1} and spacing <= {p for p, _, _ in LEVELS}
    _, steady = _focus(strip, live_degrade=False)
    assert steady.live is None


def test_live_load_counts_the_pulses_focused_not_the_holes(strip: SimRun) -> None:
    """A focuser fallen behind skips recorded pulses: the level rule's data seconds are
    those of the pulses it focused, so that the skip does not hide the load."""
    cfg = scenario_config(strip.scenario, imaging={"method": "rda"})
    focuser = Focuser(cfg, int(strip.t_ns[0]), strip.vel_ned[:256].mean(axis=0))
    seen: list[float] = []

    class Spy(LiveLevel):
        def update(self, data_s: float, busy_s: float) -> int:
            seen.append(data_s)
            return super().update(data_s, busy_s)

    focuser.live = Spy(cfg.imaging.live_budget, cfg.imaging.live_window_s)
    n = 32
    for a, skipped in ((0, False), (n, False), (8 * n, True)):  # 6 blocks skipped
        b = slice(a, a + n)
        after = np.zeros(n, bool)
        after[0] = skipped
        focuser.push(strip.echo[b], strip.t_ns[b], strip.vel_ned[b], after_skip=after)
    assert seen == pytest.approx([n / cfg.radar.prf_hz] * 3, rel=1e-12)


def test_live_page_names_every_level() -> None:
    names = level_names()
    assert names[0] == "full" and len(names) == len(LEVELS)
    # every level has its measured cost, each cheaper than the one before
    assert len(LEVEL_COST) == len(LEVELS) and LEVEL_COST[0] == 1.0
    assert all(b < a for a, b in itertools.pairwise(LEVEL_COST))
    assert json.dumps(names) in LIVE_PAGE


def _push_with_hole(run: SimRun, hole: slice, tell: bool) -> tuple[Focuser, list[Tile], int]:
    """Focus ``run`` as the live daemon does (presum first, autofocus on) without the pulses
    of ``hole``; ``tell``: the first pulse after it is marked ``after_skip``. Returns the
    focuser, the tiles, and how many times a segment's tile imager was made."""
    cfg = scenario_config(run.scenario, imaging={"method": "rda", "presum_first": True})
    keep = np.ones(run.t_ns.size, dtype=bool)
    keep[hole] = False
    rows = np.flatnonzero(keep)
    after_skip = np.diff(rows, prepend=-1) > 1 if tell else np.zeros(rows.size, dtype=bool)
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:256].mean(axis=0))
    imagers = {id(focuser._last.tiles)}
    tiles: list[Tile] = []
    for a in range(0, rows.size, cfg.imaging.block_pulses):
        r = rows[a : a + cfg.imaging.block_pulses]
        out = focuser.push(
            run.echo[r], run.t_ns[r], run.vel_ned[r], quat=run.traj.quat[r],
            after_skip=after_skip[a : a + cfg.imaging.block_pulses],
        )  # fmt: skip
        tiles += out.tiles
        imagers.add(id(focuser._last.tiles))
    return focuser, tiles + focuser.finish().tiles, len(imagers)


def test_a_skip_carries_the_segment_across_the_hole() -> None:
    """A live focuser fallen behind skips 3.4 s of pulses (longer than the segmenter's
    window, after which a silence starts a new segment): told it was a skip, it keeps the
    one segment (its track, D_los, beam and tile imager: one imager made,
    counted) and forms tiles after the hole; not told, the same hole starts a second
    segment with new state."""
    scn = load_preset("ku-vehicle", 0.05)
    run = simulate(scn, MotionSpec(kind="turbulence", seed=1), "ideal", n_pulses=1800)
    prf = scn.radar.prf_hz
    hole = slice(round(3.0 * prf), round(6.4 * prf))
    after_ns = int(run.t_ns[hole.stop])
    focuser, tiles, imagers = _push_with_hole(run, hole, tell=True)
    assert focuser.segments == 1 and imagers == 1
    assert any(t.t0_ns >= after_ns for t in tiles)
    assert any(t.t1_ns < int(run.t_ns[hole.start]) for t in tiles)
    focuser, _, imagers = _push_with_hole(run, hole, tell=False)
    assert focuser.segments == 2 and imagers == 2


def _waits(run: SimRun, push: int, **imaging: object) -> tuple[list[Tile], list[int]]:
    """Tiles of ``run`` through a live focuser fed ``push`` pulses at a time, and for each
    tile formed before the end the pulses pushed after its last one before it came out."""
    cfg = scenario_config(
        run.scenario, autofocus={"enabled": False}, imaging={"method": "rda", **imaging}
    )
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:256].mean(axis=0))
    tiles: list[Tile] = []
    waits: list[int] = []
    for a in range(0, run.t_ns.size, push):
        b = slice(a, a + push)
        out = focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b]).tiles
        tiles += out
        last = int(run.t_ns[b][-1])
        waits += [int(np.count_nonzero((run.t_ns > t.t1_ns) & (run.t_ns <= last))) for t in out]
    return tiles + focuser.finish().tiles, waits


def test_prompt_tiles_wait_for_no_later_tile(strip: SimRun) -> None:
    """A live focuser with room steps down to prompt tiles: it forms each range-Doppler
    tile as soon as the pulses reach the interpolation guard and the pre-filter's delay
    past its last pulse: none waits a tile length of flight, where tiles formed in blocks
    (the rung above, and a replay) wait up to ``block_tiles - 1`` tile lengths. The two
    give the same image (the point targets of both:
    :func:`test_live_imager_focuses_point_targets_as_theory`)."""
    cfg = scenario_config(strip.scenario, imaging={"method": "rda"})
    speed = float(np.linalg.norm(strip.vel_ned[0]))
    tile_pulses = cfg.imaging.tile_length_m / speed * cfg.radar.prf_hz
    push = 16
    # never over budget: from blocks down to prompt tiles after the first push
    prompt, waits = _waits(strip, push, live_budget=1e6, live_window_s=0.01)
    blocked, block_waits = _waits(strip, push, live_degrade=False)
    print(f"tile {tile_pulses:.0f} pulses; waits prompt {waits}, in blocks {block_waits}")
    assert len(waits) >= 4 and max(waits) < tile_pulses
    assert max(block_waits) > 2 * tile_pulses  # a block's first tile waits for the others
    # the same tiles: the blocks' ends fall elsewhere, which moves only what the partial
    # apertures there wrap into the block (at most -59 dB of the strongest pixel)
    ends = {t.index: t for t in blocked}
    assert [t.index for t in prompt] == [t.index for t in blocked]
    # blocks for the first 2 s of data, then prompt tiles: every tile once, in order
    stepped, _ = _waits(strip, push, live_budget=1e6, live_window_s=2.0)
    assert [t.index for t in stepped] == [t.index for t in blocked]
    peak = max(float(np.abs(t.data).max()) for t in blocked)
    for t in prompt:
        diff = float(np.abs(t.data - ends[t.index].data).max()) / peak
        assert diff < 2e-3, f"tile {t.index}: difference {diff:.2e} of the strongest pixel"
