"""The optimal allocation with sample costs, per-sensor minima and caps (issue 15, point 3):
``min η(r)`` over ``{r_min,i ≤ r_i ≤ r_max,i, Σ b_i r_i = B}``.

Independent routes: cvxpy's SDP ``min tr(M X)`` with the Riccati LMI on the weighted box-simplex
(Clarabel), central differences of η* in the limits and the budget for the KKT multipliers, a
tight reference optimum for the certificate, scipy's SLSQP on the cost in channel units, and the
paper-form network with the whitened sensors ``c_i/√b_i`` when the minima are equal in channel
units.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.optimize import minimize

import capalloc_rs as cr
from capalloc_rs import errors
from capalloc_rs.allocation.box_simplex import project_box_simplex
from capalloc_rs.allocation.budgeted import box_problem
from capalloc_rs.allocation.result import make_box_allocation

INF = np.inf


def _blocks(seed: int, n_sub: int = 4, eps: float = 0.1) -> Any:
    return cr.Network.random(n_sub, 2, eps=eps, seed=seed).structure


def _net(seed: int, costs: Any, r_min: Any, r_max: Any, weight: Any = None, **kw: Any) -> Any:
    st = _blocks(seed, **kw)
    return cr.Network.from_blocks(
        st.a_blocks,
        st.g_blocks,
        st.c_blocks,
        st.coupling,
        st.eps,
        r_min=r_min,
        weight=weight,
        costs=costs,
        r_max=r_max,
    )


def _heterogeneous(seed: int, weight: Any = None) -> tuple[Any, float]:
    """A network with unequal costs and minima, one sensor capped at 85 % of its uncapped optimum
    (so the cap is active), and its budget."""
    rng = np.random.default_rng(seed)
    costs, r_min = rng.uniform(0.5, 3.0, 4), rng.uniform(0.5, 1.5, 4)
    budget = float(costs @ r_min) + 6.0
    free = cr.optimal_allocation(_net(seed, costs, r_min, INF, weight), budget)
    r_max = np.full(4, INF)
    i = int(np.argmax(free.r - r_min))
    r_max[i] = r_min[i] + 0.85 * (free.r[i] - r_min[i])
    return _net(seed, costs, r_min, r_max, weight), budget


def _weight(n: int, seed: int) -> Any:
    m = np.random.default_rng(seed).normal(size=(n, n))
    return m @ m.T + 0.1 * np.eye(n)


def _sdp(net: Any, budget: float) -> tuple[float, Any]:
    """``min tr(M X)`` with ``X ⪰ Y⁻¹`` (Schur complement), the Riccati LMI
    ``YA + AᵀY − Σ r_i c_i c_iᵀ + Y G Gᵀ Y ⪯ 0`` and the weighted box-simplex on the rates."""
    cp = pytest.importorskip("cvxpy")
    n, ns = net.a.shape[0], len(net.sensors)
    m = net.error_weight if net.error_weight is not None else np.eye(n)
    ell = np.linalg.cholesky(m + 1e-300 * np.eye(n))
    y = cp.Variable((n, n), symmetric=True)
    t = cp.Variable((n, n), symmetric=True)
    r = cp.Variable(ns)
    info = sum(r[i] * (net.sensors[i] @ net.sensors[i].T) for i in range(ns))
    ric = cp.bmat(
        [[y @ net.a + net.a.T @ y - info, y @ net.g], [net.g.T @ y, -np.eye(net.g.shape[1])]]
    )
    r_max = np.asarray(net.rate_max)
    capped = np.flatnonzero(np.isfinite(r_max))
    cons = [
        cp.bmat([[t, ell.T], [ell, y]]) >> 0,
        (ric + ric.T) / 2 << 0,
        np.asarray(net.costs) @ r == budget,
        r >= np.asarray(net.rate_min),
    ]
    if capped.size:
        cons.append(r[capped] <= r_max[capped])
    prob = cp.Problem(cp.Minimize(cp.trace(t)), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert prob.status == "optimal"
    return float(prob.value), np.asarray(r.value)


@pytest.mark.parametrize(("seed", "weighted"), [(2, False), (6, False), (9, True), (13, True)])
def test_optimum_matches_the_sdp(seed: int, weighted: bool) -> None:
    weight = _weight(8, seed) if weighted else None
    net, budget = _heterogeneous(seed, weight)
    a = cr.optimal_allocation(net, budget)
    assert a.at_cap and a.at_minimum  # both kinds of bounds are active here
    eta, r = _sdp(net, budget)
    assert a.eta == pytest.approx(eta, rel=1e-7)
    # The SDP's rates are only as accurate as √(its gap) along flat directions of η (2e-5 here
    # at gap 1e-10): they are checked to 1e-4, and our η is no worse at the SDP's own rates.
    np.testing.assert_allclose(a.r, r, rtol=1e-4)
    assert a.eta <= net.cost(np.maximum(r, np.asarray(net.rate_min))) * (1 + 1e-12)
    assert a.gap <= 1e-10 * a.eta
    assert float(np.asarray(net.costs) @ a.r) == pytest.approx(budget, rel=1e-14)


@pytest.mark.parametrize("seed", [2, 9])
def test_the_three_methods_agree(seed: int) -> None:
    net, budget = _heterogeneous(seed)
    ref = cr.optimal_allocation(net, budget, hessian="exact")
    for kw in ({"hessian": "hvp"}, {"method": "projected-gradient"}):
        a = cr.optimal_allocation(net, budget, **kw)
        np.testing.assert_allclose(a.r, ref.r, rtol=1e-9)
        assert a.eta == pytest.approx(ref.eta, rel=1e-12)
        assert a.at_cap == ref.at_cap and a.at_minimum == ref.at_minimum
        assert a.mu == pytest.approx(ref.mu, rel=1e-7)


def _eta_star(seed: int, costs: Any, r_min: Any, r_max: Any, budget: float) -> float:
    return cr.optimal_allocation(_net(seed, costs, r_min, r_max), budget, tol=1e-14).eta


def test_multipliers_are_the_sensitivities_of_the_optimum() -> None:
    """``dη*/dr_max,i = −b_i ν_i`` at a cap, ``dη*/dr_min,i = b_i λ_i`` at a minimum and
    ``dη*/dB = μ``, against central differences of re-solved optima."""
    seed = 6
    net, budget = _heterogeneous(seed)
    a = cr.optimal_allocation(net, budget, tol=1e-14)
    b, lo, hi = (np.asarray(v, dtype=float) for v in (net.costs, net.rate_min, net.rate_max))
    h = 1e-4
    (k,) = a.at_cap
    up, dn = hi.copy(), hi.copy()
    up[k] += h
    dn[k] -= h
    d_cap = (_eta_star(seed, b, lo, up, budget) - _eta_star(seed, b, lo, dn, budget)) / (2 * h)
    assert d_cap == pytest.approx(-b[k] * a.upper_multipliers[k], rel=1e-5)
    assert a.upper_multipliers[k] > 0.0
    for j in a.at_minimum:
        up, dn = lo.copy(), lo.copy()
        up[j] += h
        dn[j] -= h
        d_min = (_eta_star(seed, b, up, hi, budget) - _eta_star(seed, b, dn, hi, budget)) / (2 * h)
        assert d_min == pytest.approx(b[j] * a.lower_multipliers[j], rel=1e-5)
        assert a.lower_multipliers[j] > 0.0
    d_budget = (_eta_star(seed, b, lo, hi, budget + h) - _eta_star(seed, b, lo, hi, budget - h)) / (
        2 * h
    )
    assert a.shadow_price == pytest.approx(-d_budget, rel=1e-6)
    # In rates: ∂η/∂r_i = μ b_i on the free set.
    free = [i for i in range(4) if i not in a.at_cap and i not in a.at_minimum]
    np.testing.assert_allclose(a.gradient[free], a.mu * b[free], rtol=1e-9)


@pytest.mark.parametrize("seed", [2, 11])
def test_certificate_bounds_the_true_gap(seed: int) -> None:
    """At feasible points (random ones, and iterates stopped early by a loose tolerance) the
    box-simplex Frank–Wolfe gap is at least ``η(r) − η*``, η* from a tight solve."""
    net, budget = _heterogeneous(seed)
    star = cr.optimal_allocation(net, budget, tol=1e-14).eta
    prob = box_problem(net, budget)
    rng = np.random.default_rng(seed)
    for _ in range(10):
        gamma = project_box_simplex(rng.uniform(0, 3, 4), prob.cap, prob.sigma)
        a = make_box_allocation(prob, gamma, 0, "probe", 0.0)
        assert a.gap >= a.eta - star - 1e-12 * star
        assert a.gap >= 0.0
    for kw in ({"hessian": "exact"}, {"hessian": "hvp"}, {"method": "projected-gradient"}):
        for tol in (1e-2, 1e-4, 1e-6):
            a = cr.optimal_allocation(net, budget, tol=tol, start="uniform", **kw)
            assert a.eta - star <= a.gap + 1e-12 * star
            assert a.gap <= tol * a.eta


def test_costs_alone_equal_the_whitened_paper_network() -> None:
    """With ``r_min,i = ρ/b_i`` the network in channel units has the common minimum ρ and no
    caps: it is the paper-form network with sensors ``c_i/√b_i``, whose optimum ``s`` gives
    ``r = s/b``."""
    seed, rho = 4, 0.8
    costs = np.array([0.5, 2.0, 1.25, 3.0])
    net = _net(seed, costs, rho / costs, INF)
    st = _blocks(seed)
    paper = cr.Network.from_blocks(
        st.a_blocks,
        st.g_blocks,
        [c / np.sqrt(b) for c, b in zip(st.c_blocks, costs, strict=True)],
        st.coupling,
        st.eps,
        r_min=rho,
    )
    budget = 10.0
    a, p = cr.optimal_allocation(net, budget), cr.optimal_allocation(paper, budget)
    np.testing.assert_allclose(a.r, p.r / costs, rtol=1e-10)
    assert a.eta == pytest.approx(p.eta, rel=1e-12)
    assert a.mu == pytest.approx(p.mu, rel=1e-8)


def test_costs_with_a_common_minimum_against_slsqp() -> None:
    """Costs only, one common minimum (unequal in channel units): the optimum against scipy's
    SLSQP on the cost in channel units."""
    costs = np.array([0.5, 2.0, 1.25, 3.0])
    net = _net(5, costs, 1.0, INF)
    budget = 14.0
    a = cr.optimal_allocation(net, budget)
    cu = net.in_channel_units()
    lo = np.asarray(cu.rate_min)
    res = minimize(
        lambda s: cu.cost(s),
        project_box_simplex(np.zeros(4), np.full(4, INF), budget - lo.sum()) + lo,
        jac=lambda s: cu.gradient(s),
        bounds=[(v, None) for v in lo],
        constraints=[{"type": "eq", "fun": lambda s: s.sum() - budget}],
        method="SLSQP",
        options={"ftol": 1e-15, "maxiter": 500},
    )
    assert a.eta <= res.fun * (1 + 1e-12)
    np.testing.assert_allclose(a.r, res.x / costs, rtol=1e-5)


#: Today's results (main before issue 15, recorded on this machine) of
#: ``optimal_allocation(Network.random(5, 2, eps=0.05, seed=s), 12.0, **kw)`` and
#: ``integer_allocation(..., 14)``: η, r, μ as float.hex(), the integer counts.
_TODAY = {
    (1, "core"): ("0x1.37af0b2491aecp+3", "-0x1.a04faaba125dbp-3"),
    (1, "python-exact"): ("0x1.37af0b2491aecp+3", "-0x1.a04faaba125e0p-3"),
    (1, "hvp"): ("0x1.37af0b2491aecp+3", "-0x1.a04faaba125e1p-3"),
    (1, "pg"): ("0x1.37af0b2491aecp+3", "-0x1.a04faaba12573p-3"),
    (2, "core"): ("0x1.b0b7c1cee2505p+3", "-0x1.70eec90e172e3p-2"),
    (2, "python-exact"): ("0x1.b0b7c1cee2505p+3", "-0x1.70eec90e172e0p-2"),
    (2, "hvp"): ("0x1.b0b7c1cee2505p+3", "-0x1.70eec90e172e8p-2"),
    (2, "pg"): ("0x1.b0b7c1cee2505p+3", "-0x1.70eec90e11cf8p-2"),
    (3, "core"): ("0x1.c934e1c3519adp+3", "-0x1.5c975e883f9ecp-2"),
    (3, "python-exact"): ("0x1.c934e1c3519acp+3", "-0x1.5c975e883f9e6p-2"),
    (3, "hvp"): ("0x1.c934e1c3519acp+3", "-0x1.5c975e883fa87p-2"),
    (3, "pg"): ("0x1.c934e1c3519acp+3", "-0x1.5c975e8844b78p-2"),
}
_TODAY_R = {
    (1, "core"): [
        "0x1.e773d1e41a427p+1",
        "0x1.6677608715716p+1",
        "0x1.0000000000000p+0",
        "0x1.b214cd94d04c3p+1",
        "0x1.0000000000000p+0",
    ],
    (2, "python-exact"): [
        "0x1.0000000000000p+0",
        "0x1.212765b584280p+1",
        "0x1.3cc2d4353dcdcp+1",
        "0x1.d47f752776b50p+1",
        "0x1.4d9650edc7554p+1",
    ],
    (3, "hvp"): [
        "0x1.0000000000000p+0",
        "0x1.866c244460763p+1",
        "0x1.2dd518c70737ap+1",
        "0x1.3940175cadd1fp+1",
        "0x1.927eab97ea803p+1",
    ],
}
_TODAY_INT = {1: [4, 4, 1, 4, 1], 2: [1, 3, 3, 4, 3], 3: [1, 3, 3, 3, 4]}
_KW: dict[str, dict[str, Any]] = {
    "core": {},
    "python-exact": {"engine": "python", "hessian": "exact"},
    "hvp": {"hessian": "hvp"},
    "pg": {"method": "projected-gradient"},
}


@pytest.mark.parametrize(("seed", "name"), sorted(_TODAY))
def test_the_papers_case_is_bitwise_todays(seed: int, name: str) -> None:
    """A network in the paper's form takes today's code path: ``in_channel_units()`` is the
    network itself, the box-simplex solvers are never called (they are patched to fail here),
    an explicit ``costs=1, r_max=inf`` builds the same network, and the numbers are bit for bit
    those recorded on main before the change."""
    net = cr.Network.random(5, 2, eps=0.05, seed=seed)
    assert net.is_paper_form and net.in_channel_units() is net
    a = cr.optimal_allocation(net, 12.0, **_KW[name])
    eta, mu = _TODAY[(seed, name)]
    assert a.eta.hex() == eta and a.mu.hex() == mu
    if (seed, name) in _TODAY_R:
        assert [x.hex() for x in a.r] == _TODAY_R[(seed, name)]
    assert a.at_cap == () and list(a.upper_multipliers) == [0.0] * 5
    st = net.structure
    explicit = cr.Network.from_blocks(
        st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, st.eps, costs=1.0, r_max=INF
    )
    assert explicit.is_paper_form
    b = cr.optimal_allocation(explicit, 12.0, **_KW[name])
    assert b.eta.hex() == a.eta.hex() and [x.hex() for x in b.r] == [x.hex() for x in a.r]


@pytest.mark.parametrize("seed", sorted(_TODAY_INT))
def test_the_papers_integer_case_is_todays(seed: int) -> None:
    ia = cr.integer_allocation(cr.Network.random(5, 2, eps=0.05, seed=seed), 14)
    assert list(ia.counts) == _TODAY_INT[seed] and ia.budget is None


def test_paper_form_never_reaches_the_box_solvers(monkeypatch: pytest.MonkeyPatch) -> None:
    from capalloc_rs.allocation import optimal

    def fail(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("box-simplex path taken for a paper-form network")

    monkeypatch.setattr(optimal, "budgeted_allocation", fail)
    cr.optimal_allocation(cr.Network.random(4, 2, seed=0), 9.0)


def test_budget_at_the_ends_of_its_range() -> None:
    costs, r_min, r_max = np.array([1.0, 2.0, 0.5]), np.array([1.0, 0.5, 2.0]), [2.0, 3.0, 4.0]
    net = _net(3, costs, r_min, r_max, n_sub=3)
    low, high = net.budget_range
    a = cr.optimal_allocation(net, low)
    np.testing.assert_allclose(a.r, r_min, rtol=1e-15)
    assert a.at_minimum == (0, 1, 2) and a.gap == 0.0
    b = cr.optimal_allocation(net, high)
    np.testing.assert_allclose(b.r, r_max, rtol=1e-15)
    assert b.at_cap == (0, 1, 2) and b.gap == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("budget", [1.0, 100.0, -3.0])
def test_budget_outside_the_range_is_refused(budget: float) -> None:
    net = _net(3, [1.0, 2.0, 0.5], [1.0, 0.5, 2.0], [2.0, 3.0, 4.0], n_sub=3)
    with pytest.raises(errors.InvalidInputError, match=r"r_tot.*budget range"):
        cr.optimal_allocation(net, budget)


def test_what_only_exists_for_the_simplex_is_refused() -> None:
    net, budget = _heterogeneous(2)
    with pytest.raises(errors.FeatureUnavailableError, match="method='double-bracket'"):
        cr.optimal_allocation(net, budget, method="double-bracket")
    with pytest.raises(errors.FeatureUnavailableError, match="engine='core'"):
        cr.optimal_allocation(net, budget, engine="core")
    with pytest.raises(errors.InvalidInputError, match="start='decoupled'"):
        cr.optimal_allocation(net, budget, start="decoupled")
    with pytest.raises(errors.InvalidInputError, match="start"):
        cr.optimal_allocation(net, budget, start="middle")  # type: ignore[arg-type]
    with pytest.raises(errors.InvalidInputError, match="gamma0"):
        cr.optimal_allocation(net, budget, gamma0=[1.0, 1.0, 1.0, 1e9])


def test_decoupled_start_with_costs_alone() -> None:
    """Equal minima in channel units and no caps: the decoupled start exists and gives the same
    optimum as the uniform one."""
    costs = np.array([0.5, 2.0, 1.25, 3.0])
    net = _net(4, costs, 0.8 / costs, INF)
    a = cr.optimal_allocation(net, 10.0, start="decoupled")
    b = cr.optimal_allocation(net, 10.0, start="uniform")
    np.testing.assert_allclose(a.r, b.r, rtol=1e-9)


@pytest.mark.parametrize("seed", [2, 6, 9])
def test_every_start_reaches_the_same_optimum(seed: int) -> None:
    """Unequal minima and a cap: ``start="auto"`` (the projected decoupled optimum) and the
    projected uniform point give the same optimum, with either Newton variant."""
    net, budget = _heterogeneous(seed)
    ref = cr.optimal_allocation(net, budget, start="uniform", hessian="exact")
    for kw in ({"hessian": "exact"}, {"hessian": "hvp"}, {"hessian": "hvp", "start": "uniform"}):
        a = cr.optimal_allocation(net, budget, **kw)
        np.testing.assert_allclose(a.r, ref.r, rtol=1e-9)
        assert a.at_cap == ref.at_cap and a.at_minimum == ref.at_minimum


def test_result_reports_the_new_fields() -> None:
    net, budget = _heterogeneous(6)
    a = cr.optimal_allocation(net, budget)
    d = a.to_dict()
    assert d["budget"] == budget and d["costs"] == list(np.asarray(net.costs))
    assert d["at_cap"] == list(a.at_cap) and d["at_minimum"] == list(a.at_minimum)
    assert len(d["lower_multipliers"]) == len(d["upper_multipliers"]) == 4
    assert d["shadow_price"] == -d["mu"] > 0
    text = repr(a)
    assert "at_cap=1" in text and "\n" not in text
