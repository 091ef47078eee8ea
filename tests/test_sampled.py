"""The sampled system at finite τ: doubling vs iteration, Corollary 1, Proposition 1 and 2, Monte
Carlo agreement."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg as sla

from capalloc_rs import (
    AliasingError,
    ConvergenceError,
    InvalidInputError,
    Network,
    NonFiniteError,
    Schedule,
    ScheduleError,
    UnobservableError,
    sampled_cost,
    sampled_covariance,
    simulate,
)
from capalloc_rs.sampled import (
    check_existence,
    discretise,
    fixed_point_iteration,
    period_triplet,
    propagate,
    sampled_system,
)


def observed_orders(errs: list[float]) -> np.ndarray:
    """``log2(e(τ)/e(τ/2))`` for a sequence of errors at halving τ."""
    e = np.asarray(errs)
    return np.log2(e[:-1] / e[1:])


@pytest.fixture(scope="module")
def net() -> Network:
    # Three coupled 2-state subsystems (6 states, 3 sensors, some unstable modes).
    return Network.random(3, n=2, p=1, eps=0.2, seed=11)


@pytest.fixture(scope="module")
def net2() -> Network:
    return Network.random(2, n=[2, 3], p=[1, 2], eps=0.1, seed=5)


@dataclasses.dataclass
class Plain:
    """A duck-typed stand-in with the paper's capitalised names."""

    A: np.ndarray
    G: np.ndarray
    sensors: list[np.ndarray]
    r_min: float = 1.0


def trace(m: np.ndarray) -> float:
    return float(np.trace(m))


# -- doubling ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("tau", "counts", "order"),
    [(0.5, [1, 1, 1], "interleaved"), (0.1, [3, 4, 3], "interleaved"), (1.0, [2, 5, 1], "blocked")],
)
def test_doubling_agrees_with_fixed_point_iteration(
    net: Network, tau: float, counts: list[int], order: str
) -> None:
    s = Schedule.from_counts(counts, order)  # type: ignore[arg-type]
    cov = sampled_covariance(net, tau, s)
    ref, periods = fixed_point_iteration(net, tau, s, tol=1e-15)
    rel = np.linalg.norm(cov.boundary - ref) / np.linalg.norm(ref)
    assert rel <= 1e-12, (rel, periods)
    # From a different initial covariance too (Proposition 1: the limit does not depend on Σ(0)).
    ref2, _ = fixed_point_iteration(net, tau, s, sigma0=10 * np.eye(net.n), tol=1e-15)
    assert np.linalg.norm(cov.boundary - ref2) / np.linalg.norm(ref2) <= 1e-12
    # Doubling needs ~log2(periods) steps.
    assert cov.doubling_steps <= math.log2(periods) + 6
    assert cov.spectral_radius < 1
    assert cov.residual < 1e-12


@pytest.mark.parametrize("tol", [1e-6, 1e-9, 1e-12])
def test_doubling_reports_its_stopping_contract(net: Network, tol: float) -> None:
    """``rel_change ≤ tol`` (the documented stopping rule; quadratic convergence hides a looser
    rule in Σ itself), and the fixed point's residual: one more period, computed here slot by slot
    in the information form, changes Σ by at most the reported change."""
    s = Schedule.from_counts([3, 4, 3])
    cov = sampled_covariance(net, 0.1, s, tol=tol)
    assert cov.rel_change <= tol
    assert cov.residual <= max(cov.rel_change, 1e-14)
    d = discretise(net, 0.1, s.r_tot)
    sig = cov.boundary
    for i in s:
        prior = d.E @ sig @ d.E.T + d.H
        sig = np.linalg.inv(np.linalg.inv(prior) + d.cbar[i] @ d.cbar[i].T)
    step = np.linalg.norm(sig - cov.boundary) / np.linalg.norm(cov.boundary)
    assert step <= max(cov.rel_change, 1e-13)
    assert step == pytest.approx(cov.residual, abs=1e-13)
    if tol == 1e-12:  # the default
        default = sampled_covariance(net, 0.1, s)
        assert default.rel_change <= 1e-12 and default.residual <= 1e-12


def test_doubling_needs_logarithmically_many_steps(net: Network) -> None:
    s = Schedule.from_counts([30, 40, 30])
    cov = sampled_covariance(net, 0.02, s)
    _, periods = fixed_point_iteration(net, 0.02, s, tol=1e-14)
    assert periods > 1000
    assert cov.doubling_steps <= math.ceil(math.log2(periods)) + 4


def test_per_slot_covariances(net2: Network) -> None:
    tau = 0.4
    s = Schedule([0, 1, 1, 0, 1], 2)
    cov = sampled_covariance(net2, tau, s)
    d = discretise(net2, tau, s.r_tot)
    assert cov.posteriors.shape == (5, net2.n, net2.n)
    np.testing.assert_allclose(cov.posteriors[-1], cov.boundary, rtol=1e-12, atol=1e-14)
    prev = cov.boundary
    for pos, i in enumerate(s):
        prior = d.E @ prev @ d.E.T + d.H
        np.testing.assert_allclose(cov.priors[pos], prior, rtol=1e-11, atol=1e-14)
        post = np.linalg.inv(np.linalg.inv(prior) + d.cbar[i] @ d.cbar[i].T)
        np.testing.assert_allclose(cov.posteriors[pos], post, rtol=1e-10, atol=1e-13)
        prev = cov.posteriors[pos]
    # Measured: equal to the last bit; 1e-14 leaves room for a different summation order.
    assert cov.eta_boundary == pytest.approx(trace(cov.boundary), rel=1e-14)
    assert cov.eta_average == pytest.approx(np.mean([trace(p) for p in cov.posteriors]), rel=1e-14)
    assert cov.eta("average") == cov.eta_average
    # sampled_cost agrees with sampled_covariance in both conventions.
    assert sampled_cost(net2, tau, s) == pytest.approx(cov.eta_boundary, rel=1e-13)
    assert sampled_cost(net2, tau, s, "average") == pytest.approx(cov.eta_average, rel=1e-13)


def test_results_are_immutable(net2: Network) -> None:
    cov = sampled_covariance(net2, 0.3, [0, 1])
    with pytest.raises(dataclasses.FrozenInstanceError):
        cov.eta_boundary = 0.0  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        cov.boundary[0, 0] = 1.0


def test_discretisation_is_van_loan_with_period_scaling(net2: Network) -> None:
    tau, r = 0.6, 4
    d = discretise(net2, tau, r)
    tau0 = tau / r
    np.testing.assert_allclose(d.E, sla.expm(net2.a * tau0), rtol=1e-13)
    # H = ∫₀^{τ₀} e^{As} Q e^{Aᵀs} ds by Gauss–Legendre quadrature.
    xs, ws = np.polynomial.legendre.leggauss(20)
    h = sum(
        w * sla.expm(net2.a * s) @ net2.q @ sla.expm(net2.a.T * s) * tau0 / 2
        for s, w in zip((xs + 1) * tau0 / 2, ws, strict=True)
    )
    np.testing.assert_allclose(d.H, h, rtol=1e-12)
    for cb, c in zip(d.cbar, net2.sensors, strict=True):
        np.testing.assert_allclose(cb, c * math.sqrt(tau), rtol=1e-15)


def test_period_triplet_is_the_period_map(net2: Network) -> None:
    tau = 0.7
    s = Schedule([1, 0, 1], 2)
    a, g, h = period_triplet(net2, tau, s)
    x = np.diag(np.arange(1.0, net2.n + 1))
    # T(X) = H + A X (I + G X)⁻¹ Aᵀ.
    phi = h + a @ (x @ np.linalg.inv(np.eye(net2.n) + g @ x)) @ a.T
    _, posts = propagate(net2, tau, s, x)
    np.testing.assert_allclose(phi, posts[-1], rtol=1e-11)


def test_duck_typed_network_matches_network(net2: Network) -> None:
    plain = Plain(np.array(net2.a), np.array(net2.g), [np.array(c) for c in net2.sensors])
    m = sampled_system(plain)
    np.testing.assert_allclose(m.Q, net2.q, rtol=1e-14)
    assert sampled_cost(plain, 0.3, [0, 1, 1]) == pytest.approx(
        sampled_cost(net2, 0.3, [0, 1, 1]), rel=1e-13
    )
    with pytest.raises(InvalidInputError, match="attributes A"):
        sampled_system(object())


# -- Corollary 1 and Proposition 2 ------------------------------------------------------------


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_corollary_1_first_order_convergence_to_fast_sampling_cost(
    net: Network, which: str
) -> None:
    counts = [3, 5, 2]
    s = Schedule.from_counts(counts)
    eta = net.cost(np.array(counts, dtype=float))
    taus = [0.04 / 2**k for k in range(6)]
    errs = [abs(sampled_cost(net, t, s, which) - eta) for t in taus]  # type: ignore[arg-type]
    orders = observed_orders(errs)
    # η̄(τ, R) → η(counts) with error O(τ): the scaling c̄ = ĉ√τ with r = counts is consistent.
    assert np.all(np.abs(orders - 1) < 0.1), orders
    assert abs(orders[-1] - 1) < 0.02, orders
    assert errs[-1] < 1e-2 * eta


def test_orderings_with_equal_counts_differ_by_order_tau(net: Network) -> None:
    counts = [3, 5, 2]
    inter = Schedule.from_counts(counts, "interleaved")
    block = Schedule.from_counts(counts, "blocked")
    taus = [0.04 / 2**k for k in range(6)]
    db, da = [], []
    for t in taus:
        a, b = sampled_covariance(net, t, inter), sampled_covariance(net, t, block)
        db.append(abs(a.eta_boundary - b.eta_boundary))
        da.append(abs(a.eta_average - b.eta_average))
    ob, oa = observed_orders(db), observed_orders(da)
    # The boundary figure depends on the order at first order in τ ...
    assert np.all(np.abs(ob - 1) < 0.1), ob
    assert abs(ob[-1] - 1) < 0.02, ob
    # ... the slot average only at second order (observed on every network tried).
    assert np.all(np.abs(oa - 2) < 0.1), oa


def test_small_tau_expansion_has_the_corrected_sign(net2: Network) -> None:
    """Φ_R(Σ) = Σ + τ[AΣ + ΣAᵀ − Σ W(r) Σ + Q] + O(τ²); the paper's ``+ΣWΣ`` leaves O(τ)."""
    s = Schedule([0, 1, 1, 0, 1], 2)
    r = s.counts
    w = sum(ri * c @ c.T for ri, c in zip(r, net2.sensors, strict=True))
    a, q = net2.a, net2.q
    sig = np.eye(net2.n) + 0.3 * np.ones((net2.n, net2.n))

    def drift(sign: float) -> np.ndarray:
        return np.asarray(a @ sig + sig @ a.T + sign * sig @ w @ sig + q)

    good, bad = [], []
    for k in range(6):
        tau = 0.01 / 2**k
        _, posts = propagate(net2, tau, s, sig)
        good.append(np.linalg.norm(posts[-1] - sig - tau * drift(-1.0)))
        bad.append(np.linalg.norm(posts[-1] - sig - tau * drift(+1.0)))
    assert np.all(np.abs(observed_orders(good) - 2) < 0.1), observed_orders(good)
    assert np.all(np.abs(observed_orders(bad) - 1) < 0.05), observed_orders(bad)


# -- Proposition 1 and input errors -------------------------------------------------------------


def oscillator(omega: float, damping: float = 0.1) -> Plain:
    a = np.array([[-damping, omega], [-omega, -damping]])
    return Plain(a, np.eye(2), [np.array([[1.0], [0.0]])])


def test_aliasing_is_an_error() -> None:
    osc = oscillator(2.0)
    tau = math.pi / 2.0  # e^{iωτ} = e^{−iωτ}
    with pytest.raises(AliasingError, match="alias"):
        sampled_cost(osc, tau, [0, 0])
    with pytest.raises(AliasingError):
        check_existence(osc, 2 * tau, [0])
    # Away from 𝒯's complement it is fine.
    assert math.isfinite(sampled_cost(osc, 0.9 * tau, [0, 0]))
    # Proposition 1 is only sufficient: with two slots per period the position is sampled a
    # quarter-period apart and the steady state exists — check=False computes it, exactly.
    cov = sampled_covariance(osc, tau, [0, 0], check=False)
    ref, _ = fixed_point_iteration(osc, tau, [0, 0], tol=1e-15)
    np.testing.assert_allclose(cov.boundary, ref, rtol=1e-12)


def test_aliasing_with_one_slot_per_period_really_fails() -> None:
    # Undamped oscillator sampled every half period: the velocity is never seen and grows.
    osc = oscillator(2.0, damping=0.0)
    with pytest.raises(AliasingError):
        sampled_covariance(osc, math.pi / 2.0, [0])
    with pytest.raises(ConvergenceError):
        sampled_covariance(osc, math.pi / 2.0, [0], check=False)


def test_unobservable_schedule_is_an_error() -> None:
    a = np.diag([-1.0, 0.5])
    plain = Plain(a, np.eye(2), [np.array([[1.0], [0.0]]), np.array([[0.0], [1.0]])], r_min=0)
    with pytest.raises(UnobservableError, match="dimension 1"):
        sampled_cost(plain, 0.5, [0, 0, 0])
    assert math.isfinite(sampled_cost(plain, 0.5, [0, 1, 0]))
    # Without the check, the unstable unseen mode makes the doubling overflow: a clear error.
    with pytest.raises(ConvergenceError):
        sampled_cost(plain, 0.5, [0, 0, 0], check=False)


def test_schedule_errors(net: Network) -> None:
    with pytest.raises(ScheduleError, match="sensor 7"):
        sampled_cost(net, 0.1, [0, 1, 7])
    with pytest.raises(ScheduleError, match="starved"):
        sampled_cost(net, 0.1, [0, 1, 1, 0])  # sensor 2 never sends, r_min = 1
    with pytest.raises(ScheduleError, match=">= 0"):
        sampled_cost(net, 0.1, [0, -1, 2])
    with pytest.raises(ScheduleError, match="non-empty"):
        sampled_cost(net, 0.1, [])
    with pytest.raises(ScheduleError, match="3 sensors"):
        sampled_cost(net, 0.1, Schedule([0, 1, 2, 3]))


@pytest.mark.parametrize(
    ("tau", "exc"),
    [
        (0.0, InvalidInputError),
        (-1.0, InvalidInputError),
        (math.nan, NonFiniteError),
        (math.inf, NonFiniteError),
        ("x", InvalidInputError),
    ],
)
def test_bad_tau(net: Network, tau: object, exc: type[Exception]) -> None:
    with pytest.raises(exc, match="tau"):
        sampled_cost(net, tau, [0, 1, 2])  # type: ignore[arg-type]
    assert issubclass(exc, ValueError)


def test_bad_which(net: Network) -> None:
    with pytest.raises(InvalidInputError, match="which"):
        sampled_cost(net, 0.1, [0, 1, 2], "middle")  # type: ignore[arg-type]


# -- Monte Carlo --------------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_monte_carlo_agrees_with_exact_steady_state(net2: Network, which: str) -> None:
    s = Schedule([0, 1, 1, 0, 1, 1], 2)
    mc = simulate(net2, 0.6, s, periods=400, seed=7, runs=48, which=which, level=0.99)  # type: ignore[arg-type]
    assert mc.predicted == pytest.approx(sampled_cost(net2, 0.6, s, which), rel=1e-13)  # type: ignore[arg-type]
    assert mc.contains(mc.predicted), (mc.ci_low, mc.predicted, mc.ci_high)
    # The interval is informative (a few percent), not vacuous.
    assert (mc.ci_high - mc.ci_low) < 0.1 * mc.predicted
    # Per-slot MSE follows the per-slot covariances.
    cov = sampled_covariance(net2, 0.6, s)
    np.testing.assert_allclose(mc.per_slot, np.trace(cov.posteriors, axis1=1, axis2=2), rtol=0.1)


@pytest.mark.parametrize(("runs", "level"), [(8, 0.95), (24, 0.99)])
def test_monte_carlo_interval_is_the_documented_student_t_interval(
    net2: Network, runs: int, level: float
) -> None:
    """The replications re-run here from the same seed (the error recursion of the module
    docstring, gains from the steady-state priors), then the interval built from the
    replication means by hand: mse ± t_{(1+level)/2, runs−1}·s/√runs with scipy's t quantile."""
    from scipy import stats

    from capalloc_rs.sampled.montecarlo import _psd_sqrt

    tau, s, periods, seed = 0.5, Schedule([0, 1, 1], 2), 30, 5
    mc = simulate(net2, tau, s, periods=periods, seed=seed, runs=runs, level=level)
    cov = sampled_covariance(net2, tau, s)
    d = discretise(net2, tau, s.r_tot)
    gains = []
    for pos, i in enumerate(s):
        p, c = cov.priors[pos], d.cbar[i]
        gains.append(p @ c @ np.linalg.inv(np.eye(c.shape[1]) + c.T @ p @ c))
    rng = np.random.default_rng(seed)
    e = rng.standard_normal((runs, net2.n)) @ _psd_sqrt(cov.boundary).T
    lht = _psd_sqrt(d.H).T
    total = np.zeros(runs)
    for _ in range(periods):
        for pos, i in enumerate(s):
            w = rng.standard_normal((runs, net2.n)) @ lht
            v = rng.standard_normal((runs, d.cbar[i].shape[1]))
            e = e @ d.E.T + w
            e = e - (e @ d.cbar[i] + v) @ gains[pos].T
        total += np.sum(e * e, axis=1)
    per_run = total / periods
    mse = float(per_run.mean())
    stderr = float(per_run.std(ddof=1)) / math.sqrt(runs)
    half = float(stats.t.ppf(0.5 + level / 2, runs - 1)) * stderr
    assert mc.mse == pytest.approx(mse, rel=1e-12)
    assert mc.stderr == pytest.approx(stderr, rel=1e-10)
    # The package's t quantile (Cornish–Fisher) is within 1e-3 of scipy's for df ≥ 5.
    assert mc.ci_high - mc.ci_low == pytest.approx(2 * half, rel=1e-3)
    assert mc.ci_low == pytest.approx(mse - half, rel=1e-3)
    assert mc.ci_high == pytest.approx(mse + half, rel=1e-3)


def test_monte_carlo_is_deterministic_and_state_form_is_identical(net2: Network) -> None:
    s = [0, 1, 1]
    a = simulate(net2, 0.5, s, periods=20, seed=3, runs=4)
    b = simulate(net2, 0.5, s, periods=20, seed=3, runs=4)
    assert a.mse == b.mse
    c = simulate(net2, 0.5, s, periods=20, seed=3, runs=4, track_state=True)
    assert c.mse == pytest.approx(a.mse, rel=1e-10)
    with pytest.raises(InvalidInputError, match="runs"):
        simulate(net2, 0.5, s, periods=20, seed=3, runs=1)
    with pytest.raises(InvalidInputError, match="periods"):
        simulate(net2, 0.5, s, periods=0, seed=3)


def test_monte_carlo_detects_plausible_wrong_answers(net2: Network) -> None:
    """The check has power: the fast-sampling η(counts) (3.7 % off at this τ) and the prior
    covariance at the boundary (the other reading of the paper's indexing) lie outside."""
    s = Schedule([0, 1, 1, 0, 1, 1], 2)
    mc = simulate(net2, 0.6, s, periods=1000, seed=7, runs=64, level=0.99)
    assert mc.contains(mc.predicted)
    cov = sampled_covariance(net2, 0.6, s)
    assert not mc.contains(net2.cost(s.counts.astype(float)))
    assert not mc.contains(trace(cov.priors[-1]))


def test_t_quantile_matches_scipy() -> None:
    from scipy import stats

    from capalloc_rs.sampled.montecarlo import t_quantile

    for df in (5, 10, 31, 100):
        for p in (0.975, 0.995):
            assert t_quantile(p, df) == pytest.approx(stats.t.ppf(p, df), rel=1e-3)
