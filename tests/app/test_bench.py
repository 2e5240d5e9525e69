"""``sarmoco bench``: simulator and daemon as real processes on loopback, figures on stdout.

A scaled ``thz-spotlight`` (PRF 2 kHz, 410 samples) plays for 2 s; the one JSON line
must hold every figure with a sane value, and the temporary run folder must be gone.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sarmoco.app.benchcmd import KEYS, tile_latencies_s
from sarmoco.app.cli import main
from sarmoco.daemon.threadcpu import STAGES
from sarmoco.sim.scenario import load_preset

PRESET, SCALE, DURATION_S = "thz-spotlight", 0.1, 2.0


def test_bench_prints_sane_figures_and_removes_its_folder(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "sarmoco", "bench", "--preset", PRESET, "--scale", str(SCALE),
         "--duration", str(DURATION_S), "--json", "--work", str(tmp_path)],
        check=True, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    lines = proc.stdout.splitlines()
    assert len(lines) == 1, proc.stdout
    r = json.loads(lines[0])
    assert set(KEYS) <= set(r)
    radar = load_preset(PRESET, SCALE).radar
    assert r["pulses_sent"] == round(DURATION_S * radar.prf_hz)
    assert r["exit_status"] == 0
    assert r["lost_pulses"] == r["pulses_sent"] - r["pulses_recorded"] >= 0
    assert r["pulses_taken"] == r["pulses_recorded"] > 0.9 * r["pulses_sent"]
    assert 0 < r["pulses_focused"] <= r["pulses_taken"]
    assert r["tiles"] > 0 and 0 <= r["tiles_live"] <= r["tiles"]
    assert r["realtime_ratio"] > 0 and r["cpu_realtime_ratio"] > 0
    # the whole chain costs more CPU per pulse than one FFT of the pulse, but not absurdly
    assert 1.0 < r["fft_floor_ratio"] < 1e5
    assert 0.0 < r["latency_p50_s"] <= r["latency_p99_s"] < 60.0
    # a tile waits less after its last pulse than after its first (NaN: none seen live)
    assert not r["tile_latency_last_p99_s"] > r["tile_latency_p99_s"]
    assert 50.0 < r["peak_rss_mb"] < 4096.0
    # every stage took CPU for the pulses it saw, and one of the chain's bounds it
    assert set(r["stage_cpu_us_per_pulse"]) == set(STAGES)
    for stage in ("receive", "record", "write", "focus"):
        assert 0.0 < r["stage_cpu_us_per_pulse"][stage] < 1e6, stage
    chain = {k: v for k, v in r["stage_load"].items() if k != "other"}
    assert r["bounding_stage"] in chain
    assert chain[r["bounding_stage"]] == max(chain.values())
    focus_fate = r["pulses_focused"] + r["pulses_focus_skipped"] + r["pulses_nav_flagged"]
    assert focus_fate <= r["pulses_taken"]
    assert math.isfinite(r["rss_growth_mb_per_min"])
    raw_bytes = r["pulses_recorded"] * radar.n_samples * 4  # int16 I and Q
    assert r["bytes_written"] > 0.5 * raw_bytes  # raw echoes recorded (zstd: noise stays)
    assert r["kept"] is None and list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "key"),
    [
        (["--scale", "2"], "--scale"),
        (["--duration", "0"], "--duration"),
        (["--min-level", "4"], "--min-level"),
        (["--live-budget", "0"], "--live-budget"),
    ],
)
def test_bench_refuses_bad_arguments(
    args: list[str], key: str, capsys: pytest.CaptureFixture[str]
) -> None:
    status = main(["bench", "--preset", PRESET, "--duration", "1", *args])
    assert status == 2
    assert f"bench {key}" in capsys.readouterr().err


def test_tile_latency_counts_from_the_pulse_given() -> None:
    # two polls saw tiles 0-1 and then tile 2 committed; each tile's first and last pulse
    t0 = np.array([1_000, 2_000, 3_000]) * 10**6
    t1 = t0 + 4_000 * 10**6
    polls = [(9_000 * 10**6, 0, 2), (10_000 * 10**6, 2, 3)]
    assert tile_latencies_s(polls, t0).tolist() == [8.0, 7.0, 7.0]
    assert tile_latencies_s(polls, t1).tolist() == [4.0, 3.0, 3.0]
    # a poll beyond the tiles whose times were read is left out
    assert tile_latencies_s(polls, t1[:2]).tolist() == [4.0, 3.0]
