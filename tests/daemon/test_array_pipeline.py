"""The array pipeline (:mod:`sarmoco.daemon.array_pipeline`) aligns its pulses with the
navigation exactly as the single-channel pipeline does: one constructor
(:func:`sarmoco.daemon.navigation.nav_alignment`) serves both."""

from __future__ import annotations

from pathlib import Path

from sarmoco.daemon.aligner import Aligner
from sarmoco.daemon.array_ingest import RING_PULSES
from sarmoco.daemon.array_pipeline import ArrayPipeline
from sarmoco.daemon.config import parse_config
from sarmoco.daemon.pipeline import Pipeline
from sarmoco.daemon.runner import open_recorder
from sarmoco.daemon.status import Counters
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
