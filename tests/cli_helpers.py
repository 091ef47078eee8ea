"""Helpers shared by the command-line tests: the example model, running ``capalloc`` in a real
subprocess, and the checks of its two outcomes (JSON on stdout, or one error line with status 2)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import capalloc_rs

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
MODEL = str(EXAMPLES / "three_subsystems.toml")
PKG_ROOT = str(Path(capalloc_rs.__file__).resolve().parent.parent)
#: τ at which two eigenvalues of the example's A alias (their imaginary parts differ by 2π/τ).
ALIASING_TAU = 1.5787309228252024


def has(module: str) -> bool:
    """Whether an optional dependency can be imported."""
    try:
        __import__(module)
    except ImportError:
        return False
    return True


def child_env() -> dict[str, str]:
    """The environment of a child Python: this source tree first on the path, no traceback
    switch."""
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("CAPALLOC_TRACEBACK", None)
    return env


def run(
    *args: str, cwd: Path | None = None, timeout: float = 300
) -> subprocess.CompletedProcess[str]:
    """``python -m capalloc_rs.cli ARGS`` in a child process (:func:`child_env`)."""
    return subprocess.run(
        [sys.executable, "-m", "capalloc_rs.cli", *args],
        env=child_env(),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def ok_json(*args: str, cwd: Path | None = None) -> Any:
    """The parsed ``--json`` output of a command that must succeed."""
    p = run(*args, "--json", cwd=cwd)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def assert_user_error(p: subprocess.CompletedProcess[str], *words: str) -> str:
    """Exit status 2 and exactly one ``capalloc: error: …`` line naming every word (returned)."""
    assert p.returncode == 2, (p.returncode, p.stdout, p.stderr)
    assert "Traceback" not in p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1, p.stderr
    assert lines[0].startswith("capalloc: error: ")
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]
