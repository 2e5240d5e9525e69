"""Real-data tests skip where ``../shared/data`` is missing, and fail instead under CI=true."""

from __future__ import annotations

import pytest

from tests.conftest import shared_files


def _outcome_of_missing_files() -> type[BaseException]:
    """The exception :func:`shared_files` ends a test with when its files are missing
    (caught here so that a skip cannot pass for a failure in this test itself)."""
    with pytest.raises(BaseException, match="no-such-folder") as info:
        shared_files("no-such-folder", "*.mat", 2)
    return info.type


def test_missing_shared_data_skips_outside_ci(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CI", raising=False)
    assert _outcome_of_missing_files() is pytest.skip.Exception


@pytest.mark.parametrize("value", ["true", "True"])
def test_missing_shared_data_fails_under_ci(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv("CI", value)
    assert _outcome_of_missing_files() is pytest.fail.Exception


def test_present_shared_data_is_returned(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("CI", "true")
    files = shared_files("gotcha", "data_3dsar_pass1_az00*_HH.mat", 2)
    assert [f.suffix for f in files] == [".mat", ".mat"]
