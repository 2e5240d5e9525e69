"""The ku-vehicle autofocus table (navigation only, COA baseline, two-step, PGA).

Scenario: ``ku-vehicle`` (scaled) with turbulence large enough that uncorrected targets spread
over several range cells, navigated by GPS only (≈2 m absolute, 0.3 m noise, 10 Hz). GPS
positions are far too noisy to compensate cross-track motion at a fraction of a 0.2 m cell, so
"navigation only" is the straight reference track fitted to the GPS positions (speed, heading,
origin) and nothing else. The rows:

- ``nav only``: backprojection on that track;
- ``baseline``: the paper's comparison, contrast optimisation, phase step only (no envelope);
- ``two-step``: map drift, envelope step then second-order phase step (docs/methods.md §3);
- ``two-step+PGA``: followed by PGA on the corrected pulses.

Every image is a backprojection on a small ground grid around each target (IMAGING's
``backproject``), axis 0 north (azimuth), axis 1 east (ground range); PSLR and IRW come from
``processing.metrics``. IRW theory: range ``0.886 c/2B / sin β`` on the ground, azimuth
``0.886 λ / (4 sin(θ/2))`` of the stripmap beam θ.

Acceptance 3 (``--range-orders``): the two-step method with a first- and a second-order κ range
model on a wide-swath, low-altitude variant (:func:`wide_low_case`).

Run: ``.venv/bin/python -m bench.ku_vehicle_table [--scale 0.3] [--seed 2] [--range-orders]``;
the test ``tests/processing/autofocus/test_ku_vehicle.py`` runs a smaller case.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from sarmoco.app.simconfig import MAX_SUBAPERTURE_S
from sarmoco.errors import ProcessingError
from sarmoco.processing import rangecomp
from sarmoco.processing.autofocus import (
    AutofocusConfig,
    AutofocusGeometry,
    Corrections,
    SlidingSubapertureAutofocus,
    autofocus_offline,
)
from sarmoco.processing.autofocus.pga import pga_stripmap
from sarmoco.processing.autofocus.splice import integrate_twice, line_fit
from sarmoco.processing.geometry import (
    ReferenceTrack,
    fit_reference_track,
    look_angle,
    vector_to_imaging,
)
from sarmoco.processing.imaging.backprojection import backproject
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.types import ComplexArray, FloatArray
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import Scenario, Target, load_preset

ROWS = ("nav only", "baseline", "two-step", "two-step+PGA")
EAST_FRAC = (-0.45, -0.3, -0.15, 0.0, 0.15, 0.3, 0.45)
"""Targets across the swath (ground-range fractions); near, centre and far are evaluated."""
EVALUATED = (0, 3, 6)
_KEYS = ("pslr_az_db", "pslr_rg_db", "irw_az_ratio", "irw_rg_ratio", "pos_az_m", "pos_rg_m")


@dataclass(frozen=True)
class Case:
    """One table scenario."""

    scale: float = 0.2
    cross_track_rms_m: float = 1.15
    vertical_rms_m: float = 0.5
    along_speed_rms_mps: float = 0.05
    corner_hz: float = 0.05
    motion_seed: int = 2
    seed: int = 0
    ins_grade: str = "gps"
    preset_overrides: tuple[tuple[str, Any], ...] = ()


def scene_config(**settings: float) -> AutofocusConfig:
    """Autofocus settings of the simulator's ku-vehicle scenes: their subaperture
    (:data:`~sarmoco.app.simconfig.MAX_SUBAPERTURE_S`), the rest as given or the defaults."""
    return AutofocusConfig(**({"subaperture_s": MAX_SUBAPERTURE_S} | settings))


def scenario(case: Case) -> Scenario:
    """The scaled ku-vehicle preset with targets across the swath at one along-track position."""
    base = load_preset("ku-vehicle", case.scale, **dict(case.preset_overrides))
    gc = base.scene_center_ned[1]
    targets = tuple(Target((0.0, gc + f * base.swath_m, 0.0)) for f in EAST_FRAC)
    # No lever arm: the table feeds the navigation straight to the focusing core, which takes
    # the antenna phase centre's velocity (the daemon's aligner adds the arm).
    return load_preset(
        "ku-vehicle",
        case.scale,
        targets=targets,
        lever_arm_m=(0.0, 0.0, 0.0),
        **dict(case.preset_overrides),
    )


PhaseFn = Callable[[float], FloatArray]
"""Phase removed from every pulse at one slant range, rad (shape (P,)), by a correction."""


def _no_phase(n: int) -> PhaseFn:
    return lambda _r: np.zeros(n)


def expected_position(
    run: SimRun, track: ReferenceTrack, k: int, los_m: FloatArray, phase: PhaseFn
) -> FloatArray:
    """Where target ``k`` appears in a backprojection on ``track`` of the corrected data, NED m.

    The corrections cannot observe a constant or a linear LOS displacement (docs/methods.md §3), and
    GPS-grade navigation leaves both against the fitted track (with 0.3 m noise over a
    1.4 s aperture the track's LOS slope is off by about 0.01 v): a linear range error ``b t``
    moves a target by ``-b R / v`` along track, a constant one moves it in range. So the
    expected position is the point whose reference range history matches the corrected one:
    along track, the least-squares fit (with a free constant) of the corrected carrier range
    ``R_true + λ φ / 4π`` to the reference history; across track, the mean of the corrected
    envelope ``R_true + los``. Both over the pulses that illuminate the target; three
    Gauss-Newton steps.
    """
    scn = run.scenario
    lam = scn.radar.wavelength_m
    target = run.targets_ned[k]
    lit = scn.illumination(run.apc_ned, target[None, :])[:, 0] > 0
    apc = track.position_ned(run.t_ns)[lit]
    r_true = np.linalg.norm(run.apc_ned[lit] - target, axis=1)
    r0 = float(np.min(np.linalg.norm(apc - target, axis=1)))
    carrier = r_true + lam * phase(r0)[lit] / (4.0 * np.pi)
    envelope = r_true + los_m[lit]
    pos = target.copy()
    for _ in range(3):
        los = pos - apc
        r_ref = np.linalg.norm(los, axis=1)
        g_x = los @ track.x_hat / r_ref
        g_y = los @ track.y_hat / r_ref
        design = np.column_stack([np.ones_like(g_x), g_x])
        dx = np.linalg.lstsq(design, carrier - r_ref, rcond=None)[0][1]
        dy = float(np.mean(envelope - r_ref)) / float(np.mean(g_y))
        pos = pos + dx * track.x_hat + dy * track.y_hat
    return np.asarray(pos, dtype=float)


def _grid_images(
    rc: ComplexArray,
    run: SimRun,
    track: ReferenceTrack,
    range_m: FloatArray,
    los_m: FloatArray | None = None,
    phase: PhaseFn | None = None,
) -> list[Any]:
    """Backprojections on ``track`` of small grids centred on each evaluated target's
    :func:`expected_position` (``los_m``/``phase``: the corrections applied to ``rc``)."""
    apc = track.position_ned(run.t_ns)
    n = run.t_ns.size
    images = []
    for k in EVALUATED:
        centre = expected_position(
            run, track, k, np.zeros(n) if los_m is None else los_m, phase or _no_phase(n)
        )
        grid = PlaneGrid.centred((centre[0], centre[1], 0.0), 320, 128, 0.04, 0.04)
        images.append(backproject(rc, range_m, apc, run.scenario.radar.wavelength_m, grid))
    return images


def _corrected_phase(corr: Corrections, extra_rad: FloatArray | None = None) -> PhaseFn:
    def phase(r: float) -> FloatArray:
        out = corr.phase_rad(np.array([r]))[:, 0]
        return out if extra_rad is None else out + extra_rad

    return phase


def _row(images: list[Any], theory: list[tuple[float, float]]) -> list[dict[str, float]]:
    out = []
    for img, (irw_az, irw_rg) in zip(images, theory, strict=True):
        try:
            m = point_target_metrics(img, (0.0, 0.0), search_radius_m=5.0)
        except ProcessingError:  # no -3 dB point inside the grid: hopelessly defocused
            out.append(dict.fromkeys(_KEYS, float("nan")))
            continue
        out.append(
            {
                "pslr_az_db": m.axis0.pslr_db,
                "pslr_rg_db": m.axis1.pslr_db,
                "irw_az_ratio": m.axis0.irw_m / irw_az,
                "irw_rg_ratio": m.axis1.irw_m / irw_rg,
                "pos_az_m": float(m.position_error_m[0]) if m.position_error_m else np.nan,
                "pos_rg_m": float(m.position_error_m[1]) if m.position_error_m else np.nan,
            }
        )
    return out


def _truth(run: SimRun, track: ReferenceTrack, geom: AutofocusGeometry) -> dict[str, FloatArray]:
    dev = track.deviation(run.t_ns, run.apc_ned)
    beta_c = float(look_angle(geom.ref_range_m, geom.depth_m))
    los = dev[:, 1] * np.sin(beta_c) + dev[:, 2] * np.cos(beta_c)
    acc = vector_to_imaging(run.traj.acc_ned, track)
    return {"los_m": los, "acc_yz": acc[:, 1:]}


@dataclass
class Prepared:
    """A simulated case ready for autofocus: compressed pulses, track, geometry, IRW theory."""

    run: SimRun
    rc: ComplexArray
    range_m: FloatArray
    track: ReferenceTrack
    geom: AutofocusGeometry
    theory: list[tuple[float, float]]


def motion_spec(case: Case) -> MotionSpec:
    """The turbulence of ``case`` (level attitude: the table's errors are translational)."""
    return MotionSpec(
        kind="turbulence",
        cross_track_rms_m=case.cross_track_rms_m,
        vertical_rms_m=case.vertical_rms_m,
        along_speed_rms_mps=case.along_speed_rms_mps,
        attitude_rms_rad=0.0,
        corner_hz=case.corner_hz,
        seed=case.motion_seed,
    )


def prepare(case: Case) -> Prepared:
    """Simulate ``case``, range-compress, and fit the reference track to the navigation."""
    scn = scenario(case)
    motion = motion_spec(case)
    run = simulate(scn, motion, case.ins_grade, seed=case.seed)
    radar = scn.radar
    nav = run.ins.nav
    if nav.pos_ned is None:
        raise SystemExit(f"{case.ins_grade}: the table needs a navigation source with positions")
    track = fit_reference_track(nav.t_ns, nav.pos_ned)
    geom = AutofocusGeometry(
        radar.wavelength_m, track.v0_mps, -float(track.origin_ned[2]), scn.center_slant_range_m
    )
    theory = []
    for k in EVALUATED:
        r_k = float(np.linalg.norm(run.targets_ned[k] - np.array([0, 0, -scn.altitude_m])))
        beta = float(look_angle(r_k, scn.altitude_m))
        theory.append(
            (0.886 * scn.azimuth_resolution_m, 0.886 * radar.range_resolution_m / np.sin(beta))
        )
    rc = rangecomp.compress(radar, run.echo)
    return Prepared(run, rc, rangecomp.range_axis_m(radar), track, geom, theory)


WIDE_LOW = (("altitude_m", 50.0), ("center_slant_range_m", 350.0), ("swath_m", 300.0))
"""Acceptance 3 geometry: 50 m altitude, slant ranges about 206-502 m (cos β from 0.24 to 0.10),
so the vertical motion's LOS projection changes strongly and non-linearly across the swath."""


def wide_low_case(scale: float = 0.2, motion_seed: int = 2) -> Case:
    """Acceptance 3 case: mostly vertical motion on WIDE_LOW, fast enough (corner 0.12 Hz) that
    the κ models fall visibly short of the true range dependence (:func:`range_model_limit`,
    rad rms at near / centre / far: order 1 0.33 / 0.46 / 0.78, order 2 0.05 / 0.02 / 0.13),
    with a 2.4-cell vertical spread."""
    return Case(
        scale=scale,
        cross_track_rms_m=0.3,
        vertical_rms_m=1.0,
        corner_hz=0.12,
        motion_seed=motion_seed,
        preset_overrides=WIDE_LOW,
    )


def range_model_limit(p: Prepared, order: int) -> list[float]:
    """Phase residual (rad rms) that a κ model of ``order`` leaves even with exact rates.

    The true rate error of every target's range line (second derivative of its true minus
    reference range history, all targets as if lit all the time) is fitted at each pulse
    with ``order + 1`` powers of ``Δd = R - R_c`` through the targets' ranges (unweighted);
    the misfit at each evaluated target is integrated twice and its linear trend over the
    target's lit pulses removed.
    """
    run, track = p.run, p.track
    t = (run.t_ns - run.t_ns[0]) * 1e-9
    apc = track.position_ned(run.t_ns)
    true_r = np.linalg.norm(run.apc_ned[:, None, :] - run.targets_ned[None], axis=2)
    ref_r = np.linalg.norm(apc[:, None, :] - run.targets_ned[None], axis=2)
    rate = np.gradient(
        np.gradient(-2.0 * (true_r - ref_r) / p.geom.wavelength_m, t, axis=0), t, axis=0
    )
    dd = ref_r.min(axis=0) - p.geom.ref_range_m
    design = dd[:, None] ** np.arange(order + 1)[None, :]
    misfit = rate - (design @ np.linalg.lstsq(design, rate.T, rcond=None)[0]).T
    zero = np.zeros(misfit.shape[1])
    cycles = integrate_twice(t, misfit, zero, zero)[0]
    out = []
    for k in EVALUATED:
        lit = run.scenario.illumination(run.apc_ned, run.targets_ned[k][None, :])[:, 0] > 0
        res = 2.0 * np.pi * cycles[lit, k]
        out.append(float(np.std(res - line_fit(t[lit], res[:, None])[:, 0])))
    return out


def format_range_orders(result: dict[int, Any]) -> str:
    """Acceptance 3 table: one line per range order and target."""
    lines = [
        f"{'κ order':<9}{'target':<8}{'PSLR az':>9}{'PSLR rg':>9}{'IRW az/th':>11}{'Δaz m':>8}"
        f"{'model rad':>11}"
    ]
    for order, rows in result.items():
        for name, m in zip(("near", "centre", "far"), rows, strict=True):
            lines.append(
                f"{order:<9}{name:<8}{m['pslr_az_db']:>9.2f}{m['pslr_rg_db']:>9.2f}"
                f"{m['irw_az_ratio']:>11.3f}{m['pos_az_m']:>8.3f}{m['model_rad']:>11.3f}"
            )
    return "\n".join(lines)


def range_orders(case: Case, config: AutofocusConfig | None = None) -> dict[int, Any]:
    """Acceptance 3: the two-step method with a κ range model of order 0, 1 and 2.

    Returns, per order, the near/centre/far metrics of :func:`run_case`'s rows, with the
    model's own limit (:func:`range_model_limit`) as ``model_rad``. The images are centred on
    :func:`expected_position`: GPS leaves the fitted track a LOS slope that no autofocus can
    see, which moves the targets along track by up to 5 m here (range-proportional).
    """
    cfg = config or scene_config()
    p = prepare(case)
    out: dict[int, Any] = {}
    for order in (0, 1, 2):
        corr, _ = autofocus_offline(
            p.rc, p.run.t_ns, p.range_m, p.geom, dataclasses.replace(cfg, range_order=order)
        )
        focused = corr.apply(p.rc, p.range_m)
        images = _grid_images(
            focused, p.run, p.track, p.range_m, corr.los_m, _corrected_phase(corr)
        )
        out[order] = _row(images, p.theory)
        for m, limit in zip(out[order], range_model_limit(p, order), strict=True):
            m["model_rad"] = limit
    return out


def _phase_residual(p: Prepared, corr: Corrections, k: int) -> tuple[float, float]:
    """Truth phase error of target ``k`` minus the correction at its range, over its lit
    pulses: rms after removing a line (rad), and the line's slope as an along-track shift
    (m, ``Δx = λ R slope / 4π v``)."""
    run, lam = p.run, p.geom.wavelength_m
    target = run.targets_ned[k]
    lit = run.scenario.illumination(run.apc_ned, target[None, :])[:, 0] > 0
    ref = np.linalg.norm(p.track.position_ned(run.t_ns) - target, axis=1)
    err = -4.0 * np.pi * (np.linalg.norm(run.apc_ned - target, axis=1) - ref) / lam
    r0 = float(ref.min())
    res = (err - corr.phase_rad(np.array([r0]))[:, 0])[lit]
    t = (run.t_ns[lit] - run.t_ns[0]) * 1e-9
    slope = float(np.polyfit(t, res, 1)[0])
    return float(np.std(res - line_fit(t, res[:, None])[:, 0])), lam * r0 * slope / (
        4.0 * np.pi * p.geom.speed_mps
    )


def streaming_vs_offline(
    case: Case, pin_window_s: float = 1.0, block: int = 37
) -> dict[str, list[float]]:
    """The streaming form (blocks of ``block`` pulses, pulses released during the run)
    against the offline form on one case.

    Returns per evaluated target the truth phase residual after a line (rad rms) of both,
    the rms of their difference after a line at the target's range, and the along-track
    shift of each from its line (m; the unobservable term, pinned over ``pin_window_s``
    streaming and over the whole aperture offline).
    """
    p = prepare(case)
    cfg = scene_config(pin_window_s=pin_window_s)
    offline, _ = autofocus_offline(p.rc, p.run.t_ns, p.range_m, p.geom, cfg)
    engine = SlidingSubapertureAutofocus(p.geom, p.range_m, cfg)
    parts = [engine.push(p.rc[i : i + block], p.run.t_ns[i : i + block])[1]
             for i in range(0, p.rc.shape[0], block)]  # fmt: skip
    parts.append(engine.flush()[1])
    stream = Corrections(
        np.concatenate([c.t_ns for c in parts]),
        np.concatenate([c.los_m for c in parts]),
        np.concatenate([c.phase_cycles for c in parts]),
        p.geom.ref_range_m,
    )
    out: dict[str, list[float]] = {k: [] for k in ("offline", "stream", "diff", "dx_off", "dx_st")}
    t = (p.run.t_ns - p.run.t_ns[0]) * 1e-9
    for k in EVALUATED:
        (res_o, dx_o), (res_s, dx_s) = _phase_residual(p, offline, k), _phase_residual(p, stream, k)
        r0 = np.array([float(np.linalg.norm(p.run.targets_ned[k] - p.track.origin_ned))])
        d = (stream.phase_rad(r0) - offline.phase_rad(r0))[:, 0]
        out["offline"].append(res_o)
        out["stream"].append(res_s)
        out["diff"].append(float(np.std(d - line_fit(t, d[:, None])[:, 0])))
        out["dx_off"].append(dx_o)
        out["dx_st"].append(dx_s)
    return out


def run_case(case: Case, config: AutofocusConfig | None = None) -> dict[str, Any]:
    """Simulate, focus every row, and measure; returns a JSON-able result dictionary."""
    cfg = config or scene_config()
    p = prepare(case)
    run, rc, range_m, track, geom, theory = p.run, p.rc, p.range_m, p.track, p.geom, p.theory
    radar = run.scenario.radar
    t_s = (run.t_ns - run.t_ns[0]) * 1e-9
    truth = _truth(run, track, geom)
    result: dict[str, Any] = {"case": dataclasses.asdict(case), "rows": {}, "timing_s": {}}
    result["uncorrected_spread_cells"] = float(np.ptp(truth["los_m"]) / radar.range_resolution_m)
    result["rows"]["nav only"] = _row(_grid_images(rc, run, track, range_m), theory)

    baseline_cfg = dataclasses.replace(cfg, envelope_step=False, estimator="contrast")
    t0 = time.process_time()
    corr_b, _ = autofocus_offline(rc, run.t_ns, range_m, geom, baseline_cfg)
    result["timing_s"]["baseline"] = time.process_time() - t0
    focused_b = corr_b.apply(rc, range_m)
    images = _grid_images(focused_b, run, track, range_m, corr_b.los_m, _corrected_phase(corr_b))
    result["rows"]["baseline"] = _row(images, theory)

    t0 = time.process_time()
    corr, report = autofocus_offline(rc, run.t_ns, range_m, geom, cfg)
    result["timing_s"]["two-step"] = time.process_time() - t0
    focused = corr.apply(rc, range_m)
    images = _grid_images(focused, run, track, range_m, corr.los_m, _corrected_phase(corr))
    result["rows"]["two-step"] = _row(images, theory)

    t0 = time.process_time()
    phase, updates = pga_stripmap(focused, t_s, range_m, geom.speed_mps, geom.wavelength_m)
    result["timing_s"]["pga"] = time.process_time() - t0
    refined = focused * np.exp(-1j * phase)[:, None].astype(np.complex64)
    images = _grid_images(refined, run, track, range_m, corr.los_m, _corrected_phase(corr, phase))
    result["rows"]["two-step+PGA"] = _row(images, theory)
    result["pga_rms_updates_rad"] = updates

    # the autofocus pins zero mean and trend between its first and last subaperture centres
    centres = report.series()["t_center_s"]
    inner = (t_s >= centres[0] - 1e-9) & (t_s <= centres[-1] + 1e-9)
    design = np.column_stack([np.ones_like(t_s), t_s])
    line = np.linalg.lstsq(design[inner], truth["los_m"][inner], rcond=None)[0]
    los_true = truth["los_m"] - design @ line
    los_err = corr.los_m - los_true
    result["los_rms_error_m"] = float(np.sqrt(np.mean(los_err**2)))
    result["los_max_error_m"] = float(np.max(np.abs(los_err)))
    result["los_true_rms_m"] = float(np.sqrt(np.mean(los_true**2)))
    result["range_cell_m"] = radar.range_resolution_m
    ser = report.series()
    half = 0.5 * cfg.subaperture_s
    acc_true = np.array(
        [truth["acc_yz"][np.abs(t_s - c) <= half].mean(axis=0) for c in ser["t_center_s"]]
    )
    result["a_y_rms_error_mps2"] = float(np.sqrt(np.mean((ser["a_y"] - acc_true[:, 0]) ** 2)))
    result["a_z_rms_error_mps2"] = float(np.sqrt(np.mean((ser["a_z"] - acc_true[:, 1]) ** 2)))
    beta_c = float(look_angle(geom.ref_range_m, geom.depth_m))
    proj = np.array([np.sin(beta_c), np.cos(beta_c)])
    a_los = np.column_stack([ser["a_y"], ser["a_z"]]) @ proj
    result["a_los_rms_error_mps2"] = float(np.sqrt(np.mean((a_los - acc_true @ proj) ** 2)))
    result["a_y_true_rms_mps2"] = float(np.sqrt(np.mean(acc_true[:, 0] ** 2)))
    result["a_z_true_rms_mps2"] = float(np.sqrt(np.mean(acc_true[:, 1] ** 2)))
    result["data_s"] = float(t_s[-1])
    return result


def format_table(result: dict[str, Any]) -> str:
    """The acceptance table as text: one line per row and target."""
    names = ("near", "centre", "far")
    lines = [
        f"uncorrected LOS spread {result['uncorrected_spread_cells']:.2f} range cells; "
        f"LOS truth rms {result['los_true_rms_m'] * 100:.1f} cm (detrended)",
        f"{'row':<14}{'target':<8}{'PSLR az':>9}{'PSLR rg':>9}{'IRW az/th':>11}{'IRW rg/th':>11}",
    ]
    for row in ROWS:
        for name, m in zip(names, result["rows"][row], strict=True):
            lines.append(
                f"{row:<14}{name:<8}{m['pslr_az_db']:>9.2f}{m['pslr_rg_db']:>9.2f}"
                f"{m['irw_az_ratio']:>11.3f}{m['irw_rg_ratio']:>11.3f}"
            )
    lines.append(
        f"LOS after envelope step: rms error {result['los_rms_error_m'] * 100:.2f} cm, max "
        f"{result['los_max_error_m'] * 100:.2f} cm (quarter cell "
        f"{result['range_cell_m'] * 25:.1f} cm)"
    )
    lines.append(
        f"a_y rms error {result['a_y_rms_error_mps2']:.3f} m/s² (truth rms "
        f"{result['a_y_true_rms_mps2']:.3f}); a_z {result['a_z_rms_error_mps2']:.3f} (truth "
        f"{result['a_z_true_rms_mps2']:.3f}); LOS accel {result['a_los_rms_error_mps2']:.3f}"
    )
    lines.append(
        "CPU s: "
        + ", ".join(f"{k} {v:.2f}" for k, v in result["timing_s"].items())
        + f" for {result['data_s']:.2f} s of data; PGA updates "
        + ", ".join(f"{u:.3f}" for u in result["pga_rms_updates_rad"])
    )
    return "\n".join(lines)
