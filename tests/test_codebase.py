"""Lint, types and the layering rule of docs/design.md §1, run as part of the suite."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "sarmoco"


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


@pytest.mark.parametrize(
    ("layer", "forbidden"),
    [
        ("processing", ("sarmoco.daemon", "sarmoco.drivers", "sarmoco.sim", "sarmoco.app")),
        ("drivers", ("sarmoco.processing", "sarmoco.daemon", "sarmoco.sim", "sarmoco.app")),
        ("daemon", ("sarmoco.sim", "sarmoco.app")),
        ("sim", ("sarmoco.daemon", "sarmoco.app")),
    ],
)
def test_layering(layer: str, forbidden: tuple[str, ...]) -> None:
    bad = [
        f"{p.relative_to(PACKAGE.parent)} imports {name}"
        for p in sorted((PACKAGE / layer).rglob("*.py"))
        for name in _imports(p)
        if name.startswith(forbidden)
    ]
    assert not bad, bad


def test_daemon_process_never_loads_the_simulator() -> None:
    """Every daemon module and the command line for ``sarmoco run`` leave ``sarmoco.sim`` out."""
    code = (
        "import pkgutil, sys, importlib\n"
        "import sarmoco.daemon\n"
        "for m in pkgutil.iter_modules(sarmoco.daemon.__path__, 'sarmoco.daemon.'):\n"
        "    importlib.import_module(m.name)\n"
        "from sarmoco.app.cli import build_parser\n"
        "build_parser().parse_args(['run', '--config', 'sarmoco.toml'])\n"
        "sim = ('sarmoco.sim', 'sarmoco.app.sim', 'sarmoco.app.demo')\n"
        "print(sorted(m for m in sys.modules if m.startswith(sim)))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "[]", res.stdout


def test_ruff_clean(repo_root: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "."],
        cwd=repo_root,
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_mypy_clean(repo_root: Path) -> None:
    res = subprocess.run(
        [sys.executable, "-m", "mypy", "--no-error-summary"],
        cwd=repo_root,
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stdout + res.stderr


def test_cli_help_from_installed_package(repo_root: Path) -> None:
    exe = Path(sys.executable).with_name("sarmoco")
    res = subprocess.run([str(exe), "--help"], capture_output=True, text=True)
    assert res.returncode == 0 and "usage: sarmoco" in res.stdout
    mod = subprocess.run(
        [
            sys.executable,
            "-m",
            "sarmoco",
            "config",
            "check",
            str(repo_root / "systemd/sarmoco.toml"),
        ],
        capture_output=True,
        text=True,
    )
    assert mod.returncode == 0, mod.stderr
    bad = subprocess.run(
        [sys.executable, "-m", "sarmoco", "config", "check", str(repo_root / "README.md")],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and "not valid TOML" in bad.stderr
