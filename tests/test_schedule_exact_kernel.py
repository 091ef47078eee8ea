"""The exact schedule search of equal-cost slots in the Rust kernel (``exact_impl="rust"``,
``capalloc::sampled::exact_dfs``) against brute force over every feasible schedule and against
the Python tree (``exact_impl="python"``) from the same incumbent, its limits (a valid bound),
and the fact about the boundary figure it relies on (a rotation moves the boundary to another
posterior of the same periodic orbit, so it is no symmetry)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from capalloc_rs import Network, sampled_cost, sampled_covariance
from capalloc_rs.errors import InvalidInputError
from capalloc_rs.sampled import sampled_system, schedule_limits
from capalloc_rs.sampled.exact import exact_search
from capalloc_rs.sampled.exhaustive import _cost
from capalloc_rs.sampled.schedule import Schedule

REL = 1e-10


def _net(n_sensors: int = 3, seed: int = 5, **kw) -> Network:
    rng = np.random.default_rng(seed)
    n = 3
    a = rng.standard_normal((n, n)) * 0.5 - 0.3 * np.eye(n)
    g = rng.standard_normal((n, n)) * 0.4
    sensors = [rng.standard_normal((n, 1)) for _ in range(n_sensors)]
    return Network(a, g, sensors, **{"r_min": 1.0, **kw})


def _feasible(m, lim, lengths):
    n = m.n_sensors
    hi = None if lim.hi is None else np.asarray(lim.hi)
    for length in lengths:
        for s in itertools.product(range(n), repeat=length):
            k = np.bincount(s, minlength=n)
            if np.any(k < np.asarray(lim.lo)) or (hi is not None and np.any(k > hi)):
                continue
            yield Schedule(list(s), n)


def _brute(m, tau, which, lim, lengths) -> float:
    """The least exact cost over every feasible schedule, each costed by the Rust core."""
    return min(_cost(m, tau, s, which, lim) for s in _feasible(m, lim, lengths))


def _both(m, tau, which, lim, node_limit=10**7):
    """Both implementations from the same poor incumbent (the first feasible schedule)."""
    start = next(_feasible(m, lim, [_lengths(m, lim)[-1]]))
    cost = _cost(m, tau, start, which, lim)
    return [
        exact_search(m, tau, which, lim, start, cost, node_limit, math.inf, exact_impl=impl)
        for impl in ("rust", "python")
    ]


def _lengths(m, lim) -> list[int]:
    b = float(m.sample_costs[0])
    top = math.floor(lim.budget / b * (1 + 1e-12))
    if lim.hi is not None:
        top = min(top, sum(lim.hi))
    return list(range(max(1, sum(lim.lo)), top + 1))


CASES = [
    ("random", 3, 7),
    ("random", 3, 9),
    ("random", 4, 7),
]


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize(("kind", "n_sensors", "slots"), CASES)
def test_kernel_equals_brute_force_and_the_python_tree(
    kind: str, n_sensors: int, slots: int, which: str
) -> None:
    net = Network.random(n_sensors, n=2, p=1, eps=0.2, seed=11)
    m = sampled_system(net)
    lim = schedule_limits(m, slots)
    best = _brute(m, 0.2, which, lim, [slots])
    rust, python = _both(m, 0.2, which, lim)
    for ex in (rust, python):
        assert ex.complete
        assert ex.eta_bar == pytest.approx(best, rel=REL)
        assert ex.lower_bound <= best * (1 + REL)
    # The schedule returned is feasible and its cost is its own exact cost.
    assert sorted(set(rust.schedule.slots)) == list(range(n_sensors))
    assert _cost(m, 0.2, rust.schedule, which, lim) == rust.eta_bar


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_kernel_with_weight_minima_caps_and_idle_time(which: str) -> None:
    rng = np.random.default_rng(7)
    x = rng.standard_normal((3, 3))
    cases = [
        (_net(weight=x @ x.T + np.eye(3)), 6.0),  # weighted M, the paper's case
        (_net(r_min=[2.0, 0.0, 1.0], r_max=[3, 2, 6]), 7.0),  # minima and caps
        (_net(costs=[2.0, 2.0, 2.0], r_max=[2, 3, 2]), 13.0),  # equal costs 2, one unit idle
    ]
    for net, budget in cases:
        m = sampled_system(net)
        lim = schedule_limits(m, budget)
        lengths = [round(budget)] if lim.plain else _lengths(m, lim)
        best = _brute(m, 0.4, which, lim, lengths)
        rust, python = _both(m, 0.4, which, lim)
        assert rust.complete and python.complete
        assert rust.eta_bar == pytest.approx(best, rel=REL)
        assert python.eta_bar == pytest.approx(best, rel=REL)
        assert rust.lower_bound <= best * (1 + REL)


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize("limit", [1, 2, 5, 20, 60])
def test_a_node_limit_returns_a_valid_bound(which: str, limit: int) -> None:
    net = _net(n_sensors=4, seed=9)
    m = sampled_system(net)
    lim = schedule_limits(m, 7)
    best = _brute(m, 0.5, which, lim, [7])
    rust, _ = _both(m, 0.5, which, lim, node_limit=limit)
    assert rust.nodes <= limit + m.n_sensors
    assert rust.lower_bound <= best * (1 + REL)
    assert rust.eta_bar >= best * (1 - REL)
    if rust.complete:
        assert rust.eta_bar == pytest.approx(best, rel=REL)


def test_exact_impl_is_validated() -> None:
    net = _net()
    m = sampled_system(net)
    lim = schedule_limits(m, 4)
    s = Schedule([0, 1, 2, 0], 3)
    with pytest.raises(InvalidInputError, match="exact_impl"):
        exact_search(m, 0.2, "boundary", lim, s, 1.0, 10, math.inf, exact_impl="fortran")


def test_a_rotation_moves_the_boundary_to_another_posterior() -> None:
    """η̄_boundary of the rotation starting after slot k is tr Σ_k⁺ of the orbit: the boundary
    figure is not rotation invariant (the reason the kernel uses no symmetry for it)."""
    net = Network.random(3, n=2, p=1, eps=0.2, seed=11)
    slots = [0, 1, 1, 2, 1, 0, 2]
    post = sampled_covariance(net, 0.2, slots).posteriors
    values = []
    for k in range(1, len(slots)):
        rotated = slots[k:] + slots[:k]
        values.append(sampled_cost(net, 0.2, rotated, "boundary"))
        assert values[-1] == pytest.approx(float(np.trace(post[k - 1])), rel=1e-9)
    assert max(values) - min(values) > 1e-3 * min(values)


def test_the_binding_checks_its_arguments() -> None:
    from capalloc_rs import _core

    m = sampled_system(_net())
    with pytest.raises(InvalidInputError, match="relaxed"):
        _core.sampled_exact_schedule(
            m.core, 0.2, 4, "boundary", [], [1] * 3, [4] * 3, 1.0, False, 10
        )
    with pytest.raises(InvalidInputError, match="which"):
        _core.sampled_exact_schedule(m.core, 0.2, 4, "middle", [], [1] * 3, [4] * 3, 1.0, False, 10)
    costly = sampled_system(_net(costs=[1.0, 2.0, 1.0]))
    with pytest.raises(InvalidInputError, match="equal sample costs"):
        _core.sampled_exact_schedule(
            costly.core, 0.2, 4, "boundary", [], [1] * 3, [4] * 3, 1.0, False, 10
        )
