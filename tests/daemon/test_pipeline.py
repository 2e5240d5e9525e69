"""The daemon pipeline in process: ring → aligner → focuser → recorder → report.

A scaled ku-vehicle run with turbulent cross-track motion and a tactical INS is fed
pulse by pulse (with INS samples arriving ahead of the pulses, as live), then the
store is reopened and its tiles measured: every point target must focus to the
unweighted-sinc limit within the autofocus's acceptance thresholds (PSLR ≤ -12.5 dB,
IRW ≤ 1.1 × theory) at the right place.
"""

from __future__ import annotations

import dataclasses
import math
import socket
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.simconfig import scenario_config
from sarmoco.daemon.config import Config, parse_config
from sarmoco.daemon.links import open_radar
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.status import Counters
from sarmoco.daemon.tables import tile_metrics
from sarmoco.drivers.radar import RadarUdpSource
from sarmoco.drivers.samples import AttitudeSample, EchoPackets, Validity, VelocitySample
from sarmoco.drivers.vita49 import encode_signal_packet
from sarmoco.errors import RecorderError
from sarmoco.processing.metrics import PointTargetMetrics, point_target_metrics
from sarmoco.processing.types import Image
from sarmoco.products.report import strip, write_report
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.run import SimRun, simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.store.flags import PulseFlag
from sarmoco.store.reader import open_store
from sarmoco.store.schema import REFERENCE_TRACK_ATTR

MOTION = MotionSpec(
    kind="turbulence",
    cross_track_rms_m=0.3,
    vertical_rms_m=0.15,
    along_speed_rms_mps=0.02,
    attitude_rms_rad=0.0,
    corner_hz=0.1,
    seed=1,
)
"""0.3 m rms cross-track sway: 30 wavelengths at Ku, far beyond any focusing tolerance."""

NAV_LEAD_NS = 50_000_000
"""INS samples reach the daemon up to this far ahead of the pulses, ns."""


@pytest.fixture(scope="module")
def run() -> SimRun:
    return simulate(load_preset("ku-vehicle", 0.1), MOTION, "tactical", seed=0)


def feed(
    run: SimRun,
    cfg: Config,
    store: Path,
    nav_from_ns: int | None = None,
    focus_paused_ns: tuple[int, int] | None = None,
    replay: bool = False,
    focus: Callable[[Pipeline, int], None] = Pipeline.focus,
) -> Pipeline:
    """Play a simulated run into a pipeline on the radar's virtual clock (the INS from
    ``nav_from_ns`` on, GPS ns; from its start when None). ``focus_paused_ns``: the
    pipeline is a live one that skips ahead, and focusing does not run while the radar
    clock is in that span (GPS ns), recording does. ``replay``: the first pulses are held
    for the first track's course, as ``sarmoco replay`` holds them. ``focus``: a focusing
    pass (the pipeline, the radar clock, GPS ns)."""
    nav = run.ins.nav
    with open_recorder(cfg, store) as rec:
        pipe = Pipeline(
            cfg, rec, Counters(), focus_skips=focus_paused_ns is not None, hold_course=replay
        )
        paused = focus_paused_ns or (0, 0)
        k = 0 if nav_from_ns is None else int(np.searchsorted(nav.t_ns, nav_from_ns))
        for i, t in enumerate(run.t_ns.tolist()):
            slot = pipe.ring.reserve()
            assert slot is not None
            slot.samples[...] = run.echo[i]
            pipe.ring.commit(slot, t, i)
            while k < nav.t_ns.size and nav.t_ns[k] < t + NAV_LEAD_NS:
                tk = int(nav.t_ns[k])
                vel = (float(nav.vel_ned[k, 0]), float(nav.vel_ned[k, 1]), float(nav.vel_ned[k, 2]))
                q = nav.quat[k]
                quat = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
                pipe.add_nav(
                    [
                        VelocitySample(tk, vel, Validity.VELOCITY, "sim", tk),
                        AttitudeSample(tk, quat, Validity.ATTITUDE, "sim", tk),
                    ],
                    None,
                )
                k += 1
            if i % 64 == 63:
                pipe.record(t)
                if not paused[0] <= t < paused[1]:
                    focus(pipe, t)
        pipe.finish()
    return pipe


@pytest.mark.parametrize("autofocus", [False, True], ids=["ins-only", "ins+autofocus"])
def test_pipeline_focuses_and_records(run: SimRun, tmp_path: Path, autofocus: bool) -> None:
    scn = run.scenario
    cfg = scenario_config(scn, radar={"sample_format": "float32"}, autofocus={"enabled": autofocus})
    pipe = feed(run, cfg, tmp_path / "run.zarr")
    assert pipe.focuser is not None
    summary = write_report(tmp_path / "run.zarr", tmp_path / "report")
    assert summary.complete
    assert summary.run["pulses_processed"] == run.t_ns.size
    assert summary.run["pulses_nav_flagged"] == 0
    for name in ("image.png", "motion.png", "report.json", "report.txt"):
        assert (tmp_path / "report" / name).stat().st_size > 0
    store = open_store(tmp_path / "run.zarr")
    assert store.committed("pulses") == run.t_ns.size
    assert store.committed("motion") == run.t_ns.size
    points = summary.image.points
    track = pipe.focuser.track
    truth = [track.rotation @ (tg - run.apc_ned[0]) for tg in run.targets_ned]
    irw_az = 0.886 * scn.azimuth_resolution_m
    for tgt in truth:
        near = [p for p in points if math.hypot(p["x_m"] - tgt[0], p["y_m"] - tgt[1]) < 0.5]
        assert near, f"no focused point near {tgt[:2]}: {points}"
        p = near[0]
        irw_rg = 0.886 * scn.radar.range_resolution_m * np.hypot(tgt[1], tgt[2]) / tgt[1]
        assert p["pslr_az_db"] <= -12.5 and p["pslr_rg_db"] <= -12.5, p
        assert p["irw_az_m"] <= 1.1 * irw_az and p["irw_rg_m"] <= 1.1 * irw_rg, p


def test_pulses_before_the_ins_starts_are_counted_once(run: SimRun, tmp_path: Path) -> None:
    """The INS starts 1.5 processing blocks after the first pulse: the pulses before it
    reach the motion table without a solution and are counted unfocused, so every pulse
    recorded is in the motion table once and counted in exactly one of processed,
    unfocused, skipped and out of order (the first block without navigation was left out
    of both)."""
    cfg = scenario_config(
        run.scenario, radar={"sample_format": "float32"}, autofocus={"enabled": False}
    )
    late = round(1.5 * cfg.imaging.block_pulses)
    pipe = feed(run, cfg, tmp_path / "run.zarr", nav_from_ns=int(run.t_ns[late]))
    store = open_store(tmp_path / "run.zarr")
    motion = store.read("motion", ["pulse_id", "d_los_m"])
    np.testing.assert_array_equal(motion["pulse_id"], np.arange(run.t_ns.size))
    metrics, totals = store.attrs["metrics"], pipe.totals()
    unfocused = int(np.count_nonzero(~np.isfinite(motion["d_los_m"])))
    assert metrics["pulses_unfocused"] == totals["pulses_unfocused"] == unfocused >= late
    fates = ("processed", "unfocused", "focus_skipped", "out_of_order")
    assert sum(metrics[f"pulses_{k}"] for k in fates) == run.t_ns.size


def test_a_store_that_refuses_the_first_track_costs_one_block(run: SimRun, tmp_path: Path) -> None:
    """The store's directory is away during the focusing pass that starts the focuser: the
    first reference track's write is refused (a RecorderError, which the daemon reports and
    goes on from). With the store back, the next pass records the track and focusing goes
    on from a whole state: one block's pulses lost to focusing, none to the recording."""
    cfg = scenario_config(
        run.scenario, radar={"sample_format": "float32"}, autofocus={"enabled": False}
    )
    store, away = tmp_path / "run.zarr", tmp_path / "away.zarr"
    refused: list[RecorderError] = []

    def focus(pipe: Pipeline, t_ns: int) -> None:
        if pipe.focuser is not None or refused:
            pipe.focus(t_ns)
            return
        store.rename(away)
        try:
            pipe.focus(t_ns)
        except RecorderError as exc:
            refused.append(exc)
        finally:
            away.rename(store)

    pipe = feed(run, cfg, store, focus=focus)
    assert len(refused) == 1 and "removed" in str(refused[0]), refused
    got = open_store(store)
    assert REFERENCE_TRACK_ATTR in got.attrs
    assert got.committed("pulses") == run.t_ns.size
    assert pipe.summary.pulses_processed == run.t_ns.size - cfg.imaging.block_pulses


def test_focusing_skips_ahead_on_the_same_segment(tmp_path: Path) -> None:
    """Focusing stalls for 7 s of a live run (recording goes on): the focus backlog skips
    ahead over more pulses than the segmenter's window, and the focuser goes on with the
    pulses after the hole on the segment it had (no second segment: its state is kept),
    while every pulse is recorded and the skipped ones are counted."""
    scn = load_preset("ku-vehicle", 0.05)
    run = simulate(scn, MOTION, "tactical", seed=0, n_pulses=round(14.0 * scn.radar.prf_hz))
    cfg = scenario_config(
        run.scenario,
        radar={"sample_format": "float32"},
        imaging={"method": "rda", "presum_first": True},
    )
    t0 = int(run.t_ns[0])
    pause = (t0 + 3 * 10**9, t0 + 10 * 10**9)
    pipe = feed(run, cfg, tmp_path / "skip.zarr", focus_paused_ns=pause)
    summary = pipe.summary
    assert summary.pulses_focus_skipped > 3.0 * scn.radar.prf_hz
    assert open_store(tmp_path / "skip.zarr").read("pulses", ["t_ns"])["t_ns"].size == run.t_ns.size
    assert pipe.focuser is not None and pipe.focuser.segments == 1


def test_an_empty_tile_is_a_product_not_an_error() -> None:
    empty = tile_metrics(np.zeros((4, 5), np.complex64))
    assert math.isnan(empty["entropy"]) and math.isnan(empty["contrast"])
    point = np.zeros((4, 5), np.complex64)
    point[1, 2] = 3.0
    assert tile_metrics(point) == {"entropy": 0.0, "contrast": pytest.approx(np.sqrt(19.0))}


# -- autofocus subapertures scaled to the scenario (tests/app/test_simconfig.py) ------------


# -- thz-spotlight: the autofocus removes what the INS alone leaves -------------------------

INS_ACCEL_BIAS_MPS2 = 0.2
"""East acceleration bias of the INS in the thz-spotlight test, m/s²."""


def _with_ins_accel_bias(run: SimRun, bias_mps2: float) -> SimRun:
    """``run`` whose INS east velocity drifts by ``bias_mps2`` per second from the first pulse."""
    nav = run.ins.nav
    vel = nav.vel_ned.copy()
    vel[:, 1] += bias_mps2 * (nav.t_ns - run.t_ns[0]) * 1e-9
    ins = dataclasses.replace(run.ins, nav=dataclasses.replace(nav, vel_ned=vel))
    return dataclasses.replace(run, ins=ins)


def _target_metrics(
    run: SimRun, cfg: Config, store_path: Path, replay: bool = False
) -> list[tuple[PointTargetMetrics, tuple[float, float, float]]]:
    """Feed ``run`` through a pipeline with ``cfg`` (``replay``: see :func:`feed`); the
    metrics of every target in the recorded strip (a ±1 m window: one target only) and its
    place in the imaging frame, m."""
    pipe = feed(run, cfg, store_path, replay=replay)
    store = open_store(store_path)
    if cfg.autofocus.enabled:
        assert store.committed("autofocus") >= 2
    image = strip(store)
    assert pipe.focuser is not None and image is not None
    out = []
    for tg in run.targets_ned:
        x, y, z = (float(v) for v in pipe.focuser.track.rotation @ (tg - run.apc_ned[0]))
        i = int(np.argmin(np.abs(image.axis0_m - x)))
        j = int(np.argmin(np.abs(image.axis1_m - y)))
        h0, h1 = (round(1.0 / abs(d)) for d in image.spacing_m)
        rows, cols = slice(max(i - h0, 0), i + h0 + 1), slice(max(j - h1, 0), j + h1 + 1)
        sub = Image(image.data[rows, cols], image.axis0_m[rows], image.axis1_m[cols], image.frame)
        out.append((point_target_metrics(sub), (x, y, z)))
    return out


def test_thz_spotlight_focuses_with_the_scaled_autofocus(tmp_path: Path) -> None:
    """thz-spotlight (0.12 s aperture, shorter than the default 0.4 s subaperture) with
    0.3 m rms sway and a tactical INS, through the pipeline with the autofocus settings
    of :func:`scenario_config`: the autofocus runs (it never did with the default) and
    every target focuses to PSLR <= -12.5 dB and IRW <= 1.1 x theory in both dimensions
    within 0.5 m of its place. The INS velocities carry an east ramp of
    :data:`INS_ACCEL_BIAS_MPS2` (a 20 mg accelerometer bias that INS-only compensation
    integrates into a quadratic LOS error): INS alone leaves every target's azimuth PSLR
    above the bar (measured -6.5 dB; -13.1 to -13.2 dB with the autofocus), so a no-op
    autofocus fails. (Without the ramp the tactical INS alone now reaches -13.2 dB.)"""
    run = _with_ins_accel_bias(
        simulate(load_preset("thz-spotlight", 0.1), MOTION, "tactical", seed=0),
        INS_ACCEL_BIAS_MPS2,
    )
    scn = run.scenario
    ins_only = scenario_config(
        scn, radar={"sample_format": "float32"}, autofocus={"enabled": False}
    )
    for m, _ in _target_metrics(run, ins_only, tmp_path / "ins.zarr"):
        assert m.axis0.pslr_db > -12.5, m
    cfg = scenario_config(scn, radar={"sample_format": "float32"})
    assert cfg.autofocus.enabled and cfg.autofocus.subaperture_s < scn.aperture_s / 2
    for m, (x, y, z) in _target_metrics(run, cfg, tmp_path / "thz.zarr"):
        irw_rg = 0.886 * scn.radar.range_resolution_m * math.hypot(y, z) / y
        assert math.hypot(m.axis0.peak_m - x, m.axis1.peak_m - y) < 0.5, m
        assert m.axis0.pslr_db <= -12.5 and m.axis1.pslr_db <= -12.5, m
        assert m.axis0.irw_m <= 1.1 * 0.886 * scn.azimuth_resolution_m, m
        assert m.axis1.irw_m <= 1.1 * irw_rg, m


# -- the radar reader on a real UDP socket --------------------------------------------------

READ_SAMPLES = 64
T0_NS = 1_400_000_000 * 10**9
"""GPS time of the first test pulse, ns."""


def test_read_radar_reads_blocks_and_counts_only_real_drops(tmp_path: Path) -> None:
    """VITA 49 datagrams on 127.0.0.1 into a pipeline whose ring (1024 slots) is never drained.

    The reader fills the ring with few driver calls (blocks, not one row per call);
    polling the full ring while nothing arrives drops nothing; pulses that arrive while
    it is full are read and counted as dropped; the first pulse stored after room is
    made is flagged DROPPED_BEFORE, and nothing else is.
    """
    cfg = parse_config(
        {
            "radar": {"n_samples": READ_SAMPLES, "prf_hz": 100.0, "sample_format": "int16"},
            # a scene inside the short range window (749.5 .. 759 m), or the config is refused
            "geometry": {"center_slant_range_m": 754.0},
            "imaging": {"swath_m": 4.0},
            "status": {"http_port": 0},
        }
    )
    with open_recorder(cfg, tmp_path / "read.zarr") as rec:
        pipe = Pipeline(cfg, rec, Counters())
        assert pipe.ring.capacity == 1024
        calls = 0
        with open_radar(cfg, "udp://127.0.0.1:0") as src:
            assert isinstance(src, RadarUdpSource)
            read_into = src.read_into

            def counted(out: np.ndarray, timeout_s: float = 0.1) -> EchoPackets:
                nonlocal calls
                calls += 1
                return read_into(out, timeout_s)

            src.read_into = counted  # type: ignore[method-assign]
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
                sent = 0

                def send_and_read(n: int) -> int:
                    nonlocal sent
                    got = 0
                    for k in range(sent, sent + n):
                        iq = np.full((READ_SAMPLES, 2), k % 30_000, np.int16)
                        tx.sendto(encode_signal_packet(0, T0_NS + k * 10**7, k, iq), src.address)
                        if k % 100 == 99:
                            got += pipe.read_radar(src, 1.0)
                    sent += n
                    while got < n and (more := pipe.read_radar(src, 1.0)):
                        got += more
                    return got

                assert send_and_read(1024) == 1024
                assert len(pipe.ring) == 1024 and pipe.ring.dropped == 0
                assert calls <= 1024 // 16, calls  # blocks of rows per driver call
                for _ in range(20):  # a full ring polled while nothing arrives
                    assert pipe.read_radar(src, 0.01) == 0
                assert pipe.ring.dropped == 0
                assert send_and_read(300) == 300  # read into scratch and dropped
                assert pipe.ring.dropped == 300 and len(pipe.ring) == 1024
                first = pipe.ring.pop(1024)
                assert send_and_read(5) == 5
                last = pipe.ring.pop(5)
    np.testing.assert_array_equal(first.t_ns, T0_NS + np.arange(1024) * 10**7)
    np.testing.assert_array_equal(first.samples[:, 0, 0], np.arange(1024))
    np.testing.assert_array_equal(first.pulse_id, np.arange(1024))
    assert not first.flags.any()
    np.testing.assert_array_equal(last.t_ns, T0_NS + np.arange(1324, 1329) * 10**7)
    np.testing.assert_array_equal(last.samples[:, -1, 1], np.arange(1324, 1329))
    np.testing.assert_array_equal(last.pulse_id, np.arange(1024, 1029))
    np.testing.assert_array_equal(last.flags, [PulseFlag.DROPPED_BEFORE, 0, 0, 0, 0])
