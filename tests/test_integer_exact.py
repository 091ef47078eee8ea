"""Exact integer counts (issue 16, point 1): branch-and-bound on the convex relaxation against
brute force (every feasible integer point enumerated and costed, N ≤ 5), in the paper's case and
with costs, minima and caps, coupled up to ε = 0.3 and with a weighted error ``tr(MΣ)``; the
proven lower bound is checked against the enumerated optimum, the counts against today's greedy,
and the node and time limits against feasibility and the validity of the gap."""

from __future__ import annotations

import itertools
import time
from typing import Any

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs import errors
from capalloc_rs.allocation.integer_budget import count_limits
from capalloc_rs.network.constructors import random_blocks

BB = "branch-and-bound"


def _network(seed: int, eps: float, weighted: bool, limits: bool) -> tuple[Any, float]:
    """A random block network (2 to 5 subsystems of order 1 or 2, couplings of strength ``eps``),
    optionally with a weight ``M`` and with costs, minima and caps; and a small budget."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 6))
    a, g, c, coupling, e, _ = random_blocks(n, list(rng.integers(1, 3, n)), 1, eps, seed, 1.0)
    dim = sum(x.shape[0] for x in a)
    weight = None
    if weighted:
        w = rng.normal(size=(dim, dim))
        weight = w @ w.T / dim + 0.1 * np.eye(dim)
    if not limits:
        net = cr.Network.from_blocks(a, g, c, coupling, e, 1.0, weight=weight)
        return net, float(n + int(rng.integers(1, 10 - n + 1)))
    costs = rng.choice([0.5, 1.0, 1.5, 2.0], n)
    r_min = rng.choice([0.5, 1.0, 2.0], n)
    r_max = np.where(rng.random(n) < 0.4, r_min + rng.integers(1, 4, n), np.inf)
    net = cr.Network.from_blocks(
        a, g, c, coupling, e, r_min, weight=weight, costs=costs, r_max=r_max
    )
    k_lo, _ = count_limits(net)
    return net, float(costs @ k_lo + rng.uniform(0.5, 5.0))


def _feasible(net: Any, r_tot: float) -> np.ndarray:
    """Every feasible integer point (by enumeration of the box, filtered)."""
    if net.is_paper_form:
        n, total = len(net.sensors), int(r_tot)
        k_lo = max(1, int(np.ceil(net.r_min - 1e-12)))
        rows = [p for p in itertools.product(range(k_lo, total + 1), repeat=n) if sum(p) == total]
        return np.array(rows, dtype=np.int64)
    b = np.asarray(net.costs)
    k_lo, k_hi = count_limits(net)
    top = np.minimum(k_hi, k_lo + np.floor((r_tot - b @ k_lo) / b + 1e-9).astype(int))
    rows = [
        p
        for p in itertools.product(*[range(lo, hi + 1) for lo, hi in zip(k_lo, top, strict=True)])
        if b @ np.array(p) <= r_tot * (1 + 1e-12)
    ]
    return np.array(rows, dtype=np.int64)


def _brute(net: Any, r_tot: float) -> tuple[np.ndarray, float]:
    pts = _feasible(net, r_tot)
    vals = np.array([net.cost(p.astype(float)) for p in pts])
    i = int(np.argmin(vals))
    return pts[i], float(vals[i])


def _is_feasible(net: Any, counts: np.ndarray, r_tot: float) -> bool:
    if net.is_paper_form:
        return int(counts.sum()) == int(r_tot) and bool(np.all(counts >= 1))
    b = np.asarray(net.costs)
    k_lo, k_hi = count_limits(net)
    inside = bool(np.all(counts >= k_lo) and np.all(counts <= k_hi))
    return inside and float(b @ counts) <= r_tot * (1 + 1e-12)


CASES = [
    (seed, eps, weighted, limits)
    for seed in range(6)
    for eps in (0.0, 0.1, 0.3)
    for weighted, limits in ((False, False), (True, False), (False, True), (True, True))
]


@pytest.mark.parametrize(("seed", "eps", "weighted", "limits"), CASES)
def test_branch_and_bound_equals_brute_force(
    seed: int, eps: float, weighted: bool, limits: bool
) -> None:
    net, r_tot = _network(seed, eps, weighted, limits)
    best_k, best = _brute(net, r_tot)
    res = cr.integer_allocation(net, r_tot, method=BB)
    assert res.method == "branch-and-bound" and res.stopped is None
    assert _is_feasible(net, np.asarray(res.counts), r_tot)
    assert res.eta == pytest.approx(net.cost(np.asarray(res.counts, dtype=float)), rel=1e-12)
    # The same optimum as brute force (the counts too, unless two points tie within 1e-9).
    assert res.eta <= best + 1e-9 * abs(best)
    if res.eta > best + 1e-12 * abs(best):
        assert res.eta - best <= res.tolerance
    # The proven bound: below the enumerated optimum, and the gap closed to its tolerance.
    assert res.lower_bound <= best + 1e-12 * abs(best)
    assert res.gap >= 0.0
    assert res.gap >= res.eta - best - 1e-12 * abs(best)
    assert res.proven_optimal and res.gap <= res.tolerance
    greedy = cr.integer_allocation(net, r_tot, method="greedy")
    assert res.eta <= greedy.eta
    assert greedy.lower_bound <= best + 1e-12 * abs(best) and greedy.gap >= 0.0
    assert greedy.method == "greedy" and greedy.nodes == 1
    if res.eta > best:  # a tie within the tolerance: the brute-force point is as good
        assert net.cost(best_k.astype(float)) <= res.eta


@pytest.mark.parametrize("seed", range(4))
def test_node_limit_returns_a_feasible_incumbent_with_a_valid_gap(seed: int) -> None:
    net, r_tot = _network(seed, 0.3, True, seed % 2 == 1)
    _, best = _brute(net, r_tot)
    greedy = cr.integer_allocation(net, r_tot, method="greedy")
    res = cr.integer_allocation(net, r_tot, method=BB, max_nodes=1)
    assert res.nodes <= 1
    assert _is_feasible(net, np.asarray(res.counts), r_tot)
    assert res.eta <= greedy.eta
    assert res.lower_bound <= best + 1e-12 * abs(best)
    assert res.gap >= 0.0 and res.gap >= res.eta - best - 1e-12 * abs(best)
    assert res.proven_optimal == (res.gap <= res.tolerance)
    if not res.proven_optimal:
        assert res.stopped == "max_nodes"


def test_a_passed_deadline_still_gives_feasible_counts_and_a_valid_bound() -> None:
    net = cr.Network.random(4, 2, eps=0.3, seed=7)
    _, best = _brute(net, 10)
    res = cr.integer_allocation(net, 10, method=BB, deadline=time.monotonic() - 1.0)
    assert _is_feasible(net, np.asarray(res.counts), 10)
    assert res.lower_bound <= best + 1e-12 * abs(best) and res.gap >= 0.0
    assert res.stopped in (None, "time_limit")
    res = cr.integer_allocation(net, 10, method=BB, time_limit=1e-9)
    assert _is_feasible(net, np.asarray(res.counts), 10)
    assert res.lower_bound <= best + 1e-12 * abs(best) and res.gap >= 0.0


def test_larger_coupled_case_is_never_worse_than_greedy_and_bound_holds() -> None:
    net = cr.Network.random(8, 2, eps=0.2, seed=11)
    greedy = cr.integer_allocation(net, 24, method="greedy")
    res = cr.integer_allocation(net, 24, method=BB)
    assert res.eta <= greedy.eta and res.proven_optimal and res.stopped is None
    assert greedy.lower_bound <= res.lower_bound <= res.eta
    cont = cr.optimal_allocation(net, 24.0)
    # The integer optimum is above the continuous one (the root relaxation's bound).
    assert res.lower_bound >= cont.eta - cont.optimality - 1e-12 * cont.eta


def test_result_fields_and_dict() -> None:
    net = cr.Network.random(3, 2, eps=0.1, seed=1)
    res = cr.integer_allocation(net, 7, method=BB)
    d = res.to_dict()
    for key in ("lower_bound", "gap", "proven_optimal", "tolerance", "method", "nodes", "stopped"):
        assert key in d
    assert d["proven_optimal"] is True and d["method"] == "branch-and-bound"
    assert "gap=" in repr(res) and "\n" not in repr(res)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"method": "exhaustive"}, "method"),
        ({"method": 3}, "method"),
        ({"tol": 0.0}, "tol"),
        ({"tol": 1.0}, "tol"),
        ({"tol": float("nan")}, "tol"),
        ({"max_nodes": 0}, "max_nodes"),
        ({"max_nodes": 2.5}, "max_nodes"),
        ({"time_limit": 0.0}, "time_limit"),
        ({"time_limit": -1.0}, "time_limit"),
        ({"start": "best"}, "start"),
        ({"start": None}, "start"),
    ],
)
def test_bad_keywords_name_the_argument(kwargs: dict[str, Any], name: str) -> None:
    net = cr.Network.random(3, 2, eps=0.1, seed=1)
    with pytest.raises(errors.InvalidInputError, match=name):
        cr.integer_allocation(net, 7, **kwargs)


@pytest.mark.parametrize(("n", "eps", "seed"), [(10, 0.05, 3), (10, 0.3, 5), (20, 0.05, 3)])
def test_branch_and_bound_from_the_rounded_start_is_never_worse_than_greedy(
    n: int, eps: float, seed: int
) -> None:
    """The branch-and-bound starts from the rounded continuous optimum and screened exchanges,
    not from the greedy: on these sizes it still ends no worse than greedy-plus-exchanges, and
    proven optimal."""
    net = cr.Network.random(n, 2, eps=eps, seed=seed)
    greedy = cr.integer_allocation(net, 3 * n, method="greedy")
    res = cr.integer_allocation(net, 3 * n, method=BB)
    assert res.eta <= greedy.eta and res.proven_optimal and res.stopped is None
    assert greedy.lower_bound <= res.lower_bound <= res.eta
    assert res.eta == net.cost(np.asarray(res.counts, dtype=float))


@pytest.mark.parametrize("seed", range(6))
def test_screened_start_improves_the_rounding_exactly(seed: int) -> None:
    """The screened exchanges accept only exact improvements: the start is feasible, its η is
    the cost of its counts and at most the rounded relaxed optimum's (with the budget filled)."""
    from capalloc_rs.allocation import integer as integer_mod
    from capalloc_rs.allocation.branch_and_bound import root_bound
    from capalloc_rs.allocation.integer_budget import ExchangeSearch
    from capalloc_rs.allocation.integer_relaxation import round_relaxed
    from capalloc_rs.allocation.integer_screened import rounded_start

    net, r_tot = _network(seed, 0.3, seed % 2 == 0, seed % 3 == 0)
    if net.is_paper_form:
        prob = integer_mod._paper_problem(net, int(r_tot))
    else:
        prob = integer_mod._budget_problem(net, r_tot)
    root, _ = root_bound(prob)
    assert root is not None
    search = ExchangeSearch(net, prob.b, prob.budget, prob.k_hi)
    k0 = round_relaxed(prob, root.r)
    k0, eta0 = search.fill(k0, float(search.eta(k0[None, :])[0]), None)
    k, eta, _ = rounded_start(prob, search, root.r, None)
    assert _is_feasible(net, k, r_tot)
    assert eta == pytest.approx(net.cost(k.astype(float)), rel=1e-12)
    assert eta <= eta0


@pytest.mark.parametrize("seed", range(4))
def test_the_greedy_start_stays_selectable(seed: int) -> None:
    """``start="greedy"`` (the greedy-plus-exchanges incumbent) proves the same optimum as the
    default rounded start; its evaluations include the greedy's."""
    net, r_tot = _network(seed, 0.3, seed % 2 == 0, seed % 3 == 0)
    _, best = _brute(net, r_tot)
    greedy = cr.integer_allocation(net, r_tot, method="greedy")
    res = cr.integer_allocation(net, r_tot, method=BB, start="greedy")
    rounded = cr.integer_allocation(net, r_tot, method=BB)
    assert res.method == "branch-and-bound" and res.proven_optimal and res.stopped is None
    assert res.eta <= greedy.eta and res.evaluations >= greedy.evaluations
    assert res.lower_bound <= best + 1e-12 * abs(best)
    assert abs(res.eta - rounded.eta) <= max(res.tolerance, rounded.tolerance)
