"""A survey flight of many minutes through the daemon pipeline: every target, RSS, the strip.

Run as a plain script (not part of the test suite)::

    .venv/bin/python bench/bench_survey.py [--legs 8] [--leg-s 62] [--per-leg 6]

ku-vehicle x0.1 flown as a survey (:mod:`sarmoco.sim.survey`: straight legs joined by
180° coordinated turns at the real log's turn rate, the log's wander along the legs, a
0.39 m lever arm), point targets at broadside of every leg, the preset's noise. The echoes
and the INS samples (exact, 200 Hz, INS point and attitude: the aligner adds the arm) are
generated chunk by chunk and played into a :class:`~sarmoco.daemon.pipeline.Pipeline`
with a store on disk (raw echoes not recorded) on the radar's virtual clock, as
``tests/daemon/test_pipeline.py`` does; the process's RSS is read after every chunk.
Afterwards every target is measured in the tiles of the segment that imaged it (each
tile names its track), and one panel per segment is drawn into ``--png``.

Autofocus off and ``mocomp.along_track`` on (exact INS: what is measured is the
segmentation and the INS compensation over a long strip).

``--reference`` also focuses every target alone by a plain backprojection of its own
noise-free echoes on the true APC positions (no reference track, no motion compensation,
no beam culling) and prints the pipeline's azimuth PSLR beside it: the realised aperture
(rect beam, the flight's uneven along-track sampling) sets the reference, and the
difference is what the pipeline loses on that target.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.status import Counters
from sarmoco.drivers.samples import AttitudeSample, Validity, VelocitySample
from sarmoco.processing.imaging.backprojection import backproject
from sarmoco.processing.imaging.grid import PlaneGrid
from sarmoco.processing.metrics import point_target_metrics
from sarmoco.processing.rangecomp import compress, range_axis_m
from sarmoco.processing.types import Image
from sarmoco.sim.echo import synthesize
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import pulse_times_ns
from sarmoco.sim.scenario import Scenario, load_preset
from sarmoco.sim.survey import SurveyPattern, survey_scenario, survey_spec
from sarmoco.sim.trajectory import apc_trajectory, true_trajectory
from sarmoco.store.flags import PulseFlag
from sarmoco.store.reader import RunStore, open_store

RANGE_CHUNK_PULSES = 2048
"""Pulses generated and played per chunk."""
INS_RATE_HZ = 200.0
"""Rate of the exact INS samples, Hz."""
NAV_LEAD_NS = 50_000_000
"""INS samples reach the pipeline this far ahead of the pulses, ns."""
WINDOW_M = 1.5
"""Half size of the image window measured around each target, m."""
PANEL_POOL = 4
"""Pixels max-pooled into one of the strip picture (each axis)."""
REFERENCE_PIXEL_M = 0.05
"""Pixel spacing of the reference images (both axes), m."""


def _rss_mb() -> float:
    """VmRSS of this process, MiB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return math.nan


def play(scn: Scenario, spec: MotionSpec, store: Path, seed: int) -> list[tuple[float, float]]:
    """Generate the survey chunk by chunk into a pipeline and its store; (flight s, RSS MiB)."""
    cfg = scenario_config(
        scn,
        radar={"sample_format": "float32"},
        recorder={"raw_echoes": False},
        autofocus={"enabled": False},
        mocomp={"along_track": True},
    )
    t_all = pulse_times_ns(scn.t0_ns, scn.radar.prf_hz, scn.n_pulses)
    targets, amps = scn.targets_array()
    reach_m = scn.notes["slant_window_far_m"] + 10.0
    rng = np.random.default_rng(seed)
    rss: list[tuple[float, float]] = []
    t_nav_s = -0.5
    with open_recorder(cfg, store) as rec:
        pipe = Pipeline(cfg, rec, Counters())
        for a in range(0, t_all.size, RANGE_CHUNK_PULSES):
            t_ns = t_all[a : a + RANGE_CHUNK_PULSES]
            t_s = (t_ns - scn.t0_ns) * 1e-9
            apc = apc_trajectory(scn, t_s, spec)
            near = np.linalg.norm(targets[None] - apc.pos_ned[:, None], axis=2).min(axis=0)
            k = near < reach_m
            echo = synthesize(
                scn.radar, t_ns, apc.pos_ned, targets[k], amps[k], scn.snr_db, rng,
                illumination=scn.illumination(apc.pos_ned, targets[k]),
            )  # fmt: skip
            t_ins = np.arange(t_nav_s, t_s[-1] + 0.5 * NAV_LEAD_NS * 1e-9, 1.0 / INS_RATE_HZ)
            t_nav_s = float(t_ins[-1]) + 1.0 / INS_RATE_HZ
            ins = true_trajectory(scn, t_ins, spec)
            ins_ns = scn.t0_ns + np.round(t_ins * 1e9).astype(np.int64)
            j = 0
            for i, t in enumerate(t_ns.tolist()):
                slot = pipe.ring.reserve()
                assert slot is not None
                slot.samples[...] = echo[i]
                pipe.ring.commit(slot, t, a + i)
                while j < ins_ns.size and ins_ns[j] < t + NAV_LEAD_NS:
                    tj = int(ins_ns[j])
                    v, q = ins.vel_ned[j], ins.quat[j]
                    pipe.add_nav(
                        [
                            VelocitySample(tj, (v[0], v[1], v[2]), Validity.VELOCITY, "sim", tj),
                            AttitudeSample(
                                tj, (q[0], q[1], q[2], q[3]), Validity.ATTITUDE, "sim", tj
                            ),
                        ],
                        None,
                    )
                    j += 1
                if i % 64 == 63:
                    pipe.process(t)
            rss.append((float(t_s[-1]), _rss_mb()))
        pipe.finish()
    return rss


def _track_frame(track: dict[str, Any], point_ned: np.ndarray, apc0: np.ndarray) -> np.ndarray:
    """(along, cross) of a NED point in a recorded track's imaging frame, m."""
    d = point_ned - apc0 - np.asarray(track["origin_ned"])
    return np.array([d @ np.asarray(track["x_hat_ned"]), d @ np.asarray(track["y_hat_ned"])])


def measure(
    store: RunStore, targets: np.ndarray, apc0: np.ndarray
) -> tuple[list[dict[str, float]], dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]]:
    """Every target's metrics (in its segment's tiles) and each segment's pooled panels."""
    pieces: dict[tuple[int, int], list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    panels: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
    for n in range(store.n_images):
        img, attrs = store.image(n)
        track = attrs["reference_track"]
        seg = int(track["t0_ns"])
        a0, a1, mag = img.axis0_m, img.axis1_m, np.abs(img.data)
        p = PANEL_POOL
        r, c = mag.shape[0] // p * p, mag.shape[1] // p * p
        pooled = mag[:r, :c].reshape(r // p, p, c // p, p).max(axis=(1, 3))
        panels.setdefault(seg, []).append((a0[:r:p], a1[:c:p], pooled))
        for k, tgt in enumerate(targets):
            x, y = _track_frame(track, tgt, apc0)
            i = np.flatnonzero(np.abs(a0 - x) <= WINDOW_M)
            jj = np.flatnonzero(np.abs(a1 - y) <= WINDOW_M)
            if i.size and jj.size:
                cut = img.data[i[0] : i[-1] + 1, jj[0] : jj[-1] + 1]
                pieces.setdefault((k, seg), []).append((a0[i], a1[jj], cut))
    results = []
    for k in range(len(targets)):
        best: dict[str, float] = {"target": float(k), "peak": 0.0}
        images = []
        for (kk, _seg), parts in pieces.items():
            parts.sort(key=lambda p: float(p[0][0]))
            a0 = np.concatenate([p[0] for p in parts])
            if kk == k and a0.size >= 10 and parts[0][1].size >= 10:
                data = np.concatenate([p[2] for p in parts])
                images.append(Image(data, a0, parts[0][1], "ground"))
        if images:  # the segment that holds it (another's tiles past a cut: zeros)
            image = max(images, key=lambda i: float(np.abs(i.data).max()))
            m = point_target_metrics(image)
            best = {
                "target": float(k),
                "peak": float(np.abs(image.data).max()),
                "pslr_az_db": m.axis0.pslr_db,
                "irw_az_m": m.axis0.irw_m,
                "pslr_rg_db": m.axis1.pslr_db,
                "irw_rg_m": m.axis1.irw_m,
            }
        results.append(best)
    return results, panels


def reference_pslr(scn: Scenario, spec: MotionSpec, pattern: SurveyPattern) -> list[float]:
    """Azimuth PSLR (dB) of every target focused alone on the true APC (``--reference``).

    Each target's noise-free echoes over its whole illumination on its own leg (plus 50
    pulses each side) are range compressed and backprojected onto a grid along the flight
    direction of that stretch, centred on the target.
    """
    t_all = pulse_times_ns(scn.t0_ns, scn.radar.prf_hz, scn.n_pulses)
    t_s = (t_all - scn.t0_ns) * 1e-9
    targets, amps = scn.targets_array()
    per_leg = len(targets) // pattern.legs
    n_px = round(2 * WINDOW_M / REFERENCE_PIXEL_M) + 1
    out = []
    for k, target in enumerate(targets):
        start = pattern.leg_start_s(k // per_leg)
        leg = np.flatnonzero((t_s >= start) & (t_s <= start + pattern.leg_s))
        apc = apc_trajectory(scn, t_s[leg], spec).pos_ned
        lit = scn.illumination(apc, target[None])
        on = np.flatnonzero(lit[:, 0] > 0)
        sel = np.arange(max(on.min() - 50, 0), min(on.max() + 51, leg.size))
        echo = synthesize(
            scn.radar, t_all[leg][sel], apc[sel], target[None], amps[k : k + 1], None,
            np.random.default_rng(0), illumination=lit[sel],
        )  # fmt: skip
        way = apc[sel[-1]] - apc[sel[0]]
        grid = PlaneGrid.centred(
            tuple(target), n_px, n_px, REFERENCE_PIXEL_M, REFERENCE_PIXEL_M,
            math.atan2(way[1], way[0]),
        )  # fmt: skip
        image = backproject(
            compress(scn.radar, echo), range_axis_m(scn.radar), apc[sel],
            scn.radar.wavelength_m, grid,
        )  # fmt: skip
        out.append(point_target_metrics(image).axis0.pslr_db)
    return out


def draw(panels: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray]]], png: Path) -> None:
    """One panel per segment: |image| in dB (its peak = 0), along track horizontal."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    segs = sorted(panels)
    fig, axes = plt.subplots(len(segs), 1, figsize=(12, 1.1 * len(segs) + 0.6), squeeze=False)
    for ax, seg in zip(axes[:, 0], segs, strict=True):
        tiles = sorted(panels[seg], key=lambda p: float(p[0][0]))
        a0 = np.concatenate([p[0] for p in tiles])
        mag = np.concatenate([p[2] for p in tiles])
        db = 20 * np.log10(mag / mag.max() + 1e-12)
        a1 = tiles[0][1]
        ax.imshow(
            db.T, origin="lower", aspect="auto", vmin=-40, vmax=0, cmap="gray",
            extent=(float(a0[0]), float(a0[-1]), float(a1[0]), float(a1[-1])),
        )  # fmt: skip
        ax.set_ylabel("cross (m)")
        ax.set_title(f"segment {segs.index(seg)}: {a0[-1] - a0[0]:.0f} m", fontsize=8, loc="left")
    axes[-1, 0].set_xlabel("along track in the segment's frame (m)")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--legs", type=int, default=8)
    ap.add_argument("--leg-s", type=float, default=62.0)
    ap.add_argument("--per-leg", type=int, default=6)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--png", type=Path, default=Path("docs/img/survey_strip.png"))
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--reference", action="store_true", help="each target alone on the true APC")
    args = ap.parse_args()
    spec = survey_spec(args.legs, args.leg_s, seed=args.seed + 1)
    scn = survey_scenario(load_preset("ku-vehicle", 0.1), spec, per_leg=args.per_leg)
    pattern = SurveyPattern.of(scn, spec)
    print(f"survey: {args.legs} legs x {args.leg_s} s, turns {pattern.turn_s:.1f} s, "
          f"{pattern.duration_s:.0f} s of flight, {scn.n_pulses} pulses, "
          f"{len(scn.targets)} targets", flush=True)  # fmt: skip
    start = time.monotonic()
    with tempfile.TemporaryDirectory() as work:
        rss = play(scn, spec, Path(work) / "run.zarr", args.seed)
        wall = time.monotonic() - start
        store = open_store(Path(work) / "run.zarr")
        apc0 = apc_trajectory(scn, np.zeros(1), spec).pos_ned[0]
        results, panels = measure(store, scn.targets_array()[0], apc0)
        flags = store.read("pulses", ["flags"])["flags"]
        n_turn = int(np.count_nonzero(flags & PulseFlag.TURN))
        motion = store.read("motion", ["d_los_m"])["d_los_m"]
        draw(panels, args.png)
    lam, theta = scn.radar.wavelength_m, scn.integration_angle_rad
    irw_az = 0.886 * lam / (4 * math.sin(theta / 2))
    focused = [r for r in results if "pslr_az_db" in r]
    d_max = float(np.nanmax(np.abs(motion)))
    print(f"wall {wall:.0f} s for {pattern.duration_s:.0f} s of flight; segments {len(panels)}; "
          f"turn pulses {n_turn} of {flags.size}; max |d_los| {d_max:.2f} m")  # fmt: skip
    if args.reference:
        for r, ref in zip(results, reference_pslr(scn, spec, pattern), strict=True):
            r["reference_pslr_az_db"] = ref
    for r in results:
        print(r)
    pslr = [r["pslr_az_db"] for r in focused]
    irw = [r["irw_az_m"] / irw_az for r in focused]
    print(f"targets imaged {len(focused)}/{len(results)}; azimuth PSLR {min(pslr):.2f} .. "
          f"{max(pslr):.2f} dB; IRW {min(irw):.3f} .. {max(irw):.3f} x {irw_az:.4f} m")  # fmt: skip
    if args.reference:
        loss = [r["pslr_az_db"] - r["reference_pslr_az_db"] for r in focused]
        print(f"azimuth PSLR minus the reference: mean {np.mean(loss):+.2f} dB, "
              f"{min(loss):+.2f} .. {max(loss):+.2f}")  # fmt: skip
    half = len(rss) // 2
    print(f"RSS MiB: first chunk {rss[0][1]:.0f}, middle {rss[half][1]:.0f}, "
          f"last {rss[-1][1]:.0f}, max {max(r for _, r in rss):.0f}")  # fmt: skip
    if args.json is not None:
        args.json.write_text(json.dumps({"targets": results, "rss": rss, "wall_s": wall}))


if __name__ == "__main__":
    main()
