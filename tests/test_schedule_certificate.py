"""How good is a schedule: the exact branch-and-bound (``best_schedule(method="exact")``) against
brute force over every feasible schedule, and the proven lower bound (``lower_bound``, ``gap``)
against the brute-force optimum and against the searched schedules of larger networks."""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import pytest

from capalloc_rs import Network, sampled_cost, sampled_covariance
from capalloc_rs.errors import InvalidInputError
from capalloc_rs.sampled import best_schedule, sampled_system, schedule_limits
from capalloc_rs.sampled.relaxation import (
    Triplet,
    _period,
    _power,
    dominating_information,
    power_from_zero,
    relaxed_lower_bound,
    relaxed_period,
)

REL = 1e-10


def _net(costs=None, r_max=None, weight=None, seed: int = 5, n_sensors: int = 3) -> Network:
    rng = np.random.default_rng(seed)
    n = 3
    a = rng.standard_normal((n, n)) * 0.5 - 0.3 * np.eye(n)
    g = rng.standard_normal((n, n)) * 0.4
    sensors = [rng.standard_normal((n, 1)) for _ in range(n_sensors)]
    return Network(a, g, sensors, r_min=1.0, costs=costs, r_max=r_max, weight=weight)


def _feasible(net: Network, budget: float, plain: bool):
    """Every feasible schedule (brute force): the paper's case exactly ``budget`` slots, else
    every length whose counts are within the limits and whose units fit the budget."""
    m = sampled_system(net)
    b = m.sample_costs
    lo = m.min_counts
    hi = m.max_counts
    n = m.n_sensors
    lengths = [round(budget)] if plain else range(1, int(budget / b.min()) + 1)
    for length in lengths:
        for s in itertools.product(range(n), repeat=length):
            k = np.bincount(s, minlength=n)
            if np.any(k < lo) or (hi is not None and np.any(k > np.asarray(hi))):
                continue
            if float(k @ b) <= budget * (1 + 1e-12):
                yield list(s)


def _brute(net: Network, tau: float, budget: float, which: str, plain: bool) -> float:
    kw = {} if plain else {"budget": budget}
    return min(sampled_cost(net, tau, s, which, **kw) for s in _feasible(net, budget, plain))


def test_star_product_is_the_composition() -> None:
    rng = np.random.default_rng(1)
    n = 3

    def psd() -> np.ndarray:
        x = rng.standard_normal((n, n))
        return x @ x.T

    t1 = Triplet(rng.standard_normal((n, n)), psd(), psd())
    t2 = Triplet(rng.standard_normal((n, n)), psd(), psd())
    x = psd()
    want = t2.apply(t1.apply(x))
    np.testing.assert_allclose(t1.then(t2).apply(x), want, rtol=1e-12, atol=1e-12)
    # The update triplet is (X⁻¹ + J)⁻¹.
    j = psd()
    np.testing.assert_allclose(
        Triplet.update(j).apply(x), np.linalg.inv(np.linalg.inv(x) + j), rtol=1e-9
    )


def test_relaxed_period_by_powers_is_the_unit_by_unit_composition() -> None:
    # The period composed run by run by binary powering against the plain left fold of its
    # units, on the paper's case (one run) and with costs (runs of updates and predictions).
    for net, budget in ((_net(), 7.0), (_net(costs=[1.0, 2.5, 1.5]), 9.0)):
        m = sampled_system(net)
        lim = schedule_limits(m, budget)
        p = relaxed_period(m, 0.4, lim)
        assert p is not None
        for j in dominating_information([np.sqrt(0.4) * c for c in m.sensors]):
            total, unit = _period(p, j)
            fold = functools.reduce(Triplet.then, unit, Triplet.identity(m.n)).then(p.tail)
            x = np.eye(m.n)
            np.testing.assert_allclose(total.apply(x), fold.apply(x), rtol=1e-12, atol=0)
            for a, b in ((total.a, fold.a), (total.g, fold.g), (total.h, fold.h)):
                np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-13 * np.abs(b).max())
    for k in (1, 2, 5, 8):
        t = Triplet.prediction(np.eye(2) * 0.9, np.eye(2) * 0.1)
        want = functools.reduce(Triplet.then, [t] * k)
        np.testing.assert_allclose(_power(t, k).h, want.h, rtol=1e-14)


def test_dominating_information_dominates_every_sensor() -> None:
    rng = np.random.default_rng(2)
    cbar = [rng.standard_normal((4, 1)) for _ in range(6)] + [rng.standard_normal((4, 2))]
    for j in dominating_information(cbar):
        for c in cbar:
            assert np.linalg.eigvalsh(j - c @ c.T).min() >= -1e-12


def test_relaxed_iterates_lie_below_every_steady_state() -> None:
    """The relaxation theorem as matrices: Ψ^{2^k}(0) ⪯ Σ̄(R) for schedules of the network."""
    net = _net()
    m = sampled_system(net)
    tau = 0.5
    d_cbar = [np.sqrt(tau) * c for c in m.sensors]
    from capalloc_rs.sampled import discretise

    d = discretise(m, tau, 6)
    rho = Triplet.prediction(d.E, d.H).then(Triplet.update(dominating_information(d_cbar)[0]))
    psi = Triplet.identity(m.n)
    for _ in range(6):
        psi = psi.then(rho)
    x = power_from_zero(psi)
    for s in ([0, 1, 2, 0, 1, 2], [2, 2, 0, 1, 1, 0], [0, 0, 0, 0, 1, 2]):
        sig = sampled_covariance(net, tau, s).boundary
        assert np.linalg.eigvalsh(sig - x).min() >= -1e-10 * np.trace(sig)


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize("tau", [0.2, 1.0])
def test_exact_equals_brute_force_on_three_sensors_seven_slots(which: str, tau: float) -> None:
    net = Network.random(3, n=2, p=1, eps=0.2, seed=11)
    best = _brute(net, tau, 7, which, plain=True)
    res = best_schedule(net, tau, 7, which=which, method="exact")
    assert res.proven_optimal and res.gap == 0.0
    assert res.eta_bar == pytest.approx(best, rel=REL)
    assert sampled_cost(net, tau, res.schedule, which) == pytest.approx(best, rel=REL)
    # The local search's bound is valid too (and not tight).
    plain = best_schedule(net, tau, 7, which=which)
    assert plain.lower_bound <= best
    assert plain.gap >= plain.eta_bar - best - 1e-12 * best
    assert plain.gap > 0


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_exact_with_equal_costs_caps_and_idle_time(which: str) -> None:
    """Equal non-unit costs, a cap and a budget that leaves idle time: every length searched."""
    net = _net(costs=[2.0, 2.0, 2.0], r_max=[2, 3, 2])
    budget = 13.0  # at most 6 slots of 2 units, one unit idle
    best = _brute(net, 0.4, budget, which, plain=False)
    res = best_schedule(net, 0.4, budget, which=which, method="exact")
    assert res.proven_optimal
    assert res.eta_bar == pytest.approx(best, rel=REL)
    assert res.lower_bound <= res.eta_bar
    m = sampled_system(net)
    assert relaxed_lower_bound(m, 0.4, schedule_limits(m, budget), which) <= best


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_weighted_cost_exact_and_bound(which: str) -> None:
    rng = np.random.default_rng(7)
    x = rng.standard_normal((3, 3))
    net = _net(weight=x @ x.T + np.eye(3))
    best = _brute(net, 0.3, 6, which, plain=True)  # one minimum, no cap: exactly 6 slots
    res = best_schedule(net, 0.3, 6, which=which, method="exact")
    assert res.proven_optimal
    assert res.eta_bar == pytest.approx(best, rel=REL)
    assert best_schedule(net, 0.3, 6, which=which).lower_bound <= best


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize("budget", [6.0, 8.0])
def test_bound_with_unequal_costs_is_below_brute_force(which: str, budget: float) -> None:
    net = _net(costs=[1.0, 2.0, 1.5])
    best = _brute(net, 0.4, budget, which, plain=False)
    res = best_schedule(net, 0.4, budget, which=which)
    assert res.lower_bound <= best
    assert 0 <= res.gap and res.eta_bar >= best * (1 - REL)
    exact = best_schedule(net, 0.4, budget, which=which, method="exact")
    assert exact.proven_optimal and exact.eta_bar == pytest.approx(best, rel=REL)


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_four_sensors_with_a_node_limit_keep_a_valid_gap(which: str) -> None:
    net = _net(n_sensors=4, seed=9)
    best = _brute(net, 0.5, 7, which, plain=True)
    full = best_schedule(net, 0.5, 7, which=which, method="exact")
    assert full.proven_optimal and full.eta_bar == pytest.approx(best, rel=REL)
    cut = best_schedule(net, 0.5, 7, which=which, method="exact", node_limit=3)
    assert cut.nodes <= 3 + 4  # the limit is checked before every node's children
    assert not cut.proven_optimal or cut.eta_bar == pytest.approx(best, rel=REL)
    assert cut.lower_bound <= best
    assert cut.gap >= cut.eta_bar - best - REL * best
    assert cut.to_dict()["nodes"] == cut.nodes


@pytest.mark.parametrize("n_sensors", [5, 10])
@pytest.mark.parametrize("which", ["boundary", "average"])
def test_bound_below_the_searched_schedule_on_larger_networks(n_sensors: int, which: str) -> None:
    net = Network.random(n_sensors, n=2, p=1, eps=0.2, seed=3)
    res = best_schedule(net, 0.2, 2 * n_sensors, which=which)
    assert math.isfinite(res.lower_bound)
    assert 0 < res.lower_bound <= res.eta_bar
    assert res.gap == pytest.approx(res.eta_bar - res.lower_bound, rel=1e-12)
    d = res.to_dict()
    assert {"lower_bound", "gap", "proven_optimal", "nodes"} <= set(d)
    assert "gap=" in repr(res)


def test_bound_with_costs_on_a_larger_network() -> None:
    rng = np.random.default_rng(4)
    base = Network.random(6, n=2, p=1, eps=0.2, seed=4)
    net = Network(
        base.a, base.g, list(base.sensors), r_min=1.0, costs=rng.choice([1.0, 2.0], size=6)
    )
    res = best_schedule(net, 0.3, 14.0)
    assert 0 < res.lower_bound <= res.eta_bar


def test_certify_false_and_bad_keywords() -> None:
    net = Network.random(3, n=2, p=1, eps=0.2, seed=11)
    res = best_schedule(net, 0.2, 6, certify=False)
    assert math.isnan(res.lower_bound) and not res.proven_optimal
    for bad in (0, -1, 2.5, True, "5"):
        with pytest.raises(InvalidInputError, match="node_limit"):
            best_schedule(net, 0.2, 6, method="exact", node_limit=bad)
    with pytest.raises(InvalidInputError, match="certify"):
        best_schedule(net, 0.2, 6, certify=1)  # type: ignore[arg-type]


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize("seed", [11, 12])
def test_grouped_bound_is_below_brute_force_and_tighter(which: str, seed: int) -> None:
    """certify="grouped" (the paper's case): still ≤ the brute-force optimum, and at least the
    relaxed bound (it is the larger of both)."""
    net = Network.random(3, n=2, p=1, eps=0.2, seed=seed)
    best = _brute(net, 0.2, 7, which, plain=True)
    res = best_schedule(net, 0.2, 7, which=which, certify="grouped")
    relaxed = best_schedule(net, 0.2, 7, which=which)
    assert relaxed.lower_bound <= res.lower_bound <= best
    assert res.gap >= res.eta_bar - best - REL * best


def test_grouped_bound_with_a_weight_and_coupled_sensors() -> None:
    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, 3))
    net = _net(weight=x @ x.T + 0.1 * np.eye(3), n_sensors=3, seed=8)
    for which in ("boundary", "average"):
        best = _brute(net, 0.3, 6, which, plain=True)
        res = best_schedule(net, 0.3, 6, which=which, certify="grouped")
        assert res.lower_bound <= best
        assert best_schedule(net, 0.3, 6, which=which).lower_bound <= best  # cheap grouped
    # A paper-form version of the same network (no weight): the grouped bound applies.
    plain_net = Network(net.a, net.g, list(net.sensors), r_min=1.0)
    best = _brute(plain_net, 0.3, 6, "boundary", plain=True)
    res = best_schedule(plain_net, 0.3, 6, certify="grouped")
    assert res.lower_bound <= best


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_grouped_bound_below_the_searched_schedule_at_n5(which: str) -> None:
    net = Network.random(5, n=2, p=1, eps=0.2, seed=3)
    res = best_schedule(net, 0.2, 10, which=which, certify="grouped")
    default = best_schedule(net, 0.2, 10, which=which)
    loose = best_schedule(net, 0.2, 10, which=which, certify="relaxed")
    assert loose.lower_bound <= default.lower_bound <= res.lower_bound <= res.eta_bar
    assert res.gap <= default.gap < loose.gap


def test_grouped_bound_with_the_weight_is_valid() -> None:
    """The grouped split M = Σ_g M_g with a weight (paper's counts, Network.random with M)."""
    base = Network.random(3, n=2, p=1, eps=0.2, seed=11)
    rng = np.random.default_rng(5)
    x = rng.standard_normal((6, 6))
    net = Network(base.a, base.g, list(base.sensors), r_min=1.0, weight=x @ x.T)
    from capalloc_rs.sampled.grouped import grouped_lower_bound

    m = sampled_system(net)
    lim = schedule_limits(m, 7)
    for which in ("boundary", "average"):
        best = _brute(net, 0.2, 7, which, plain=True)
        bound = grouped_lower_bound(m, 0.2, lim, which)
        assert relaxed_lower_bound(m, 0.2, lim, which) <= bound <= best


def test_time_limit_returns_the_incumbent_with_a_valid_gap() -> None:
    net = _net(n_sensors=4, seed=9)
    best = _brute(net, 0.5, 7, "boundary", plain=True)
    res = best_schedule(net, 0.5, 7, method="exact", time_limit=1e-6)
    assert res.eta_bar >= best * (1 - REL)
    assert res.lower_bound <= best
    assert res.gap >= res.eta_bar - best - REL * best
    assert res.proven_optimal == (res.gap == 0.0)


def test_one_trajectory_bounds_every_rotation() -> None:
    """The phase lemma of ``grouped``: each posterior of a schedule's periodic trajectory lies
    below the boundary steady state of the rotation that ends at that slot."""
    net = _net(seed=6)
    s = [0, 1, 1, 2, 0, 2, 1]
    post = sampled_covariance(net, 0.4, s).posteriors
    for r in range(1, len(s) + 1):
        rotated = s[r:] + s[:r]
        sig = sampled_covariance(net, 0.4, rotated).boundary
        assert np.linalg.eigvalsh(sig - post[r - 1]).min() >= -1e-10 * np.trace(sig)


def test_block_supersets_cover_every_set_up_to_rotation() -> None:
    """Every set of k positions on the cycle has a rotation inside one of the block unions or
    inside the longest-gap positions."""
    from capalloc_rs.sampled.grouped import _block_sets, _gap_run

    L = 9
    for k in range(1, L + 1):
        for max_sets in (1, 3, 10):
            blocks = [set(b) for b in _block_sets(L, k, max_sets)]
            run = set(_gap_run(L, k))
            for p in itertools.combinations(range(L), k):
                rots = [{(x - r) % L for x in p} for r in range(L)]
                assert any(q <= b for q in rots for b in blocks)
                assert any(q <= run for q in rots)


@functools.cache
def _brute_3x9(which: str) -> float:
    """The brute-force optimum of ``Network.random(3, seed=12)`` with 9 slots (every schedule
    using every sensor, each costed by the Rust core's evaluation)."""
    core = sampled_system(Network.random(3, n=2, p=1, eps=0.2, seed=12)).core
    return min(
        float(core.cost(0.2, np.asarray(s, dtype=np.int64), which))
        for s in itertools.product(range(3), repeat=9)
        if len(set(s)) == 3
    )


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize("max_sets", [1, 2, 5, 1000])
def test_grouped_bound_with_blocks_and_gaps_is_below_brute_force(
    which: str, max_sets: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Few sets: the block and longest-gap entries are used; every variant stays ≤ the optimum,
    and the default certificate (cheap grouped) is the larger of it and the relaxed bound."""
    from capalloc_rs.sampled import grouped

    net = Network.random(3, n=2, p=1, eps=0.2, seed=12)
    m = sampled_system(net)
    lim = schedule_limits(m, 9)
    best = _brute_3x9(which)
    monkeypatch.setattr(grouped, "MAX_SETS", max_sets)
    assert grouped.grouped_lower_bound(m, 0.2, lim, which) <= best
    monkeypatch.setattr(grouped, "CHEAP_SETS", max_sets)
    res = best_schedule(net, 0.2, 9, which=which)
    old = best_schedule(net, 0.2, 9, which=which, certify="relaxed")
    assert old.lower_bound <= res.lower_bound <= best
    assert res.gap < old.gap


def test_cheap_bound_is_skipped_beyond_its_work_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    from capalloc_rs.sampled import grouped

    net = Network.random(4, n=2, p=1, eps=0.2, seed=3)
    m = sampled_system(net)
    lim = schedule_limits(m, 8)
    assert math.isfinite(grouped.grouped_lower_bound(m, 0.2, lim, "boundary", cheap=True))
    monkeypatch.setattr(grouped, "CHEAP_WORK", 1.0)
    assert math.isnan(grouped.grouped_lower_bound(m, 0.2, lim, "boundary", cheap=True))
    res = best_schedule(net, 0.2, 8)  # the relaxed bound alone
    assert res.lower_bound == pytest.approx(relaxed_lower_bound(m, 0.2, lim, "boundary"), rel=1e-15)
