"""``make install`` / ``make uninstall``: the onboard layout, into temporary roots.

Each install creates a real virtual environment and installs the package into it
(``PIP_ARGS=--no-deps``: the test checks the layout, the unit and the scripts, not the
pinned dependencies, whose download would take minutes).

- Staged (``DESTDIR``, ``PREFIX=/opt/sarmoco``): the venv's scripts run from PREFIX
  (no DESTDIR left in them), the unit starts ``/opt/sarmoco/bin/sarmoco`` and documents
  the README installed under PREFIX (with the documentation pages its links name), the
  sysctl drop-in is in place, an existing
  ``/etc/sarmoco/sarmoco.toml`` is not overwritten, and uninstall leaves only that
  operator file.
- In place (``PREFIX`` and ``SYSCONFDIR`` under the temporary directory, no DESTDIR): the
  installed unit, as installed, passes ``systemd-analyze verify`` with no output; the
  example configuration is installed and, unchanged, removed again by uninstall.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import unavailable
from tests.test_systemd import _analyze

PYTHON = f"PYTHON={Path(sys.executable).resolve()}"


def _make(repo_root: Path, target: str, *args: str) -> subprocess.CompletedProcess[str]:
    res = subprocess.run(
        ["make", "--no-print-directory", "-C", str(repo_root), target, PYTHON,
         "PIP_ARGS=--no-deps", *args],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    return res


def _files(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*") if not p.is_dir()}


def _unit_line(unit: Path, key: str) -> str:
    lines = [ln for ln in unit.read_text().splitlines() if ln.startswith(f"{key}=")]
    assert len(lines) == 1, lines
    return lines[0].split("=", 1)[1]


def test_staged_install_and_uninstall(repo_root: Path, tmp_path: Path) -> None:
    root = tmp_path / "root"
    mine = root / "etc/sarmoco/sarmoco.toml"
    mine.parent.mkdir(parents=True)
    mine.write_text("# the operator's own configuration\n")
    _make(repo_root, "install", f"DESTDIR={root}")

    prefix = root / "opt/sarmoco"
    exe = prefix / "bin/sarmoco"
    assert exe.is_file() and os.access(exe, os.X_OK)
    assert exe.read_text().splitlines()[0] == "#!/opt/sarmoco/bin/python"
    for script in (prefix / "bin").iterdir():
        if script.is_file() and not script.is_symlink():
            assert str(root) not in script.read_text(errors="replace"), script
    version = subprocess.run(
        [str(prefix / "bin/python"), "-c",
         "import importlib.metadata as m; print(m.version('sarmoco'))"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert version.stdout.strip() == "0.1.0"

    unit = root / "etc/systemd/system/sarmoco.service"
    assert _unit_line(unit, "ExecStart") == (
        "/opt/sarmoco/bin/sarmoco run --config /etc/sarmoco/sarmoco.toml"
    )
    doc = _unit_line(unit, "Documentation")
    assert doc == "file:/opt/sarmoco/share/doc/sarmoco/README.md"
    readme = root / doc.removeprefix("file:/")
    assert readme.read_text() == (repo_root / "README.md").read_text()
    pages = re.findall(r"\]\((docs/[^)#]+)", readme.read_text())  # its links into the docs
    assert pages and [p for p in pages if not (readme.parent / p).is_file()] == [], pages
    assert (root / "etc/sysctl.d/90-sarmoco.conf").read_text() == (
        repo_root / "systemd/sarmoco-sysctl.conf"
    ).read_text()
    assert mine.read_text() == "# the operator's own configuration\n"

    _make(repo_root, "uninstall", f"DESTDIR={root}")
    assert _files(root) == {"etc/sarmoco/sarmoco.toml"}
    assert not prefix.exists()


def test_installed_unit_verifies(repo_root: Path, tmp_path: Path) -> None:
    prefix, etc = tmp_path / "opt/sarmoco", tmp_path / "etc"
    where = [f"PREFIX={prefix}", f"SYSCONFDIR={etc}"]
    _make(repo_root, "install", *where)
    config = etc / "sarmoco/sarmoco.toml"
    assert config.read_text() == (repo_root / "systemd/sarmoco.toml").read_text()
    unit = etc / "systemd/system/sarmoco.service"
    assert _unit_line(unit, "ExecStart") == f"{prefix}/bin/sarmoco run --config {config}"
    try:
        tool = _analyze()
    except pytest.skip.Exception:
        tool = None
    if tool is not None:
        res = subprocess.run([tool, "verify", str(unit)], capture_output=True, text=True)
        assert res.returncode == 0 and not (res.stdout + res.stderr).strip(), (
            res.stdout + res.stderr
        )
    _make(repo_root, "uninstall", *where)
    assert _files(tmp_path) == set()
    if tool is None:
        unavailable("systemd-analyze not installed: the unit was not verified")
