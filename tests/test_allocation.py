"""optimal_allocation and integer_allocation on real (coupled, heterogeneous) networks."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.optimize import minimize

from capalloc_rs import Network, errors
from capalloc_rs.allocation import integer_allocation, optimal_allocation


def net_random(seed: int, n_sub: int = 5, eps: float = 0.1, **kw) -> Network:
    return Network.random(n_sub, 2, eps=eps, seed=seed, **kw)


def scipy_cost(net: Network, r: np.ndarray) -> float:
    """η(r) through scipy only: AΣ + ΣAᵀ − Σ C diag(r) Cᵀ Σ + Q = 0 is scipy's CARE with
    a → Aᵀ, b → C = [ĉ_1 … ĉ_N], r → diag(1/r) (repeated over each sensor's outputs)."""
    c = np.hstack(net.sensors)
    w = np.concatenate([np.full(s.shape[1], ri) for s, ri in zip(net.sensors, r, strict=True)])
    sigma = sla.solve_continuous_are(net.a.T, c, net.q, np.diag(1.0 / w))
    return float(np.trace(sigma))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kkt_and_certificate_at_the_optimum(seed):
    net = net_random(seed)
    a = optimal_allocation(net, 5 + 12.0)
    assert a.gap <= 1e-12 * a.eta
    assert a.kkt_residual < 1e-8
    assert a.mu <= 0
    assert a.r.sum() == pytest.approx(17.0, rel=1e-14) and np.all(a.r >= net.r_min)
    np.testing.assert_allclose(a.gradient[a.active], a.mu, rtol=1e-8)
    inactive = np.setdiff1d(np.arange(5), a.active)
    assert np.all(a.gradient[inactive] >= a.mu * (1 + 1e-9))
    # The certificate is a real bound: every feasible point is at least η*.
    rng = np.random.default_rng(seed)
    for _ in range(10):
        g = rng.dirichlet(np.ones(5)) * a.sigma
        assert net.cost(g + net.r_min) >= a.eta - 1e-12 * a.eta


@pytest.mark.parametrize("seed", [3, 4])
def test_three_methods_agree(seed):
    net = net_random(seed, 4, eps=0.15)
    newton = optimal_allocation(net, 4 + 9.0)
    pg = optimal_allocation(net, 4 + 9.0, method="projected-gradient")
    flow = optimal_allocation(net, 4 + 9.0, method="double-bracket")
    assert pg.eta == pytest.approx(newton.eta, rel=1e-10)
    assert flow.eta == pytest.approx(newton.eta, rel=1e-8)
    np.testing.assert_allclose(pg.r, newton.r, atol=1e-4)
    assert newton.iterations < pg.iterations
    assert flow.method == "double-bracket" and flow.gap <= 1e-9 * flow.eta


def test_agrees_with_scipy_slsqp_on_scipy_care():
    net = net_random(5, 4, eps=0.1)
    r_tot = 4 + 6.0
    ours = optimal_allocation(net, r_tot)
    res = minimize(
        lambda r: scipy_cost(net, r),
        np.full(4, r_tot / 4),
        method="SLSQP",
        bounds=[(net.r_min, None)] * 4,
        constraints=[{"type": "eq", "fun": lambda r: r.sum() - r_tot}],
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert res.success
    assert ours.eta <= res.fun * (1 + 1e-9)  # we are never worse than SLSQP
    assert ours.eta == pytest.approx(res.fun, rel=1e-7)
    np.testing.assert_allclose(ours.r, res.x, atol=2e-3)
    assert scipy_cost(net, ours.r) == pytest.approx(ours.eta, rel=1e-10)


def test_unique_optimum_from_different_starts():
    net = net_random(6, 5, eps=0.2)
    rng = np.random.default_rng(1)
    sols = [
        optimal_allocation(net, 15.0, gamma0=rng.dirichlet(np.ones(5)) * 10.0).r for _ in range(5)
    ]
    for s in sols[1:]:
        np.testing.assert_allclose(s, sols[0], atol=1e-8)


def test_boundary_cases():
    net = net_random(7, 3)
    zero = optimal_allocation(net, 3.0)  # σ = 0
    assert zero.sigma == 0.0 and zero.active.size == 0 and zero.gap == 0.0
    np.testing.assert_array_equal(zero.r, np.ones(3))
    single = Network.random(1, 3, seed=2)
    one = optimal_allocation(single, 5.0)
    assert one.r.tolist() == [5.0] and one.gap == 0.0
    assert one.eta == pytest.approx(single.cost([5.0]))
    with pytest.raises(errors.InvalidInputError, match="infeasible"):
        optimal_allocation(net, 2.5)
    for bad in (float("inf"), float("nan"), -float("inf")):
        with pytest.raises(errors.InvalidInputError, match="r_tot"):
            optimal_allocation(net, bad)
        with pytest.raises(errors.InvalidInputError, match="r_tot"):
            integer_allocation(net, bad)  # type: ignore[arg-type]
    with pytest.raises(errors.InvalidInputError, match="tol"):
        optimal_allocation(net, 10.0, tol=float("nan"))
    with pytest.raises(errors.InvalidInputError):
        optimal_allocation(net, 10.0, gamma0=[1.0, 1.0, 1.0])  # does not sum to σ = 7


def test_a_sensor_that_never_becomes_active():
    base = net_random(8, 3, eps=0.05)
    weak = [s if i < 2 else 1e-3 * s for i, s in enumerate(base.sensors)]
    net = Network(base.a, base.g, weak, r_min=1.0)
    a = optimal_allocation(net, 3 + 20.0)
    assert 2 not in a.active and a.gamma[2] == 0.0
    assert a.gradient[2] > a.mu


def test_newton_is_fast_for_larger_networks():
    net = net_random(9, 30, eps=0.05)
    a = optimal_allocation(net, 30 + 60.0)
    assert a.iterations <= 20 and a.gap <= 1e-12 * a.eta


def brute_force(net: Network, r_tot: int) -> tuple[np.ndarray, float]:
    n = len(net.sensors)
    combos = [c for c in itertools.product(range(1, r_tot + 1), repeat=n) if sum(c) == r_tot]
    vals = net.cost_many(np.array(combos, dtype=float))
    k = int(np.argmin(vals))
    return np.array(combos[k]), float(vals[k])


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("r_tot", [5, 9, 14])
def test_integer_allocation_is_exact_when_decoupled(seed, r_tot):
    net = net_random(seed, 3, eps=0.0)
    res = integer_allocation(net, r_tot)
    _, best = brute_force(net, r_tot)
    assert res.eta == pytest.approx(best, rel=1e-12)
    assert res.counts.sum() == r_tot and res.counts.min() >= 1


@pytest.mark.parametrize("seed", [3, 4])
def test_integer_allocation_weak_coupling_matches_brute_force(seed):
    net = net_random(seed, 3, eps=0.1)
    res = integer_allocation(net, 11)
    _, best = brute_force(net, 11)
    assert res.eta == pytest.approx(best, rel=1e-12)


def test_integer_allocation_is_exchange_optimal_and_beats_rounding():
    net = net_random(10, 5, eps=0.1)
    res = integer_allocation(net, 60)
    for i, j in itertools.permutations(range(5), 2):
        if res.counts[i] > 1:
            c = res.counts.astype(float)
            c[i] -= 1
            c[j] += 1
            assert net.cost(c) >= res.eta * (1 - 1e-13)
    cont = optimal_allocation(net, 60.0)
    rounded = np.round(cont.r)
    rounded[np.argmax(rounded)] += 60 - rounded.sum()
    assert res.eta <= net.cost(rounded) + 1e-13
    assert res.eta >= cont.eta  # the relaxation is a lower bound


def greedy_counts(net: Network, r_tot: int) -> np.ndarray:
    """The greedy marginal allocation alone (each slot to the sensor it helps most), from r_min."""
    counts = np.full(len(net.sensors), int(net.r_min))
    while counts.sum() < r_tot:
        cand = counts + np.eye(counts.size, dtype=int)
        counts = cand[int(np.argmin(net.cost_many(cand.astype(float))))]
    return counts


def test_integer_exchange_phase_reaches_the_brute_force_optimum_on_a_coupled_network():
    # Strong coupling (ε = 1) makes η far from separable: the greedy phase stops at (5, 6, 1),
    # second best of the 55 integer points, and one exchange (a slot from sensor 1 to sensor 2)
    # reaches the optimum (5, 5, 2). Found by scanning Network.random(3, 2, eps=1, seed) seeds.
    net = Network.random(3, 2, eps=1.0, seed=25)
    counts, best = brute_force(net, 12)
    greedy = greedy_counts(net, 12)
    assert greedy.tolist() == [5, 6, 1] and net.cost(greedy.astype(float)) > best
    res = integer_allocation(net, 12, method="greedy")  # today's greedy, counted
    assert res.exchanges == 1
    np.testing.assert_array_equal(res.counts, counts)
    assert counts.tolist() == [5, 5, 2]
    assert res.eta == best
    # Evaluations: greedy 3 per slot (9 spare slots), one for its point, then the exchange rounds:
    # 4 moves from (5, 6, 1) (sensor 2 is at r_min and cannot give) — one improves — and all 6
    # from (5, 5, 2), none improving.
    assert res.evaluations == 9 * 3 + 1 + 4 + 6
