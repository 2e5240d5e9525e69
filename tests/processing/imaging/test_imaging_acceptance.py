"""Each imager focuses an ideal-track point target to the sinc limits.

A scaled simulated point target (``sarmoco.sim``, ideal motion, no noise, no
window anywhere) is range compressed and focused; the cuts through its peak
must give PSLR within 0.3 dB of -13.26 dB and IRW within 5 % of theory:

- range: ``0.886 c / (2 B)`` in slant range (range-Doppler), divided by
  ``cos(grazing)`` on a ground grid (backprojection);
- azimuth (range-Doppler, backprojection): ``0.886 lambda / (4 sin(dtheta / 2))``
  with ``dtheta`` the angle the illuminated aperture subtends at the target
  (P pulses count as P spacings), i.e. ``0.886 v / B_doppler``;
- polar format: ``0.886 * 2 pi / extent`` of the rectangle inscribed in the polar annulus
  of the data (computed here from the band and the aperture angle, not from the code's own
  ``pfa_support``): azimuth ``0.886 lambda_max / (4 sin(dtheta / 2))`` (the lowest
  frequency sets the width), ground range ``0.886 c / (2 (f_max cos(dtheta / 2) - f_min))``
  divided by ``cos(grazing)``, ``dtheta`` from the first to the last pulse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from sarmoco.processing import rangecomp
from sarmoco.processing.imaging import (
    PlaneGrid,
    backproject,
    phase_history_from_compressed,
    polar_format,
    range_doppler,
    validity_radius_m,
)
from sarmoco.processing.metrics import PointTargetMetrics, point_target_metrics
from sarmoco.processing.types import C_MPS, ComplexArray, FloatArray, Image
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import Scenario, Target, load_preset

PSLR_SINC_DB = -13.26
IRW_SINC = 0.886


@dataclass(frozen=True)
class Compressed:
    scn: Scenario
    rc: ComplexArray
    range_axis_m: FloatArray
    apc_ned: FloatArray
    targets_ned: FloatArray


def _compressed(preset: str, scale: float, offsets_m: list[tuple[float, float]]) -> Compressed:
    """Simulate targets at (north, east) ground offsets from the scene centre, ideal track."""
    base = load_preset(preset, scale=scale)
    c = base.scene_center_ned
    targets = tuple(Target((c[0] + dn, c[1] + de, 0.0)) for dn, de in offsets_m)
    scn = load_preset(preset, scale=scale, snr_db=None, targets=targets)
    run = simulate(scn, MotionSpec(kind="ideal"), "ideal")
    rc = rangecomp.compress(scn.radar, run.echo)
    return Compressed(scn, rc, rangecomp.range_axis_m(scn.radar), run.apc_ned, run.targets_ned)


@pytest.fixture(scope="module")
def stripmap() -> Compressed:
    return _compressed("ku-vehicle", 0.05, [(0.0, 0.0)])


@pytest.fixture(scope="module")
def spotlight() -> Compressed:
    return _compressed("thz-spotlight", 0.1, [(0.0, 0.0)])


def _aperture_angle(d: Compressed, apc: FloatArray) -> float:
    """Angle that the first and last of the APC positions ``apc`` subtend at the target, rad."""
    u0, u1 = apc[0] - d.targets_ned[0], apc[-1] - d.targets_ned[0]
    return math.acos(float(u0 @ u1 / np.linalg.norm(u0) / np.linalg.norm(u1)))


def _azimuth_irw_theory(d: Compressed) -> float:
    lit = d.scn.illumination(d.apc_ned, d.targets_ned[:1])[:, 0] > 0
    angle = _aperture_angle(d, d.apc_ned[lit]) * lit.sum() / (lit.sum() - 1)
    return IRW_SINC * d.scn.radar.wavelength_m / (4.0 * math.sin(angle / 2.0))


def _pfa_irw_theory(d: Compressed) -> tuple[float, float]:
    half = 0.5 * _aperture_angle(d, d.apc_ned)
    radar = d.scn.radar
    f_min = radar.carrier_hz - 0.5 * radar.bandwidth_hz
    f_max = radar.carrier_hz + 0.5 * radar.bandwidth_hz
    return (
        IRW_SINC * C_MPS / f_min / (4.0 * math.sin(half)),
        IRW_SINC * C_MPS / (2.0 * (f_max * math.cos(half) - f_min)) / _cos_grazing(d),
    )


def _slant_irw_theory(d: Compressed) -> float:
    return IRW_SINC * C_MPS / (2.0 * d.scn.radar.bandwidth_hz)


def _cos_grazing(d: Compressed) -> float:
    los = d.targets_ned[0] - d.apc_ned[d.apc_ned.shape[0] // 2]
    return float(np.hypot(los[0], los[1]) / np.linalg.norm(los))


def _ground_grid(d: Compressed, n: int, spacing_m: float) -> PlaneGrid:
    return PlaneGrid.centred(d.scn.scene_center_ned, n, n, spacing_m, spacing_m)


def _check(m: PointTargetMetrics, irw_theory: tuple[float, float], label: str) -> None:
    """Assert the sinc limits, and print the README's row (``pytest -s``): PSLR / ISLR in dB,
    IRW in cm with theory in brackets, azimuth then range."""
    cells = [
        f"{cut.pslr_db:.2f} / {cut.islr_db:.2f} | {100 * cut.irw_m:.2f} ({100 * th:.2f})"
        for cut, th in ((m.axis0, irw_theory[0]), (m.axis1, irw_theory[1]))
    ]
    print(f"\n| {label} | {' | '.join(cells)} |")
    for name, cut, th in (("azimuth", m.axis0, irw_theory[0]), ("range", m.axis1, irw_theory[1])):
        msg = f"{label} {name}: PSLR {cut.pslr_db:.2f} dB, IRW {cut.irw_m:.4f} m vs {th:.4f} m"
        assert abs(cut.pslr_db - PSLR_SINC_DB) <= 0.3, msg
        assert abs(cut.irw_m / th - 1.0) <= 0.05, msg
    assert m.position_error_m is not None
    assert np.hypot(*m.position_error_m) < 0.1 * min(irw_theory), f"{label}: {m.position_error_m}"


def test_range_doppler_point_target(stripmap: Compressed) -> None:
    d = stripmap
    tgt = d.targets_ned[0]
    # closest approach of the straight APC track (the antenna sits a lever arm off the INS point)
    r0 = float(np.hypot(*(tgt[1:] - d.apc_ned[:, 1:].mean(axis=0))))
    img = range_doppler(d.rc, d.range_axis_m, d.apc_ned[:, 0], d.scn.radar.wavelength_m)
    assert img.frame == "slant"
    m = point_target_metrics(img, (float(tgt[0]), r0), search_radius_m=1.0)
    _check(m, (_azimuth_irw_theory(d), _slant_irw_theory(d)), "RDA")


@pytest.mark.parametrize("case", ["stripmap", "spotlight"])
def test_backprojection_point_target(case: str, request: pytest.FixtureRequest) -> None:
    d: Compressed = request.getfixturevalue(case)
    grid = _ground_grid(d, 64, 0.04)
    img = backproject(d.rc, d.range_axis_m, d.apc_ned, d.scn.radar.wavelength_m, grid)
    assert img.data.dtype == np.complex64 and img.frame == "ground"
    m = point_target_metrics(img, (0.0, 0.0), search_radius_m=1.0)
    _check(m, (_azimuth_irw_theory(d), _slant_irw_theory(d) / _cos_grazing(d)), f"BP {case}")


def _pfa(d: Compressed, grid: PlaneGrid) -> tuple[Image, FloatArray]:
    centre = np.asarray(grid.origin_m)
    ref = np.linalg.norm(d.apc_ned - centre[None, :], axis=1)
    radar = d.scn.radar
    ph, freq = phase_history_from_compressed(
        d.rc, d.range_axis_m, radar.carrier_hz, radar.bandwidth_hz, ref
    )
    return polar_format(ph, freq, d.apc_ned, grid), freq


def test_polar_format_point_target(spotlight: Compressed) -> None:
    grid = _ground_grid(spotlight, 96, 0.04)
    img, _ = _pfa(spotlight, grid)
    m = point_target_metrics(img, (0.0, 0.0), search_radius_m=1.0)
    # measured 0.1416 / 0.1629 m against 0.1423 / 0.1621 m
    _check(m, _pfa_irw_theory(spotlight), "PFA")


def test_polar_format_matches_backprojection_in_validity_region() -> None:
    offsets = [(0.0, 0.0), (1.5, -2.0), (-2.2, 1.1), (2.4, 2.3), (-1.0, -2.6)]
    d = _compressed("thz-spotlight", 0.1, offsets)
    grid = _ground_grid(d, 160, 0.04)
    pfa, freq = _pfa(d, grid)
    assert validity_radius_m(freq, d.apc_ned, grid) > 10 * max(np.hypot(*o) for o in offsets)
    bp = backproject(d.rc, d.range_axis_m, d.apc_ned, d.scn.radar.wavelength_m, grid)
    a, b = np.abs(pfa.data), np.abs(bp.data)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    assert np.linalg.norm(a - b) < 0.05
    for dn, de in offsets:
        m = point_target_metrics(pfa, (dn, de), search_radius_m=0.3)
        assert m.position_error_m is not None
        assert np.hypot(*m.position_error_m) < 0.02
