"""optimal_allocation / integer_allocation against the closed-form decoupled scalar model.

These tests need no Rust: the oracle is tests/scalar_model.py (closed-form Riccati roots, derivative
formulas checked here by finite differences), and the optimum is found independently by solving the
KKT conditions Σ_i γ_i(μ) = σ for μ with brentq.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scalar_model import ScalarNetwork, random_scalar_network

from capalloc_rs import allocation, errors
from capalloc_rs.allocation import (
    frank_wolfe_gap,
    integer_allocation,
    optimal_allocation,
    project_simplex,
)
from capalloc_rs.allocation import integer as integer_mod

METHODS = ["newton", "projected-gradient", "double-bracket"]


def test_scalar_model_derivatives_match_finite_differences():
    net = random_scalar_network(0)
    r = np.array([1.3, 2.0, 0.7, 5.0, 1.1])
    h = 1e-6
    fd = np.array([(net.cost(r + h * e) - net.cost(r - h * e)) / (2 * h) for e in np.eye(5)])
    np.testing.assert_allclose(net.gradient(r), fd, rtol=1e-7)
    fd2 = np.array(
        [(net.gradient(r + h * e) - net.gradient(r - h * e)) / (2 * h) for e in np.eye(5)]
    )
    np.testing.assert_allclose(net.hessian(r), fd2, rtol=1e-6, atol=1e-10)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("method", METHODS)
def test_matches_closed_form_optimum(seed, method):
    net = random_scalar_network(seed)
    for sigma in (0.5, 3.0, 20.0):
        alloc = optimal_allocation(net, sigma + 5 * net.r_min, method=method)
        gamma_ref, mu_ref = net.optimum(sigma)
        eta_ref = net.cost(gamma_ref + 1)
        # Tolerances ≥ 10× the largest error measured over these 12 problems (seeds 0–3,
        # σ = 0.5, 3, 20): η 2e-16 (Newton) / 4e-16 (PG); γ/max(σ,1) 1.6e-13 / 1.9e-10 / 4e-7
        # (flow); μ 2.7e-14 / 1.3e-11.
        if method == "double-bracket":
            # The flow certifies gap ≤ 1e-9·η; γ is only weakly determined along flat directions.
            assert alloc.eta == pytest.approx(eta_ref, rel=1e-9)
            np.testing.assert_allclose(alloc.gamma, gamma_ref, atol=1e-5 * max(sigma, 1))
        else:
            newton = method == "newton"
            assert alloc.eta == pytest.approx(eta_ref, rel=1e-14)
            gamma_tol = (1e-11 if newton else 1e-8) * max(sigma, 1)
            np.testing.assert_allclose(alloc.gamma, gamma_ref, atol=gamma_tol)
            assert alloc.mu == pytest.approx(mu_ref, rel=1e-12 if newton else 1e-9)
        assert alloc.eta >= eta_ref - 1e-13 * eta_ref
        assert alloc.gap <= 1e-9 * alloc.eta
        assert alloc.mu <= 0
        assert alloc.gamma.sum() == pytest.approx(sigma, rel=1e-14)
        assert np.all(alloc.gamma >= 0)
        assert np.all(alloc.r >= net.r_min)


def test_newton_certificate_and_kkt():
    net = random_scalar_network(7, 8)
    alloc = optimal_allocation(net, 8 + 4.0)
    assert alloc.kkt_residual < 1e-8
    assert alloc.gap <= 1e-12 * alloc.eta
    assert alloc.method == "newton"
    g = alloc.gradient
    inactive = np.setdiff1d(np.arange(8), alloc.active)
    assert np.all(g[inactive] >= alloc.mu - 1e-10 * abs(alloc.mu))
    np.testing.assert_allclose(g[alloc.active], alloc.mu, rtol=1e-8)
    with pytest.raises(ValueError):
        alloc.r[0] = 5.0  # results are immutable


def test_sensor_that_never_becomes_active():
    # Sensor 2 is nearly useless (tiny c): it stays at r_min for moderate σ.
    net = ScalarNetwork(
        a=np.array([0.5, -1.0, -1.0]), c=np.array([1.0, 1.0, 1e-3]), q=np.ones(3), r_min=1.0
    )
    alloc = optimal_allocation(net, 3 + 10.0)
    assert 2 not in alloc.active
    assert alloc.gamma[2] == 0.0
    assert alloc.gradient[2] > alloc.mu


def test_boundary_cases():
    net = random_scalar_network(3)
    zero = optimal_allocation(net, 5.0)  # σ = 0
    assert zero.sigma == 0 and np.all(zero.gamma == 0) and zero.active.size == 0
    assert zero.mu == pytest.approx(np.min(zero.gradient))
    one = ScalarNetwork(a=np.array([0.3]), c=np.array([1.0]), q=np.array([1.0]))
    a1 = optimal_allocation(one, 4.0)
    assert a1.gamma[0] == 3.0 and a1.r[0] == 4.0 and a1.gap == 0.0
    with pytest.raises(errors.InvalidInputError, match="infeasible"):
        optimal_allocation(net, 4.0)
    with pytest.raises(errors.InvalidInputError, match="method"):
        optimal_allocation(net, 10.0, method="simplex")  # type: ignore[arg-type]


def test_uniqueness_from_different_starts():
    net = random_scalar_network(11, 6)
    sigma = 7.0
    rng = np.random.default_rng(0)
    sols = []
    for _ in range(5):
        g0 = rng.dirichlet(np.ones(6)) * sigma
        sols.append(optimal_allocation(net, sigma + 6, gamma0=g0).gamma)
    for s in sols[1:]:
        np.testing.assert_allclose(s, sols[0], atol=1e-10)


def test_projection_onto_simplex():
    rng = np.random.default_rng(1)
    for _ in range(50):
        y = rng.normal(size=7) * 3
        x = project_simplex(y, 2.5)
        assert x.min() >= 0 and x.sum() == pytest.approx(2.5, rel=1e-15)
        # Optimality of the projection: ⟨y − x, z − x⟩ ≤ 0 for vertices z.
        for k in range(7):
            z = np.zeros(7)
            z[k] = 2.5
            assert (y - x) @ (z - x) <= 1e-12


def test_frank_wolfe_gap_bounds_suboptimality():
    net = random_scalar_network(4)
    sigma = 6.0
    opt = net.cost(net.optimum(sigma)[0] + 1)
    rng = np.random.default_rng(2)
    for _ in range(20):
        g = rng.dirichlet(np.ones(5)) * sigma
        assert frank_wolfe_gap(g, net.gradient(g + 1)) >= net.cost(g + 1) - opt - 1e-12


def brute_force(net, r_tot):
    n = len(net.sensors)
    best, arg = np.inf, None
    for combo in itertools.product(range(1, r_tot + 1), repeat=n):
        if sum(combo) == r_tot:
            v = net.cost(np.array(combo, dtype=float))
            if v < best:
                best, arg = v, combo
    return np.array(arg), best


def all_compositions_optimum(net, r_tot):
    """Brute force over every integer point with 4 counts ≥ 1 summing to r_tot, evaluated at once
    with the closed-form per-sensor costs."""
    k = np.arange(1, r_tot + 1)
    a, b, c = np.meshgrid(k, k, k, indexing="ij")
    d = r_tot - a - b - c
    ok = d >= 1
    rows = np.stack([a[ok], b[ok], c[ok], d[ok]], axis=1).astype(float)
    vals = np.sum(net.sigma_i(rows), axis=1)
    i = int(np.argmin(vals))
    return rows[i].astype(int), float(net.cost(rows[i]))


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("r_tot", [4, 9, 15])
def test_integer_allocation_equals_brute_force(seed, r_tot):
    net = random_scalar_network(seed, 4)
    res = integer_allocation(net, r_tot)
    counts, best = brute_force(net, r_tot)
    assert res.eta == pytest.approx(best, rel=1e-13)
    assert res.counts.sum() == r_tot and res.counts.min() >= 1


def test_integer_allocation_large_uses_continuous_start(monkeypatch):
    net = random_scalar_network(5, 4)
    calls = []
    original = allocation.optimal_allocation

    def spy(*args, **kwargs):
        calls.append(args[1:])
        return original(*args, **kwargs)

    monkeypatch.setattr(integer_mod, "optimal_allocation", spy)
    res = integer_allocation(net, 60, method="greedy")  # today's greedy: its evaluations counted
    assert calls == [(60.0,)]  # spare = 56 > 4N: the continuous optimum seeds the greedy phase
    assert res.counts.sum() == 60
    # Greedy from r_min would cost spare·N = 224 evaluations; from the floor of the continuous
    # optimum (Σ = 58 here) it costs 2·N, then one for the point and N(N−1) at most per exchange
    # round (only sensors above r_min may give a slot).
    n, spare = 4, 56
    cont = original(net, 60.0)
    floor_start = 1 + np.floor(cont.gamma + 1e-9)
    assert floor_start.sum() == 58
    assert np.all(res.counts >= floor_start)  # no exchange happened: greedy only added slots
    assert res.exchanges == 0
    movable = int(np.sum(res.counts > 1))
    assert res.evaluations == (60 - 58) * n + 1 + movable * (n - 1)
    assert res.evaluations < spare
    # The same counts as brute force over all C(59, 3) = 32 509 integer points (vectorised).
    counts, best = all_compositions_optimum(net, 60)
    np.testing.assert_array_equal(res.counts, counts)
    assert res.eta == pytest.approx(best, rel=1e-13)
    # Exchange-optimal: no single move improves.
    for i, j in itertools.permutations(range(4), 2):
        if res.counts[i] > 1:
            c = res.counts.astype(float).copy()
            c[i] -= 1
            c[j] += 1
            assert net.cost(c) >= res.eta - 1e-12


def test_integer_allocation_bad_input():
    net = random_scalar_network(0, 3)
    with pytest.raises(errors.InvalidInputError):
        integer_allocation(net, 2)
    with pytest.raises(errors.InvalidInputError):
        integer_allocation(net, 5.5)  # type: ignore[arg-type]


def test_integer_allocation_r_min_and_capacity_checks():
    net = random_scalar_network(0, 3)
    # issue 13: one rule for slot counts: at least ⌈r_min⌉ each (as schedules), and at least 1
    for r_min, lo in ((1.5, 2), (0.0, 1), (0.5, 1), (2.0000000000001, 2)):
        ok = ScalarNetwork(a=net.a, c=net.c, q=net.q, r_min=r_min)
        counts = integer_allocation(ok, 12).counts
        assert sum(counts) == 12 and min(counts) >= lo
        # by an independent route: the best of all integer points with those bounds
        best = min(
            (c for c in itertools.product(range(lo, 13), repeat=3) if sum(c) == 12),
            key=lambda c: net.cost(np.asarray(c, dtype=float)),
        )
        assert list(counts) == list(best)
    bad = ScalarNetwork(a=net.a, c=net.c, q=net.q, r_min=-2.0)
    with pytest.raises(errors.InvalidInputError, match="r_min"):
        integer_allocation(bad, 12)
    with pytest.raises(errors.InvalidInputError, match="N·r_min = 6"):
        integer_allocation(ScalarNetwork(a=net.a, c=net.c, q=net.q, r_min=1.5), 5)
    two = ScalarNetwork(a=net.a, c=net.c, q=net.q, r_min=2.0)
    with pytest.raises(errors.InvalidInputError, match="N·r_min = 6"):
        integer_allocation(two, 5)
    res = integer_allocation(two, 9)
    counts, best = brute_force_min(two, 9)
    np.testing.assert_array_equal(res.counts, counts)
    assert res.counts.min() >= 2 and res.eta == pytest.approx(best, rel=1e-13)
    with pytest.raises(ValueError, match="read-only"):
        res.counts[0] = 5


def brute_force_min(net, r_tot):
    """Brute force over integer points with every count ≥ r_min."""
    lo = int(net.r_min)
    n = len(net.sensors)
    best, arg = np.inf, None
    for combo in itertools.product(range(lo, r_tot + 1), repeat=n):
        if sum(combo) == r_tot:
            v = net.cost(np.array(combo, dtype=float))
            if v < best:
                best, arg = v, combo
    return np.array(arg), best


@pytest.mark.parametrize(("r_tot", "seeded"), [(4 + 16, False), (4 + 17, True)])
def test_integer_allocation_continuous_start_threshold(monkeypatch, r_tot, seeded):
    # The continuous start is used when spare > 4N (N = 4): not at spare = 16, at spare = 17.
    net = random_scalar_network(5, 4)
    calls = []
    original = allocation.optimal_allocation
    monkeypatch.setattr(
        integer_mod, "optimal_allocation", lambda *a, **k: calls.append(a[1]) or original(*a, **k)
    )
    res = integer_allocation(net, r_tot)
    assert calls == ([float(r_tot)] if seeded else [])
    counts, best = all_compositions_optimum(net, r_tot)
    np.testing.assert_array_equal(res.counts, counts)


def test_integer_allocation_makes_no_exchange_between_equal_costs():
    # Three identical sensors: permutations of the counts tie (up to rounding of the sum's order),
    # the greedy result is already optimal, and no exchange may be counted for a tie.
    one = random_scalar_network(2, 1)
    net = ScalarNetwork(a=np.repeat(one.a, 3), c=np.repeat(one.c, 3), q=np.repeat(one.q, 3))
    for r_tot in (10, 11, 12):
        res = integer_allocation(net, r_tot)
        assert res.exchanges == 0
        assert sorted(res.counts.tolist()) == sorted(
            [r_tot // 3 + (1 if k < r_tot % 3 else 0) for k in range(3)]
        )
        assert res.eta == pytest.approx(brute_force(net, r_tot)[1], rel=1e-14)
