"""optimal_allocation(method="newton", hessian="hvp"): Newton–CG with Hessian-vector products
from one cached evaluation point per step, against the exact-Hessian Newton method and the
projected gradient method."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import capalloc_rs.allocation as al
import capalloc_rs.allocation.newton as al_newton
import capalloc_rs.allocation.optimal as al_optimal
from capalloc_rs import Network, errors
from capalloc_rs.allocation import optimal_allocation


def net_random(seed: int, n_sub: int = 8, eps: float = 0.1, **kw: Any) -> Network:
    return Network.random(n_sub, 2, eps=eps, seed=seed, **kw)


class CountingPoint:
    def __init__(self, owner: CountingNetwork, point: Any) -> None:
        self._owner, self._point = owner, point
        self.products = 0
        owner.points.append(self)

    @property
    def value(self) -> float:
        return float(self._point.value)

    @property
    def gradient(self) -> np.ndarray:
        return np.asarray(self._point.gradient)

    def hvp(self, v: Any) -> np.ndarray:
        v = np.asarray(v)
        self.products += 1 if v.ndim == 1 else v.shape[1]
        return np.asarray(self._point.hvp(v))

    def hessian(self) -> np.ndarray:
        self._owner.hessians += 1
        return np.asarray(self._point.hessian())


class CountingNetwork:
    """A Network wrapper that counts full Hessians and Hessian-vector products."""

    def __init__(self, net: Network) -> None:
        self.net = net
        self.hessians = 0
        self.points: list[CountingPoint] = []

    @property
    def r_min(self) -> float:
        return self.net.r_min

    @property
    def sensors(self) -> Any:
        return self.net.sensors

    @property
    def structure(self) -> Any:
        return self.net.structure

    def cost(self, r: Any) -> float:
        return self.net.cost(r)

    def gradient(self, r: Any) -> np.ndarray:
        return self.net.gradient(r)

    def value_and_gradient(self, r: Any) -> tuple[float, np.ndarray]:
        return self.net.value_and_gradient(r)

    def hessian(self, r: Any) -> np.ndarray:
        self.hessians += 1
        return self.net.hessian(r)

    def value_gradient_hessian(self, r: Any) -> tuple[float, np.ndarray, np.ndarray]:
        self.hessians += 1
        return self.net.value_gradient_hessian(r)

    def at(self, r: Any) -> CountingPoint:
        return CountingPoint(self, self.net.at(r))


def assert_same_optimum(a: al.Allocation, b: al.Allocation, rel: float = 1e-10) -> None:
    assert a.eta == pytest.approx(b.eta, rel=rel)
    np.testing.assert_allclose(a.r, b.r, rtol=0, atol=1e-5 * max(1.0, a.sigma))
    np.testing.assert_array_equal(a.active, b.active)


@pytest.mark.parametrize(
    ("seed", "n_sub", "eps", "extra"),
    [(0, 6, 0.1, 6.0), (1, 8, 0.3, 4.0), (2, 10, 0.05, 30.0), (3, 12, 0.8, 12.0), (4, 7, 0.0, 9.0)],
)
def test_newton_cg_reaches_the_exact_newton_and_gradient_optimum(
    seed: int, n_sub: int, eps: float, extra: float
) -> None:
    net = net_random(seed, n_sub, eps)
    r_tot = n_sub * net.r_min + extra
    tol = 1e-11
    # From the uniform start, so that CG has work to do (at ε = 0 the decoupled start is optimal).
    cg = optimal_allocation(net, r_tot, hessian="hvp", tol=tol, start="uniform")
    exact = optimal_allocation(net, r_tot, hessian="exact", tol=tol)
    pg = optimal_allocation(net, r_tot, method="projected-gradient", tol=tol)
    assert cg.method == "newton" and cg.hessian == "hvp" and cg.hvp_count > 0
    assert_same_optimum(cg, optimal_allocation(net, r_tot, hessian="hvp", tol=tol))
    assert exact.hessian == "exact" and exact.hvp_count == 0
    assert pg.hessian is None and pg.hvp_count == 0
    assert cg.gap <= tol * cg.eta
    assert cg.r.sum() == pytest.approx(r_tot, rel=1e-14) and np.all(cg.r >= net.r_min)
    assert_same_optimum(cg, exact)
    assert_same_optimum(cg, pg)
    # KKT of Theorem 1 at the Newton–CG point.
    np.testing.assert_allclose(cg.gradient[cg.active], cg.mu, rtol=1e-8)
    inactive = np.setdiff1d(np.arange(n_sub), cg.active)
    assert np.all(cg.gradient[inactive] >= cg.mu * (1 + 1e-9))


def test_newton_cg_on_a_general_network_without_preconditioner() -> None:
    blk = net_random(5, 9, 0.2)
    gen = Network(blk.a, blk.g, list(blk.sensors))  # same model, no block structure
    assert (
        al_newton._decoupled_curvature(gen) is None
        and al_newton._decoupled_curvature(blk) is not None
    )
    a = optimal_allocation(gen, 9 + 8.0, hessian="hvp")
    b = optimal_allocation(blk, 9 + 8.0, hessian="exact")
    assert a.gap <= 1e-12 * a.eta
    assert_same_optimum(a, b)


def test_newton_cg_preconditioner_is_formed_again_only_when_rates_move(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """After the decoupled start the rates move by O(ε): one set of decoupled curvatures serves
    the solve; from the uniform start they are formed again after the long first step. The
    optimum is the exact-Hessian one either way."""
    net = net_random(4, 30, eps=0.05)
    calls: list[np.ndarray] = []
    make = al_newton._decoupled_curvature

    def counting(n: object) -> object:
        f = make(n)
        assert f is not None

        def curvature(r: np.ndarray) -> np.ndarray:
            calls.append(r.copy())
            return f(r)

        return curvature

    monkeypatch.setattr(al_newton, "_decoupled_curvature", counting)
    exact = optimal_allocation(net, 3 * 30, hessian="exact")
    for start, at_least in (("decoupled", 1), ("uniform", 2)):
        calls.clear()
        a = optimal_allocation(net, 3 * 30, hessian="hvp", start=start)
        assert a.gap <= 1e-12 * a.eta and a.iterations >= 2
        assert_same_optimum(a, exact)
        assert len(calls) >= at_least
        if start == "decoupled":
            assert len(calls) == 1
        # Formed again only after a move of more than 10 %.
        for prev, cur in zip(calls[:-1], calls[1:], strict=True):
            assert np.any(np.abs(cur - prev) > al_newton.PRECONDITIONER_RTOL * prev)


def test_newton_cg_with_a_sensor_that_never_becomes_active() -> None:
    base = net_random(8, 4, eps=0.05)
    weak = [s if i != 2 else 1e-3 * s for i, s in enumerate(base.sensors)]
    net = Network(base.a, base.g, weak, r_min=1.0)
    a = optimal_allocation(net, 4 + 20.0, hessian="hvp")
    assert 2 not in a.active and a.gamma[2] == 0.0 and a.gradient[2] > a.mu
    assert_same_optimum(a, optimal_allocation(net, 4 + 20.0, hessian="exact"))


def test_newton_cg_many_inactive_sensors_and_tiny_capacity() -> None:
    net = net_random(12, 15, eps=0.1)
    for extra in (1e-3, 0.5, 3.0):
        a = optimal_allocation(net, 15 + extra, hessian="hvp")
        b = optimal_allocation(net, 15 + extra, hessian="exact")
        assert a.gap <= 1e-12 * a.eta
        assert_same_optimum(a, b)
        assert a.active.size < 15
    one = optimal_allocation(net, 15 + 1e-3, hessian="hvp")
    assert one.active.size == 1  # only the most valuable sensor gets the sliver


def test_newton_cg_boundary_cases() -> None:
    net = net_random(7, 3)
    zero = optimal_allocation(net, 3.0, hessian="hvp")  # σ = 0
    assert zero.sigma == 0.0 and zero.active.size == 0 and zero.gap == 0.0
    assert zero.hessian == "hvp" and zero.hvp_count == 0
    np.testing.assert_array_equal(zero.r, np.ones(3))
    single = Network.random(1, 3, seed=2)  # N = 1: one sensor
    one = optimal_allocation(single, 5.0, hessian="hvp")
    assert one.r.tolist() == [5.0] and one.gap == 0.0
    assert one.eta == pytest.approx(single.cost([5.0]))
    general_one = Network(single.a, single.g, list(single.sensors))
    assert optimal_allocation(general_one, 5.0, hessian="hvp").eta == pytest.approx(one.eta)


def test_newton_cg_with_a_non_regular_subsystem() -> None:
    """The paper's Example 1 is not a regular triplet: its η'' can vanish, so the Hessian may be
    singular and CG meets (numerically) zero curvature."""
    g1 = np.linalg.cholesky(np.array([[5.0, -3.0], [-3.0, 4.0]]))
    rng = np.random.default_rng(1)
    a_blocks = [np.diag([-1.0, -2.0]), np.array([[0.0, 1.0], [-2.0, -0.5]]), np.array([[-0.3]])]
    g_blocks = [g1, np.eye(2), np.array([[0.7]])]
    c_blocks = [np.array([1.0, 1.0]), np.array([1.0, 0.0]), np.array([1.0])]
    coupling = rng.standard_normal((5, 5))
    for lo, hi in ((0, 2), (2, 4), (4, 5)):
        coupling[lo:hi, lo:hi] = 0.0
    net = Network.from_blocks(a_blocks, g_blocks, c_blocks, coupling, eps=0.05)
    assert net.check().subsystems[0].regular is False
    a = optimal_allocation(net, 3 + 6.0, hessian="hvp")
    b = optimal_allocation(net, 3 + 6.0, method="projected-gradient")
    assert a.eta == pytest.approx(b.eta, rel=1e-10)
    assert a.gap <= 1e-12 * a.eta


def test_newton_cg_from_different_starts() -> None:
    net = net_random(6, 6, eps=0.2)
    rng = np.random.default_rng(1)
    sols = [
        optimal_allocation(net, 16.0, hessian="hvp", gamma0=rng.dirichlet(np.ones(6)) * 10.0)
        for _ in range(4)
    ]
    vertex = np.zeros(6)
    vertex[3] = 10.0
    sols.append(optimal_allocation(net, 16.0, hessian="hvp", gamma0=vertex))
    for s in sols[1:]:
        np.testing.assert_allclose(s.r, sols[0].r, atol=1e-8)


def test_newton_cg_never_forms_the_hessian() -> None:
    n_sub = 60
    net = CountingNetwork(net_random(21, n_sub, eps=0.05))
    a = optimal_allocation(net, 3.0 * n_sub, hessian="hvp")
    assert a.hessian == "hvp" and a.gap <= 1e-12 * a.eta
    assert net.hessians == 0
    per_point = [p.products for p in net.points]
    assert sum(per_point) == a.hvp_count > 0
    # Far fewer products than the N solves of one exact Hessian, at every step.
    assert max(per_point) < n_sub // 2
    assert a.hvp_count < n_sub * a.iterations // 2
    # One evaluation point per Newton step (plus the last), none wasted on re-solving the CARE.
    assert len(net.points) <= a.iterations + 2
    # The same counter sees the exact variant's Hessians.
    counted = CountingNetwork(net.net)
    b = optimal_allocation(counted, 3.0 * n_sub, hessian="exact")
    assert counted.hessians == b.iterations > 0
    assert sum(p.products for p in counted.points) == 0
    assert_same_optimum(a, b)


def test_auto_picks_exact_for_small_and_hvp_for_large_networks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    small = net_random(0, 5)
    assert optimal_allocation(small, 12.0).hessian == "exact"
    assert optimal_allocation(small, 12.0, hessian="auto").hessian == "exact"
    monkeypatch.setattr(al_optimal, "HVP_MIN_SENSORS", 5)
    big = optimal_allocation(small, 12.0)
    assert big.hessian == "hvp" and big.hvp_count > 0
    assert big.method == "newton"

    class NoPoints:  # a network without at(r): auto falls back to the exact Hessian
        def __init__(self, net: Network) -> None:
            self._net = net
            self.r_min, self.sensors = net.r_min, net.sensors

        def cost(self, r: Any) -> float:
            return self._net.cost(r)

        def gradient(self, r: Any) -> np.ndarray:
            return self._net.gradient(r)

        def hessian(self, r: Any) -> np.ndarray:
            return self._net.hessian(r)

    plain = NoPoints(small)
    res = optimal_allocation(plain, 12.0)  # type: ignore[arg-type]
    assert res.hessian == "exact" and res.eta == pytest.approx(big.eta, rel=1e-10)
    with pytest.raises(errors.InvalidInputError, match="at"):
        optimal_allocation(plain, 12.0, hessian="hvp")  # type: ignore[arg-type]


def test_bad_hessian_argument() -> None:
    net = net_random(0, 3)
    with pytest.raises(errors.InvalidInputError, match="hessian"):
        optimal_allocation(net, 6.0, hessian="cg")  # type: ignore[arg-type]
    # Other methods ignore the Newton variant.
    pg = optimal_allocation(net, 6.0, method="projected-gradient", hessian="hvp")
    assert pg.hessian is None


def test_allocation_stays_backwards_compatible() -> None:
    """The new fields have defaults: code that builds an Allocation the old way still works."""
    a = optimal_allocation(net_random(1, 3), 7.0)
    old = al.Allocation(
        a.r, a.gamma, a.sigma, a.r_tot, a.eta, a.gradient, a.mu, a.active, a.kkt_residual, a.gap,
        a.iterations, a.method,
    )  # fmt: skip
    assert old.hessian is None and old.hvp_count == 0
