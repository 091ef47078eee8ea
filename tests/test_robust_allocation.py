"""The robust allocation over a set of models (issue 16, point 2): the mean and the worst-case
optimum against an independent SDP (cvxpy + Clarabel, one Riccati LMI per model), the validity of
the certificates, K = 1 = optimal_allocation bit for bit, the validation of the arguments, costs and
caps, and the integer counts."""

from __future__ import annotations

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs.allocation import RobustAllocation
from capalloc_rs.errors import InputError, InvalidInputError


def _coupled(seed: int, num: int, eps: float = 0.3, n_sub: int = 3, **limits) -> list[cr.Network]:
    """``num`` networks with the subsystems of ``Network.random(n_sub, 2, seed=seed)`` and
    independent random couplings of strength ``eps`` (the uncertain coupling)."""
    st = cr.Network.random(n_sub, 2, eps=0.0, seed=seed).structure
    rng = np.random.default_rng(seed + 100)
    nets = []
    for _ in range(num):
        c = rng.standard_normal(st.coupling.shape) * (st.coupling != 0)
        nets.append(cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, c, eps, **limits))
    return nets


def _sdp(nets: list[cr.Network], budget: float, weights=None):
    """min Σ w_k tr T_k (or, weights None, min t with tr T_k ≤ t) over the rates, with per model
    [[T_k, I], [I, Y_k]] ⪰ 0 and the Riccati LMI [[Y_kA_k + A_kᵀY_k − Σ r_i c_ic_iᵀ, Y_kG_k],
    [G_kᵀY_k, −I]] ⪯ 0 (Y_k = Σ_k⁻¹); Σ b_i r_i = B, r_min ≤ r ≤ r_max."""
    cp = pytest.importorskip("cvxpy")
    net0 = nets[0]
    nn = net0.num_sensors
    r = cp.Variable(nn)
    cons = [net0.costs @ r == budget, r >= net0.rate_min]
    capped = np.isfinite(net0.rate_max)
    if np.any(capped):
        cons.append(r[np.flatnonzero(capped)] <= net0.rate_max[capped])
    traces = []
    for net in nets:
        n = net.n
        y = cp.Variable((n, n), symmetric=True)
        t = cp.Variable((n, n), symmetric=True)
        info = sum(r[i] * (net.sensors[i] @ net.sensors[i].T) for i in range(nn))
        ric = cp.bmat(
            [[y @ net.a + net.a.T @ y - info, y @ net.g], [net.g.T @ y, -np.eye(net.g.shape[1])]]
        )
        cons += [cp.bmat([[t, np.eye(n)], [np.eye(n), y]]) >> 0, (ric + ric.T) / 2 << 0]
        traces.append(cp.trace(t))
    if weights is None:
        top = cp.Variable()
        cons += [tr <= top for tr in traces]
        obj = top
    else:
        obj = sum(w * tr for w, tr in zip(weights, traces, strict=True))
    prob = cp.Problem(cp.Minimize(obj), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert prob.status == "optimal"
    return float(prob.value), np.asarray(r.value)


@pytest.mark.parametrize("seed", [0, 1])
def test_mean_optimum_against_the_sdp(seed: int) -> None:
    nets = _coupled(seed, 3)
    w = np.array([0.5, 0.2, 0.3])
    got = robust_allocation_checked(nets, 9.0, "mean", weights=w)
    want, r_sdp = _sdp(nets, 9.0, w)
    assert got.value == pytest.approx(want, rel=1e-7)
    assert got.lower_bound <= want * (1 + 1e-9)
    np.testing.assert_allclose(got.r, r_sdp, atol=1e-4)
    assert got.gap <= 1e-10 * got.value


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_worst_case_optimum_against_the_epigraph_sdp(seed: int) -> None:
    nets = _coupled(seed, 4)
    got = robust_allocation_checked(nets, 9.0, "worst")
    want, r_sdp = _sdp(nets, 9.0)
    assert got.value == pytest.approx(want, rel=1e-7)
    assert got.lower_bound <= want * (1 + 1e-9)
    np.testing.assert_allclose(got.r, r_sdp, atol=1e-4)
    assert got.value == max(got.eta_per_model)
    # the worst case is no worse than at the mean optimum, nor at any model's nominal optimum
    mean = cr.robust_allocation(nets, 9.0)
    assert got.value <= max(mean.eta_per_model) * (1 + 1e-12)
    for net in nets:
        nominal = cr.optimal_allocation(net, 9.0).r
        assert got.value <= max(m.cost(nominal) for m in nets) * (1 + 1e-12)


def robust_allocation_checked(nets, budget, objective, **kw) -> RobustAllocation:
    """The result, with the invariants every result must satisfy."""
    res = cr.robust_allocation(nets, budget, objective=objective, **kw)
    etas = np.array([n.cost(res.r) for n in nets])
    np.testing.assert_allclose(res.eta_per_model, etas, rtol=1e-12)
    assert res.gap >= 0 and res.value - res.lower_bound == pytest.approx(res.gap, abs=1e-12)
    assert float(nets[0].costs @ res.r) == pytest.approx(budget, rel=1e-13)
    assert np.all(res.r >= nets[0].rate_min * (1 - 1e-14))
    assert np.all(res.r <= nets[0].rate_max * (1 + 1e-14))
    assert sum(res.weights) == pytest.approx(1.0) and min(res.weights) >= 0
    d = res.to_dict()
    assert d["objective"] == objective and d["num_models"] == len(nets)
    assert repr(res).startswith("RobustAllocation(")
    return res


def test_worst_certificate_is_a_lower_bound_for_any_weights() -> None:
    """Σ λ_k η_k at the λ-mixture's own optimum ≤ the worst-case optimum, for every λ: the
    reported bound is below it too."""
    nets = _coupled(3, 3)
    worst = robust_allocation_checked(nets, 8.0, "worst")
    rng = np.random.default_rng(0)
    for _ in range(3):
        lam = rng.dirichlet(np.ones(3))
        mix = cr.robust_allocation(nets, 8.0, weights=lam)
        assert mix.lower_bound <= worst.value * (1 + 1e-12)
    assert worst.lower_bound <= worst.value


def test_costs_and_caps_are_respected_and_match_the_sdp() -> None:
    limits = {"costs": [1.0, 2.0, 0.5], "r_min": [0.5, 1.0, 1.0], "r_max": [np.inf, 3.0, 4.0]}
    nets = _coupled(4, 3, **limits)
    for objective, weights in (("mean", None), ("worst", None)):
        got = robust_allocation_checked(nets, 10.0, objective)
        want, _ = _sdp(nets, 10.0, None if objective == "worst" else np.full(3, 1 / 3))
        assert got.value == pytest.approx(want, rel=1e-7)
        del weights


def test_one_model_is_optimal_allocation_bitwise() -> None:
    net = _coupled(5, 1)[0]
    want = cr.optimal_allocation(net, 9.0)
    for objective in ("mean", "worst"):
        got = cr.robust_allocation([net], 9.0, objective=objective)
        assert np.array_equal(got.r, want.r) and got.value == want.eta
        assert got.eta_per_model == (want.eta,) and got.gap == want.gap


def test_sampler_is_deterministic_with_a_seed() -> None:
    st = cr.Network.random(3, 2, eps=0.0, seed=6).structure

    def sampler(rng: np.random.Generator) -> cr.Network:
        eps = rng.uniform(0.0, 0.3)
        return cr.Network.from_blocks(st.a_blocks, st.g_blocks, st.c_blocks, st.coupling, eps)

    a = cr.robust_allocation(sampler, 9.0, objective="worst", num_models=4, seed=7)
    b = cr.robust_allocation(sampler, 9.0, objective="worst", num_models=4, seed=7)
    assert np.array_equal(a.r, b.r) and a.num_models == 4
    with pytest.raises(InvalidInputError, match="num_models"):
        cr.robust_allocation(sampler, 9.0)


def test_models_with_different_sensors_are_refused() -> None:
    nets = _coupled(0, 2)
    other = cr.Network.random(4, 2, seed=1)
    with pytest.raises(InvalidInputError, match="models"):
        cr.robust_allocation([nets[0], other], 9.0)
    costed = _coupled(0, 1, costs=[1.0, 2.0, 1.0])[0]
    with pytest.raises(InvalidInputError, match=r"models\[1\].*costs"):
        cr.robust_allocation([nets[0], costed], 9.0)
    capped = _coupled(0, 1, r_max=5.0)[0]
    with pytest.raises(InvalidInputError, match="rate_max"):
        cr.robust_allocation([nets[0], capped], 9.0)
    with pytest.raises(InvalidInputError, match="empty"):
        cr.robust_allocation([], 9.0)
    with pytest.raises(InvalidInputError, match="models"):
        cr.robust_allocation(nets[0], 9.0)
    with pytest.raises(InvalidInputError, match=r"models\[1\]"):
        cr.robust_allocation([nets[0], 3], 9.0)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"weights": [1.0]}, "weights"),
        ({"weights": [1.0, -1.0]}, "weights"),
        ({"weights": [0.0, 0.0]}, "weights"),
        ({"weights": [1.0, np.nan]}, "weights"),
        ({"objective": "worst", "weights": [1.0, 1.0]}, "weights"),
        ({"objective": "median"}, "objective"),
        ({"tol": -1.0}, "tol"),
        ({"max_iter": 0}, "max_iter"),
        ({"num_models": 3}, "num_models"),
        ({"seed": 1}, "seed"),
    ],
)
def test_bad_keywords_are_refused(kw, match) -> None:
    nets = _coupled(0, 2)
    with pytest.raises(InputError, match=match):
        cr.robust_allocation(nets, 9.0, **kw)


def test_infeasible_budget_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="budget"):
        cr.robust_allocation(_coupled(0, 2), 2.0)


def test_weights_are_normalised() -> None:
    nets = _coupled(1, 2)
    a = cr.robust_allocation(nets, 9.0, weights=[1.0, 3.0])
    b = cr.robust_allocation(nets, 9.0, weights=[0.25, 0.75])
    assert a.weights == pytest.approx((0.25, 0.75))
    np.testing.assert_allclose(a.r, b.r, rtol=1e-12)


def test_model_files_are_accepted(tmp_path) -> None:
    nets = _coupled(2, 2)
    paths = []
    for k, net in enumerate(nets):
        p = tmp_path / f"m{k}.json"
        net.save(p)
        paths.append(str(p))
    a = cr.robust_allocation(paths, 9.0, objective="worst")
    b = cr.robust_allocation(nets, 9.0, objective="worst")
    np.testing.assert_allclose(a.r, b.r, rtol=1e-12)


@pytest.mark.parametrize("objective", ["mean", "worst"])
def test_integer_counts_against_brute_force(objective: str) -> None:
    """Greedy plus exchanges: feasible, never below the proven lower bound, and on this small
    case equal to the best of all integer points (checked by enumeration; no optimality is
    claimed in general)."""
    nets = _coupled(1, 3)
    res = cr.robust_integer_allocation(nets, 9, objective=objective)
    assert res.counts.sum() == 9 and np.all(res.counts >= 1)
    vals = np.array([[n.cost(res.counts.astype(float)) for n in nets]])
    want = float(np.mean(vals)) if objective == "mean" else float(np.max(vals))
    assert res.value == pytest.approx(want, rel=1e-13)
    best = np.inf
    for i in range(1, 8):
        for j in range(1, 9 - i):
            k = np.array([i, j, 9 - i - j], dtype=float)
            v = [n.cost(k) for n in nets]
            best = min(best, float(np.mean(v)) if objective == "mean" else max(v))
    assert res.lower_bound <= best <= res.value
    assert res.value == pytest.approx(best, rel=1e-12)
    assert res.to_dict()["proven_optimal"] is False


def test_integer_counts_with_costs_fit_the_budget() -> None:
    nets = _coupled(4, 3, costs=[1.0, 2.0, 0.5], r_max=[10.0, 3.0, 6.0])
    res = cr.robust_integer_allocation(nets, 10.0, objective="worst")
    assert res.spent <= 10.0 and float(nets[0].costs @ res.counts) == res.spent
    assert np.all(res.counts <= [10, 3, 6]) and res.gap >= 0


def test_concurrent_evaluations_equal_serial_ones() -> None:
    """The thread pool changes nothing: every model's value, gradient and Hessian are those of
    its own serial call, bit for bit."""
    from capalloc_rs.allocation.model_set import ModelSet

    nets = _coupled(2, 4)
    s = np.array([2.0, 3.0, 4.0])
    with ModelSet(nets) as ms:
        f, g, h = ms.values_gradients_hessians(s)
    for k, net in enumerate(nets):
        fk, gk, hk = net.value_gradient_hessian(s, threads=1)
        assert f[k] == fk and np.array_equal(g[k], gk) and np.array_equal(h[k], hk)
