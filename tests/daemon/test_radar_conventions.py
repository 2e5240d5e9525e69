"""A digitiser's conventions through the daemon's focusing chain: a scene simulated with a
down-chirp and conjugated I/Q (spectral inversion) focuses, with the matching
``radar.chirp_direction`` and ``radar.iq_conjugate``, exactly as the same scene with the
simulator's own convention (up-chirp, plain I/Q): same IRW and peak position, PSLR within the
bar (the range sidelobes of a down-chirp are the mirror image of an up-chirp's, so the higher
of the two first sidelobes may change side: thz range PSLR -12.83..-13.25 dB for the up-chirp,
-12.83..-12.95 dB for the down-chirp). With the default keys it does not focus.

Both receive chains: ku-vehicle (matched filter) and thz-spotlight (dechirp), scale 0.1,
ideal track and INS, no noise, autofocus off.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.processing.imaging.tiles import Tile
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import Image
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset

WINDOW_M = 1.5
"""Half-size of the image window measured about each target, m."""

DIGITISER = {"chirp_direction": "down", "iq_conjugate": True}
DEFAULT_KEYS = {"chirp_direction": "up", "iq_conjugate": False}


def _run(preset: str, **convention: Any) -> SimRun:
    scn = load_preset(preset, 0.1, snr_db=None, **convention)
    return simulate(scn, MotionSpec(kind="ideal"), "ideal")


def _focus(run: SimRun, radar: dict[str, Any]) -> list[Tile]:
    cfg = scenario_config(run.scenario, autofocus={"enabled": False}, radar=radar)
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[0])
    tiles: list[Tile] = []
    for a in range(0, run.t_ns.size, cfg.imaging.block_pulses):
        b = slice(a, a + cfg.imaging.block_pulses)
        tiles += focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b]).tiles
    return tiles + focuser.finish().tiles


def _windows(run: SimRun, tiles: list[Tile]) -> list[tuple[Image, tuple[float, float]]]:
    """The pixels within WINDOW_M of each target (ideal track: imaging frame = shifted NED)."""
    tiles = sorted(tiles, key=lambda t: t.index)
    a0 = np.concatenate([t.grid.axis0_m for t in tiles])
    data = np.concatenate([t.data for t in tiles])
    a1 = tiles[0].grid.axis1_m
    out = []
    for x, y, _ in run.targets_ned - run.apc_ned[0]:
        i = np.flatnonzero(np.abs(a0 - x) <= WINDOW_M)
        j = np.flatnonzero(np.abs(a1 - y) <= WINDOW_M)
        win = Image(data[i[0] : i[-1] + 1, j[0] : j[-1] + 1], a0[i], a1[j], "ground")
        out.append((win, (float(x), float(y))))
    return out


@pytest.mark.parametrize("preset", ["ku-vehicle", "thz-spotlight"])
def test_digitiser_convention_focuses_like_the_simulators(preset: str) -> None:
    reference = _windows(plain := _run(preset), _focus(plain, DEFAULT_KEYS))
    inverted = _run(preset, **DIGITISER)
    matching = _windows(inverted, _focus(inverted, DIGITISER))
    default_keys = _windows(inverted, _focus(inverted, DEFAULT_KEYS))
    for (ref, at), (got, _), (wrong, _) in zip(reference, matching, default_keys, strict=True):
        mr = point_target_metrics(ref, at, 0.5)
        mg = point_target_metrics(got, at, 0.5)
        for name, r, g in (("az", mr.axis0, mg.axis0), ("rg", mr.axis1, mg.axis1)):
            msg = f"{preset} target {at}, {name}: simulator's convention {r}, digitiser's {g}"
            assert abs(g.irw_m / r.irw_m - 1.0) <= 0.01, msg
            assert abs(g.peak_m - r.peak_m) <= 0.05 * r.irw_m, msg
            assert g.pslr_db <= {"az": -13.0, "rg": -12.5}[name], msg
        peak_db = 20.0 * np.log10(np.abs(wrong.data).max() / np.abs(got.data).max())
        assert peak_db < -6.0, f"{preset} target {at}: default keys peak {peak_db:.1f} dB"
