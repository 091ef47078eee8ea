"""``best_schedule(method="exact")`` with **unequal** sample costs (slots of different lengths, a
budget with idle time, per-sensor minima and caps, an error weight) against brute force over
every valid schedule, and every reported lower bound against the brute-force optimum."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from capalloc_rs import Network
from capalloc_rs.sampled import best_schedule, sampled_system, schedule_limits
from capalloc_rs.sampled.exact_grid import grid_exact_search
from capalloc_rs.sampled.relaxation import relaxed_lower_bound
from capalloc_rs.sampled.schedule import Schedule

REL = 1e-10
TAU = 0.4


def _net(costs, seed: int = 5, r_max=None, r_min=1.0, weight=None, n_sensors: int = 3) -> Network:
    rng = np.random.default_rng(seed)
    n = 3
    a = rng.standard_normal((n, n)) * 0.5 - 0.3 * np.eye(n)
    g = rng.standard_normal((n, n)) * 0.4
    sensors = [rng.standard_normal((n, 1)) for _ in range(n_sensors)]
    return Network(a, g, sensors, r_min=r_min, costs=costs, r_max=r_max, weight=weight)


def _all_valid(net: Network, budget: float):
    """Every schedule (any length) whose counts meet the minima and caps and whose slots fit
    the budget."""
    m = sampled_system(net)
    b, lo, hi, n = m.sample_costs, np.asarray(m.min_counts), m.max_counts, m.n_sensors
    for length in range(1, int(budget / b.min() * (1 + 1e-12)) + 1):
        for s in itertools.product(range(n), repeat=length):
            k = np.bincount(s, minlength=n)
            if np.any(k < lo) or (hi is not None and np.any(k > np.asarray(hi))):
                continue
            if float(k @ b) <= budget * (1 + 1e-12):
                yield s


def _brute(net: Network, budget: float, which: str) -> float:
    """The least exact cost over every valid schedule (each costed by the Rust core's
    evaluation of the whole schedule, with the idle rest of the budget)."""
    core = sampled_system(net).core
    best = math.inf
    for s in _all_valid(net, budget):
        best = min(best, float(core.cost(TAU, np.asarray(s, dtype=np.int64), which, budget=budget)))
    return best


CASES = [
    ([1.0, 2.0, 3.0], 8.0, 5),
    ([1.0, 2.0, 3.0], 10.0, 7),
    ([1.0, 2.0, 1.5], 7.0, 6),  # a half-unit grid
    ([3.0, 1.0, 2.0], 9.5, 8),  # half a unit always idle
    ([0.2, 0.1, 0.3], 1.0, 9),  # decimal costs: the grid 1/10 (not a binary fraction)
]


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize(("costs", "budget", "seed"), CASES)
def test_exact_equals_brute_force_with_unequal_costs(
    costs: list[float], budget: float, seed: int, which: str
) -> None:
    net = _net(costs, seed=seed)
    best = _brute(net, budget, which)
    res = best_schedule(net, TAU, budget, which=which, method="exact")
    assert res.proven_optimal and res.gap == 0.0
    assert res.eta_bar == pytest.approx(best, rel=REL)
    # The schedule is valid and its reported cost is its own exact cost.
    m = sampled_system(net)
    assert schedule_limits(m, budget).fits(res.schedule.counts)
    own = m.core.cost(TAU, res.schedule.as_array(), which, budget=budget)
    assert res.eta_bar == pytest.approx(own, rel=1e-12)
    # Every bound is below the optimum: the default one and the local search's.
    assert relaxed_lower_bound(m, TAU, schedule_limits(m, budget), which) <= best
    assert best_schedule(net, TAU, budget, which=which).lower_bound <= best


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_exact_with_costs_minima_caps_and_weight(which: str) -> None:
    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, 3))
    net = _net(
        [1.0, 2.0, 3.0],
        seed=9,
        r_max=[4.0, 2.0, 2.0],
        r_min=[2.0, 1.0, 0.0],
        weight=x @ x.T + 0.1 * np.eye(3),
    )
    best = _brute(net, 9.0, which)
    res = best_schedule(net, TAU, 9.0, which=which, method="exact")
    assert res.proven_optimal
    assert res.eta_bar == pytest.approx(best, rel=REL)
    counts = res.schedule.counts
    assert counts[0] >= 2 and counts[1] >= 1 and counts[0] <= 4 and counts[1] <= 2
    assert res.lower_bound <= best * (1 + REL)
    assert best_schedule(net, TAU, 9.0, which=which).lower_bound <= best


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_a_node_limit_keeps_a_valid_gap_with_costs(which: str) -> None:
    net = _net([1.0, 2.0, 3.0], seed=7)
    best = _brute(net, 10.0, which)
    m = sampled_system(net)
    lim = schedule_limits(m, 10.0)
    start = Schedule([0, 1, 2], 3)
    start_cost = float(m.core.cost(TAU, start.as_array(), which, budget=10.0))
    for limit in (1, 5, 40):
        found = grid_exact_search(m, TAU, which, lim, start, start_cost, limit, math.inf)
        assert found is not None
        schedule, eta, lower, nodes, complete = found
        assert nodes <= limit + 3  # checked before every node's children (3 sensors)
        assert lower <= best and eta >= best * (1 - REL)
        assert not complete or eta == pytest.approx(best, rel=REL)
    cut = best_schedule(net, TAU, 10.0, which=which, method="exact", node_limit=2)
    assert cut.lower_bound <= best
    assert cut.gap >= cut.eta_bar - best - REL * best
