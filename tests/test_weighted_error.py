"""The weighted error ``η_M(r) = tr(M Σ(r))``: value, gradient, Hessian and the optimum, each
checked by an independent route (scipy, finite differences, extended precision, an SDP)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import scipy.linalg as sla

import capalloc_rs as cr
from capalloc_rs.errors import InputError, ShapeError

mp_riccati = pytest.importorskip("mp_riccati")


def _net(seed: int = 0, n_sub: int = 3, weight=None, eps: float = 0.2) -> cr.Network:
    base = cr.Network.random(n_sub, 2, eps=eps, seed=seed)
    return cr.Network(base.a, base.g, list(base.sensors), weight=weight)


def _weight(n: int, seed: int = 1, rank: int | None = None) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lm = rng.standard_normal((rank or n, n))
    return lm.T @ lm + (0 if rank else 0.1) * np.eye(n)


def _scipy_sigma(net: cr.Network, r: np.ndarray) -> np.ndarray:
    c = np.hstack(net.sensors)
    w = np.concatenate([np.full(s.shape[1], ri) for s, ri in zip(net.sensors, r, strict=True)])
    return sla.solve_continuous_are(net.a.T, c, net.q, np.diag(1.0 / w))


def test_value_is_the_weighted_trace_of_scipys_solution() -> None:
    m = _weight(6)
    net = _net(weight=m)
    for r in (np.array([1.0, 2.0, 3.0]), np.array([0.05, 40.0, 7.0])):
        want = float(np.trace(m @ _scipy_sigma(net, r)))
        assert net.cost(r) == pytest.approx(want, rel=1e-11)


def test_output_weight_estimates_the_outputs() -> None:
    """M = LᵀL: η_M = tr(L Σ Lᵀ), the error of estimating y = L x."""
    ell = np.array([[1.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, -1.0]])
    net = _net(weight=ell.T @ ell)
    r = np.array([1.5, 2.5, 0.5])
    sigma = _scipy_sigma(net, r)
    assert net.cost(r) == pytest.approx(float(np.trace(ell @ sigma @ ell.T)), rel=1e-11)


@pytest.mark.parametrize("rank", [None, 2])
def test_gradient_and_hessian_against_finite_differences(rank) -> None:
    net = _net(weight=_weight(6, rank=rank))
    r = np.array([1.0, 2.0, 3.0])
    f, g, h = net.value_gradient_hessian(r)
    step = 1e-4
    for i in range(3):
        e = np.zeros(3)
        e[i] = step
        fd = (net.cost(r + e) - net.cost(r - e)) / (2 * step)
        assert g[i] == pytest.approx(fd, rel=1e-7, abs=1e-12)
        fd_h = (net.gradient(r + e) - net.gradient(r - e)) / (2 * step)
        np.testing.assert_allclose(h[:, i], fd_h, rtol=1e-6, atol=1e-10)
    v = np.array([0.3, -1.0, 0.5])
    np.testing.assert_allclose(net.hvp(r, v), h @ v, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(net.at(r).hvp(v), h @ v, rtol=1e-10, atol=1e-14)


def test_value_error_bounds_the_true_error() -> None:
    """The reported bound covers the distance to the solution in extended precision."""
    base = cr.Network.random(2, 2, eps=0.3, seed=5)
    m = _weight(4, seed=2)
    net = cr.Network(base.a, base.g, list(base.sensors), weight=m)
    for r in (np.array([1.0, 3.0]), np.array([1e4, 2e5])):
        p = net.at(r)
        w = sum(k * (c @ c.T) for c, k in zip(net.sensors, r, strict=True))
        x = mp_riccati.care(net.a.T, w, net.q, p.sigma)
        exact = float(np.sum(m * mp_riccati.to_float(x)))
        assert abs(p.value - exact) <= p.value_error
        assert p.value_error <= 1e-10 * exact


def test_identity_weight_is_the_plain_trace_bitwise() -> None:
    plain = _net()
    same = _net(weight=np.eye(6))
    assert same.error_weight is None and same == plain
    r = np.array([1.0, 2.0, 3.0])
    assert same.cost(r) == plain.cost(r)
    assert np.array_equal(same.gradient(r), plain.gradient(r))
    a, b = cr.optimal_allocation(same, 9.0), cr.optimal_allocation(plain, 9.0)
    assert a.eta == b.eta and np.array_equal(a.r, b.r)


def test_weighted_optimum_against_an_sdp() -> None:
    """min tr(M Σ) over the rates, as the SDP min tr T s.t. [[T, Lᵀ], [L, Y]] ⪰ 0 and the
    Riccati LMI [[YA + AᵀY − Σ r_i c_i c_iᵀ, Y G], [Gᵀ Y, −I]] ⪯ 0 in Y = Σ⁻¹ (M = L Lᵀ)."""
    cp = pytest.importorskip("cvxpy")
    m = _weight(6, seed=3)
    net = _net(seed=2, weight=m)
    total = 9.0
    n, nn = 6, 3
    ell = np.linalg.cholesky(m)
    y = cp.Variable((n, n), symmetric=True)
    t = cp.Variable((n, n), symmetric=True)
    r = cp.Variable(nn)
    info = sum(r[i] * (net.sensors[i] @ net.sensors[i].T) for i in range(nn))
    ric = cp.bmat(
        [[y @ net.a + net.a.T @ y - info, y @ net.g], [net.g.T @ y, -np.eye(net.g.shape[1])]]
    )
    cons = [
        cp.bmat([[t, ell.T], [ell, y]]) >> 0,
        (ric + ric.T) / 2 << 0,
        cp.sum(r) == total,
        r >= net.r_min,
    ]
    prob = cp.Problem(cp.Minimize(cp.trace(t)), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert prob.status == "optimal"
    got = cr.optimal_allocation(net, total)
    assert got.eta == pytest.approx(prob.value, rel=1e-7)
    np.testing.assert_allclose(got.r, r.value, atol=1e-4)
    assert got.gap <= 1e-10 * got.eta


def test_weighted_filtration_equals_the_rescaled_plain_one() -> None:
    """Decoupled scalar subsystems with diagonal M: m_i σ_i(r) is the plain error of the
    subsystem with c_i/√m_i and G_i·√m_i, so both filtrations have the same breakpoints."""
    a = [np.array([[-1.0]]), np.array([[-0.3]]), np.array([[0.5]])]
    g = [np.array([[1.0]]), np.array([[2.0]]), np.array([[0.7]])]
    c = [np.array([[1.0]]), np.array([[0.5]]), np.array([[1.5]])]
    mw = np.array([3.0, 0.2, 1.0])
    weighted = cr.Network.from_blocks(a, g, c, weight=np.diag(mw))
    plain = cr.Network.from_blocks(
        a,
        [gi * np.sqrt(k) for gi, k in zip(g, mw, strict=True)],
        [ci / np.sqrt(k) for ci, k in zip(c, mw, strict=True)],
    )
    fw = cr.filtration(weighted, 20.0, progress=False)
    fp = cr.filtration(plain, 20.0, progress=False)
    bw = np.array([e.sigma for e in fw.events])
    bp = np.array([e.sigma for e in fp.events])
    assert len(bw) == len(bp) >= 1
    np.testing.assert_allclose(bw, bp, rtol=1e-9)
    assert fw.entry_order == fp.entry_order


@pytest.mark.parametrize(
    ("weight", "error", "match"),
    [
        (np.ones((5, 5)), ShapeError, "weight must be 6×6"),
        (np.triu(np.ones((6, 6))), InputError, "weight M must be symmetric"),
        (-np.eye(6), InputError, "weight M must be positive semidefinite"),
        (np.zeros((6, 6)), InputError, "weight M must be nonzero"),
        (np.full((6, 6), np.nan), InputError, "weight"),
        ("I", InputError, "weight"),
    ],
)
def test_bad_weights_name_the_argument(weight, error, match) -> None:
    with pytest.raises(error, match=match):
        _net(weight=weight)


def test_weight_survives_files_pickle_and_equality(tmp_path) -> None:
    m = _weight(6, rank=3)
    net = _net(weight=m)
    assert net != _net() and hash(net) != hash(_net())
    assert "weighted" in repr(net)
    r = np.array([1.0, 2.0, 3.0])
    for fmt in ("toml", "json", "npz"):
        path = tmp_path / f"w.{fmt}"
        net.save(path)
        back = cr.Network.load(path)
        assert back == net and back.cost(r) == net.cost(r)
    assert pickle.loads(pickle.dumps(net)) == net
    blocks = cr.Network.random(3, 2, eps=0.2, seed=0)
    wb = cr.Network.from_blocks(
        blocks.structure.a_blocks,
        blocks.structure.g_blocks,
        blocks.structure.c_blocks,
        blocks.structure.coupling,
        0.2,
        weight=m,
    )
    path = tmp_path / "wb.toml"
    wb.save(path)
    assert cr.Network.load(path) == wb


def test_from_model_takes_the_weight() -> None:
    base = cr.Network.random(3, 2, eps=0.2, seed=0)
    m = _weight(6)
    net = cr.Network.from_model(base.a, base.g, 1.0, [s.T for s in base.sensors], 1.0, weight=m)
    assert net.cost([1.0, 2.0, 3.0]) == pytest.approx(
        _net(weight=m).cost([1.0, 2.0, 3.0]), rel=1e-14
    )


def test_sampled_functions_take_a_weighted_network() -> None:
    """The sampled cost of a weighted network is tr(M Σ̄) (tests/test_sampled_weighted.py checks
    it against an independent fixed point, Corollary 1 and Monte Carlo)."""
    net = _net(weight=_weight(6))
    cov = cr.sampled_covariance(net, 0.2, [0, 1, 2])
    want = float(np.sum(net.error_weight * cov.boundary))
    assert cr.sampled_cost(net, 0.2, [0, 1, 2]) == pytest.approx(want, rel=1e-12)
    assert cr.best_schedule(net, 0.2, 6, progress=False).eta_bar <= cr.sampled_cost(
        net, 0.2, cr.round_robin_schedule(net, 6)
    ) * (1 + 1e-12)


@pytest.mark.parametrize("weight", [None, "M"])
def test_shadow_price_is_the_sensitivity_of_the_optimum(weight) -> None:
    """−μ = −dη*/dr_tot (envelope theorem), by central differences of the optimal value."""
    net = _net(seed=4, weight=None if weight is None else _weight(6, seed=4))
    total, h = 9.0, 1e-3
    a = cr.optimal_allocation(net, total)
    fd = (cr.optimal_allocation(net, total + h).eta - cr.optimal_allocation(net, total - h).eta) / (
        2 * h
    )
    assert a.shadow_price == -a.mu > 0
    assert a.shadow_price == pytest.approx(-fd, rel=1e-6)
    assert a.to_dict()["shadow_price"] == a.shadow_price


@pytest.mark.parametrize("eps", [0.0, 0.1])
def test_weighted_optimum_is_the_same_from_every_start_and_engine(eps) -> None:
    """The decoupled start of a weighted block network (diagonal blocks M_ii at ε = 0) and the
    core loop give the optimum of the previous algorithm (uniform start, Python loop)."""
    base = cr.Network.random(4, 2, eps=eps, seed=6)
    st = base.structure
    m = _weight(8, seed=6)
    net = cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, eps, weight=m)
    ref = cr.optimal_allocation(net, 12.0, start="uniform", engine="python")
    for kw in ({}, {"engine": "core"}, {"start": "decoupled"}):
        got = cr.optimal_allocation(net, 12.0, **kw)
        assert got.eta == pytest.approx(ref.eta, rel=1e-12)
        np.testing.assert_array_equal(got.active, ref.active)
        assert got.gap <= 1e-12 * got.eta
    # a weight blind to one subsystem: no separable start, the same optimum
    m0 = m.copy()
    m0[:2, :] = 0.0
    m0[:, :2] = 0.0
    blind = cr.Network.from_blocks(
        st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, eps, weight=m0
    )
    a = cr.optimal_allocation(blind, 12.0)
    b = cr.optimal_allocation(blind, 12.0, start="uniform", engine="python")
    assert a.eta == pytest.approx(b.eta, rel=1e-12)
