"""What the README cites exists: files, bench modules and their flags, make targets, the
``sarmoco`` verbs and their options, and the tests that ``pytest ... -k`` selects.

Cheap: nothing is run. Each check reads the README's code spans (`...`, joined across line
breaks), its indented and fenced command blocks and its image links.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
from pathlib import Path

import pytest

from sarmoco.app.cli import build_parser

PACKAGE_DIRS = ("app/", "daemon/", "drivers/", "processing/", "sim/")
"""Paths the README writes relative to ``sarmoco/`` (``daemon/array_pipeline.py``)."""


def commands(readme: str) -> list[str]:
    """Code spans, indented lines and fenced lines, whitespace collapsed."""
    fence = r"```[^\n]*\n(.*?)```"
    blocks = [line for b in re.findall(fence, readme, re.S) for line in b.split("\n")]
    indented = [line.strip() for line in readme.split("\n") if line.startswith("    ")]
    prose = "\n".join(
        line
        for line in re.sub(fence, "", readme, flags=re.S).split("\n")
        if not line.startswith("    ")
    )
    spans = [" ".join(s.split()) for s in re.findall(r"`([^`]+)`", prose)]
    return spans + blocks + indented


def cited_paths(readme: str) -> set[str]:
    """Repository paths in code spans and image links."""
    tokens = [t for s in commands(readme) for t in s.split()]
    tokens += re.findall(r"\]\(([^)\s]+)\)", readme)
    out = set()
    for tok in tokens:
        tok = tok.rstrip(",.;:)")
        if re.fullmatch(r"(sarmoco|tests|bench|docs|systemd|\.ci)/[\w./-]*", tok):
            out.add(tok)
        elif tok.startswith(PACKAGE_DIRS) and re.fullmatch(r"[\w/]+\.py", tok):
            out.add("sarmoco/" + tok)
    return out


@pytest.fixture(scope="module")
def readme(repo_root: Path) -> str:
    return (repo_root / "README.md").read_text()


def test_cited_files_exist(readme: str, repo_root: Path) -> None:
    paths = cited_paths(readme)
    assert len(paths) > 50  # the parser still finds the README's citations
    missing = sorted(p for p in paths if not (repo_root / p).exists())
    assert not missing, f"README cites paths that do not exist: {missing}"


def test_bench_modules_and_their_flags_exist(readme: str, repo_root: Path) -> None:
    pattern = r"python (?:-m bench\.(\w+)|bench/(\w+)\.py)((?: --?[\w-]+(?: [\w.@=-]+)?)*)"
    seen = 0
    for line in commands(readme):
        for m in re.finditer(pattern, line):
            path = repo_root / "bench" / f"{m.group(1) or m.group(2)}.py"
            assert path.exists(), f"README: {m.group(0)!r}: no {path.name} in bench/"
            source = path.read_text()
            for flag in re.findall(r"(--[\w-]+)", m.group(3)):
                assert f'"{flag}"' in source, f"README: {m.group(0)!r}: {path.name} has no {flag}"
            seen += 1
    assert seen > 10


def test_make_targets_exist(readme: str, repo_root: Path) -> None:
    makefile = (repo_root / "Makefile").read_text()
    targets = set(re.findall(r"^([\w-]+):", makefile, re.M))
    cited = {m for line in commands(readme) for m in re.findall(r"\bmake (\w+)", line)}
    assert {"demo", "test", "figures"} <= cited
    assert cited <= targets, f"README cites make targets not in the Makefile: {cited - targets}"


def _verb_options(parser: argparse.ArgumentParser, verb: list[str]) -> set[str]:
    """Option strings of a (nested) verb, its deferred arguments added."""
    for word in verb:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[word]
        with contextlib.redirect_stderr(io.StringIO()), contextlib.suppress(SystemExit):
            parser.parse_known_args([])  # adds a VerbParser's deferred arguments
    return {s for a in parser._actions for s in a.option_strings}


def test_sarmoco_verbs_and_options_exist(readme: str) -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    verbs = set(sub.choices)
    options_of: dict[tuple[str, ...], set[str]] = {}
    seen = 0
    for line in commands(readme):
        for m in re.finditer(r"(?<![\w/.-])sarmoco ([a-z][\w-]*)((?: [^`|]*)?)", line):
            verb = m.group(1)
            if verb not in verbs:
                continue  # prose ("sarmoco runs ...") is not a command line
            words = [verb] + (["check"] if verb == "config" and "check" in m.group(2) else [])
            key = tuple(words)
            if key not in options_of:
                options_of[key] = _verb_options(build_parser(), words)
            options = options_of[key]
            for flag in re.findall(r"(?<![\w-])(--[a-z][\w-]*)", m.group(2)):
                assert flag in options, f"README: {m.group(0)!r}: `sarmoco {verb}` has no {flag}"
            seen += 1
    cited = {
        m.group(1) for line in commands(readme) for m in re.finditer(r"sarmoco ([a-z][\w-]*)", line)
    }
    assert seen > 20 and {"run", "replay", "sim", "bench", "demo"} <= cited


def test_pytest_selections_match_tests(readme: str, repo_root: Path) -> None:
    """``pytest ... FILE -k WORD`` selects at least one test of FILE."""
    pattern = r"pytest [^`]*?(tests/[\w/]+\.py) -k \"?(\w+(?: or \w+)*)"
    seen = 0
    for line in commands(readme):
        for m in re.finditer(pattern, line):
            source = (repo_root / m.group(1)).read_text()
            names = re.findall(r"^(?:async )?def (test_\w+)", source, re.M)
            for word in m.group(2).split(" or "):
                assert any(word in n for n in names), f"README: {m.group(0)!r} selects no test"
            seen += 1
    assert seen >= 5
