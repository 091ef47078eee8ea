"""Subnormal, tiny and huge data through every public entry point (capalloc-rs issue 12): each
call returns a correct answer (checked by an independent route, see ``_edge_child.py``) or a
package exception — never a hang, a wrong number or a foreign exception.

The calls run in a child process with a timeout, so that a regression (e.g. the subnormal-Q hang
of Van Loan's integral, ``van_loan(−I, 1e-310·I, 0.7)``) fails the test instead of hanging CI.
The timeout is generous and only guards against hangs; nothing here asserts on wall time.
"""

from __future__ import annotations

import json
import subprocess
import sys
from functools import cache
from pathlib import Path

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import errors, limits

CHILD = Path(__file__).with_name("_edge_child.py")
#: Guard against hangs only: every group takes well under a second when it works.
HANG_TIMEOUT = 300

SCALES = ("4.94066e-324", "1e-310", "1e-300", "1e+300")
C_SCALES = ("1e-155", "1e-150", "1e+150")


@cache
def run_group(group: str) -> dict[str, str]:
    try:
        proc = subprocess.run(
            [sys.executable, str(CHILD), group],
            capture_output=True,
            text=True,
            timeout=HANG_TIMEOUT,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"the {group} edge cases did not finish in {HANG_TIMEOUT} s: a hang")
    assert proc.returncode == 0, proc.stderr[-3000:]
    result: dict[str, str] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def cases(group: str, names: tuple[str, ...], scales: tuple[str, ...]) -> list[object]:
    out: list[object] = []
    for name in names:
        for s in scales:
            case = f"{name}@{s}"
            # Tiny-Q cases (care@1e-300, cost_tiny_q@1e-160) once returned wrong numbers
            # silently; the refined CARE gets them right (each outcome is checked exactly).
            out.append(pytest.param(group, case, id=case))
    return out


def check(group: str, case: str) -> None:
    outcome = run_group(group)[case]
    assert outcome == "ok" or outcome.startswith("error:"), outcome


LINALG = (
    "van_loan",
    "van_loan_identity",
    "expm",
    "solve_continuous_lyapunov",
    "solve_sylvester",
    "schur",
    "care",
    "solve_continuous_are",
)


@pytest.mark.parametrize(("group", "case"), cases("linalg", LINALG, SCALES))
def test_linalg_entry_points(group: str, case: str) -> None:
    check(group, case)


def test_van_loan_subnormal_q_is_exact_not_refused() -> None:
    # The issue's call must give the answer, not merely an error.
    for s in ("4.94066e-324", "1e-310"):
        assert run_group("linalg")[f"van_loan_identity@{s}"] == "ok"
        assert run_group("linalg")[f"van_loan@{s}"] == "ok"


@pytest.mark.parametrize(
    ("group", "case"),
    cases("network", ("cost", "gradient", "optimal_allocation"), C_SCALES)
    + cases("network", ("cost_tiny_q",), ("1e-150", "1e-160")),
)
def test_network_entry_points(group: str, case: str) -> None:
    check(group, case)


@pytest.mark.parametrize(
    ("group", "case"),
    cases("sampled", ("sampled_cost", "best_schedule", "simulate"), C_SCALES),
)
def test_sampled_entry_points(group: str, case: str) -> None:
    check(group, case)


@pytest.mark.parametrize("case", ["issue_sampled_cost", "issue_best_schedule", "issue_simulate"])
def test_issue_model_with_subnormal_q(case: str) -> None:
    # Network(A, 1e-160·I, [e1, e2]) used to hang sampled_cost, best_schedule and simulate.
    assert run_group("sampled")[case] == "ok"


# ------------------------------------------------------------------- work refused up front


def test_state_dimension_is_refused_up_front() -> None:
    with pytest.raises(errors.InvalidInputError, match="MAX_STATE_DIMENSION"):
        capalloc_rs.Network.random(1, n=10**9)
    with pytest.raises(errors.InvalidInputError, match="MAX_STATE_DIMENSION"):
        capalloc_rs.Network.random(3, n=[2, 10**9, 2])
    with pytest.raises(errors.InvalidInputError, match="MAX_SENSORS"):
        capalloc_rs.Network.random(10**9)


def test_state_dimension_limit_is_overridable(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(limits, "MAX_STATE_DIMENSION", 3)
    capalloc_rs.Network.random(1, n=3, seed=1)
    with pytest.raises(errors.InvalidInputError, match="MAX_STATE_DIMENSION"):
        capalloc_rs.Network.random(1, n=4, seed=1)
    with pytest.raises(errors.InvalidInputError, match="state dimension n = 4"):
        capalloc_rs.Network(-np.eye(4), np.eye(4), [np.ones(4)])


def test_slots_per_period_are_refused_up_front(monkeypatch: pytest.MonkeyPatch) -> None:
    net = capalloc_rs.Network.random(2, seed=1)
    # `capalloc schedule MODEL --tau 0.5 --r-tot 1e300` used to spin here.
    with pytest.raises(errors.InvalidInputError, match="MAX_SLOTS_PER_PERIOD"):
        capalloc_rs.best_schedule(net, 0.5, int(1e300))
    with pytest.raises(errors.InvalidInputError, match="MAX_SLOTS_PER_PERIOD"):
        capalloc_rs.Schedule.round_robin(2, 10**12)
    with pytest.raises(errors.InvalidInputError, match="MAX_SLOTS_PER_PERIOD"):
        capalloc_rs.Schedule.from_counts([10**12, 1])
    monkeypatch.setattr(limits, "MAX_SLOTS_PER_PERIOD", 5)
    with pytest.raises(errors.InvalidInputError, match="MAX_SLOTS_PER_PERIOD"):
        capalloc_rs.sampled_cost(net, 0.5, [0, 1, 0, 1, 0, 1])
    assert capalloc_rs.sampled_cost(net, 0.5, [0, 1, 0, 1]) > 0
