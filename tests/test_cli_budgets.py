"""Budgets and progress of the long searches through the CLI (in process): --max-moves,
--max-nodes, --time-limit are reported, not errors; bad budgets are one line and exit 2; the
progress bar only on a terminal."""

from __future__ import annotations

import json
from typing import Any

import pytest
from cli_helpers import MODEL, has

import capalloc_rs
from capalloc_rs import Network
from capalloc_rs.allocation import filtration

# -- budgets and progress of the long searches (issue 12, point 3), in-process ------------------


@pytest.fixture(scope="module")
def moving_model(tmp_path_factory: pytest.TempPathFactory) -> str:
    """A network whose best-schedule search at τ = 0.8, r_tot = 12 makes several moves (see
    tests/test_budgets.py), saved as a model file for the CLI."""
    path = tmp_path_factory.mktemp("budgets") / "moving.npz"
    Network.random(4, seed=11).save(str(path))
    return str(path)


def _main_json(capsys: pytest.CaptureFixture[str], *args: str) -> Any:
    from capalloc_rs.cli import main

    assert main([*args, "--json", "--no-progress"]) == 0
    out = capsys.readouterr()
    assert out.err == ""  # --no-progress: nothing on stderr
    return json.loads(out.out)


def test_schedule_move_budget_is_reported(
    moving_model: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from capalloc_rs.cli import main

    args = ("schedule", moving_model, "--tau", "0.8", "--r-tot", "12")
    full = _main_json(capsys, *args)
    assert (full["converged"], full["stopped"]) == (True, "local_minimum")
    assert full["moves"] >= 2
    part = _main_json(capsys, *args, "--max-moves", "1")
    assert (part["converged"], part["stopped"], part["moves"]) == (False, "max_moves", 1)
    # The same as the API with the same budget (an independent call).
    api = capalloc_rs.best_schedule(
        Network.load(moving_model), 0.8, 12, max_moves=1, progress=False
    )
    assert part["schedule"] == [int(i) for i in api.schedule] and part["eta_bar"] == api.eta_bar
    assert full["eta_bar"] <= part["eta_bar"] < min(part["baselines"].values())
    assert main([*args, "--max-moves", "1", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "converged: False" in text and "stopped early (max_moves)" in text
    assert main([*args, "--time-limit", "1e-9", "--json", "--no-progress"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert (d["converged"], d["stopped"], d["moves"]) == (False, "time_limit", 0)


def test_trace_node_budget_is_reported(capsys: pytest.CaptureFixture[str]) -> None:
    from capalloc_rs.cli import main

    full = _main_json(capsys, "trace", MODEL, "--sigma-max", "6")
    assert (full["converged"], full["stopped"], full["sigma_max"]) == (True, "completed", 6.0)
    part = _main_json(capsys, "trace", MODEL, "--sigma-max", "6", "--max-nodes", "2")
    assert (part["converged"], part["stopped"]) == (False, "max_nodes")
    api = filtration(Network.load(MODEL), 6.0, max_nodes=2, progress=False)
    assert part["sigma_max"] == api.sigma_max < 6.0
    assert part["breakpoints"] == list(api.breakpoints)
    assert main(["trace", MODEL, "--sigma-max", "6", "--max-nodes", "2", "--no-progress"]) == 0
    assert "stopped early (max_nodes)" in capsys.readouterr().out
    d = _main_json(capsys, "trace", MODEL, "--sigma-max", "6", "--time-limit", "1e-9")
    assert (d["converged"], d["stopped"]) == (False, "time_limit")


@pytest.mark.parametrize(
    ("cmd", "option", "value", "words"),
    [
        ("schedule", "--max-moves", "-1", ("--max-moves", "non-negative")),
        ("schedule", "--max-moves", "nan", ("--max-moves", "integer")),
        ("schedule", "--max-moves", "many", ("--max-moves", "integer")),
        ("schedule", "--max-moves", "1.5", ("--max-moves", "integer")),
        ("schedule", "--time-limit", "-1", ("--time-limit", "positive")),
        ("schedule", "--time-limit", "0", ("--time-limit", "positive")),
        ("schedule", "--time-limit", "nan", ("--time-limit", "positive")),
        ("schedule", "--time-limit", "inf", ("--time-limit", "positive")),
        ("schedule", "--time-limit", "soon", ("--time-limit", "number")),
        ("trace", "--max-nodes", "-2", ("--max-nodes", "positive")),
        ("trace", "--max-nodes", "0", ("--max-nodes", "positive")),
        ("trace", "--max-nodes", "nan", ("--max-nodes", "integer")),
        ("trace", "--max-nodes", "two", ("--max-nodes", "integer")),
        ("trace", "--time-limit", "-0.5", ("--time-limit", "positive")),
        ("trace", "--time-limit", "nan", ("--time-limit", "positive")),
        ("trace", "--time-limit", "later", ("--time-limit", "number")),
    ],
)
def test_bad_budgets_are_one_line_and_exit_2(
    cmd: str,
    option: str,
    value: str,
    words: tuple[str, ...],
    capsys: pytest.CaptureFixture[str],
) -> None:
    from capalloc_rs.cli import main

    base = (
        ["trace", MODEL, "--sigma-max", "6"]
        if cmd == "trace"
        else ["schedule", MODEL, "--tau", "0.5", "--r-tot", "7"]
    )
    assert main([*base, f"{option}={value}"]) == 2
    out = capsys.readouterr()
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("capalloc: error: "), out.err
    assert "Traceback" not in out.err and out.out == ""
    for w in words:
        assert w in lines[0], lines[0]


@pytest.mark.skipif(not has("tqdm"), reason="the progress bar needs tqdm")
@pytest.mark.parametrize(
    "args",
    [
        ["trace", MODEL, "--sigma-max", "6"],
        ["schedule", MODEL, "--tau", "0.5", "--r-tot", "7"],
    ],
)
def test_progress_on_a_terminal_and_no_progress(
    args: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from capalloc_rs import _progress
    from capalloc_rs.cli import main

    # stderr "is a terminal": the default progress=None of the API shows a bar through the CLI.
    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: True)
    assert main([*args, "--json"]) == 0
    shown = capsys.readouterr()
    name = "filtration" if args[0] == "trace" else "best_schedule"
    assert name in shown.err and json.loads(shown.out)
    assert main([*args, "--json", "--no-progress"]) == 0
    quiet = capsys.readouterr()
    # the same result either way (but the search's wall time, which to_dict() reports)
    same = [
        {k: v for k, v in json.loads(o).items() if k != "elapsed"} for o in (quiet.out, shown.out)
    ]
    assert quiet.err == "" and same[0] == same[1]
    # Not a terminal: no bar without --no-progress either.
    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: False)
    assert main([*args, "--json"]) == 0
    assert capsys.readouterr().err == ""
