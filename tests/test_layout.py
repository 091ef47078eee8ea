"""The package's shape, enforced: layering (import-linter contract in pyproject.toml), no import
cycles between modules, no ``importlib`` lookups, and the 500-line rule for modules
(``scripts/check_module_size.py``)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGE = REPO / "python" / "capalloc_rs"

grimp = pytest.importorskip("grimp", reason="import-linter (the dev extra) is not installed")


def _graph() -> object:
    return grimp.build_graph("capalloc_rs")


def test_layers_contract_holds() -> None:
    """model (network) → algorithms (allocation, sampled) → sweeps → CLI, over a base of helpers."""
    code = (
        "import sys; from importlinter.cli import lint_imports_command; "
        "sys.exit(lint_imports_command())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, "--no-cache", "--config", str(REPO / "pyproject.toml")],
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]


def _cycles(graph: object) -> list[list[str]]:
    """Every import cycle between modules of the package (Tarjan's strongly connected
    components of size > 1, or a module importing itself)."""
    modules = sorted(m for m in graph.modules if m != "capalloc_rs")  # type: ignore[attr-defined]
    # Edges into the root package are `from .. import _core` (see the test on root imports).
    edges = {
        m: sorted(set(graph.find_modules_directly_imported_by(m)) - {"capalloc_rs"})  # type: ignore[attr-defined]
        for m in modules
    }
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, []):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))
    for m in modules:
        if m not in index:
            visit(m)
    return found


def test_no_import_cycles_between_modules() -> None:
    assert _cycles(_graph()) == []


def _root_imports(path: Path) -> list[str]:
    """Names a module takes from the root package (``from .. import x``, ``from capalloc_rs
    import x``)."""
    rel = path.relative_to(PACKAGE).with_suffix("")
    depth = len(rel.parts)  # `from .` in a package's __init__ is the package itself
    names = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.ImportFrom):
            continue
        root = (node.level == depth and node.module is None) or (
            node.level == 0 and node.module == "capalloc_rs"
        )
        if root:
            names += [a.name for a in node.names]
    return names


def test_root_package_gives_only_modules() -> None:
    """Below the root package, `from .. import x` takes a module (or the extension's version),
    never a name re-exported by the root's __init__ — which would import every layer and hide
    upward imports from the layers contract."""
    allowed = {p.stem for p in PACKAGE.glob("*.py")} | {
        p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()
    }
    allowed |= {"_core", "__version__"}
    bad = {
        str(p.relative_to(REPO)): sorted(set(_root_imports(p)) - allowed)
        for p in PACKAGE.rglob("*.py")
        if p.parent != PACKAGE or p.name != "__init__.py"
    }
    assert {k: v for k, v in bad.items() if v} == {}


def test_no_importlib_lookups() -> None:
    """Functions are imported, not looked up by name (``_optional`` imports optional third-party
    dependencies, the one legitimate use)."""
    offenders = [
        str(p.relative_to(REPO))
        for p in PACKAGE.rglob("*.py")
        if "importlib" in p.read_text(encoding="utf-8") and p.name != "_optional.py"
    ]
    assert offenders == []


def test_no_module_over_500_lines_without_a_reason() -> None:
    out = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "check_module_size.py")],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stdout
