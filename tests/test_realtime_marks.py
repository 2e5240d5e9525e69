"""The ``realtime`` list of tests/conftest.py (the tests `make test` runs alone, after the
rest ran on two xdist workers) covers every module that starts a live run, and names
tests that exist: a renamed test would otherwise leave it silently, and run beside
another worker."""

from __future__ import annotations

import re
from pathlib import Path

from tests.conftest import EXCLUSIVE, LONGEST_FIRST, REALTIME

LIVE = re.compile(
    r"run_loopback\(|\bDaemon\(|\bPopen\(|pin_to_host=True"
    r"|os\.kill\([^)\n]*SIGKILL\)|\"sarmoco\", \"bench\""
)
"""What starts a live run: simulator and daemon on loopback, a ``sarmoco run`` process
(tests/daemon/test_daemon_process.py's ``Daemon``), a process left running beside the test
(``sarmoco sim --serve``, writers to kill), play pinned to the host clock, a SIGKILL at a
random moment, ``sarmoco bench``."""


def unlisted(sources: dict[str, str]) -> list[str]:
    """The modules (path: source) that start a live run and are not in ``REALTIME``."""
    return sorted(
        path for path, text in sources.items() if LIVE.search(text) and path not in REALTIME
    )


def test_every_module_that_starts_a_live_run_is_listed(repo_root: Path) -> None:
    sources = {
        p.relative_to(repo_root).as_posix(): p.read_text()
        for p in sorted((repo_root / "tests").rglob("test_*.py"))
        if p.name != Path(__file__).name  # its own patterns
    }
    bad = unlisted(sources)
    assert not bad, f"start a live run, not in tests/conftest.py REALTIME: {bad}"
    new = {"tests/daemon/test_new.py": "summary = run_loopback(tmp_path / 'out', 0.1)\n"}
    assert unlisted(sources | new) == ["tests/daemon/test_new.py"]  # the check can fail


def test_the_listed_tests_exist(repo_root: Path) -> None:
    for path, names in REALTIME.items():
        source = (repo_root / path).read_text()
        missing = [n for n in names if not re.search(rf"^def {n}\(", source, re.M)]
        assert not missing, f"tests/conftest.py REALTIME names tests not in {path}: {missing}"


def test_the_exclusive_tests_are_realtime_ones() -> None:
    for path, names in EXCLUSIVE.items():
        assert path in REALTIME, path
        assert not REALTIME[path] or set(names) <= set(REALTIME[path]), (path, names)
        assert names or not REALTIME[path], path  # a whole module only if wholly realtime


def test_the_longest_first_modules_exist(repo_root: Path) -> None:
    missing = [path for path in LONGEST_FIRST if not (repo_root / path).is_file()]
    assert not missing, f"tests/conftest.py LONGEST_FIRST names modules that are gone: {missing}"
