"""Network.at(r): the cached evaluation point (CostPoint) and its Hessian-vector products."""

from __future__ import annotations

import pickle
import threading

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs.errors import (
    CapallocError,
    InvalidInputError,
    NonFiniteError,
    NoStabilizingSolutionError,
    NumericalError,
    ShapeError,
)
from capalloc_rs.network import CostPoint


def heterogeneous(eps: float = 0.4, seed: int = 7) -> cr.Network:
    """Sizes 2, 3, 1, 2; outputs 1, 2, 1, 1; coupled."""
    return cr.Network.random(4, n=[2, 3, 1, 2], p=[1, 2, 1, 1], eps=eps, seed=seed)


def rates_for(net: cr.Network, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0.5, 3.0, net.num_sensors)


def test_point_has_the_values_of_one_evaluation() -> None:
    net = heterogeneous()
    r = rates_for(net)
    p = net.at(r)
    ev = net.evaluate(r, 2)
    assert isinstance(p, CostPoint) and p.network is net
    assert p.value == ev.value
    np.testing.assert_array_equal(p.gradient, ev.gradient)
    np.testing.assert_array_equal(p.sigma, ev.sigma)
    np.testing.assert_array_equal(p.rates, r)
    np.testing.assert_array_equal(p.hessian(), ev.hessian)
    np.testing.assert_array_equal(p.hessian(threads=1), ev.hessian)
    assert p.care_residual == ev.care_residual
    assert p.closed_loop_abscissa == ev.closed_loop_abscissa < 0


def test_example_1_point() -> None:
    g = np.linalg.cholesky(np.array([[5.0, -3.0], [-3.0, 4.0]]))
    net = cr.Network(np.diag([-1.0, -2.0]), g, [np.array([1.0, 1.0])])
    p = net.at([1.0])
    np.testing.assert_allclose(p.sigma, [[2.0, -1.0], [-1.0, 1.0]], atol=1e-13)
    assert p.value == pytest.approx(3.0, rel=1e-13)


@pytest.mark.parametrize("eps", [0.0, 0.4, 1.2])
def test_hvp_equals_the_exact_hessian_times_v(eps: float) -> None:
    net = heterogeneous(eps, seed=3)
    r = rates_for(net, 1)
    p = net.at(r)
    h = p.hessian()
    rng = np.random.default_rng(5)
    v = rng.standard_normal(net.num_sensors)
    hv = p.hvp(v)
    assert hv.shape == (net.num_sensors,)
    scale = np.max(np.abs(h @ v))
    np.testing.assert_allclose(hv, h @ v, rtol=0, atol=1e-12 * scale)
    vv = rng.standard_normal((net.num_sensors, 3))
    hvv = p.hvp(vv)
    assert hvv.shape == (net.num_sensors, 3)
    np.testing.assert_allclose(hvv, h @ vv, rtol=0, atol=1e-12 * np.max(np.abs(h @ vv)))
    # Unit vectors give the Hessian's columns.
    np.testing.assert_allclose(
        p.hvp(np.eye(net.num_sensors)), h, rtol=0, atol=1e-12 * np.abs(h).max()
    )


def test_hvp_matches_differences_of_the_gradient() -> None:
    net = heterogeneous(0.6, seed=11)
    r = rates_for(net, 2)
    v = np.random.default_rng(3).standard_normal(net.num_sensors)
    hv = net.at(r).hvp(v)
    step = 1e-5
    fd = (net.at(r + step * v).gradient - net.at(r - step * v).gradient) / (2 * step)
    np.testing.assert_allclose(fd, hv, rtol=0, atol=1e-7 * np.max(np.abs(hv)))


def test_repeated_products_on_one_point_equal_network_hvp() -> None:
    net = cr.Network.random(12, 2, eps=0.2, seed=4)
    r = rates_for(net, 4)
    p = net.at(r)
    rng = np.random.default_rng(0)
    for _ in range(5):
        v = rng.standard_normal(net.num_sensors)
        first = p.hvp(v)
        np.testing.assert_array_equal(first, net.hvp(r, v))  # bitwise: same code, same factor
        np.testing.assert_array_equal(p.hvp(v), first)
    vv = rng.standard_normal((net.num_sensors, 4))
    np.testing.assert_array_equal(p.hvp(vv), net.hvp(r, vv))
    # Any memory layout of v.
    np.testing.assert_array_equal(p.hvp(np.asfortranarray(vv)), p.hvp(np.ascontiguousarray(vv)))
    np.testing.assert_array_equal(p.hvp(vv[:, ::2]), net.hvp(r, vv[:, ::2]))


def test_point_is_immutable_read_only_and_pickles() -> None:
    net = heterogeneous()
    r = rates_for(net)
    p = net.at(r)
    for arr in (p.gradient, p.sigma, p.rates):
        assert not arr.flags.writeable
    with pytest.raises(AttributeError):
        p.value = 1.0  # type: ignore[misc]
    with pytest.raises(AttributeError):
        del p._point
    r[0] = 99.0  # the point keeps its own copy of the rates
    assert p.rates[0] != 99.0
    q = pickle.loads(pickle.dumps(p))
    assert q.value == p.value and q.network == net
    v = np.arange(net.num_sensors, dtype=float)
    np.testing.assert_array_equal(q.hvp(v), p.hvp(v))
    assert "CostPoint" in repr(p)


def test_products_from_several_threads_agree() -> None:
    net = cr.Network.random(20, 2, eps=0.1, seed=1)
    p = net.at(rates_for(net))
    v = np.random.default_rng(2).standard_normal((net.num_sensors, 2))
    want = p.hvp(v)
    out: list[np.ndarray] = []
    threads = [threading.Thread(target=lambda: out.append(p.hvp(v))) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(out) == 4
    for o in out:
        np.testing.assert_array_equal(o, want)


def test_bad_input_raises_the_package_errors() -> None:
    net = heterogeneous()
    with pytest.raises(ShapeError):
        net.at([1.0, 2.0])
    with pytest.raises(InvalidInputError):
        net.at([1.0, -1.0, 1.0, 1.0])
    with pytest.raises(NonFiniteError):
        net.at([1.0, np.nan, 1.0, 1.0])
    with pytest.raises(ShapeError):
        net.at(np.ones((4, 1)))
    p = net.at(rates_for(net))
    with pytest.raises(ShapeError):
        p.hvp(np.ones(3))
    with pytest.raises(ShapeError):
        p.hvp(np.ones((5, 2)))
    with pytest.raises(ShapeError):
        p.hvp(np.ones((4, 2, 1)))
    with pytest.raises(NonFiniteError):
        p.hvp([1.0, np.inf, 0.0, 0.0])
    with pytest.raises(NonFiniteError):
        p.hvp([1.0, np.nan, 0.0, 0.0])
    with pytest.raises(NonFiniteError):
        p.hvp(np.full((4, 2), np.nan))
    with pytest.raises(CapallocError):
        p.hvp(["a", "b", "c", "d"])
    with pytest.raises(InvalidInputError):
        p.hessian(threads=0)


def test_no_stabilising_solution_is_a_numerical_error() -> None:
    # An unstable mode no sensor sees; built without validation, as after unpickling.
    net = cr.Network._build(
        np.diag([1.0, -1.0]), np.eye(2), (np.array([[0.0], [1.0]]),), 1.0, None, validate=False
    )
    with pytest.raises(NumericalError) as info:
        net.at([1.0])
    assert isinstance(info.value, NoStabilizingSolutionError | cr.SingularProblemError)
