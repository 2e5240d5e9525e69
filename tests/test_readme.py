"""What the README and the documentation site cite exists, and the site builds.

Every Markdown page a user reads (``README.md`` and ``docs/**/*.md``) is checked: the files
it names, the bench modules and their flags, make targets, the ``sarmoco`` verbs and their
options, the configuration keys, and the tests that ``pytest ... -k`` selects. The generated
reference pages (``docs/cli.md`` from ``--help``, the key table of
``docs/configuration.md``) must equal what ``docs/gen_reference.py`` writes, and
``mkdocs build --strict`` (every internal link and anchor resolves) must pass.

Cheap but for the site build (a few seconds): nothing else is run. Each check reads the
pages' code spans (`...`, joined across line breaks), their indented and fenced command
blocks and their links.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import os
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

from sarmoco.app.cli import build_parser
from sarmoco.daemon.config import describe_keys

PACKAGE_DIRS = ("app/", "daemon/", "drivers/", "processing/", "products/", "sim/", "store/")
"""Paths the pages write relative to ``sarmoco/`` (``daemon/array_pipeline.py``)."""

README_MAX_LINES = 200
"""The README is the front door; the rest lives in docs/."""

HISTORY = re.compile(r"issue [0-9]|\(issue", re.I)
"""Development history has no place in what users read."""


def commands(page: str) -> list[str]:
    """Code spans, indented lines and fenced lines, whitespace collapsed."""
    fence = r"```[^\n]*\n(.*?)```"
    blocks = [line for b in re.findall(fence, page, re.S) for line in b.split("\n")]
    indented = [line.strip() for line in page.split("\n") if line.startswith("    ")]
    prose = "\n".join(
        line
        for line in re.sub(fence, "", page, flags=re.S).split("\n")
        if not line.startswith("    ")
    )
    spans = [" ".join(s.split()) for s in re.findall(r"`([^`]+)`", prose)]
    return spans + blocks + indented


def cited_paths(page: str) -> set[str]:
    """Repository paths in code spans and links (a link's ``#anchor`` dropped)."""
    tokens = [t for s in commands(page) for t in s.split()]
    tokens += re.findall(r"\]\(([^)\s]+)\)", page)
    out = set()
    for tok in tokens:
        tok = tok.split("#")[0].rstrip(",.;:)")
        if re.fullmatch(r"(sarmoco|tests|bench|docs|systemd|\.ci)/[\w./-]*", tok):
            out.add(tok)
        elif tok.startswith(PACKAGE_DIRS) and re.fullmatch(r"[\w/]+\.py", tok):
            out.add("sarmoco/" + tok)
    return out


@pytest.fixture(scope="module")
def pages(repo_root: Path) -> dict[str, str]:
    """Every page users read, by path relative to the repository."""
    paths = [repo_root / "README.md", *sorted((repo_root / "docs").rglob("*.md"))]
    return {str(p.relative_to(repo_root)): p.read_text() for p in paths}


def _lines(pages: dict[str, str]) -> list[tuple[str, str]]:
    return [(name, line) for name, text in pages.items() for line in commands(text)]


def _gen_reference(repo_root: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "gen_reference", repo_root / "docs" / "gen_reference.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_site_has_its_pages(pages: dict[str, str]) -> None:
    guides = ("getting-started", "operator", "integrator", "ground-processing")
    reference = ("configuration", "cli", "store", "methods", "design", "measurements/index")
    for page in guides + reference:
        assert f"docs/{page}.md" in pages


def test_readme_is_a_front_door(pages: dict[str, str]) -> None:
    readme = pages["README.md"]
    assert len(readme.splitlines()) <= README_MAX_LINES
    assert "make demo" in readme and "make test" in readme


def test_no_development_history(repo_root: Path, pages: dict[str, str]) -> None:
    code = [p for d in ("sarmoco", "tests", "bench") for p in (repo_root / d).rglob("*.py")]
    code = sorted(p for p in code if p != Path(__file__).resolve())  # this file names it
    sources = {str(p.relative_to(repo_root)): p.read_text() for p in code}
    hits = [
        f"{name}: {line.strip()}"
        for name, text in {**pages, **sources}.items()
        for line in text.splitlines()
        if HISTORY.search(line)
    ]
    assert not hits, "\n".join(hits)


def test_cited_files_exist(pages: dict[str, str], repo_root: Path) -> None:
    cited = {(name, p) for name, text in pages.items() for p in cited_paths(text)}
    assert len(cited) > 100  # the parser still finds the pages' citations
    missing = sorted(f"{name}: {p}" for name, p in cited if not (repo_root / p).exists())
    assert not missing, f"pages cite paths that do not exist: {missing}"


def test_bench_modules_and_their_flags_exist(pages: dict[str, str], repo_root: Path) -> None:
    pattern = r"python (?:-m bench\.(\w+)|bench/(\w+)\.py)((?: --?[\w-]+(?: [\w.@=-]+)?)*)"
    seen = 0
    for name, line in _lines(pages):
        for m in re.finditer(pattern, line):
            path = repo_root / "bench" / f"{m.group(1) or m.group(2)}.py"
            assert path.exists(), f"{name}: {m.group(0)!r}: no {path.name} in bench/"
            source = path.read_text()
            for flag in re.findall(r"(--[\w-]+)", m.group(3)):
                assert f'"{flag}"' in source, f"{name}: {m.group(0)!r}: {path.name} has no {flag}"
            seen += 1
    assert seen > 10


def test_make_targets_exist(pages: dict[str, str], repo_root: Path) -> None:
    makefile = (repo_root / "Makefile").read_text()
    targets = set(re.findall(r"^([\w-]+):", makefile, re.M))
    cited = {m for _, line in _lines(pages) for m in re.findall(r"\bmake (\w+)", line)}
    assert {"demo", "test", "figures", "docs", "install"} <= cited
    assert cited <= targets, f"pages cite make targets not in the Makefile: {cited - targets}"


def _verb_options(parser: argparse.ArgumentParser, verb: list[str]) -> set[str]:
    """Option strings of a (nested) verb, its deferred arguments added."""
    for word in verb:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[word]
        with contextlib.redirect_stderr(io.StringIO()), contextlib.suppress(SystemExit):
            parser.parse_known_args([])  # adds a VerbParser's deferred arguments
    return {s for a in parser._actions for s in a.option_strings}


def test_sarmoco_verbs_and_options_exist(pages: dict[str, str]) -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    verbs = set(sub.choices)
    options_of: dict[tuple[str, ...], set[str]] = {}
    seen = 0
    for name, line in _lines(pages):
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
                assert flag in options, f"{name}: {m.group(0)!r}: `sarmoco {verb}` has no {flag}"
            seen += 1
    cited = {
        m.group(1) for _, line in _lines(pages) for m in re.finditer(r"sarmoco ([a-z][\w-]*)", line)
    }
    assert seen > 20 and verbs <= cited, f"verbs no page shows: {verbs - cited}"


def test_configuration_keys_exist(pages: dict[str, str]) -> None:
    """``section.key`` in a code span names a key of the configuration."""
    keys = {row["key"] for row in describe_keys()}
    sections = "|".join(sorted({k.split(".")[0] for k in keys}))
    files = r"(?:vrt|tlog|log|sbg|py|toml|json|txt|png)\b"  # radar.vrt, ins.log: files
    pattern = rf"(?<![\w./-])((?:{sections})\.(?!{files})[a-z_][a-z0-9_]*)(?![\w(])"
    cited = {(name, m) for name, line in _lines(pages) for m in re.findall(pattern, line)}
    assert len(cited) > 50
    unknown = sorted(f"{name}: {k}" for name, k in cited if k not in keys)
    assert not unknown, f"pages name configuration keys that do not exist: {unknown}"


def test_pytest_selections_match_tests(pages: dict[str, str], repo_root: Path) -> None:
    """``pytest ... FILE -k WORD`` selects at least one test of FILE."""
    pattern = r"pytest [^`]*?(tests/[\w/]+\.py) -k \"?(\w+(?: or \w+)*)"
    seen = 0
    for name, line in _lines(pages):
        for m in re.finditer(pattern, line):
            source = (repo_root / m.group(1)).read_text()
            names = re.findall(r"^(?:async )?def (test_\w+)", source, re.M)
            for word in m.group(2).split(" or "):
                assert any(word in n for n in names), f"{name}: {m.group(0)!r} selects no test"
            seen += 1
    assert seen >= 5


def test_generated_pages_are_current(repo_root: Path) -> None:
    """docs/cli.md is the parser's ``--help``, docs/configuration.md's table the keys'."""
    for path, text in _gen_reference(repo_root).generated().items():
        assert path.read_text() == text, f"{path} is stale: run python docs/gen_reference.py"


def test_cli_page_shows_every_option(repo_root: Path) -> None:
    page = (repo_root / "docs" / "cli.md").read_text()
    parser = build_parser()
    for words, _ in _gen_reference(repo_root)._verbs(parser):
        assert f"## sarmoco {' '.join(words)}\n" in page
        for option in _verb_options(build_parser(), list(words)):
            assert option in page, f"sarmoco {' '.join(words)} {option}"


def test_site_builds_strict(repo_root: Path, tmp_path: Path) -> None:
    """``mkdocs build --strict``: every page in the navigation, link and anchor resolves."""
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict",
         "--config-file", str(repo_root / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
        capture_output=True, text=True, timeout=120,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "site" / "operator.html").exists()
