"""The weighted sampled cost ``η̄_M = tr(M Σ̄)``: against the fixed point of the slot maps with
``M``, Corollary 1 (``→ η_M(counts) = net.cost``), Monte Carlo, the search, and the weighted
sensitivity of the screened search (the adjoint Stein equation with right-hand side ``M``)
against finite differences of ``η̄_M`` — with and without sample costs and idle time."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from _sampled_reference import fixed_point

from capalloc_rs import Network, best_schedule, sampled_cost, sampled_covariance, simulate
from capalloc_rs.sampled import round_robin_schedule, sampled_system


def _weight(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, n))
    return x @ x.T / n + 0.1 * np.eye(n)


def _net(costs=None, extra: list[tuple[int, float, float]] = (), seed: int = 5) -> Network:
    """A 3-state network with 3 sensors and a weight; ``extra``: near-copies ``(i, scale,
    cost)`` of sensor ``i`` appended (for finite differences)."""
    rng = np.random.default_rng(seed)
    n = 3
    a = rng.standard_normal((n, n)) * 0.5 - 0.3 * np.eye(n)
    g = rng.standard_normal((n, n)) * 0.4
    sensors = [rng.standard_normal((n, 1)) for _ in range(3)]
    cs = list(costs) if costs is not None else [1.0] * 3
    for i, scale, cost in extra:
        sensors.append(sensors[i] * scale)
        cs.append(cost)
    return Network(a, g, sensors, r_min=1.0, costs=cs, weight=_weight(n))


@pytest.mark.parametrize(("costs", "budget"), [(None, None), ([1.0, 2.0, 0.5], 10.0)])
def test_weighted_cost_matches_the_fixed_point_with_m(costs, budget) -> None:
    net = _net(costs)
    slots = [0, 1, 2, 0, 2, 1]
    cs = [float(b) for b in net.costs]
    b = budget if budget is not None else sum(cs[i] for i in slots)
    q = net.g @ net.g.T
    ref = fixed_point(net.a, q, list(net.sensors), cs, 0.4, slots, b, weight=net.error_weight)
    for which, want in zip(("boundary", "average"), ref, strict=True):
        assert sampled_cost(net, 0.4, slots, which, budget=budget) == pytest.approx(want, rel=1e-10)
    cov = sampled_covariance(net, 0.4, slots, budget=budget)
    assert cov.eta_boundary == pytest.approx(float(np.sum(net.error_weight * cov.boundary)))


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_weighted_corollary_1(which) -> None:
    """η̄_M → η_M(counts) = tr(M Σ(counts)) as τ → 0, first order."""
    net = _net([1.0, 2.0, 0.5])
    slots = [2, 0, 1, 2, 0, 2]
    limit = net.cost([2.0, 1.0, 3.0])
    errs = [
        abs(sampled_cost(net, t, slots, which, budget=7.0) - limit)
        for t in (0.01, 0.005, 0.0025, 0.00125)
    ]
    orders = np.log2(np.asarray(errs[:-1]) / np.asarray(errs[1:]))
    assert np.all(np.abs(orders - 1.0) < 0.1), orders


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_weighted_monte_carlo_contains_tr_m_sigma(which) -> None:
    net = _net([1.0, 2.0, 0.5])
    mc = simulate(net, 0.4, [0, 1, 2, 0], 600, seed=3, runs=16, which=which, budget=6.0)
    assert mc.contains(sampled_cost(net, 0.4, [0, 1, 2, 0], which, budget=6.0))


def test_weighted_search_beats_round_robin() -> None:
    net = _net()
    res = best_schedule(net, 0.4, 7, progress=False)
    rr = sampled_cost(net, 0.4, round_robin_schedule(net, 7))
    assert res.eta_bar <= rr * (1 + 1e-12)


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize(
    ("costs", "budget", "extra_cost"),
    [
        (None, None, 1.0),  # unit slots, no idle time
        ([1.0, 2.0, 0.5, 0.5], 10.0, 0.5),  # unequal slots, idle tail, the same length
        ([1.0, 2.0, 0.5, 0.5], 10.0, "shift"),  # the copy's slot is longer by ε (tail shorter)
    ],
)
def test_weighted_sensitivity_matches_finite_differences(which, costs, budget, extra_cost) -> None:
    """The screen's predicted change of a reassignment to a near-copy of the slot's sensor (ĉ
    scaled by 1 + ε, or the same ĉ with a cost larger by ε) is the derivative of η̄_M: it
    matches the exact change to O(ε²)."""
    slots = [0, 1, 2, 0, 2, 1]
    pos = 4  # slot 4 carries sensor 2
    for eps in (1e-4, 5e-5):
        if extra_cost == "shift":
            extra = [(2, 1.0, 0.5 + eps)]
        else:
            extra = [(2, 1.0 + eps, float(extra_cost))]
        cs = None if costs is None else costs[:3]
        full = _net(cs, extra)
        # The near-copy has no sample in the schedule: a duck-typed network with r_min = 0.
        net = SimpleNamespace(
            A=full.a,
            G=full.g,
            sensors=full.sensors,
            r_min=0.0,
            costs=full.costs,
            error_weight=full.error_weight,
        )
        m = sampled_system(net)
        kw = {} if budget is None else {"budget": budget}
        sc = m.core.screen(0.4, np.asarray(slots, dtype=np.int64), which, 1, **kw)
        moved = list(slots)
        moved[pos] = 3
        exact = sampled_cost(net, 0.4, moved, which, **kw) - sampled_cost(
            net, 0.4, slots, which, **kw
        )
        predicted = float(np.asarray(sc.reassign)[pos, 3])
        assert abs(exact) > 1e-9
        assert predicted == pytest.approx(exact, rel=5 * eps)
