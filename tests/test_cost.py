"""The cost η(r) = tr Σ(r) and its exact derivatives, against scipy, finite differences and the
paper's Example 1; batched evaluation; errors."""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import pickle
import sys
from collections.abc import Callable

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import given, settings
from hypothesis import strategies as st

import capalloc_rs as cr
from capalloc_rs.errors import (
    InvalidInputError,
    NonFiniteError,
    NoStabilizingSolutionError,
    NumericalError,
    ShapeError,
)

F = np.ndarray


def example1() -> cr.Network:
    g = np.linalg.cholesky(np.array([[5.0, -3.0], [-3.0, 4.0]]))
    return cr.Network(np.diag([-1.0, -2.0]), g, [np.array([1.0, 1.0])])


def heterogeneous(eps: float = 0.4, seed: int = 7) -> cr.Network:
    """Sizes 2, 3, 1, 2; outputs 1, 2, 1, 1; coupled."""
    return cr.Network.random(4, n=[2, 3, 1, 2], p=[1, 2, 1, 1], eps=eps, seed=seed)


def rates_for(net: cr.Network, seed: int = 0) -> F:
    return np.random.default_rng(seed).uniform(0.5, 3.0, net.num_sensors)


# -- an independent reference written with scipy ---------------------------------------------------


def scipy_sigma(net: cr.Network, r: F) -> F:
    """``AΣ + ΣAᵀ − Σ C R⁻¹ Cᵀ Σ + Q = 0`` with ``R = diag(1/r_i)`` by scipy's CARE."""
    c = net.sensor_matrix
    rinv = np.concatenate([np.full(p, 1.0 / ri) for p, ri in zip(net.outputs, r, strict=True)])
    return sla.solve_continuous_are(net.a.T, c, net.q, np.diag(rinv))


def scipy_derivatives(net: cr.Network, r: F) -> tuple[F, F]:
    """Gradient and Hessian by the formulas of docs/concepts.md, with scipy's Lyapunov solver."""
    s = scipy_sigma(net, r)
    cs = [c @ c.T for c in net.sensors]
    w = sum(ri * ci for ri, ci in zip(r, cs, strict=True))
    acl = net.a - s @ w
    y = sla.solve_continuous_lyapunov(acl.T, -np.eye(net.n))
    grad = np.array([-np.trace(s @ ci @ s @ y) for ci in cs])
    sp = [sla.solve_continuous_lyapunov(acl, s @ ci @ s) for ci in cs]
    nn = len(cs)
    hess = np.empty((nn, nn))
    for i in range(nn):
        for j in range(nn):
            hess[i, j] = -2 * (
                np.trace(y @ sp[i] @ w @ sp[j])
                + np.trace(y @ sp[i] @ cs[j] @ s)
                + np.trace(y @ sp[j] @ cs[i] @ s)
            )
    return grad, hess


def five_point(f: Callable[[F], F], r: F, i: int, h: float) -> F:
    """``∂f/∂r_i`` by the fourth-order central difference."""
    e = np.zeros_like(r)
    e[i] = h
    return (-f(r + 2 * e) + 8 * f(r + e) - 8 * f(r - e) + f(r - 2 * e)) / (12 * h)


# -- the paper's Example 1 ------------------------------------------------------------------------


def test_example_1_covariance() -> None:
    net = example1()
    sigma = net.covariance([1.0])
    np.testing.assert_allclose(sigma, [[2.0, -1.0], [-1.0, 1.0]], atol=1e-13)
    np.testing.assert_allclose(sigma @ np.array([1.0, 1.0]), [1.0, 0.0], atol=1e-13)
    assert net.cost([1.0]) == pytest.approx(3.0, abs=1e-13)
    ev = net.evaluate([1.0], order=2)
    assert ev.value == pytest.approx(3.0, abs=1e-13)
    assert ev.closed_loop_abscissa < 0 and ev.care_residual < 1e-14
    # η'(1) = −1/4 and η''(1) = 7/32: the Riccati root solved in mpmath at 50 digits and
    # differentiated by central differences there (example1_mpmath below), an independent route.
    assert ev.gradient is not None and ev.hessian is not None
    assert ev.gradient[0] == pytest.approx(-0.25, rel=1e-12)
    assert ev.hessian[0, 0] == pytest.approx(7 / 32, rel=1e-10)
    np.testing.assert_allclose(net.gradient([1.0]), [-0.25], rtol=1e-12)
    np.testing.assert_allclose(net.hessian([1.0]), [[7 / 32]], rtol=1e-10)


def example1_mpmath(r: float) -> tuple[float, float, float]:
    """``(η, η', η'')`` of Example 1 at rate ``r`` with mpmath: ``Σ`` from the three scalar
    equations of ``AΣ + ΣAᵀ − rΣccᵀΣ + P = 0`` by findroot at 50 digits, derivatives by central
    differences with h = 1e-12 at that precision (truncation O(h²) = 1e-24, rounding 1e-45/h²).
    (mpmath.diff's default second derivative of this root came out wrong, 1/4: not used.)"""
    mp = pytest.importorskip("mpmath")
    with mp.workdps(50):
        a = mp.matrix([[-1, 0], [0, -2]])
        c = mp.matrix([[1], [1]])
        p = mp.matrix([[5, -3], [-3, 4]])

        def eta(rr: object) -> object:
            def care(s11: object, s12: object, s22: object) -> list[object]:
                s = mp.matrix([[s11, s12], [s12, s22]])
                m = a * s + s * a.T - rr * s * c * c.T * s + p
                return [m[0, 0], m[0, 1], m[1, 1]]

            s11, _, s22 = mp.findroot(care, (2, -1, 1), tol=mp.mpf(10) ** -45)
            return s11 + s22

        h = mp.mpf("1e-12")
        e0, ep, em = eta(mp.mpf(r)), eta(mp.mpf(r) + h), eta(mp.mpf(r) - h)
        return float(e0), float((ep - em) / (2 * h)), float((ep - 2 * e0 + em) / h**2)


@pytest.mark.parametrize("r", [1.0, 2.5])
def test_example_1_derivatives_against_mpmath(r: float) -> None:
    net = example1()
    value, grad, hess = example1_mpmath(r)
    if r == 1.0:
        assert (value, grad, hess) == pytest.approx((3.0, -0.25, 7 / 32), rel=1e-14)
    ev = net.evaluate([r], order=2)
    assert ev.value == pytest.approx(value, rel=1e-13)
    assert ev.gradient is not None and ev.hessian is not None
    assert ev.gradient[0] == pytest.approx(grad, rel=1e-12)
    assert ev.hessian[0, 0] == pytest.approx(hess, rel=1e-10)


# -- agreement with scipy -------------------------------------------------------------------------


@pytest.mark.parametrize("eps", [0.0, 0.2, 1.0])
def test_covariance_agrees_with_scipy(eps: float) -> None:
    for seed in range(3):
        net = cr.Network.random(5, n=[2, 3, 1, 2, 4], p=[1, 2, 1, 1, 3], eps=eps, seed=seed)
        r = rates_for(net, seed)
        ours, ref = net.covariance(r), scipy_sigma(net, r)
        assert np.linalg.norm(ours - ref) <= 1e-10 * np.linalg.norm(ref)
        np.testing.assert_array_equal(ours, ours.T)
        assert net.cost(r) == pytest.approx(np.trace(ref), rel=1e-12)


def test_derivatives_agree_with_scipy_reference() -> None:
    net = heterogeneous()
    r = rates_for(net, 3)
    g_ref, h_ref = scipy_derivatives(net, r)
    v, g, h = net.value_gradient_hessian(r)
    assert np.linalg.norm(g - g_ref) <= 1e-9 * np.linalg.norm(g_ref)
    assert np.linalg.norm(h - h_ref) <= 1e-9 * np.linalg.norm(h_ref)


def test_covariance_agrees_with_python_control_lqe() -> None:
    control = pytest.importorskip("control")
    net = heterogeneous()
    r = rates_for(net, 1)
    c = net.sensor_matrix
    rinv = np.concatenate([np.full(p, 1.0 / ri) for p, ri in zip(net.outputs, r, strict=True)])
    _, p_ctrl, _ = control.lqe(net.a, net.g, c.T, np.eye(net.n), np.diag(rinv))
    np.testing.assert_allclose(net.covariance(r), p_ctrl, rtol=1e-9, atol=1e-12)


# -- derivatives against finite differences -------------------------------------------------------


@pytest.mark.parametrize("eps", [0.0, 0.4, 1.5])
def test_gradient_matches_finite_differences(eps: float) -> None:
    net = heterogeneous(eps=eps)
    r = rates_for(net, 5)
    grad = net.gradient(r)

    def cost(x: F) -> F:
        return np.array(net.cost(x))

    for i in range(net.num_sensors):
        fd = float(five_point(cost, r, i, 1e-3 * r[i]))
        assert abs(fd - grad[i]) <= 1e-7 * abs(grad[i]), (i, fd, grad[i])


@pytest.mark.parametrize("eps", [0.0, 0.4, 1.5])
def test_hessian_matches_differences_of_the_gradient(eps: float) -> None:
    net = heterogeneous(eps=eps)
    r = rates_for(net, 6)
    hess = net.hessian(r)
    np.testing.assert_array_equal(hess, hess.T)
    fd = np.column_stack(
        [five_point(net.gradient, r, j, 1e-3 * r[j]) for j in range(net.num_sensors)]
    )
    assert np.abs(fd - hess).max() <= 1e-6 * np.abs(hess).max()


def test_hvp_matches_hessian() -> None:
    net = cr.Network.random(12, n=2, p=1, eps=0.3, seed=2)
    r = rates_for(net, 2)
    hess = net.hessian(r)
    rng = np.random.default_rng(0)
    v = rng.standard_normal(12)
    hv = net.hvp(r, v)
    assert hv.shape == (12,)
    assert np.linalg.norm(hv - hess @ v) <= 1e-11 * np.linalg.norm(hess) * np.linalg.norm(v)
    vv = rng.standard_normal((12, 3))
    hvv = net.hvp(r, vv)
    assert hvv.shape == (12, 3)
    assert np.linalg.norm(hvv - hess @ vv) <= 1e-11 * np.linalg.norm(hess) * np.linalg.norm(vv)
    np.testing.assert_array_equal(net.hvp(r, vv[:, 1]), hvv[:, 1])


def test_one_call_matches_separate_calls() -> None:
    net = heterogeneous()
    r = rates_for(net, 4)
    v, g, h = net.value_gradient_hessian(r)
    assert v == net.cost(r)
    np.testing.assert_array_equal(g, net.gradient(r))
    np.testing.assert_array_equal(h, net.hessian(r))
    v2, g2 = net.value_and_gradient(r)
    assert v2 == v
    np.testing.assert_array_equal(g2, g)
    ev = net.evaluate(r, order=0)
    assert ev.gradient is None and ev.hessian is None and ev.value == v
    assert not ev.sigma.flags.writeable and not ev.rates.flags.writeable
    np.testing.assert_array_equal(ev.sigma, net.covariance(r))


# -- structure: separation at ε = 0, signs, convexity ----------------------------------------------


def test_decoupled_network_is_a_sum_of_subsystem_costs() -> None:
    net = cr.Network.random(5, n=[2, 3, 1, 2, 2], p=[1, 2, 1, 1, 1], eps=0.0, seed=9)
    st_ = net.structure
    assert st_ is not None
    r = rates_for(net, 9)
    v, g, h = net.value_gradient_hessian(r)
    total = 0.0
    for i, (a, gi, c) in enumerate(zip(st_.a_blocks, st_.g_blocks, st_.c_blocks, strict=True)):
        sub = cr.Network(a, gi, [c])
        vi, gsub, hsub = sub.value_gradient_hessian(r[i : i + 1])
        total += vi
        assert gsub[0] == pytest.approx(g[i], rel=1e-11)
        assert hsub[0, 0] == pytest.approx(h[i, i], rel=1e-10)
    assert total == pytest.approx(v, rel=1e-12)
    off = h - np.diag(np.diag(h))
    assert np.abs(off).max() <= 1e-10 * np.abs(h).max()


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    num=st.integers(1, 6),
    eps=st.sampled_from([0.0, 0.1, 0.5, 2.0]),
    p=st.integers(1, 2),
)
def test_gradient_negative_and_hessian_psd(seed: int, num: int, eps: float, p: int) -> None:
    """η is decreasing in every rate and convex for every ε (docs/concepts.md)."""
    net = cr.Network.random(num, n=2, p=p, eps=eps, seed=seed)
    r = rates_for(net, seed % 1000)
    _, g, h = net.value_gradient_hessian(r)
    assert np.all(g < 0)
    lam = np.linalg.eigvalsh(h)
    assert lam.min() >= -1e-10 * max(1.0, np.abs(lam).max())


# -- batches --------------------------------------------------------------------------------------


def test_batches_are_bitwise_identical_to_single_calls() -> None:
    net = cr.Network.random(8, n=2, p=1, eps=0.2, seed=5)
    rates = np.random.default_rng(1).uniform(0.3, 4.0, (17, 8))
    values = net.cost_many(rates)
    vals2, grads = net.value_and_gradient_many(rates)
    assert values.shape == (17,) and grads.shape == (17, 8)
    for k in range(17):
        assert values[k] == net.cost(rates[k])
        v, g = net.value_and_gradient(rates[k])
        assert vals2[k] == v
        np.testing.assert_array_equal(grads[k], g)
    np.testing.assert_array_equal(net.gradient_many(rates), grads)
    np.testing.assert_array_equal(net.cost_many(rates, threads=1), values)
    np.testing.assert_array_equal(net.cost_many(np.asfortranarray(rates)), values)
    assert net.cost_many(np.empty((0, 8))).shape == (0,)


def test_batch_errors() -> None:
    net = example1()
    rates = np.array([[1.0], [-1.0], [2.0]])
    with pytest.raises(InvalidInputError, match="row 1: rates must be non-negative"):
        net.cost_many(rates)
    with pytest.raises(InvalidInputError, match="row 1"):
        net.value_and_gradient_many(rates)
    values = net.cost_many(rates, nan_on_error=True)
    assert np.isnan(values[1]) and values[0] == net.cost([1.0])
    _, grads = net.value_and_gradient_many(rates, nan_on_error=True)
    assert np.isnan(grads[1]).all() and not np.isnan(grads[2]).any()
    with pytest.raises(ShapeError, match=r"\(K, 1\)"):
        net.cost_many(np.ones((3, 2)))
    with pytest.raises(ShapeError):
        net.cost_many(np.ones(3))
    with pytest.raises(NonFiniteError):
        net.cost_many(np.array([[np.nan]]))
    with pytest.raises(InvalidInputError, match="threads"):
        net.cost_many(np.ones((2, 1)), threads=0)


# -- errors ---------------------------------------------------------------------------------------


def test_bad_rates() -> None:
    net = heterogeneous()
    good = rates_for(net)
    for method in (net.cost, net.covariance, net.gradient, net.hessian, net.weight):
        with pytest.raises(ShapeError, match="one rate per sensor"):
            method(good[:-1])
        with pytest.raises(ShapeError):
            method(np.ones((2, 4)))
        bad = good.copy()
        bad[2] = -1e-3  # a rate 0 is allowed: the sensor is off
        with pytest.raises(InvalidInputError, match=r"r\[2\]"):
            method(bad)
        bad[2] = -1.0
        with pytest.raises(InvalidInputError):
            method(bad)
        bad[2] = np.nan
        with pytest.raises(NonFiniteError):
            method(bad)
    with pytest.raises(ShapeError, match="v must have shape"):
        net.hvp(good, np.ones(3))
    with pytest.raises(NonFiniteError):
        net.hvp(good, np.array([1.0, np.inf, 0.0, 0.0]))
    with pytest.raises(NonFiniteError):
        net.hvp(good, np.array([1.0, np.nan, 0.0, 0.0]))
    with pytest.raises(InvalidInputError, match="order"):
        net.evaluate(good, order=3)


def test_no_stabilising_solution_is_a_numerical_error() -> None:
    """Validation rejects undetectable networks; an unobservable mode exactly on the imaginary axis
    that slips through (validated=False path, e.g. an old pickle) fails in the Riccati solver."""
    net = cr.Network(np.diag([-1.0, -2.0]), np.eye(2), [np.array([0.0, 1.0])])
    # Detectable: the unobserved mode x₁ (ẋ₁ = −x₁ + w₁) is stable, its variance is 1/2 and
    # the observed x₂ (ẋ₂ = −2x₂ + w₂, y = x₂) has the scalar Riccati root √5 − 2 (= ½·(−4 + √20)
    # from −4s − s² + 1 = 0): η = 1/2 + √5 − 2.
    assert net.cost([1.0]) == pytest.approx(0.5 + np.sqrt(5.0) - 2.0, rel=1e-13)
    unsafe = cr.Network._build(
        np.diag([0.0, -2.0]), np.eye(2), [np.array([[0.0], [1.0]])], 1.0, None, validate=False
    )
    with pytest.raises(NumericalError) as info:
        unsafe.cost([1.0])
    assert isinstance(info.value, NoStabilizingSolutionError | cr.SingularProblemError)


# -- misc -----------------------------------------------------------------------------------------


def test_weight_and_gamma() -> None:
    net = heterogeneous()
    r = rates_for(net)
    w = net.weight(r)
    ref = sum(ri * c @ c.T for ri, c in zip(r, net.sensors, strict=True))
    np.testing.assert_allclose(w, ref, rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(net.rates_from_gamma(np.zeros(4)), np.full(4, net.r_min))


def test_pickled_network_evaluates_identically() -> None:
    net = heterogeneous()
    back = pickle.loads(pickle.dumps(net))
    r = rates_for(net)
    assert back.cost(r) == net.cost(r)
    np.testing.assert_array_equal(back.hessian(r), net.hessian(r))


_FORK_NET = cr.Network.random(10, n=2, p=1, eps=0.2, seed=1)


def _fork_work(k: int) -> tuple[float, float]:
    r = np.full(10, 1.0 + k)
    return float(_FORK_NET.hessian(r)[0, 0]), float(_FORK_NET.cost_many(r[None, :])[0])


@pytest.mark.skipif(sys.platform != "linux", reason="fork start method")
def test_parallel_work_survives_fork() -> None:
    """rayon's global pool hangs in a forked child; ours is rebuilt there."""
    r = np.full(10, 1.0)
    expected = [_fork_work(k) for k in range(3)]  # starts the thread pool in this process
    ctx = mp.get_context("fork")
    with cf.ProcessPoolExecutor(2, mp_context=ctx) as ex:
        got = list(ex.map(_fork_work, range(3), timeout=120))
    assert got == expected
    assert _FORK_NET.hessian(r, threads=1)[0, 0] == expected[0][0]


def test_threads_argument() -> None:
    net = cr.Network.random(9, n=2, p=1, eps=0.2, seed=3)
    r = rates_for(net)
    h = net.hessian(r)
    for t in (1, 2, 3):
        np.testing.assert_array_equal(net.hessian(r, threads=t), h)
        np.testing.assert_array_equal(net.value_gradient_hessian(r, threads=t)[2], h)
    with pytest.raises(InvalidInputError, match="threads"):
        net.hessian(r, threads=0)


def test_a_sensor_that_sees_nothing_has_zero_derivatives() -> None:
    base = heterogeneous(eps=0.3)
    net = cr.Network(base.a, base.g, [*base.sensors, np.zeros(base.n)])
    r = np.append(rates_for(base), 1.7)
    v, g, h = net.value_gradient_hessian(r)
    v0, g0, h0 = base.value_gradient_hessian(r[:-1])
    assert v == pytest.approx(v0, rel=1e-13)
    assert g[-1] == 0.0 and np.all(h[-1] == 0.0) and np.all(h[:, -1] == 0.0)
    np.testing.assert_allclose(g[:-1], g0, rtol=1e-11)
    np.testing.assert_allclose(h[:-1, :-1], h0, rtol=1e-9, atol=1e-12 * np.abs(h0).max())
    np.testing.assert_array_equal(net.hvp(r, np.zeros(5)), np.zeros(5))
