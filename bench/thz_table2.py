"""A table like Table 2 of the THz paper (seed 002): raw, INS-only D_los, D_los + range-variant
term, position-based (GPS) compensation, on the scaled ``thz-spotlight`` scenario.

Scenario: the paper's velocity-error study geometry, r0 = 3 km, v0 = 62 m/s, 0.2 THz, 1.1 GHz,
0.16 m azimuth resolution (``load_preset("thz-spotlight", scale, center_slant_range_m=3000,
speed_mps=62)``), with turbulent motion (:class:`MotionSpec` ``turbulence``: 0.3 m rms
cross-track and vertical displacement, 0.1 m/s rms along-track speed, 0.5 Hz corner) and
three point targets: the scene centre and two at ±0.35 swath in ground range, moved ±6 m
along track so that no target falls in another's cuts.

Rows (every row is imaged by time-domain backprojection onto a 0.04 m ground grid around the
target, with the APC positions the row's method believes in):

- ``truth``: the true APC positions, no compensation (the ideal-focus reference);
- ``raw``: no compensation, imaged on the INS reference track;
- ``INS D_los (1st order)``: docs/methods.md §2 with the scene-centre β, envelope shift above
  0.25 cell;
- ``INS D_los + range-variant``: β per range bin (``order=2``); the squint residual of eq. 29,
  which the daemon's tile imager removes per pixel, is below 0.01 rad here (k ΔY ψ² / (2 sin β)
  with ΔY ~ 0.3 m, ψ ≤ 2.4 mrad) and is left out;
- ``position-based (GPS)``: the deviation of the GPS-grade positions (10 Hz, 0.3 m white,
  ≈2 m offset; ``sim.ins.GRADES["gps"]``) from their own reference track, same correction and
  imaging; the paper's GPS+INS baseline.

INS-only processing knows no absolute position: its imaging frame is anchored at the true APC
of the first pulse (an INS aligned at the aperture start); the GPS row uses the GPS position.
Columns: PSLR and ISLR of the range cut (the paper's) and of the azimuth cut through the peak
(metrics windows: :mod:`sarmoco.processing.metrics`), peak position error, and the time of
navigation interpolation + compensation + imaging relative to the INS-only row.

A second table sweeps the along-track speed error Δv of the imaging reference track (the
paper's Fig. 2 study; D_los neglects it) for the INS-only method.

INS grades are named units modelled from their datasheets (:mod:`sarmoco.sim.ins`: ``tactical``
= NovAtel SPAN-IGM-S1, ``ellipse-d`` = SBG Ellipse2-D, ``mems`` = Xsens MTi-G-710), each sampled
at its datasheet output rate. A third table (``--sweep-seeds N``) gives the INS-only (1st order)
scene-centre azimuth PSLR of every named grade over motion/INS seeds 0..N-1.

Run: ``.venv/bin/python -m bench.thz_table2 [--scale 0.25] [--seed 0] [--grade tactical]
[--sweep-seeds 6]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from dataclasses import dataclass

import numpy as np
import pytest

from sarmoco.processing import rangecomp
from sarmoco.processing.geometry import ReferenceTrack, reference_track_from_velocity
from sarmoco.processing.imaging.backprojection import backproject
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.metrics import PointTargetMetrics, point_target_metrics
from sarmoco.processing.mocomp import (
    InsMotionCompensator,
    LosGeometry,
    correct_los,
    displacement_from_positions,
)
from sarmoco.processing.navinterp import interpolate_nav
from sarmoco.processing.types import ComplexArray, FloatArray, NavSamples
from sarmoco.sim.ins import GRADES, measure_ins
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import INS_MARGIN_S, SimRun, simulate
from sarmoco.sim.scenario import Scenario, Target, load_preset
from sarmoco.sim.trajectory import true_trajectory

PAPER_TABLE2 = {
    "raw": (-8.3447, -3.4372),
    "INS-only": (-12.4318, -4.6624),
    "GPS+INS": (-11.6924, -3.9005),
}
"""The paper's Table 2 (range cut): PSLR, ISLR in dB."""

GRID_SPACING_M = 0.04
GRID_PIXELS = 192
ALONG_OFFSET_M = 6.0
ENVELOPE_FRACTION = 0.25
INS_MAX_GAP_NS = 50_000_000
GPS_MAX_GAP_NS = 200_000_000
METHODS = ("truth", "raw", "INS D_los (1st order)", "INS D_los + range-variant", "GPS position")
NAMED_GRADES = ("tactical", "ellipse-d", "mems")
COARSE_FACTOR = 4
PEAK_SEARCH_M = 20.0


@dataclass(frozen=True)
class Case:
    """One simulated acquisition with everything the methods need."""

    run: SimRun
    gps_nav: NavSamples
    rc: ComplexArray
    axis_m: FloatArray


@dataclass(frozen=True)
class Row:
    """One method's result on one target."""

    method: str
    target: int
    metrics: PointTargetMetrics
    comp_seconds: float
    seconds: float


def scenario(scale: float) -> Scenario:
    """The scaled velocity-error-study scenario with the three separated targets."""
    base = load_preset("thz-spotlight", scale, center_slant_range_m=3000.0, speed_mps=62.0)
    gc = base.scene_center_ned[1]
    off = 0.35 * base.swath_m
    targets = (
        Target((0.0, gc, 0.0)),
        Target((ALONG_OFFSET_M, gc - off, 0.0)),
        Target((-ALONG_OFFSET_M, gc + off, 0.0)),
    )
    # No lever arm: this study feeds the INS samples straight to the focusing core, which
    # takes the antenna phase centre's velocity (the daemon's aligner adds the arm).
    return load_preset(
        "thz-spotlight",
        scale,
        center_slant_range_m=3000.0,
        speed_mps=62.0,
        targets=targets,
        lever_arm_m=(0.0, 0.0, 0.0),
    )


def make_case(scn: Scenario, grade: str, seed: int, motion: MotionSpec) -> Case:
    """Simulate the echoes with an INS of ``grade`` (at its datasheet rate) and a GPS beside it."""
    run = simulate(scn, motion, grade, ins_rate_hz=GRADES[grade].output_rate_hz, seed=seed)
    t_s = (run.t_ns - scn.t0_ns) * 1e-9
    gps = measure_ins(
        lambda t: true_trajectory(scn, t, motion),
        float(t_s[0]) - INS_MARGIN_S,
        float(t_s[-1]) + INS_MARGIN_S,
        10.0,
        "gps",
        seed=seed + 1000,
        epoch_ns=scn.t0_ns,
    )
    return Case(
        run, gps.nav, rangecomp.compress(scn.radar, run.echo), rangecomp.range_axis_m(scn.radar)
    )


def _geometry(case: Case, track: ReferenceTrack, order: int) -> LosGeometry:
    scn = case.run.scenario
    return LosGeometry.build(
        scn.radar,
        case.axis_m,
        scn.altitude_m,
        scn.center_slant_range_m,
        order=order,  # type: ignore[arg-type]
        envelope_fraction=ENVELOPE_FRACTION,
    )


def _image(
    case: Case, rc: ComplexArray, apc_ned: FloatArray, target: int, search_m: float = 0.0
) -> PointTargetMetrics:
    """Backproject a fine grid around ``target`` and measure it.

    With ``search_m`` > 0 the fine grid is centred on the brightest pixel of a coarse strip
    (4 x the spacing, ±``search_m`` along track, ±3 m across, clear of the other targets) around
    the target: a velocity offset of the INS moves the image along track by r0 δv / v0 (5 m
    for 0.1 m/s here), further than the fine grid reaches.
    """
    tgt = case.run.targets_ned[target]
    centre = (float(tgt[0]), float(tgt[1]), float(tgt[2]))
    lam = case.run.scenario.radar.wavelength_m
    if search_m > 0:
        step = COARSE_FACTOR * GRID_SPACING_M
        coarse = PlaneGrid.centred(centre, int(2 * search_m / step), int(6.0 / step), step, step)
        mag = np.abs(backproject(rc, case.axis_m, apc_ned, lam, coarse).data)
        i0, i1 = np.unravel_index(int(np.argmax(mag)), mag.shape)
        centre = (centre[0] + coarse.axis0_m[i0], centre[1] + coarse.axis1_m[i1], centre[2])
    grid = PlaneGrid.centred(centre, GRID_PIXELS, GRID_PIXELS, GRID_SPACING_M, GRID_SPACING_M)
    img = backproject(rc, case.axis_m, apc_ned, lam, grid)
    expected = (float(tgt[0]) - centre[0], float(tgt[1]) - centre[1])
    return point_target_metrics(img, expected, search_radius_m=None if search_m > 0 else 3.0)


def _compensate(case: Case, method: str, dv_mps: float) -> tuple[ComplexArray, FloatArray]:
    """Range-compressed pulses after ``method``'s correction, and the APC track to image on."""
    run = case.run
    if method == "truth":
        return case.rc, run.apc_ned
    if method == "GPS position":
        nav = interpolate_nav(case.gps_nav, run.t_ns, GPS_MAX_GAP_NS)
        assert nav.pos_ned is not None
        track = reference_track_from_velocity(run.t_ns, nav.vel_ned, nav.pos_ned[0])
        track = dataclasses.replace(track, v0_mps=track.v0_mps + dv_mps)
        disp = displacement_from_positions(run.t_ns, nav.pos_ned, track)
        rc, _ = correct_los(case.rc, run.t_ns, disp, _geometry(case, track, 1))
        return rc, track.position_ned(run.t_ns)
    nav = interpolate_nav(run.ins.nav, run.t_ns, INS_MAX_GAP_NS)
    track = reference_track_from_velocity(run.t_ns, nav.vel_ned, run.apc_ned[0])
    rc = case.rc
    if method != "raw":
        order = 1 if method == "INS D_los (1st order)" else 2
        comp = InsMotionCompensator(track, _geometry(case, track, order))
        rc, _ = comp.compensate(case.rc, run.t_ns, nav.vel_ned)
    return rc, dataclasses.replace(track, v0_mps=track.v0_mps + dv_mps).position_ned(run.t_ns)


def focus(
    case: Case,
    method: str,
    target: int,
    dv_mps: float = 0.0,
    repeat: int = 1,
    search_m: float = 0.0,
) -> Row:
    """Compensate (per ``method``), backproject around ``target`` and measure it.

    ``dv_mps`` is added to the along-track speed of the imaging reference track; ``search_m``:
    see :func:`_image`. Times are the best of ``repeat`` runs: compensation alone, and
    compensation + imaging.
    """
    comp_s, total_s = float("inf"), float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        rc, apc = _compensate(case, method, dv_mps)
        t1 = time.perf_counter()
        metrics = _image(case, rc, apc, target, search_m)
        t2 = time.perf_counter()
        comp_s, total_s = min(comp_s, t1 - t0), min(total_s, t2 - t0)
    return Row(method, target, metrics, comp_s, total_s)


def table2(case: Case, targets: tuple[int, ...], repeat: int = 2) -> list[Row]:
    """Every method on every target (after one warm-up of the imager)."""
    focus(case, "truth", targets[0])
    return [focus(case, m, k, repeat=repeat) for k in targets for m in METHODS]


def format_rows(rows: list[Row], reference: str = "INS D_los (1st order)") -> str:
    """Rows as a text table; time relative to ``reference`` on the same target."""
    ref = {r.target: r.seconds for r in rows if r.method == reference}
    head = (
        f"{'tgt':>3} {'method':<27} {'rg PSLR':>8} {'rg ISLR':>8} {'az PSLR':>8} {'az ISLR':>8}"
        f" {'az IRW':>7} {'pos err (az, rg) m':>19} {'comp ms':>8} {'time':>6}"
    )
    lines = [head]
    for r in rows:
        m = r.metrics
        err = m.position_error_m or (float("nan"), float("nan"))
        lines.append(
            f"{r.target:>3} {r.method:<27} {m.axis1.pslr_db:8.2f} {m.axis1.islr_db:8.2f}"
            f" {m.axis0.pslr_db:8.2f} {m.axis0.islr_db:8.2f} {m.axis0.irw_m:7.3f}"
            f" {err[0]:9.3f} {err[1]:9.3f} {1e3 * r.comp_seconds:8.1f}"
            f" {100 * r.seconds / ref[r.target]:5.1f}%"
        )
    return "\n".join(lines)


def dv_sweep(case: Case, dvs: tuple[float, ...]) -> str:
    """INS-only (1st order) azimuth quality at the scene centre against Δv of the imaging track."""
    lines = [f"{'dv m/s':>7} {'az PSLR':>8} {'az ISLR':>8} {'az IRW':>7} {'rg PSLR':>8}"]
    for dv in dvs:
        m = focus(case, "INS D_los (1st order)", 0, dv).metrics
        lines.append(
            f"{dv:7.2f} {m.axis0.pslr_db:8.2f} {m.axis0.islr_db:8.2f} {m.axis0.irw_m:7.3f}"
            f" {m.axis1.pslr_db:8.2f}"
        )
    return "\n".join(lines)


def report(scale: float, seed: int, grade: str) -> str:
    """The whole printout."""
    scn = scenario(scale)
    motion = MotionSpec(kind="turbulence", seed=seed)
    case = make_case(scn, grade, seed, motion)
    r = scn.radar
    head = [
        f"thz-spotlight scale {scale}: r0 {scn.center_slant_range_m:.0f} m, v0 {scn.speed_mps} m/s,"
        f" {r.carrier_hz / 1e9:.0f} GHz, B {r.bandwidth_hz / 1e9:.1f} GHz, PRF {r.prf_hz:.0f} Hz,"
        f" {case.run.t_ns.shape[0]} pulses x {r.n_samples} samples,"
        f" aperture {scn.aperture_s:.3f} s",
        f"motion: turbulence seed {seed} (0.3 m rms cross/vertical, 0.5 Hz corner);"
        f" INS grade {grade!r} ({GRADES[grade].unit}) at {GRADES[grade].output_rate_hz:.0f} Hz;"
        " GPS grade 'gps' at 10 Hz",
        "theory: unweighted sinc PSLR -13.26 dB, ISLR -9.91 dB (these windows);"
        f" az IRW {0.886 * scn.azimuth_resolution_m:.3f} m",
        "paper Table 2 (range cut, PSLR/ISLR dB): "
        + ", ".join(f"{k} {p:.2f}/{i:.2f}" for k, (p, i) in PAPER_TABLE2.items()),
        "",
        format_rows(table2(case, (0, 1, 2))),
        "",
        "along-track speed error of the imaging track (INS-only, 1st order, scene centre):",
        dv_sweep(case, (0.0, 0.1, 0.5, 1.0, 1.5)),
    ]
    return "\n".join(head)


def grade_sweep(scale: float, seeds: int) -> str:
    """INS-only (1st order) scene-centre azimuth PSLR of each named grade over seeds 0..N-1."""
    scn = scenario(scale)
    lines = [
        f"{'grade':<10} {'seed':>4} {'az PSLR':>8} {'az ISLR':>8} {'az IRW':>7} {'shift m':>8}"
    ]
    for grade in NAMED_GRADES:
        for seed in range(seeds):
            case = make_case(scn, grade, seed, MotionSpec(kind="turbulence", seed=seed))
            m = focus(case, "INS D_los (1st order)", 0, search_m=PEAK_SEARCH_M).metrics
            shift = float(np.hypot(*m.position_error_m)) if m.position_error_m else float("nan")
            lines.append(
                f"{grade:<10} {seed:4d} {m.axis0.pslr_db:8.2f} {m.axis0.islr_db:8.2f}"
                f" {m.axis0.irw_m:7.3f} {shift:8.2f}"
            )
    return "\n".join(lines)


@pytest.mark.bench
def test_thz_table2() -> None:
    """Full table (``pytest bench -m bench``)."""
    print(report(0.25, 0, "tactical"))


def main() -> None:
    """Command-line entry."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--grade", default="tactical", choices=sorted(GRADES))
    ap.add_argument("--sweep-seeds", type=int, default=0, help="also the grade sweep, N seeds")
    args = ap.parse_args()
    print(report(args.scale, args.seed, args.grade))
    if args.sweep_seeds:
        print("\nINS-only (1st order), scene centre, per named INS grade:")
        print(grade_sweep(args.scale, args.sweep_seeds))


if __name__ == "__main__":
    main()
