"""Issue 13, point 4, sweeps: a sweep from a plain script (no ``if __name__ == "__main__":``)
falls back to threads with one warning, and an in-memory sweep runs without pyarrow."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from cli_helpers import MODEL, child_env

import capalloc_rs as ca

# -- 6. sweeps from a plain script, and without pyarrow -------------------------------------------

_SCRIPT = """
import capalloc_rs as ca
net = ca.Network.load({model!r})
table = ca.sweep([net, {model!r}], [6.0, 8.0], workers=2, progress=False)
print("ROWS", [(r["task_id"], r["eta"], r["error"]) for r in table.to_pylist()])
"""


def _run_script(
    tmp_path: Path, text: str, *blocked_modules: str
) -> subprocess.CompletedProcess[str]:
    script = tmp_path / "tutorial.py"
    hook = (
        (
            "import sys\n"
            "class _B:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            f"        if name.split('.')[0] in {blocked_modules!r}:\n"
            "            raise ImportError(name)\n"
            "sys.meta_path.insert(0, _B())\n"
        )
        if blocked_modules
        else ""
    )
    script.write_text(hook + text)
    return subprocess.run(
        [sys.executable, str(script)],
        env=child_env(),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _rows(p: subprocess.CompletedProcess[str]) -> list[tuple[str, float, Any]]:
    assert p.returncode == 0, p.stderr
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("ROWS ")]
    assert len(line) == 1, p.stdout
    rows: list[tuple[str, float, Any]] = eval(line[0][5:])  # our own repr of plain values
    return rows


def _expected_etas() -> list[float]:
    net = ca.Network.load(MODEL)
    return [ca.optimal_allocation(net, r).eta for r in (6.0, 8.0)] * 2


def test_sweep_from_an_unguarded_script_falls_back_to_threads(tmp_path: Path) -> None:
    p = _run_script(tmp_path, _SCRIPT.format(model=MODEL))
    rows = _rows(p)
    assert [e for _, _, e in rows] == [None] * 4
    assert [eta for _, eta, _ in rows] == pytest.approx(_expected_etas(), rel=1e-9)
    warns = [ln for ln in p.stderr.splitlines() if "UnguardedMainWarning" in ln]
    assert len(warns) == 1, p.stderr
    assert "tutorial.py:4" in warns[0] and "if __name__" in warns[0] and "threads" in warns[0]
    # guarded: worker processes, no warning, the same rows
    body = _SCRIPT.format(model=MODEL).strip().splitlines()
    guarded = "\n".join([body[0], 'if __name__ == "__main__":'] + ["    " + b for b in body[1:]])
    q = _run_script(tmp_path, guarded + "\n")
    assert _rows(q) == rows
    assert "UnguardedMainWarning" not in q.stderr


def test_unguarded_call_detection() -> None:
    import ast

    from capalloc_rs.sweep.mainguard import _is_main_guard, unguarded_call

    def first(src: str) -> ast.stmt:
        return ast.parse(src).body[0]

    assert _is_main_guard(first('if __name__ == "__main__":\n    pass'))
    assert _is_main_guard(first("if '__main__' == __name__:\n    pass"))
    assert not _is_main_guard(first('if __name__ != "__main__":\n    pass'))
    assert not _is_main_guard(first("if True:\n    pass"))
    assert unguarded_call() is None  # under pytest, no script's top level is running


def test_sweep_in_memory_without_pyarrow(tmp_path: Path) -> None:
    text = _SCRIPT.format(model=MODEL) + (
        "print(type(table).__name__, table.num_rows, table.column('error').null_count)\n"
        "try:\n"
        "    ca.sweep([net], [6.0], out='o', progress=False)\n"
        "except ca.MissingDependencyError as exc:\n"
        "    print('OUT', exc)\n"
        "try:\n"
        "    table.to_pandas()\n"
        "except ImportError as exc:\n"
        "    print('PANDAS', type(exc).__name__, exc)\n"
    )
    guarded = 'if __name__ == "__main__":\n' + "\n".join(
        "    " + ln for ln in text.strip().splitlines()
    )
    p = _run_script(tmp_path, guarded + "\n", "pyarrow", "pandas")
    rows = _rows(p)
    assert [eta for _, eta, _ in rows] == pytest.approx(_expected_etas(), rel=1e-9)
    assert "RowTable 4 4" in p.stdout
    assert "OUT pyarrow is not installed" in p.stdout and "capalloc-rs[sweep]" in p.stdout
    assert "PANDAS MissingDependencyError pandas" in p.stdout
    assert not (tmp_path / "o").exists()
    if importlib.util.find_spec("pyarrow") is not None:  # the same rows as the pyarrow table
        net = ca.Network.load(MODEL)
        t = ca.sweep([net, MODEL], [6.0, 8.0], executor=ca.SerialExecutor(), progress=False)
        assert [(r["task_id"], r["eta"], r["error"]) for r in t.to_pylist()] == rows
