"""The ``capalloc`` command line never shows a traceback (issue 12 points 3 and 6).

* hypothesis draws argument lists from a vocabulary of subcommands, options and malformed values
  and runs :func:`capalloc_rs.cli.main` in process: status 0 or 2, and on 2 exactly one line
  ``capalloc: error: …`` on stderr (with ``--json`` also an error object on stdout);
* a closed stdout pipe (``capalloc demo | head -2``) ends quietly with status 0;
* Ctrl-C ends with status 130 and one line.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import capalloc_rs  # noqa: E402
from capalloc_rs.cli import main  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
MODEL = str(EXAMPLES / "three_subsystems.toml")
PKG_ROOT = str(Path(capalloc_rs.__file__).resolve().parent.parent)


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("CAPALLOC_TRACEBACK", None)
    return env


def check_outcome(code: int, out: str, err: str, as_json: bool) -> None:
    assert "Traceback" not in err and "Traceback" not in out
    assert code in (0, 2), (code, err)
    if code == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("capalloc: error: "), err
        if as_json:
            e = json.loads(out.strip().splitlines()[-1])["error"]
            assert e["message"] and e["type"]


# Values a user may type. Valid-but-huge work (e.g. a million Monte Carlo periods) is left out:
# the fuzz is about malformed input, each call must stay small.
VALUES = [
    "5",
    "4",
    "0.5",
    "0",
    "-1",
    "-3.5",
    "nan",
    "inf",
    "-inf",
    "1e309",
    "1" * 5000,
    "100000000000",
    "",
    " ",
    "abc",
    "0x10",
    "1,2",
    "0,1,0,2",
    "0,,1",
    "7,7",
    "-1,0",
    "0,1,99999999999999999999999",
    "\x00",
    "é",
]
OPTIONS = [
    "--r-tot",
    "--tau",
    "--sigma-max",
    "--periods",
    "--runs",
    "--seed",
    "--tol",
    "--method",
    "--hessian",
    "--which",
    "--schedule",
    "--plot",
    "--integer",
    "--no-plot",
    "--json",
    "--bogus",
]
COMMANDS = ["check", "solve", "trace", "schedule", "simulate", "demo", "frobnicate", ""]
MODELS = [MODEL, "/nonexistent/model.toml", str(EXAMPLES), "model.txt", ""]


@st.composite
def argv(draw: st.DrawFn) -> list[str]:
    cmd = draw(st.sampled_from(COMMANDS))
    args = [cmd] if cmd else []
    if cmd in ("check", "solve", "trace", "schedule", "simulate"):
        args.append(draw(st.sampled_from(MODELS)))
    for _ in range(draw(st.integers(0, 5))):
        opt = draw(st.sampled_from(OPTIONS))
        args.append(opt)
        if opt not in ("--integer", "--no-plot", "--json") and draw(st.booleans()):
            args.append(draw(st.sampled_from(VALUES)))
    if cmd == "demo" and "--no-plot" not in args:
        args.append("--no-plot")  # the demo would write a plot into the working directory
    if "--plot" in args:
        args = [a for a in args if a != "--plot"]
    return args


@settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(args=argv())
def test_random_command_lines_never_show_a_traceback(
    args: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(args)
    out, err = capsys.readouterr()
    check_outcome(code, out, err, "--json" in args)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["simulate", MODEL, "--tau", "0.5", "--r-tot", "4", "--runs", "100000000000"], "runs"),
        (["simulate", MODEL, "--tau", "0.5", "--r-tot", "4", "--periods", "10000000000"], "MAX"),
        (["solve", MODEL, "--r-tot", "1e309"], "positive"),
        (["solve", MODEL, "--r-tot", "1" * 5000], "5000 characters"),
        (["simulate", MODEL, "--tau", "0.5", "--r-tot", "4", "--runs", "1" * 400], "finite"),
        (["solve", MODEL, "--r-tot", "1e300", "--integer"], "r_tot"),
        (["simulate", MODEL, "--tau", "0.5", "--schedule", "0,1,99999999999999999999"], "sensor"),
    ],
)
def test_argument_sizes(args: list[str], words: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Regressions: these ended in MemoryError/OverflowError tracebacks."""
    assert main(args) == 2
    out, err = capsys.readouterr()
    check_outcome(2, out, err, False)
    assert words in err


def test_json_errors_go_to_stdout_as_well(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solve", MODEL, "--r-tot", "2", "--json"]) == 2
    out, err = capsys.readouterr()
    e = json.loads(out)["error"]
    assert e["type"] == "InvalidInputError" and "infeasible" in e["message"]
    assert err.strip() == f"capalloc: error: {e['message']}"
    assert main(["solve", MODEL, "--json"]) == 2  # a usage error
    out, err = capsys.readouterr()
    e = json.loads(out)["error"]
    assert e["type"] == "UsageError" and "--r-tot" in e["message"]
    assert err.strip() == f"capalloc: error: {e['message']}"


# -- closed pipes -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "args", [["demo", "--no-plot"], ["demo", "--no-plot", "--json"], ["check", MODEL]]
)
def test_closed_stdout_pipe_ends_quietly(args: list[str], tmp_path: Path) -> None:
    """stdout is a pipe whose reader has gone before anything is written: every write fails with
    EPIPE. The command ends with status 0 and says nothing (like other Unix tools)."""
    r, w = os.pipe()
    os.close(r)
    try:
        p = subprocess.run(
            [sys.executable, "-m", "capalloc_rs.cli", *args],
            env=_env(),
            cwd=tmp_path,
            stdout=w,
            stderr=subprocess.PIPE,
            text=True,
            timeout=300,
        )
    finally:
        os.close(w)
    assert p.returncode == 0, p.stderr
    assert p.stderr == ""


def test_demo_piped_into_head(tmp_path: Path) -> None:
    """``capalloc demo | head -2``: the demo's status is 0 and nothing is on stderr."""
    script = (
        f"{sys.executable} -m capalloc_rs.cli demo --no-plot 2>{tmp_path / 'err'} | head -2; "
        'echo "status=${PIPESTATUS[0]}"'
    )
    p = subprocess.run(
        ["bash", "-c", script],
        env=_env(),
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = p.stdout.strip().splitlines()
    assert lines[-1] == "status=0", p.stdout
    assert len(lines) == 3 and lines[0].startswith("capalloc demo")
    assert (tmp_path / "err").read_text() == ""


# -- Ctrl-C ---------------------------------------------------------------------------------------

_HELD = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    import capalloc_rs.cli.allocation as solve_command  # the module of `capalloc solve`
    from capalloc_rs.cli import main

    def held(*args, **kwargs):  # the ready marker, then "a long computation"
        Path(sys.argv[1]).write_text("running")
        while True:
            time.sleep(0.01)

    solve_command.optimal_allocation = held
    sys.exit(main(sys.argv[2:]))
    """
)


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_ctrl_c_exits_130_with_one_line(tmp_path: Path, json_flag: list[str]) -> None:
    ready = tmp_path / "ready"
    proc = subprocess.Popen(
        [sys.executable, "-c", _HELD, str(ready), "solve", MODEL, "--r-tot", "5", *json_flag],
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 300  # guards against a hung child only
        while not ready.exists():
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=60)
    assert proc.returncode == 130
    assert err == "capalloc: interrupted\n"
    assert out == ""
