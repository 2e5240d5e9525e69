"""Longer coverage-guided runs (atheris), marked ``fuzz_long``: not part of the test
command (``-m 'not bench and not fuzz_long'``); run them with
``pytest -m fuzz_long tests/fuzz`` after ``pip install -e .[fuzz]``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris")

REPO = Path(__file__).resolve().parents[2]
RUNS = 200_000
"""Inputs per target (a few minutes each on one core)."""
RSS_LIMIT_MB = 2048
"""libFuzzer kills the run (a failure) when its resident memory exceeds this."""


@pytest.mark.fuzz_long
@pytest.mark.parametrize("target", ["vita", "sbg", "config"])
def test_coverage_guided(target: str, tmp_path: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "tests.fuzz.atheris_harness", target, f"-runs={RUNS}",
         f"-rss_limit_mb={RSS_LIMIT_MB}", "-max_len=4096", f"-artifact_prefix={tmp_path}/"],
        cwd=REPO, capture_output=True, text=True, timeout=3600,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-4000:]
