"""Newton from the decoupled (ε = 0) optimum (``start="auto"``/``"decoupled"``) against Newton
from the uniform point (``start="uniform"``, the reference): the same optimum (η to 1e-12, the
same active set, both certified), fewer steps; at ε = 0 the start is the optimum, which the full
network's own gradient certifies (an independent route: the separable solve never forms the
coupled Riccati equation)."""

from __future__ import annotations

import numpy as np
import pytest

import capalloc_rs as ca
from capalloc_rs.allocation import decoupled_start, optimal_allocation


def _same_optimum(new: ca.Allocation, ref: ca.Allocation, tol: float = 1e-12) -> None:
    assert abs(new.eta - ref.eta) <= tol * ref.eta + new.eta_error + ref.eta_error
    assert list(new.active) == list(ref.active)
    for res in (new, ref):
        assert res.gap <= max(tol * res.eta, 10 * res.eta_error)
    # Both are within their certificates of the optimum: γ agrees to the square root of that.
    np.testing.assert_allclose(new.gamma, ref.gamma, rtol=0, atol=1e-5 * new.sigma)


@pytest.mark.parametrize(("n_sens", "seed"), [(5, 3), (5, 11), (20, 3), (50, 3)])
def test_decoupled_start_reaches_the_uniform_starts_optimum(n_sens: int, seed: int) -> None:
    net = ca.Network.random(n_sens, 2, eps=0.05, seed=seed)
    new = optimal_allocation(net, 3.0 * n_sens)
    ref = optimal_allocation(net, 3.0 * n_sens, start="uniform")
    _same_optimum(new, ref)
    assert new.iterations <= ref.iterations
    explicit = optimal_allocation(net, 3.0 * n_sens, start="decoupled")
    assert explicit.eta == new.eta and np.array_equal(explicit.r, new.r)


@pytest.mark.slow
def test_decoupled_start_at_200_sensors() -> None:
    net = ca.Network.random(200, 2, eps=0.05, seed=3)
    new = optimal_allocation(net, 600.0)
    ref = optimal_allocation(net, 600.0, start="uniform")
    _same_optimum(new, ref)
    assert new.iterations < ref.iterations and new.hvp_count < ref.hvp_count


@pytest.mark.parametrize("n_sens", [4, 12])
def test_at_eps_zero_the_decoupled_start_is_the_optimum(n_sens: int) -> None:
    net = ca.Network.random(n_sens, 2, eps=0.0, seed=5)
    sigma = 3.0 * n_sens - n_sens * net.r_min
    g0 = decoupled_start(net, sigma, 1e-13)
    assert g0 is not None and g0.sum() == pytest.approx(sigma, rel=1e-15)
    # The full network's certificate at the start: the gradient of the n-dimensional cost.
    p = net.at(g0 + net.r_min)
    g = np.asarray(p.gradient)
    gap = float(g0 @ (g - g.min()))
    assert gap <= 1e-12 * p.value
    res = optimal_allocation(net, 3.0 * n_sens)
    assert res.iterations == 0 and np.array_equal(res.gamma, g0)
    _same_optimum(res, optimal_allocation(net, 3.0 * n_sens, start="uniform"))


def test_the_exact_and_cg_variants_agree_from_the_decoupled_start() -> None:
    net = ca.Network.random(30, 2, eps=0.1, seed=8)
    exact = optimal_allocation(net, 70.0, hessian="exact")
    cg = optimal_allocation(net, 70.0, hessian="hvp")
    _same_optimum(exact, cg)


@pytest.mark.parametrize(("r_min", "r_tot"), [(1e6, 3e12), (1e-3, 5.0), (1.0, 1e6)])
def test_badly_scaled_and_large_rates_are_no_worse_than_the_uniform_start(
    r_min: float, r_tot: float
) -> None:
    net = ca.Network.random(6, 2, eps=0.05, seed=4, r_min=r_min)
    new = optimal_allocation(net, r_tot)
    ref = optimal_allocation(net, r_tot, start="uniform")
    # Not worse than the reference beyond the accuracy of η; both certified as far as η allows.
    assert new.eta <= ref.eta + new.eta_error + ref.eta_error + 1e-12 * ref.eta
    assert abs(new.eta - ref.eta) <= 1e-12 * ref.eta + new.eta_error + ref.eta_error
    assert new.optimality <= max(1e-8 * new.eta, 10 * new.eta_error)


def test_other_methods_keep_the_uniform_start_unless_asked() -> None:
    net = ca.Network.random(5, 2, eps=0.05, seed=3)
    pg = optimal_allocation(net, 15.0, method="projected-gradient")
    pg_dec = optimal_allocation(net, 15.0, method="projected-gradient", start="decoupled")
    assert abs(pg.eta - pg_dec.eta) <= 1e-10 * pg.eta
    assert pg_dec.iterations <= pg.iterations


def test_start_is_validated_and_gamma0_takes_precedence() -> None:
    net = ca.Network.random(5, 2, eps=0.05, seed=3)
    with pytest.raises(ca.InvalidInputError, match="start"):
        optimal_allocation(net, 15.0, start="nearby")  # type: ignore[arg-type]
    with pytest.raises(ca.InvalidInputError, match="start"):
        optimal_allocation(net, 15.0, start=1)  # type: ignore[arg-type]
    general = ca.Network(net.a, net.g, list(net.sensors), r_min=net.r_min)
    assert general.structure is None
    with pytest.raises(ca.InvalidInputError, match="start='decoupled'"):
        optimal_allocation(general, 15.0, start="decoupled")
    # auto on a network without blocks: the uniform start, the same optimum
    _same_optimum(optimal_allocation(general, 15.0), optimal_allocation(net, 15.0))
    g0 = np.full(5, 2.0)
    a = optimal_allocation(net, 15.0, gamma0=g0, start="decoupled")
    b = optimal_allocation(net, 15.0, gamma0=g0, start="uniform")
    assert a.eta == b.eta and a.iterations == b.iterations


def test_decoupled_start_bad_arguments_name_themselves() -> None:
    net = ca.Network.random(3, 2, eps=0.05, seed=3)
    st = net.structure
    assert st is not None
    from capalloc_rs import _core

    with pytest.raises(ca.InvalidInputError):
        _core.separable_allocation(
            list(st.a_blocks), list(st.g_blocks), list(st.c_blocks), 1.0, -1.0, 1e-12, 10
        )
    with pytest.raises(ca.ShapeError, match="same length"):
        _core.separable_allocation(
            list(st.a_blocks), list(st.g_blocks)[:2], list(st.c_blocks), 1.0, 1.0, 1e-12, 10
        )
    assert decoupled_start(ca.Network(net.a, net.g, list(net.sensors)), 3.0, 1e-12) is None


@pytest.mark.parametrize("n_sens", [3, 10])
def test_warm_started_and_cold_newton_give_the_same_optimum(
    n_sens: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``warm=True`` (every point from the previous one), ``warm=False`` (every point cold) and the
    default agree; ``warm=True`` really warm-starts, ``warm=False`` never does."""
    net = ca.Network.random(n_sens, 2, eps=0.1, seed=2)
    seen: list[bool] = []
    orig = ca.network.CostPoint.warm

    def spy(self: ca.network.CostPoint, r: np.ndarray) -> ca.network.CostPoint:
        seen.append(True)
        return orig(self, r)

    monkeypatch.setattr(ca.network.CostPoint, "warm", spy)
    r_tot = 3.0 * n_sens
    cold = optimal_allocation(net, r_tot, warm=False, engine="python")
    assert not seen
    hot = optimal_allocation(net, r_tot, warm=True, engine="python")
    assert seen
    _same_optimum(hot, cold, tol=1e-13)
    _same_optimum(optimal_allocation(net, r_tot, engine="python"), cold, tol=1e-13)
    # The core loop (its warm starts are in Rust) agrees warm or cold.
    for w in (True, False, None):
        _same_optimum(optimal_allocation(net, r_tot, warm=w, engine="core"), cold, tol=1e-13)
    with pytest.raises(ca.InvalidInputError, match="warm"):
        optimal_allocation(net, 3.0 * n_sens, warm="yes")  # type: ignore[arg-type]


def test_a_point_reached_from_the_decoupled_covariance_is_the_cold_point() -> None:
    from capalloc_rs.allocation.decoupled import decoupled_covariance

    net = ca.Network.random(12, 2, eps=0.05, seed=7)
    r = np.linspace(1.5, 4.0, 12)
    s0 = decoupled_covariance(net, r)
    warm = net.at(r, start=s0)
    cold = net.at(r)
    assert warm.warm_started and warm.warm_fallback is None
    assert abs(warm.value - cold.value) <= warm.value_error + cold.value_error
    assert warm.value == pytest.approx(cold.value, rel=1e-13)
    np.testing.assert_allclose(warm.gradient, cold.gradient, rtol=1e-10, atol=0)
    # A start that is not stabilising: the cold solve, and the reason.
    bad = net.at(r, start=np.zeros((net.n, net.n)))
    assert bad.warm_fallback is not None and bad.value == cold.value
    with pytest.raises(ca.ShapeError, match="start"):
        net.at(r, start=np.eye(3))
    with pytest.raises(ca.NonFiniteError, match="start"):
        net.at(r, start=np.full((net.n, net.n), np.nan))
