"""The box-simplex ``{0 ≤ x ≤ c, Σx = σ}`` of the allocation with costs and limits: projection,
Frank–Wolfe vertex and gap, KKT multipliers and the active-set QP, each against an independent
route (a root finder, a linear program, a convex QP solver)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq, linprog

from capalloc_rs.allocation.box_simplex import (
    box_frank_wolfe,
    box_frank_wolfe_gap,
    box_kkt,
    box_qp,
    project_box_simplex,
)
from capalloc_rs.allocation.simplex import frank_wolfe_gap, project_simplex


def _case(seed: int, n: int, capped: float = 0.5) -> tuple[np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng(seed)
    y = 3.0 * rng.normal(size=n)
    cap = np.where(rng.random(n) < capped, rng.uniform(0.1, 2.0, n), np.inf)
    total = float(np.sum(cap)) if np.all(np.isfinite(cap)) else 5.0 * n
    return y, cap, float(rng.uniform(0.0, 1.0) * total)


@pytest.mark.parametrize("seed", range(40))
def test_projection_solves_the_threshold_equation(seed: int) -> None:
    """x = clip(y − τ, 0, c) with Σx = σ, τ found independently by Brent's method."""
    n = 1 + seed % 7
    y, cap, sigma = _case(seed, n)
    x = project_box_simplex(y, cap, sigma)
    assert np.all(x >= 0.0) and np.all(x <= cap)
    assert x.sum() == pytest.approx(sigma, abs=1e-12 * max(sigma, 1.0))

    def phi(t: float) -> float:
        return float(np.sum(np.clip(y - t, 0.0, cap))) - sigma

    lo, hi = (
        float(np.min(y - np.where(np.isfinite(cap), cap, 0.0))) - 10.0 * n - 10.0,
        float(np.max(y)),
    )
    if phi(lo) <= 0.0 or phi(hi) >= 0.0:
        return  # σ at an end of the range: the point is forced
    tau = brentq(phi, lo, hi, xtol=1e-15, rtol=1e-15)
    np.testing.assert_allclose(x, np.clip(y - tau, 0.0, cap), atol=1e-10)


def test_projection_without_caps_is_the_simplex_projection() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        y = rng.normal(size=6)
        np.testing.assert_allclose(
            project_box_simplex(y, np.full(6, np.inf), 2.5), project_simplex(y, 2.5), atol=1e-14
        )


def test_projection_at_the_ends_of_the_range() -> None:
    cap = np.array([1.0, 2.0, 0.5])
    y = np.array([3.0, -1.0, 0.2])
    np.testing.assert_array_equal(project_box_simplex(y, cap, 3.5), cap)
    np.testing.assert_array_equal(project_box_simplex(y, cap, 0.0), np.zeros(3))


@pytest.mark.parametrize("seed", range(20))
def test_frank_wolfe_vertex_is_the_linear_programs_optimum(seed: int) -> None:
    n = 2 + seed % 6
    g, cap, sigma = _case(seed, n)
    fw, _ = box_frank_wolfe(g, cap, sigma)
    bounds = [(0.0, None if np.isinf(c) else float(c)) for c in cap]
    lp = linprog(g, A_eq=np.ones((1, n)), b_eq=[sigma], bounds=bounds, method="highs")
    assert lp.status == 0
    assert g @ fw == pytest.approx(lp.fun, abs=1e-10 * (1.0 + abs(lp.fun)))
    # The gap at any feasible point is gᵀ(x − x_FW) ≥ 0.
    x = project_box_simplex(np.random.default_rng(seed).normal(size=n), cap, sigma)
    gap = box_frank_wolfe_gap(x, g, cap, sigma)
    assert gap >= 0.0
    assert gap == pytest.approx(g @ x - lp.fun, abs=1e-10 * (1.0 + abs(lp.fun)))


def test_gap_without_caps_is_the_simplex_gap() -> None:
    rng = np.random.default_rng(0)
    g = rng.normal(size=5)
    x = project_simplex(rng.normal(size=5), 3.0)
    assert box_frank_wolfe_gap(x, g, np.full(5, np.inf), 3.0) == pytest.approx(
        frank_wolfe_gap(x, g), rel=1e-14, abs=1e-15
    )


def test_kkt_multipliers_signs_and_sets() -> None:
    """Free sensors share μ; at a minimum λ = g − μ, at a cap ν = μ − g (read off by hand)."""
    cap = np.array([np.inf, 1.0, 2.0, np.inf])
    gamma = np.array([0.7, 1.0, 0.3, 0.0])
    g = np.array([-2.0, -3.0, -2.0, -1.5])
    mu, at_min, at_cap, res = box_kkt(gamma, g, cap, 0.0)
    assert mu == -2.0 and res == 0.0
    assert list(np.flatnonzero(at_min)) == [3] and list(np.flatnonzero(at_cap)) == [1]
    bad = np.array([-2.0, -1.0, -2.0, -1.5])  # the capped sensor would rather give back
    assert box_kkt(gamma, bad, cap, 0.0)[3] == pytest.approx(0.5)


@pytest.mark.parametrize("seed", range(8))
def test_qp_against_cvxpy(seed: int) -> None:
    cp = pytest.importorskip("cvxpy")
    rng = np.random.default_rng(seed)
    n = 3 + seed % 5
    m = rng.normal(size=(n, n))
    h = m @ m.T + 0.1 * np.eye(n)
    q = 3.0 * rng.normal(size=n)
    cap = np.where(rng.random(n) < 0.6, rng.uniform(0.2, 1.5, n), np.inf)
    sigma = 0.5 * float(np.sum(np.where(np.isfinite(cap), cap, 1.0)))
    x0 = project_box_simplex(np.zeros(n), cap, sigma)
    x = box_qp(h, q, x0, cap, sigma, max_iter=20 * n + 100)
    v = cp.Variable(n)
    fin = np.isfinite(cap)
    cons = [cp.sum(v) == sigma, v >= 0]
    if np.any(fin):
        cons.append(v[np.flatnonzero(fin)] <= cap[fin])
    prob = cp.Problem(cp.Minimize(q @ v + 0.5 * cp.quad_form(v, h)), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-12, tol_gap_rel=1e-12, tol_feas=1e-12)
    assert prob.status == "optimal"
    assert q @ x + 0.5 * x @ h @ x == pytest.approx(prob.value, rel=1e-9, abs=1e-9)
    np.testing.assert_allclose(x, v.value, atol=1e-6)
    assert np.all(x >= 0.0) and np.all(x <= cap) and x.sum() == pytest.approx(sigma, rel=1e-14)
