"""Fast factorised backprojection against the direct sum, on point targets.

Simulated point targets (ku-vehicle ×0.05 at 1 kHz, thz-spotlight ×0.1 at 20 kHz; ideal
track, no noise, imaging frame turned by the INS heading error of the bench replays),
azimuth pre-filtered as the daemon does, imaged on the same pixels around each target by
the direct kernel and by FFBP with the factorisation planned from the phase-error budget
``imaging.ffbp_max_phase_error_rad`` (default 0.3 rad). Within that budget the image error
must stay within :data:`LIMITS`; a factorisation forced too coarse for it must not (the budget
is what holds the error); the daemon's focusing chain with ``imaging.method = "ffbp"``
must focus targets as the direct one does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.config import Config, parse_config
from sarmoco.daemon.focuser import Focuser
from sarmoco.errors import ConfigError, ProcessingError
from sarmoco.processing.imaging import PlaneGrid
from sarmoco.processing.imaging.backprojection import RangeLines, backproject_into
from sarmoco.processing.imaging.ffbp import Factorisation, ffbp_into, plan_factorisation
from sarmoco.processing.imaging.presum import AzimuthPrefilter
from sarmoco.processing.imaging.tiles import Tile, TileImager
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import ComplexArray, FloatArray, Image
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import Target, load_preset
from tests.processing.imaging.test_tiles import (
    HEADING_ERROR_RAD,
    SQUINT_TOLERANCE_RAD,
    Case,
    _case,
    _window,
)

BUDGET_RAD = Config().imaging.ffbp_max_phase_error_rad
"""The default phase-error budget, rad."""


@dataclass(frozen=True)
class Limits:
    """Image error allowed within the budget: relative L2 over the window, PSLR change (dB),
    IRW change (fraction) on both cuts, peak change (fraction)."""

    l2: float = 0.04
    pslr_db: float = 0.2
    irw: float = 0.01
    peak: float = 0.03


LIMITS = Limits()


@dataclass(frozen=True)
class Prepared:
    """Pre-filtered pulses of a case, upsampled, with their APCs in the imaging frame."""

    case: Case
    lines: RangeLines
    dr_m: float
    apc_m: FloatArray
    half_beam_rad: float


@dataclass(frozen=True)
class Comparison:
    """FFBP against direct on one target's window."""

    l2: float
    d_pslr_db: tuple[float, float]
    irw_ratio: tuple[float, float]
    peak_ratio: float
    plan: Factorisation

    def violations(self, lim: Limits = LIMITS) -> list[str]:
        """What exceeds ``lim`` (empty: within the budget's limits)."""
        out = [f"L2 {self.l2:.4f}"] if self.l2 > lim.l2 else []
        out += [f"PSLR change {d:+.3f} dB" for d in self.d_pslr_db if abs(d) > lim.pslr_db]
        out += [f"IRW ratio {r:.4f}" for r in self.irw_ratio if abs(r - 1.0) > lim.irw]
        if abs(self.peak_ratio - 1.0) > lim.peak:
            out.append(f"peak ratio {self.peak_ratio:.4f}")
        return out

    def __str__(self) -> str:
        return (
            f"{self.plan}: L2 {self.l2:.4f}, PSLR change az {self.d_pslr_db[0]:+.3f} "
            f"rg {self.d_pslr_db[1]:+.3f} dB, IRW ratio az {self.irw_ratio[0]:.4f} "
            f"rg {self.irw_ratio[1]:.4f}, peak ratio {self.peak_ratio:.4f}"
        )


def _prepare(case: Case) -> Prepared:
    """Pre-filter the case's pulses (the daemon's default oversampling 1.25)."""
    scn = case.scn
    lam = scn.radar.wavelength_m
    beam = scn.integration_angle_rad + 2 * SQUINT_TOLERANCE_RAD
    pre = AzimuthPrefilter(scn.radar.prf_hz, 2 * scn.speed_mps * math.sin(beam / 2) / lam, 1.25)
    rc, t = pre.push(case.rc, case.t_ns)
    rc_end, t_end = pre.flush()
    rc, t = np.concatenate([rc, rc_end]), np.concatenate([t, t_end])
    step = (case.apc_img[-1] - case.apc_img[0]) / float(case.t_ns[-1] - case.t_ns[0])
    apc = case.apc_img[0] + (t - case.t_ns[0])[:, None].astype(np.float64) * step
    dr = float(case.axis_m[1] - case.axis_m[0])
    return Prepared(case, RangeLines.upsample(rc, case.axis_m), dr, apc, beam / 2)


@pytest.fixture(scope="module")
def ku() -> Prepared:
    sw = load_preset("ku-vehicle", 0.05).swath_m
    offsets = [(0.0, -0.4 * sw), (0.0, 0.4 * sw)]
    return _prepare(_case("ku-vehicle", 0.05, 1000.0, offsets, HEADING_ERROR_RAD))


@pytest.fixture(scope="module")
def thz() -> Prepared:
    sw = load_preset("thz-spotlight", 0.1).swath_m
    offsets = [(0.0, 0.0), (0.0, 0.4 * sw), (1.5, -0.3 * sw)]
    return _prepare(_case("thz-spotlight", 0.1, 20_000.0, offsets, HEADING_ERROR_RAD))


def _grid(tgt: FloatArray, pixel_m: float, half_m: float = 1.5) -> PlaneGrid:
    n = round(half_m / pixel_m)
    ax = np.arange(-n, n + 1) * pixel_m
    return PlaneGrid(tgt[0] + ax, tgt[1] + ax, (0.0, 0.0, float(tgt[2])), 0.0, "ground")


def _images(
    prep: Prepared,
    grid: PlaneGrid,
    budget_rad: float,
    factorisation: Factorisation | None = None,
    compensated_dy_m: FloatArray | None = None,
) -> tuple[ComplexArray, ComplexArray, Factorisation]:
    """Direct and FFBP pixels of ``grid``, and the factorisation FFBP used."""
    lam = prep.case.scn.radar.wavelength_m
    shape = (grid.axis0_m.size, grid.axis1_m.size)
    ref = np.zeros(shape, np.complex64)
    backproject_into(
        ref,
        prep.lines,
        prep.apc_m,
        lam,
        grid,
        beam_half_angle_rad=prep.half_beam_rad,
        compensated_dy_m=compensated_dy_m,
    )
    got = np.zeros(shape, np.complex64)
    plan = ffbp_into(
        got,
        prep.lines,
        prep.dr_m,
        prep.apc_m,
        lam,
        grid,
        budget_rad,
        beam_half_angle_rad=prep.half_beam_rad,
        compensated_dy_m=compensated_dy_m,
        factorisation=factorisation,
    )
    return ref, got, plan


def _compare(
    prep: Prepared,
    tgt: FloatArray,
    pixel_m: float,
    budget_rad: float,
    factorisation: Factorisation | None = None,
    compensated_dy_m: FloatArray | None = None,
) -> Comparison:
    grid = _grid(tgt, pixel_m)
    ref, got, plan = _images(prep, grid, budget_rad, factorisation, compensated_dy_m)
    m = [
        point_target_metrics(Image(d, grid.axis0_m, grid.axis1_m, "ground"), (tgt[0], tgt[1]), 0.5)
        for d in (ref, got)
    ]
    return Comparison(
        float(np.linalg.norm(got - ref) / np.linalg.norm(ref)),
        (m[1].axis0.pslr_db - m[0].axis0.pslr_db, m[1].axis1.pslr_db - m[0].axis1.pslr_db),
        (m[1].axis0.irw_m / m[0].axis0.irw_m, m[1].axis1.irw_m / m[0].axis1.irw_m),
        float(np.max(np.abs(got)) / np.max(np.abs(ref))),
        plan,
    )


@pytest.mark.parametrize(("name", "pixel_m"), [("ku", 0.05), ("thz", 0.04)])
def test_ffbp_matches_direct_within_the_budget(
    name: str, pixel_m: float, request: pytest.FixtureRequest
) -> None:
    prep: Prepared = request.getfixturevalue(name)
    for tgt in prep.case.targets_img:
        c = _compare(prep, tgt, pixel_m, BUDGET_RAD)
        print(f"{name} target {tgt[:2].round(2)}: {c}")
        assert c.plan.stages >= 1  # factorised, not the direct fallback
        assert c.violations() == [], str(c)
        # the budget split over four merges by two (five subimage levels on 60 pulses)
        deep = _compare(prep, tgt, pixel_m, BUDGET_RAD, Factorisation(2, 4, BUDGET_RAD / 4))
        print(f"{name} target {tgt[:2].round(2)}: {deep}")
        assert deep.violations() == [], str(deep)


def test_one_thread_and_all_give_the_same_pixels(ku: Prepared) -> None:
    """Each thread writes its intermediate columns to its own scratch rows: the direct and
    the factorised kernels on all of numba's threads give the pixels one thread gives, to
    the last bit (threads sharing scratch overwrite each other's columns)."""
    threads = numba.get_num_threads()
    if threads < 2:
        pytest.skip("numba has one thread here: nothing runs side by side")
    grid = _grid(ku.case.targets_img[0], 0.02, half_m=4.0)
    try:
        numba.set_num_threads(1)
        alone = _images(ku, grid, BUDGET_RAD)
    finally:
        numba.set_num_threads(threads)
    together = _images(ku, grid, BUDGET_RAD)
    assert alone[2].stages > 1  # the factorised kernels ran, not the direct one again
    for one, many in zip(alone[:2], together[:2], strict=True):
        assert np.abs(one).max() > 0 and np.array_equal(one, many)


def test_the_budget_controls_the_error(ku: Prepared) -> None:
    """The error grows with the budget; a factorisation forced coarser than the default
    budget allows (one stage's phase bound 2 rad, nearest angle sample) breaks the limits."""
    tgt = ku.case.targets_img[0]
    errors = [_compare(ku, tgt, 0.05, b).l2 for b in (0.1, 0.5, 2.0)]
    print("L2 at budgets 0.1 / 0.5 / 2 rad:", errors)
    assert errors[0] < errors[1] < errors[2]
    assert errors[0] < 0.01
    coarse = _compare(ku, tgt, 0.05, BUDGET_RAD, Factorisation(4, 3, 2.0, angle_order=0))
    print("forced coarse:", coarse)
    assert coarse.violations() != []


def test_squint_residual_of_the_compensation_is_removed_as_direct(ku: Prepared) -> None:
    """Pulses compensated per bin for a 3 m sidestep (eq. 29 residual up to ~0.9 rad at the
    beam edges): FFBP applies the per-pulse term in its first stage as the direct kernel does."""
    grid = _grid(ku.case.targets_img[1], 0.05)
    dy = np.full(ku.apc_m.shape[0], 3.0)
    deep = Factorisation(2, 3, BUDGET_RAD / 3)
    ref, got, _ = _images(ku, grid, BUDGET_RAD, deep, dy)
    plain, _, _ = _images(ku, grid, BUDGET_RAD, deep)
    effect = float(np.linalg.norm(plain - ref) / np.linalg.norm(ref))
    error = float(np.linalg.norm(got - ref) / np.linalg.norm(ref))
    print(f"eq. 29 term: changes the direct image by {effect:.4f} (L2), FFBP off by {error:.4f}")
    assert effect > 4 * LIMITS.l2
    assert error <= LIMITS.l2


def test_planner_prefers_direct_when_factorising_does_not_pay(ku: Prepared) -> None:
    """Four pulses onto a few pixels: no stage is cheaper, so FFBP is the direct kernel."""
    tgt = ku.case.targets_img[0]
    grid = _grid(tgt, 0.05, half_m=0.2)
    few = Prepared(
        ku.case,
        RangeLines(ku.lines.data[200:204], ku.lines.r_first_m, ku.lines.dr_m),
        ku.dr_m,
        ku.apc_m[200:204],
        ku.half_beam_rad,
    )
    ref, got, plan = _images(few, grid, BUDGET_RAD)
    assert plan.stages == 0
    np.testing.assert_array_equal(got, ref)


def test_bad_arguments_are_refused(ku: Prepared) -> None:
    tgt = ku.case.targets_img[0]
    grid = _grid(tgt, 0.05)
    lam = ku.case.scn.radar.wavelength_m
    out = np.zeros((grid.axis0_m.size, grid.axis1_m.size), np.complex64)
    with pytest.raises(ProcessingError, match="budget"):
        plan_factorisation(np.zeros((8, 5)), grid, ku.dr_m, lam, 4.0)
    with pytest.raises(ProcessingError, match="stage_phase_rad"):
        Factorisation(2, 2, 0.0)
    with pytest.raises(ProcessingError, match="apc"):
        ffbp_into(out, ku.lines, ku.dr_m, ku.apc_m[:-1], lam, grid, BUDGET_RAD)
    over = ku.apc_m.copy()
    over[:, 1] = tgt[1]  # the track above the pixels: no side to put polar samples on
    with pytest.raises(ProcessingError, match="above the grid"):
        ffbp_into(
            out,
            ku.lines,
            ku.dr_m,
            over,
            lam,
            grid,
            BUDGET_RAD,
            factorisation=Factorisation(2, 2, 0.2),
        )


@pytest.mark.parametrize(
    ("imaging", "message"),
    [
        ({"method": "fast"}, "imaging.method"),
        ({"ffbp_max_phase_error_rad": 4.0}, "imaging.ffbp_max_phase_error_rad"),
        ({"ffbp_max_phase_error_rad": 0.0}, "imaging.ffbp_max_phase_error_rad"),
    ],
)
def test_config_keys_are_validated(imaging: dict[str, object], message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace(".", r"\.")):
        parse_config({"imaging": imaging})


# -- the daemon's chain ------------------------------------------------------------------


@pytest.fixture(scope="module")
def spotlight() -> SimRun:
    c = load_preset("thz-spotlight", 0.1).scene_center_ned
    targets = tuple(Target((c[0], c[1] + de, 0.0)) for de in (-4.0, 0.0, 4.0))
    scn = load_preset("thz-spotlight", 0.1, snr_db=None, targets=targets, prf_hz=20_000.0)
    return simulate(scn, MotionSpec(kind="turbulence", seed=3), "ideal")


def _focus(run: SimRun, method: str) -> tuple[list[Tile], Focuser]:
    cfg = scenario_config(
        run.scenario, autofocus={"enabled": False}, imaging={"method": method, "pixel_m": 0.04}
    )
    focuser = Focuser(cfg, int(run.t_ns[0]), run.vel_ned[:256].mean(axis=0))
    tiles: list[Tile] = []
    for a in range(0, run.t_ns.size, cfg.imaging.block_pulses):
        b = slice(a, a + cfg.imaging.block_pulses)
        tiles += focuser.push(run.echo[b], run.t_ns[b], run.vel_ned[b]).tiles
    return tiles + focuser.finish().tiles, focuser


def test_daemon_tiles_with_ffbp_focus_as_direct(spotlight: SimRun) -> None:
    """thz-spotlight ×0.1, turbulent flight, INS compensation, pre-filter, tiles: with
    ``imaging.method = "ffbp"`` each target's PSLR within the budget's 0.2 dB of the direct
    tiles', IRW too, and focused (azimuth PSLR <= -12.5 dB)."""
    (fast, focuser), (direct, _) = _focus(spotlight, "ffbp"), _focus(spotlight, "direct")
    assert isinstance(focuser._last.imager, TileImager)
    assert focuser._last.imager.ffbp_budget_rad == BUDGET_RAD
    assert [t.index for t in fast] == [t.index for t in direct]
    track = focuser.track
    for tgt in spotlight.targets_ned:
        d = tgt - spotlight.apc_ned[0]
        at = np.array([d @ track.x_hat, d @ track.y_hat, d[2]])
        ma = point_target_metrics(_window(fast, at, 1.5), (at[0], at[1]), 0.5)
        mb = point_target_metrics(_window(direct, at, 1.5), (at[0], at[1]), 0.5)
        for name, f, s in (("az", ma.axis0, mb.axis0), ("rg", ma.axis1, mb.axis1)):
            print(
                f"y {at[1]:6.2f} m {name}: PSLR {f.pslr_db:.3f} / {s.pslr_db:.3f} dB, "
                f"IRW {f.irw_m:.5f} / {s.irw_m:.5f} m (ffbp / direct)"
            )
            assert abs(f.pslr_db - s.pslr_db) <= LIMITS.pslr_db
            assert abs(f.irw_m / s.irw_m - 1.0) <= LIMITS.irw
        assert ma.axis0.pslr_db <= -12.5
