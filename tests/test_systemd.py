"""The systemd unit: `systemd-analyze verify` clean, exposure score <= 2.5."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import unavailable

MAX_EXPOSURE = 2.5


def _analyze() -> str:
    tool = shutil.which("systemd-analyze")
    if tool is None:
        unavailable("systemd-analyze not installed")
    return tool


@pytest.fixture
def unit(tmp_path: Path, repo_root: Path) -> Path:
    """The unit with ExecStart pointing at the installed ``sarmoco`` script."""
    exe = Path(sys.executable).with_name("sarmoco")
    assert exe.exists(), f"sarmoco console script not installed next to {sys.executable}"
    text = (repo_root / "systemd" / "sarmoco.service").read_text()
    assert "ExecStart=/opt/sarmoco/bin/sarmoco run --config" in text
    out = tmp_path / "sarmoco.service"
    out.write_text(text.replace("/opt/sarmoco/bin/sarmoco", str(exe)))
    return out


def test_verify_prints_nothing(unit: Path) -> None:
    res = subprocess.run(
        [_analyze(), "verify", str(unit)], capture_output=True, text=True, timeout=60
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert res.stdout.strip() == "" and res.stderr.strip() == "", res.stdout + res.stderr


def test_security_exposure(unit: Path) -> None:
    res = subprocess.run(
        [_analyze(), "security", "--offline=yes", str(unit)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    match = re.search(r"Overall exposure level for \S+: ([0-9.]+)", res.stdout)
    assert match, res.stdout + res.stderr
    assert float(match.group(1)) <= MAX_EXPOSURE, res.stdout


def test_unit_essentials(repo_root: Path) -> None:
    text = (repo_root / "systemd" / "sarmoco.service").read_text()
    for line in (
        "Type=notify",
        "Restart=on-failure",
        "ConfigurationDirectory=sarmoco",
        "StateDirectory=sarmoco",
        "DeviceAllow=char-ttyUSB rw",
        "DeviceAllow=char-ttyACM rw",
        "ProtectSystem=strict",
        "StartLimitBurst=",
    ):
        assert line in text, line
    assert re.search(r"^WatchdogSec=\d+s$", text, re.M)
    assert re.search(r"^RestrictAddressFamilies=.*AF_CAN", text, re.M)
