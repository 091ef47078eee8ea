"""``capalloc simulate --time-limit SECONDS --no-progress`` and the Monte Carlo's ``time_limit``.

The budget covers the whole command (the schedule search of ``--r-tot``, then the Monte Carlo);
hitting it is reported like ``trace``/``schedule`` report theirs: exit status 0, ``converged:
False``, ``stopped: time_limit`` and one ``stopped early (time_limit)`` line. A limit of 1e-9 s is
used up by the time of the first check (after the set-up), deterministically — what the existing
budget tests of ``trace`` and ``schedule`` rely on as well."""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import Network, errors
from capalloc_rs.cli import build_parser, main

MODEL = str(Path(__file__).resolve().parent.parent / "examples" / "three_subsystems.toml")
PKG_ROOT = str(Path(capalloc_rs.__file__).resolve().parent.parent)
SCHED = ("simulate", MODEL, "--tau", "0.5", "--schedule", "0,1,2,1,2")
SMALL = ("--periods", "20", "--runs", "8", "--seed", "3")


MC = sys.modules.get("capalloc_rs.sampled.montecarlo")


def _json(capsys: pytest.CaptureFixture[str], *args: str) -> Any:
    assert main([*args, "--json", "--no-progress"]) == 0
    out = capsys.readouterr()
    assert out.err == ""  # --no-progress: nothing on stderr
    return json.loads(out.out)


def test_options_parse() -> None:
    args = build_parser().parse_args([*SCHED, "--time-limit", "2.5", "--no-progress"])
    assert (args.time_limit, args.no_progress) == (2.5, True)
    args = build_parser().parse_args(list(SCHED))
    assert (args.time_limit, args.no_progress) == (None, False)


def test_generous_limit_changes_nothing(capsys: pytest.CaptureFixture[str]) -> None:
    free = _json(capsys, *SCHED, *SMALL)
    timed = _json(capsys, *SCHED, *SMALL, "--time-limit", "3600")
    assert timed == free
    assert (free["converged"], free["stopped"], free["periods_completed"]) == (
        True,
        "completed",
        20,
    )
    # The numbers are the API's (an independent call with the same seed).
    mc = capalloc_rs.simulate(
        Network.load(MODEL), 0.5, capalloc_rs.Schedule([0, 1, 2, 1, 2], 3), 20, 3, runs=8
    )
    assert free["mse"] == mc.mse and mc.stopped == "completed" and mc.converged


def test_time_limit_stops_the_monte_carlo(capsys: pytest.CaptureFixture[str]) -> None:
    d = _json(capsys, *SCHED, *SMALL, "--time-limit", "1e-9")
    assert (d["converged"], d["stopped"], d["periods_completed"]) == (False, "time_limit", 0)
    assert d["mse"] is None and d["ci"] == [None, None] and d["schedule"] == [0, 1, 2, 1, 2]
    assert d["eta_bar"] > 0  # the exact prediction is still computed
    assert main([*SCHED, *SMALL, "--time-limit", "1e-9", "--no-progress"]) == 0
    out = capsys.readouterr()
    assert out.err == ""
    stops = [ln for ln in out.out.splitlines() if "stopped early" in ln]
    assert stops == ["  stopped early (time_limit): Monte Carlo over 0 of 20 periods "
                     "(raise --time-limit to simulate them all)"]  # fmt: skip
    assert "converged: False" in out.out


def test_time_limit_covers_the_schedule_search(capsys: pytest.CaptureFixture[str]) -> None:
    args = ("simulate", MODEL, "--tau", "0.8", "--r-tot", "12", *SMALL)
    d = _json(capsys, *args, "--time-limit", "1e-9")
    assert (d["converged"], d["stopped"], d["mse"]) == (False, "time_limit", None)
    assert d["source"] == "best" and d["periods_completed"] == 0
    # The schedule is the search's best after its starting candidates, as the API gives it
    # for the same budget.
    part = capalloc_rs.best_schedule(Network.load(MODEL), 0.8, 12, time_limit=1e-9, progress=False)
    assert part.stopped == "time_limit" and d["schedule"] == [int(i) for i in part.schedule]
    assert main([*args, "--time-limit", "1e-9", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert [ln for ln in text.splitlines() if "stopped early" in ln] == [
        "  stopped early (time_limit) in the schedule search: the best schedule found so far, "
        "no Monte Carlo run (raise --time-limit)"
    ]


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "abc", ""])
def test_bad_time_limit_is_one_line_exit_2(value: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*SCHED, *SMALL, f"--time-limit={value}"]) == 2
    out = capsys.readouterr()
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("capalloc: error: "), out.err
    assert "--time-limit" in lines[0] and out.out == ""


def test_bad_time_limit_in_a_real_process_has_no_traceback() -> None:
    env = dict(os.environ)
    env["PYTHONPATH"] = PKG_ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("CAPALLOC_TRACEBACK", None)
    p = subprocess.run(
        [sys.executable, "-m", "capalloc_rs.cli", *SCHED, "--time-limit", "abc"],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert p.stderr.strip().splitlines() == [
        "capalloc: error: simulate: argument --time-limit: expected a number, got 'abc' "
        "(see capalloc simulate --help)"
    ]


# -- the API: montecarlo.simulate(time_limit=, progress=) --------------------------------------


def _net_sched() -> tuple[Any, Any]:
    return Network.load(MODEL), capalloc_rs.Schedule([0, 1, 2, 1, 2], 3)


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_stopped_monte_carlo_is_the_run_over_the_completed_periods(
    which: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The module's clock replaced by one that advances one second per reading: the start reads
    # 1000, the check before period k (k = 0, 1, …) 1001 + k, so with time_limit = 6.5 exactly
    # 6 periods run (deterministic).
    simulate = capalloc_rs.simulate
    mod = sys.modules[simulate.__module__]
    clock = itertools.count(1000.0)
    monkeypatch.setattr(mod, "time", SimpleNamespace(monotonic=lambda: float(next(clock))))
    net, sched = _net_sched()
    part = simulate(net, 0.5, sched, 40, 11, runs=6, which=which, time_limit=6.5, progress=False)
    monkeypatch.undo()
    assert (part.stopped, part.converged, part.periods, part.periods_completed) == (
        "time_limit",
        False,
        40,
        6,
    )
    # Independent route: the same seed and 6 periods without a limit draws the same noise.
    full = simulate(net, 0.5, sched, 6, 11, runs=6, which=which, progress=False)
    assert full.stopped == "completed" and full.periods_completed == 6
    assert part.mse == full.mse and (part.ci_low, part.ci_high) == (full.ci_low, full.ci_high)
    np.testing.assert_array_equal(part.per_slot, full.per_slot)


def test_monte_carlo_progress_and_burn_in(monkeypatch: pytest.MonkeyPatch) -> None:
    simulate = capalloc_rs.simulate
    net, sched = _net_sched()
    seen: list[dict[str, Any]] = []
    mc = simulate(net, 0.5, sched, 5, 1, runs=4, burn_in=2, progress=seen.append)
    assert [d["period"] for d in seen] == [1, 2, 3, 4, 5, 6, 7] and "elapsed" in seen[0]
    assert mc.periods_completed == 5
    # A budget used up during the burn-in: no recorded period, NaN estimates.
    mod = sys.modules[simulate.__module__]
    clock = itertools.count(0.0)
    monkeypatch.setattr(mod, "time", SimpleNamespace(monotonic=lambda: float(next(clock))))
    early = simulate(net, 0.5, sched, 5, 1, runs=4, burn_in=2, time_limit=1.5, progress=False)
    monkeypatch.undo()
    assert (early.stopped, early.periods_completed) == ("time_limit", 0)
    assert np.isnan(early.mse) and not early.contains(early.predicted)


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), "soon"])
def test_monte_carlo_bad_time_limit(bad: Any) -> None:
    net, sched = _net_sched()
    with pytest.raises(errors.InvalidInputError, match="time_limit"):
        capalloc_rs.simulate(net, 0.5, sched, 5, 1, runs=4, time_limit=bad)
