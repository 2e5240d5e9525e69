"""Shared fixtures: where the repository and the shared data live."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def repo_root() -> Path:
    """The repository root."""
    return REPO


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """``../shared/data`` beside the repository (real data nobody on the team made)."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared data not found at {SHARED_DATA}")
    return SHARED_DATA


def shared_files(subdir: str, pattern: str, count: int) -> list[Path]:
    """The ``count`` files of ``../shared/data/<subdir>`` that match ``pattern``, sorted.

    Where they are missing the calling test is skipped on a developer's machine, but fails
    under ``CI=true``: a CI run must not pass by skipping the real-data tests.
    """
    folder = SHARED_DATA / subdir
    files = sorted(folder.glob(pattern))
    if len(files) != count:
        msg = f"{count} files {pattern!r} expected in {folder}, found {len(files)}"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return files


@pytest.fixture(scope="session")
def gotcha_files() -> list[Path]:
    """The two 1° files of AFRL GOTCHA pass 1 HH (234 pulses)."""
    return shared_files("gotcha", "data_3dsar_pass1_az00*_HH.mat", 2)
