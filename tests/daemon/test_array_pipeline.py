"""The array pipeline (:mod:`sarmoco.daemon.array_pipeline`) aligns its pulses with the
navigation exactly as the single-channel pipeline does: one constructor
(:func:`sarmoco.daemon.navigation.nav_alignment`) serves both."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sarmoco.app.simarray import array_config_table
from sarmoco.daemon.aligner import Aligner
from sarmoco.daemon.array_ingest import RING_PULSES
from sarmoco.daemon.array_pipeline import ArrayPipeline
from sarmoco.daemon.config import parse_config
from sarmoco.daemon.links import open_radar
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.status import Counters
from sarmoco.sim.array_run import simulate_array, write_array_run
from sarmoco.sim.array_scenario import load_array_preset
from sarmoco.store.reader import open_store
from tests.daemon.test_array_config import ARRAY_RADAR

INS = {
    "max_gap_s": 0.03,
    "bridge_gap_s": 0.25,
    "latency_budget_s": 0.4,
    "clock_step_tolerance_s": 0.7,
    "lever_arm_m": [0.1, -0.2, 0.3],
}
"""``ins`` keys that all differ from their defaults."""


def _alignment(aligner: Aligner) -> tuple[object, ...]:
    return (
        aligner.max_gap_ns,
        aligner.bridge_gap_ns,
        aligner.latency_budget_ns,
        aligner.nav.kinematics.clock_tolerance_ns,
        aligner.nav.attitude.clock_tolerance_ns,
        tuple(aligner.lever_arm_body_m.tolist()) if aligner.lever_arm_body_m is not None else None,
    )


def test_both_pipelines_align_as_the_ins_section_says(tmp_path: Path) -> None:
    expected = (30_000_000, 250_000_000, 400_000_000, 700_000_000, 700_000_000, (0.1, -0.2, 0.3))
    single = parse_config({"ins": INS})
    array = parse_config({"radar": ARRAY_RADAR, "geometry": {"height_m": 200.0}, "ins": INS})
    with open_recorder(single, tmp_path / "single.zarr") as rec:
        pipe = Pipeline(single, rec, Counters())
        assert _alignment(pipe.aligner) == expected
        assert pipe.aligner.max_block == single.imaging.block_pulses
    with open_recorder(array, tmp_path / "array.zarr") as rec:
        mimo = ArrayPipeline(array, rec, Counters())
        assert _alignment(mimo.aligner) == expected
        assert mimo.aligner.max_block == RING_PULSES and mimo.aligner.ring is mimo.backlog
        assert mimo.aligner.nav is mimo.nav


def test_recording_stores_every_channel_before_any_navigation(tmp_path: Path) -> None:
    """The recording path stores each whole pulse, every channel a row, as it comes: with
    no INS sample yet (the aligner would hold every pulse), the radar file's pulses are in
    the store and waiting in the backlog for their navigation."""
    scn = load_array_preset(0.02)
    write_array_run(simulate_array(scn, "ideal"), tmp_path / "sim")
    cfg = parse_config(array_config_table(scn, tmp_path / "sim", "int16"))
    n_c = cfg.radar.channels
    with (
        open_radar(cfg, str(tmp_path / "sim" / "radar.vrt")) as radar,
        open_recorder(cfg, tmp_path / "run.zarr") as rec,
    ):
        pipe = ArrayPipeline(cfg, rec, Counters())
        while pipe.radar.read(radar, 0.0, pipe.ring.free) or not radar.eof:
            pipe.record(None)
        assert pipe.nav.span_ns() is None  # no navigation at all
        assert len(pipe.backlog) == scn.n_pulses == pipe.summary.pulses
        assert rec.pulses.rows == scn.n_pulses * n_c
        assert pipe.focus(pipe.now_ns(live=False)) == 0  # the aligner waits for the INS
    p = open_store(tmp_path / "run.zarr").read("pulses", ["t_ns", "channel"])
    assert (p["channel"].reshape(-1, n_c) == np.arange(n_c)).all()
    assert np.unique(p["t_ns"]).size == scn.n_pulses
