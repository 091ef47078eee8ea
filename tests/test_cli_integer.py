"""``capalloc solve --integer`` with ``--method greedy|branch-and-bound``, ``--time-limit`` and
``--max-nodes`` (the API's numbers, the proven bound in the text output, bad combinations as one
line and exit status 2), and the proven lower bound of ``capalloc schedule`` in its text output."""

from __future__ import annotations

import pytest
from cli_helpers import MODEL, assert_user_error, ok_json, run

from capalloc_rs import Network, best_schedule, integer_allocation


@pytest.mark.parametrize("method", ["greedy", "branch-and-bound"])
def test_integer_method_gives_the_api_result(method: str) -> None:
    net = Network.load(MODEL)
    res = integer_allocation(net, 9, method=method)
    d = ok_json("solve", MODEL, "--r-tot", "9", "--integer", "--method", method)
    assert d["method"] == method and d["counts"] == [int(k) for k in res.counts]
    assert d["eta"] == res.eta and d["lower_bound"] == res.lower_bound
    assert d["proven_optimal"] == res.proven_optimal
    p = run("solve", MODEL, "--r-tot", "9", "--integer", "--method", method)
    assert p.returncode == 0, p.stderr
    assert method in p.stdout and f"lower bound {res.lower_bound:.10g}" in p.stdout
    assert f"gap {res.gap:.3g}" in p.stdout
    assert ("proven optimal" in p.stdout) == res.proven_optimal


def test_integer_default_method_is_greedy() -> None:
    d = ok_json("solve", MODEL, "--r-tot", "9", "--integer")
    assert d["method"] == "greedy"


def test_node_limit_is_reported_not_an_error() -> None:
    net = Network.load(MODEL)
    res = integer_allocation(net, 9, method="branch-and-bound", max_nodes=1)
    args = ("solve", MODEL, "--r-tot", "9", "--integer", "--method", "branch-and-bound")
    d = ok_json(*args, "--max-nodes", "1")
    assert d["nodes"] <= 1 and d["stopped"] == res.stopped
    assert d["lower_bound"] == res.lower_bound and d["gap"] >= 0.0
    p = run(*args, "--max-nodes", "1")
    assert p.returncode == 0, p.stderr
    if res.stopped is not None:
        assert "stopped early (max_nodes)" in p.stdout
    d = ok_json(*args, "--time-limit", "60")
    assert d["proven_optimal"] is True and d["stopped"] is None


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--integer", "--method", "newton"], ("--method newton", "--integer")),
        (["--method", "greedy"], ("--method greedy", "--integer")),
        (["--time-limit", "5"], ("--time-limit", "--integer")),
        (["--max-nodes", "5"], ("--max-nodes", "--integer")),
        (["--integer", "--max-nodes", "5"], ("--max-nodes", "branch-and-bound")),
        (["--integer", "--method", "exhaustive"], ("invalid choice",)),
        (["--integer", "--method", "branch-and-bound", "--max-nodes", "0"], ("--max-nodes",)),
        (["--integer", "--method", "branch-and-bound", "--max-nodes", "1.5"], ("--max-nodes",)),
        (["--integer", "--time-limit", "0"], ("--time-limit",)),
        (["--integer", "--time-limit", "nan"], ("--time-limit",)),
    ],
)
def test_bad_integer_options_are_one_line(extra: list[str], words: tuple[str, ...]) -> None:
    assert_user_error(run("solve", MODEL, "--r-tot", "9", *extra), *words)


def test_robust_refuses_the_integer_search_options() -> None:
    p = run("solve", "--robust", "worst", MODEL, MODEL, "--r-tot", "9", "--time-limit", "5")
    assert_user_error(p, "--time-limit", "--robust")


def test_schedule_text_shows_the_proven_bound() -> None:
    best = best_schedule(Network.load(MODEL), 0.5, 7)
    p = run("schedule", MODEL, "--tau", "0.5", "--r-tot", "7")
    assert p.returncode == 0, p.stderr
    assert f"lower bound   = {best.lower_bound:.10g}" in p.stdout
    assert f"gap = {best.gap:.3g}" in p.stdout
    assert f"proven_optimal: {best.proven_optimal}" in p.stdout
