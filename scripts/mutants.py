#!/usr/bin/env python3
"""A small mutation-testing runner for the files a change touches (not run in CI).

Why this module is long: one tool — mutation operators, the runner with its timeouts, the report.

Each *mutant* is the source file with one small, bug-like change; the chosen tests are run against
it, and a mutant the tests still pass on ("survivor") marks an untested behaviour — or a change
that is equivalent (argue that in docs/mutation-testing.md). Usage::

    scripts/mutants.py python/capalloc_rs/allocation.py --only _armijo,integer_allocation \\
        --tests "tests/test_line_search.py tests/test_allocation_scalar.py"
    scripts/mutants.py rust/sampled/doubling.rs --only doubling --cargo "sampled::"
    scripts/mutants.py python/capalloc_rs/filtration.py --list        # just show the mutants

Python files (``.py``) are mutated on the syntax tree (``ast``): comparison operators flipped
(``<``↔``<=``, ``<``↔``>``, ``==``↔``!=``, ``in``↔``not in``, ``is``↔``is not``), arithmetic
``+``↔``-``, ``*``↔``/``, ``and``↔``or``, ``not x``→``x``, ``-x``→``x``, augmented ``+=``↔``-=``
and ``&=``→``|=``, numeric constants ``n``→``n+1``/``n−1`` (integers) or ``x``→``2x``/``0``
(floats; tiny division guards such as ``1e-300`` are left alone), ``True``↔``False``, and a
dropped ``raise`` (→ ``pass``). Docstrings and annotations are not mutated. Each mutant is
written with ``ast.unparse`` into a temporary copy of ``python/`` (with the built extension) that
comes first on ``PYTHONPATH``; the working tree is never touched and can be edited meanwhile.
Then ``python -m pytest -x -q TESTS`` runs. Build the extension first (``maturin develop``) so
that the copy has a current ``_core``.

Rust files (``.rs``) are mutated in place (restored after every run, on Ctrl-C and on SIGTERM; do
not edit the file meanwhile), token by token in code only (comments, string literals and
``#[cfg(test)]`` modules are masked): spaced comparison operators (rustfmt's layout, so generics
are left alone), ``==``↔``!=``, ``&&``↔``||``, spaced ``+ - * /``, ``+=``↔``-=``, numeric
literals. Each mutant runs ``cargo test --lib --quiet FILTER`` (``--cargo``); a mutant that does
not compile counts as killed. If ``cargo mutants`` is installed, ``--cargo-mutants`` hands the
file to it instead (``cargo mutants --file F``), which knows Rust's syntax and also replaces
whole function bodies.

``--only NAME[,NAME]`` restricts the mutants to the bodies of those functions (Python: def names;
Rust: ``fn`` names, by brace matching), ``--lines A-B`` to a line range. Exit status 0 when every
mutant was killed (or timed out), 1 when some survived, 2 on bad usage or when the tests fail
without any mutation. ``--json OUT`` writes the full result list.

Timeouts: a mutant can turn a loop into one that never ends (``h *= 0.25`` → ``h /= 0.25`` grows a
step that should shrink). Each test run is therefore given ``--timeout SECONDS``; when it is
exceeded the whole test process group (pytest or cargo and everything they started) is killed and
the mutant counts as **killed (timeout)** — a change that makes the tests hang is detected, as in
mutmut and cargo-mutants. Before the mutants, the tests are run once on the unmutated file (the
baseline: it must pass, else every mutant would look killed); the default timeout is
``max(180, 5 × baseline)`` seconds — a few minutes for the subsets the runner is meant for.
"""

from __future__ import annotations

import argparse
import ast
import atexit
import copy
import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class Mutant:
    file: str
    line: int
    col: int
    description: str
    key: int  # index into the file's mutant list
    status: str = "pending"  # killed / survived / timeout / error
    seconds: float = 0.0


# ------------------------------------------------------------------------------------- Python

_CMP_SWAPS: dict[type[ast.cmpop], list[type[ast.cmpop]]] = {
    ast.Lt: [ast.LtE, ast.Gt],
    ast.LtE: [ast.Lt, ast.GtE],
    ast.Gt: [ast.GtE, ast.Lt],
    ast.GtE: [ast.Gt, ast.LtE],
    ast.Eq: [ast.NotEq],
    ast.NotEq: [ast.Eq],
    ast.In: [ast.NotIn],
    ast.NotIn: [ast.In],
    ast.Is: [ast.IsNot],
    ast.IsNot: [ast.Is],
}
_BIN_SWAPS: dict[type[ast.operator], type[ast.operator]] = {
    ast.Add: ast.Sub,
    ast.Sub: ast.Add,
    ast.Mult: ast.Div,
    ast.Div: ast.Mult,
    ast.FloorDiv: ast.Div,
    ast.Pow: ast.Mult,
    ast.BitAnd: ast.BitOr,
}
_SYMBOL = {
    ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!=",
    ast.In: "in", ast.NotIn: "not in", ast.Is: "is", ast.IsNot: "is not", ast.Add: "+",
    ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.FloorDiv: "//", ast.Pow: "**",
    ast.BitAnd: "&", ast.BitOr: "|", ast.And: "and", ast.Or: "or",
}  # fmt: skip


def _docstring_ids(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            if isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
                out.add(id(body[0].value))
    return out


def _annotation_ids(tree: ast.AST) -> set[int]:
    out: set[int] = set()
    for node in ast.walk(tree):
        anns = []
        if isinstance(node, ast.AnnAssign):
            anns.append(node.annotation)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            anns.append(node.returns)
            a = node.args
            for arg in [*a.posonlyargs, *a.args, *a.kwonlyargs, a.vararg, a.kwarg]:
                if arg is not None:
                    anns.append(arg.annotation)
        for ann in anns:
            if ann is not None:
                out.update(id(n) for n in ast.walk(ann))
    return out


def _in_scope(node: ast.AST, spans: list[tuple[int, int]] | None) -> bool:
    if spans is None:
        return True
    line = getattr(node, "lineno", None)
    return line is not None and any(a <= line <= b for a, b in spans)


def _python_spans(tree: ast.AST, only: list[str] | None, lines: tuple[int, int] | None):
    if only is None and lines is None:
        return None
    spans = []
    if lines is not None:
        spans.append(lines)
    if only:
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name in only:
                spans.append((node.lineno, node.end_lineno or node.lineno))
    return spans


def _python_sites(tree: ast.AST, spans) -> Iterator[tuple[ast.AST, str, object]]:
    """Yields ``(node, description, how)`` for every mutation of ``tree`` in scope, in a
    deterministic order (``ast.walk``), so that a fresh parse reproduces them."""
    skip = _docstring_ids(tree) | _annotation_ids(tree)
    for node in ast.walk(tree):
        if id(node) in skip or not _in_scope(node, spans):
            continue
        if isinstance(node, ast.Compare):
            for k, op in enumerate(node.ops):
                for new in _CMP_SWAPS.get(type(op), []):
                    yield node, f"{_SYMBOL[type(op)]} -> {_SYMBOL[new]}", ("cmp", k, new)
        elif isinstance(node, (ast.BinOp, ast.AugAssign)):
            new = _BIN_SWAPS.get(type(node.op))
            if new is not None:
                aug = "=" if isinstance(node, ast.AugAssign) else ""
                yield node, f"{_SYMBOL[type(node.op)]}{aug} -> {_SYMBOL[new]}{aug}", ("bin", new)
        elif isinstance(node, ast.BoolOp):
            new_b = ast.Or if isinstance(node.op, ast.And) else ast.And
            yield node, f"{_SYMBOL[type(node.op)]} -> {_SYMBOL[new_b]}", ("bool", new_b)
        elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.Not, ast.USub)):
            yield node, f"drop unary {'not' if isinstance(node.op, ast.Not) else '-'}", ("unary",)
        elif isinstance(node, ast.Raise):
            yield node, "raise -> pass", ("raise",)
        elif isinstance(node, ast.Constant):
            v = node.value
            if isinstance(v, bool):
                yield node, f"{v} -> {not v}", ("const", not v)
            elif isinstance(v, int):
                yield node, f"{v} -> {v + 1}", ("const", v + 1)
                yield node, f"{v} -> {v - 1}", ("const", v - 1)
            elif isinstance(v, float):
                if 0.0 < abs(v) < 1e-100:
                    continue  # a division guard such as max(x, 1e-300): mutants are equivalent
                if v == 0.0:
                    yield node, "0.0 -> 1.0", ("const", 1.0)
                else:
                    yield node, f"{v!r} -> {2 * v!r}", ("const", 2 * v)
                    yield node, f"{v!r} -> 0.0", ("const", 0.0)


class _Apply(ast.NodeTransformer):
    def __init__(self, target: ast.AST, how: tuple) -> None:
        self.target, self.how = target, how

    def visit(self, node: ast.AST) -> ast.AST:
        if node is not self.target:
            return self.generic_visit(node)
        kind = self.how[0]
        if kind == "cmp":
            assert isinstance(node, ast.Compare)
            node.ops[self.how[1]] = self.how[2]()
        elif kind == "bin":
            node.op = self.how[1]()  # type: ignore[attr-defined]
        elif kind == "bool":
            node.op = self.how[1]()  # type: ignore[attr-defined]
        elif kind == "unary":
            return node.operand  # type: ignore[attr-defined]
        elif kind == "raise":
            return ast.Pass()
        elif kind == "const":
            node.value = self.how[1]  # type: ignore[attr-defined]
        return node


def python_mutants(path: Path, only, lines) -> list[tuple[Mutant, str]]:
    src = path.read_text()
    tree = ast.parse(src)
    spans = _python_spans(tree, only, lines)
    out = []
    for key, (node, desc, how) in enumerate(_python_sites(tree, spans)):
        fresh = copy.deepcopy(tree)
        # Locate the same node in the copy: walk order is preserved by deepcopy.
        pairs = dict(zip(map(id, ast.walk(tree)), ast.walk(fresh), strict=True))
        mutated = _Apply(pairs[id(node)], how).visit(fresh)
        ast.fix_missing_locations(mutated)
        code = ast.unparse(mutated)
        m = Mutant(str(path.relative_to(ROOT)), node.lineno, node.col_offset, desc, key)
        out.append((m, code + "\n"))
    out.sort(key=lambda mc: (mc[0].line, mc[0].col, mc[0].key))
    return out


# --------------------------------------------------------------------------------------- Rust

_RS_TOKENS = [
    (r"(?<=\s)<=(?=\s)", ["<"]),
    (r"(?<=\s)>=(?=\s)", [">"]),
    (r"(?<=\s)<(?=\s)", ["<="]),  # spaced: comparisons (rustfmt), not generics
    (r"(?<=\s)>(?=\s)", [">="]),
    (r"==", ["!="]),
    (r"!=", ["=="]),
    (r"&&", ["||"]),
    (r"\|\|", ["&&"]),
    (r"(?<=\s)\+(?=\s)", ["-"]),
    (r"(?<=\s)-(?=\s)", ["+"]),
    (r"(?<=\s)\*(?=\s)", ["/"]),
    (r"(?<=\s)/(?=\s)", ["*"]),
    (r"\+=", ["-="]),
    (r"-=", ["+="]),
]
_RS_NUM = re.compile(r"(?<![\w.])(\d+\.\d+(?:e-?\d+)?|\d+e-?\d+|\d+)(?![\w.])")


def _rust_code_lines(src: list[str], only, lines) -> list[int]:
    """Indices of lines eligible for mutation: not comments, not in a ``#[cfg(test)]`` item, inside
    the ``--only`` functions and ``--lines`` range when given."""
    ok = [True] * len(src)
    depth_skip = None
    depth = 0
    pending_test = False
    fn_spans: list[tuple[int, int]] = []
    fn_start = None
    fn_depth = 0
    for i, line in enumerate(src):
        code = line.split("//", 1)[0]
        if line.strip().startswith("#[cfg(test)]"):
            pending_test = True
        if only and fn_start is None:
            m = re.search(r"\bfn\s+(\w+)", code)
            if m and m.group(1) in only:
                fn_start, fn_depth = i, depth
        opens, closes = code.count("{"), code.count("}")
        if pending_test and opens:
            depth_skip, pending_test = depth, False
        if depth_skip is not None:
            ok[i] = False
        depth += opens - closes
        if depth_skip is not None and depth <= depth_skip and closes:
            depth_skip = None
        if fn_start is not None and depth <= fn_depth and (opens or closes) and i > fn_start:
            fn_spans.append((fn_start, i))
            fn_start = None
        if not code.strip() or line.lstrip().startswith(("//", "#", "use ")):
            ok[i] = False
    out = []
    for i in range(len(src)):
        if not ok[i]:
            continue
        if lines is not None and not (lines[0] <= i + 1 <= lines[1]):
            continue
        if only and not any(a <= i <= b for a, b in fn_spans):
            continue
        out.append(i)
    return out


def _rust_mask(text: str) -> str:
    """``text`` with comments and the contents of string and char literals blanked (newlines
    kept), so that operators and numbers are only found in code, also across multi-line strings."""
    out = list(text)
    i, n = 0, len(text)
    while i < n:
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out[i:j] = " " * (j - i)
            i = j
        elif text[i] == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            for k in range(i, min(j + 1, n)):
                if out[k] != "\n":
                    out[k] = " "
            i = j + 1
        elif text[i] == "'" and i + 2 < n and (text[i + 2] == "'" or text[i + 1] == "\\"):
            j = text.find("'", i + 2 if text[i + 1] == "\\" else i + 1)
            out[i : j + 1] = " " * (j + 1 - i)
            i = j + 1
        else:
            i += 1
    return "".join(out)


def rust_mutants(path: Path, only, lines) -> list[tuple[Mutant, str]]:
    text = path.read_text()
    src = text.splitlines(keepends=True)
    masked_lines = _rust_mask(text).splitlines(keepends=True)
    out = []
    key = 0
    for i in _rust_code_lines(src, only, lines):
        line = src[i]
        masked = masked_lines[i]
        edits: list[tuple[int, int, str, str]] = []
        for pat, repls in _RS_TOKENS:
            for m in re.finditer(pat, masked):
                for r in repls:
                    edits.append((m.start(), m.end(), r, f"{m.group(0)} -> {r}"))
        for m in _RS_NUM.finditer(masked):
            tok = m.group(0)
            if "." in tok or "e" in tok:
                v = float(tok)
                new = "1.0" if v == 0 else repr(2 * v)
            else:
                new = str(int(tok) + 1)
            edits.append((m.start(), m.end(), new, f"{tok} -> {new}"))
        for a, b, r, desc in sorted(edits):
            mutated = src.copy()
            mutated[i] = line[:a] + r + line[b:]
            m = Mutant(str(path.relative_to(ROOT)), i + 1, a, desc, key)
            out.append((m, "".join(mutated)))
            key += 1
    return out


# ------------------------------------------------------------------------------------- runner


def _run(cmd: list[str], timeout: float, env: dict[str, str]) -> str:
    # A fresh bytecode cache per mutant: a stale .pyc of the same size and second never runs.
    cache = tempfile.mkdtemp(prefix="mutants-pyc-")
    try:
        return _run_in(cmd, timeout, {**env, "PYTHONPYCACHEPREFIX": cache})
    finally:
        shutil.rmtree(cache, ignore_errors=True)


def _run_in(cmd: list[str], timeout: float, env: dict[str, str]) -> str:
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    try:
        rc = proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        return "timeout"
    except BaseException:  # Ctrl-C: stop the test run too (it is in its own session)
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
    return "survived" if rc == 0 else "killed"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", type=Path)
    ap.add_argument("--tests", default="tests", help="pytest arguments for .py mutants")
    ap.add_argument("--cargo", default="", help="cargo test --lib filter for .rs mutants")
    ap.add_argument("--only", help="comma-separated function names")
    ap.add_argument("--lines", help="A-B: only this line range")
    ap.add_argument(
        "--timeout",
        type=float,
        default=None,
        help="seconds per test run; a mutant whose tests run longer is killed (timeout) "
        "(default: max(180, 5 × the unmutated baseline run))",
    )
    ap.add_argument("--list", action="store_true", help="list the mutants, run nothing")
    ap.add_argument("--json", type=Path, help="write every result here")
    ap.add_argument("--python", default=sys.executable, help="interpreter for pytest")
    ap.add_argument("--cargo-mutants", action="store_true", help="delegate .rs to cargo mutants")
    args = ap.parse_args(argv)
    if args.timeout is not None and not args.timeout > 0:
        ap.error(f"--timeout must be a positive number of seconds, got {args.timeout}")

    def interrupted(signum: int, frame: object) -> None:
        raise KeyboardInterrupt  # SIGTERM too: run the finally blocks that restore files

    signal.signal(signal.SIGTERM, interrupted)
    signal.signal(signal.SIGINT, interrupted)  # also when started in the background
    only = args.only.split(",") if args.only else None
    lines = tuple(int(v) for v in args.lines.split("-")) if args.lines else None
    env = dict(os.environ)
    env.setdefault("CARGO_TERM_COLOR", "never")
    # Python mutants are written into a private copy of python/ (with the built extension), put
    # first on PYTHONPATH: the working tree is never modified, so work can go on meanwhile.
    scratch = Path(tempfile.mkdtemp(prefix="mutants-"))
    shutil.copytree(
        ROOT / "python", scratch / "python", ignore=shutil.ignore_patterns("__pycache__")
    )
    atexit.register(shutil.rmtree, scratch, True)
    env_py = {**env, "PYTHONPATH": str(scratch / "python") + os.pathsep + env.get("PYTHONPATH", "")}
    if any(f.suffix == ".py" for f in args.files) and not args.list:
        where = subprocess.run(
            [args.python, "-c", "import capalloc_rs; print(capalloc_rs.__file__)"],
            env=env_py, capture_output=True, text=True, check=False,
        )  # fmt: skip
        if not where.stdout.startswith(str(scratch)):
            print(f"mutants: the tests would not import the mutated copy: {where}", file=sys.stderr)
            return 2

    results: list[Mutant] = []
    for f in args.files:
        path = (ROOT / f).resolve() if not f.is_absolute() else f
        if not path.is_file() or path.suffix not in (".py", ".rs"):
            print(f"mutants: {f}: not a .py or .rs file", file=sys.stderr)
            return 2
        if path.suffix == ".rs" and args.cargo_mutants:
            if shutil.which("cargo-mutants") is None:
                print("mutants: cargo-mutants is not installed", file=sys.stderr)
                return 2
            cmd = ["cargo", "mutants", "--file", str(path.relative_to(ROOT)), "--", "--lib"]
            print("$", shlex.join(cmd))
            subprocess.run(cmd, cwd=ROOT, check=False)
            continue
        muts = (python_mutants if path.suffix == ".py" else rust_mutants)(path, only, lines)
        if path.suffix == ".py":
            cmd = [args.python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider"]
            cmd += shlex.split(args.tests)
        else:
            cmd = ["cargo", "test", "--lib", "--quiet", *shlex.split(args.cargo)]
        print(f"{path.relative_to(ROOT)}: {len(muts)} mutants; tests: {shlex.join(cmd)}")
        if args.list:
            for m, _ in muts:
                print(f"  {m.file}:{m.line}:{m.col}  {m.description}")
            continue
        target = path
        if path.suffix == ".py":
            try:
                target = scratch / path.relative_to(ROOT)
            except ValueError:
                print(f"mutants: {f}: not inside {ROOT}", file=sys.stderr)
                return 2
        run_env = env_py if path.suffix == ".py" else env
        # Baseline: the tests must pass on the unmutated file; their time sets the timeout.
        t0 = time.monotonic()
        base = _run(cmd, args.timeout or 3600.0, run_env)
        baseline = time.monotonic() - t0
        if base != "survived":
            print(f"mutants: the tests fail without any mutation ({base}): fix them first",
                  file=sys.stderr)  # fmt: skip
            return 2
        timeout = args.timeout if args.timeout is not None else max(180.0, 5.0 * baseline)
        print(f"  baseline passed in {baseline:.1f} s; timeout per mutant {timeout:.0f} s")
        original = target.read_bytes()
        try:
            for n, (m, code) in enumerate(muts, 1):
                target.write_text(code)
                t0 = time.monotonic()
                m.status = _run(cmd, timeout, run_env)
                m.seconds = round(time.monotonic() - t0, 1)
                results.append(m)
                shown = "killed (timeout)" if m.status == "timeout" else m.status
                print(f"  [{n}/{len(muts)}] {shown:8s} {m.file}:{m.line}  {m.description}")
                sys.stdout.flush()
        finally:
            target.write_bytes(original)
    if args.list:
        return 0
    survivors = [m for m in results if m.status == "survived"]
    killed = sum(m.status in ("killed", "timeout") for m in results)
    if results:
        timeouts = sum(m.status == "timeout" for m in results)
        print(
            f"\n{killed}/{len(results)} killed ({100 * killed / len(results):.0f} %; "
            f"{timeouts} of them by the timeout)"
        )
    for m in survivors:
        print(f"SURVIVED {m.file}:{m.line}:{m.col}  {m.description}")
    if args.json:
        args.json.write_text(json.dumps([asdict(m) for m in results], indent=1))
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
