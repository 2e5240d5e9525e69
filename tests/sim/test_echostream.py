"""Echoes streamed by blocks (long live runs) against the one-array echo, and the truth
record written with its run part serialized once."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from sarmoco.sim.echo import noise_sigma
from sarmoco.sim.echostream import ECHO_ARRAY_MAX_BYTES, EchoStream, streams
from sarmoco.sim.emit_radar import INT16_PEAK, RadarEmitter
from sarmoco.sim.emitter import WireTime
from sarmoco.sim.faults import Faults
from sarmoco.sim.insfeed import InsFeed
from sarmoco.sim.motionspec import MotionSpec
from sarmoco.sim.outfiles import TruthWriter, truth_record, write_truth
from sarmoco.sim.run import simulate
from sarmoco.sim.scenario import load_preset
from sarmoco.sim.transports import FileLink

MOTION = MotionSpec("turbulence", seed=1)


def run_pair(snr_db: float | None, n_pulses: int = 700) -> tuple[np.ndarray, EchoStream]:
    """The same ku-vehicle x0.1 pulses (a target lit from pulse ~0) as one array and as a
    stream of 64-pulse blocks."""
    scn = dataclasses.replace(load_preset("ku-vehicle", 0.1), snr_db=snr_db)
    whole = simulate(scn, MOTION, "tactical", seed=5, n_pulses=n_pulses)
    stream = simulate(scn, MOTION, "tactical", seed=5, n_pulses=n_pulses, stream_echo=True)
    assert isinstance(stream.echo, EchoStream) and isinstance(whole.echo, np.ndarray)
    np.testing.assert_array_equal(stream.apc_ned, whole.apc_ned)
    blocks = EchoStream(scn, stream.t_ns, stream.apc_ned, stream.echo.seed, block_pulses=64)
    return whole.echo, blocks


def test_noise_free_stream_is_the_array_echo_in_any_read_order() -> None:
    whole, stream = run_pair(None)
    assert stream.shape == whole.shape and len(stream) == whole.shape[0]
    order = [*range(0, 300), *range(650, 700), *range(100, 130)]  # backwards across blocks
    for k in order:
        np.testing.assert_array_equal(stream[k], whole[k])
    assert np.abs(whole).max() > 0.5  # targets lit: the rows are not just zeros
    with pytest.raises(IndexError, match="pulse 700"):
        stream[700]


def test_noisy_stream_has_the_array_statistics_and_repeats_itself() -> None:
    whole, stream = run_pair(0.0)
    rows = np.stack([stream[k] for k in range(len(stream))])
    sigma = noise_sigma(0.0)
    # the same signal under other noise draws: the difference is noise of twice the power
    diff_power = float(np.mean(np.abs(rows - whole) ** 2))
    assert diff_power == pytest.approx(2.0 * sigma**2, rel=0.02)
    assert float(np.mean(np.abs(rows) ** 2)) == pytest.approx(
        float(np.mean(np.abs(whole) ** 2)), rel=0.02
    )
    np.testing.assert_array_equal(stream.block(3), rows[192:256])  # a block is made again alike
    signal, _ = run_pair(None)
    n3, n4 = rows[192:256] - signal[192:256], rows[256:320] - signal[256:320]
    correlation = abs(np.vdot(n3, n4)) / (np.linalg.norm(n3) * np.linalg.norm(n4))
    assert correlation < 0.02  # each block draws its own noise


def test_peak_bound_holds_and_is_tight_for_point_targets() -> None:
    whole, stream = run_pair(0.0)
    peak = float(np.abs(whole.view(np.float32)).max())
    bound = stream.peak_iq_bound()
    assert peak < bound < 2.0 * peak, (peak, bound)


def test_streamed_radar_packets_saturate_nothing(tmp_path: Path) -> None:
    _, stream = run_pair(0.0, n_pulses=300)
    scn = stream.scenario
    em = RadarEmitter(FileLink(tmp_path / "r.vrt"), scn.radar, stream.t_ns, stream)
    assert em.iq_scale == pytest.approx(INT16_PEAK / stream.peak_iq_bound())
    rows = np.stack([em.wire_samples(k) for k in range(len(stream))]).astype(np.float32)
    np.testing.assert_allclose(
        rows / em.iq_scale, np.stack([stream[k] for k in range(300)]).view(np.float32),
        atol=0.5 / em.iq_scale * 1.001,
    )  # fmt: skip
    assert np.abs(rows).max() < INT16_PEAK
    em.close()


def test_long_runs_stream() -> None:
    scn = load_preset("ku-vehicle", 0.1)
    per_pulse = scn.radar.n_samples * 8
    assert not streams(scn, ECHO_ARRAY_MAX_BYTES // per_pulse)
    assert streams(scn, ECHO_ARRAY_MAX_BYTES // per_pulse + 1)
    assert streams(scn, round(30 * 60 * scn.radar.prf_hz))  # the soak's 30 minutes


def test_truth_writer_writes_the_truth_record(tmp_path: Path) -> None:
    scn = load_preset("ku-vehicle", 0.1)
    run = simulate(scn, MOTION, "tactical", n_pulses=40)
    faults = Faults()
    feed = InsFeed.from_run(run, faults)
    em = RadarEmitter(FileLink(tmp_path / "r.vrt"), scn.radar, run.t_ns, run.echo)
    wire = WireTime(shift_ns=123_456_789)
    write_truth(tmp_path / "a.json", truth_record(run, feed, faults, {"radar": em}, wire))
    TruthWriter(tmp_path / "b.json", run).write(feed, faults, {"radar": em}, wire)
    a, b = ((tmp_path / n).read_text() for n in ("a.json", "b.json"))
    assert a == b and json.loads(b)["wire"]["shift_ns"] == 123_456_789
    em.close()
