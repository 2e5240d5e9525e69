"""Lint, types and the layering rule of docs/design.md §1, run as part of the suite."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "sarmoco"


MAX_FUNCTION_LINES = 90
"""The longest function (decorators excluded, docstring included) anywhere in the package."""


def _module_name(path: Path, package: Path) -> str:
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, package: Path = PACKAGE) -> set[str]:
    """Every module ``path`` imports, by absolute name, in every form: ``import a.b``,
    ``from a import b`` (``a.b`` when ``b`` is a module), relative imports, imports inside
    functions or ``TYPE_CHECKING`` blocks, and ``importlib.import_module("a.b")``."""
    module = _module_name(path, package)
    is_package = path.name == "__init__.py"
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")[: None if is_package else -1]
                base = base[: len(base) - (node.level - 1)]
                origin = ".".join(base + ([node.module] if node.module else []))
            else:
                origin = node.module or ""
            names.add(origin)
            names.update(f"{origin}.{a.name}" for a in node.names)
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            names.add(node.args[0].value)
    return names


LAYERS = {
    "processing": (
        "sarmoco.store",
        "sarmoco.daemon",
        "sarmoco.products",
        "sarmoco.drivers",
        "sarmoco.sim",
        "sarmoco.app",
    ),
    "drivers": (
        "sarmoco.processing",
        "sarmoco.store",
        "sarmoco.daemon",
        "sarmoco.products",
        "sarmoco.sim",
        "sarmoco.app",
    ),
    "store": ("sarmoco.daemon", "sarmoco.products", "sarmoco.sim", "sarmoco.app"),
    "daemon": ("sarmoco.products", "sarmoco.sim", "sarmoco.app"),
    "products": ("sarmoco.sim", "sarmoco.app"),
    "sim": ("sarmoco.store", "sarmoco.daemon", "sarmoco.products", "sarmoco.app"),
}
"""Each layer and the packages it must not import (docs/design.md)."""

PRODUCTS_FROM_DAEMON = ("sarmoco.daemon.config",)
"""What the products may use of the daemon: the run's configuration as it flew (read back
from the store's attributes)."""


def _layering_violations(package: Path) -> list[str]:
    return [
        f"{p.relative_to(package.parent)} imports {name}"
        for layer, forbidden in LAYERS.items()
        for p in sorted((package / layer).rglob("*.py"))
        for name in sorted(_imports(p, package))
        if name == forbidden or any(name == f or name.startswith(f + ".") for f in forbidden)
    ]


def _import_cycles(package: Path) -> list[list[str]]:
    """Strongly connected groups of more than one module in the package's import graph."""
    files = {_module_name(p, package): p for p in package.rglob("*.py")}
    graph = {
        m: {d for d in _imports(p, package) if d in files and d != m} for m, p in files.items()
    }
    order: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        order[v] = low[v] = len(order)
        stack.append(v)
        for w in graph[v]:
            if w not in order:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], order[w])
        if low[v] == order[v]:
            group = [stack.pop()]
            while group[-1] != v:
                group.append(stack.pop())
            if len(group) > 1:
                cycles.append(sorted(group))

    for v in sorted(graph):
        if v not in order:
            visit(v)
    return cycles


def _long_functions(package: Path) -> list[str]:
    return [
        f"{p.relative_to(package.parent)}:{node.lineno} {node.name} "
        f"{node.end_lineno - node.lineno + 1} lines"
        for p in sorted(package.rglob("*.py"))
        for node in ast.walk(ast.parse(p.read_text(), str(p)))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno is not None
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]


def _packages_without_all(package: Path) -> list[str]:
    """Packages whose ``__init__`` declares no ``__all__``, or lists a name it does not
    define and that is no submodule."""
    bad = []
    for init in sorted(package.rglob("__init__.py")):
        tree = ast.parse(init.read_text(), str(init))
        declared = [
            node.value
            for node in ast.walk(tree)
            if isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets)
        ]
        if not declared or not isinstance(declared[0], ast.List | ast.Tuple):
            bad.append(f"{init.relative_to(package.parent)}: no __all__ list")
            continue
        defined = {
            name
            for node in ast.walk(tree)
            for name in (
                [a.asname or a.name for a in node.names]
                if isinstance(node, ast.ImportFrom)
                else [t.id for t in node.targets if isinstance(t, ast.Name)]
                if isinstance(node, ast.Assign)
                else [node.name]
                if isinstance(node, ast.FunctionDef | ast.ClassDef)
                else []
            )
        }
        for elt in declared[0].elts:
            name = elt.value if isinstance(elt, ast.Constant) else None
            is_module = name is not None and (
                (init.parent / f"{name}.py").exists()
                or (init.parent / name / "__init__.py").exists()
            )
            if not (isinstance(name, str) and (name in defined or is_module)):
                bad.append(f"{init.relative_to(package.parent)}: __all__ names {name!r}")
    return bad


def _declared_all(init: Path) -> list[str]:
    for node in ast.walk(ast.parse(init.read_text(), str(init))):
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return [e.value for e in getattr(node.value, "elts", []) if isinstance(e, ast.Constant)]
    return []


def _internal_imports(package: Path) -> list[str]:
    """Imports from outside a package of a module or name its ``__all__`` does not list."""
    public = {
        _module_name(init, package): set(_declared_all(init))
        for init in package.rglob("__init__.py")
    }
    bad = []
    for path in sorted(package.rglob("*.py")):
        here = _module_name(path, package)
        for name in sorted(_imports(path, package)):
            for pkg, names in public.items():
                if (here + ".").startswith(pkg + ".") or not name.startswith(pkg + "."):
                    continue
                sub = name[len(pkg) + 1 :].split(".")[0]
                if sub not in names:
                    bad.append(f"{path.relative_to(package.parent)} imports {pkg}.{sub}")
    return sorted(set(bad))


@pytest.mark.parametrize("layer", sorted(LAYERS))
def test_layering(layer: str) -> None:
    bad = [v for v in _layering_violations(PACKAGE) if v.startswith(f"sarmoco/{layer}/")]
    assert not bad, bad


def test_products_use_only_the_daemons_configuration() -> None:
    """The ground products stand on the store; of the daemon they read only
    :data:`PRODUCTS_FROM_DAEMON`."""
    bad = [
        f"{p.relative_to(PACKAGE.parent)} imports {name}"
        for p in sorted((PACKAGE / "products").rglob("*.py"))
        for name in sorted(_imports(p))
        if (name == "sarmoco.daemon" or name.startswith("sarmoco.daemon."))
        and not any(name == f or name.startswith(f + ".") for f in PRODUCTS_FROM_DAEMON)
    ]
    assert not bad, bad


def test_tests_import_no_bench_code() -> None:
    """Benchmarks may build on the tests' workloads (tests/workloads), never the reverse."""
    tests = PACKAGE.parent / "tests"
    bad = [
        f"{p.relative_to(tests.parent)} imports {name}"
        for p in sorted(tests.rglob("*.py"))
        for name in sorted(_imports(p))
        if name == "bench" or name.startswith("bench.")
    ]
    assert not bad, bad


def test_no_import_cycles() -> None:
    """No module imports itself through others, counting deferred and type-only imports."""
    assert not _import_cycles(PACKAGE), _import_cycles(PACKAGE)


def test_no_long_functions() -> None:
    assert not _long_functions(PACKAGE), _long_functions(PACKAGE)


def test_every_package_declares_its_api() -> None:
    """Each package lists its public modules and names in ``__all__``; what it leaves out is
    internal, and no module outside the package imports it (tests may)."""
    assert not _packages_without_all(PACKAGE), _packages_without_all(PACKAGE)
    assert not _internal_imports(PACKAGE), _internal_imports(PACKAGE)


def _plant(root: Path, files: dict[str, str]) -> Path:
    package = root / "sarmoco"
    for name, text in files.items():
        path = package / name
        path.parent.mkdir(parents=True, exist_ok=True)
        for parent in [path.parent, *path.parent.parents]:
            if parent == root:
                break
            (parent / "__init__.py").touch()
        path.write_text(text)
    return package


@pytest.mark.parametrize(
    "text",
    [
        "from sarmoco import daemon\n",
        "from ..daemon import config\n",
        "from ..daemon.config import Config\n",
        "import sarmoco.daemon.config as c\n",
        "def f():\n    from sarmoco.daemon import store\n",
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import sarmoco.sim\n",
        "import importlib\nm = importlib.import_module('sarmoco.app.cli')\n",
    ],
)
def test_planted_layering_violation_is_found(tmp_path: Path, text: str) -> None:
    package = _plant(tmp_path, {"processing/bad.py": text, "daemon/config.py": ""})
    assert _layering_violations(package), text


def test_planted_cycle_long_function_and_missing_all_are_found(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    package = _plant(
        tmp_path,
        {
            "sim/a.py": "def f():\n    from sarmoco.sim import b\n",
            "sim/b.py": "from . import a\n",
            "sim/c.py": f"def long():\n{body}\n",
            "__init__.py": "__all__ = ['sim', 'missing']\n",
            "app/cli.py": "from sarmoco.sim import a\n",
        },
    )
    (package / "app" / "__init__.py").write_text("__all__ = ['cli']\n")
    assert _import_cycles(package) == [["sarmoco.sim.a", "sarmoco.sim.b"]]
    assert [s.split()[1] for s in _long_functions(package)] == ["long"]
    assert _packages_without_all(package) == [
        "sarmoco/__init__.py: __all__ names 'missing'",
        "sarmoco/sim/__init__.py: no __all__ list",
    ]
    assert _internal_imports(package) == ["sarmoco/app/cli.py imports sarmoco.sim.a"]


def test_daemon_process_never_loads_the_simulator() -> None:
    """Every daemon module and the command line for ``sarmoco run`` leave ``sarmoco.sim`` out,
    and the ground products with their plotting library; and ``scipy.signal``, whose import
    (with the SciPy packages it pulls in) costs more CPU than the rest of a daemon's start,
    in every ``sarmoco`` process."""
    code = (
        "import pkgutil, sys, importlib\n"
        "import sarmoco.daemon\n"
        "for m in pkgutil.iter_modules(sarmoco.daemon.__path__, 'sarmoco.daemon.'):\n"
        "    importlib.import_module(m.name)\n"
        "from sarmoco.app.cli import build_parser\n"
        "build_parser().parse_args(['run', '--config', 'sarmoco.toml'])\n"
        "sim = ('sarmoco.sim', 'sarmoco.app.sim', 'sarmoco.app.demo', 'sarmoco.products',"
        " 'matplotlib', 'scipy.signal')\n"
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
