"""Sensors that may be switched off: ``r_min,i = 0``, accepted when the sensors with a positive
minimum detect the state on their own (then η is finite on the whole feasible set)."""

from __future__ import annotations

import numpy as np
import pytest

import capalloc_rs as cr
from capalloc_rs.errors import InvalidInputError


def _blocks() -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Three scalar subsystems: 0 and 2 stable, 1 unstable."""
    a = [np.array([[-1.0]]), np.array([[0.4]]), np.array([[-0.3]])]
    g = [np.array([[1.0]]), np.array([[0.8]]), np.array([[1.5]])]
    c = [np.array([[1.0]]), np.array([[1.2]]), np.array([[0.7]])]
    return a, g, c


def _coupled(r_min: object, **kw: object) -> cr.Network:
    a, g, c = _blocks()
    coupling = {(0, 1): np.array([[0.3]]), (2, 0): np.array([[-0.2]])}
    return cr.Network.from_blocks(a, g, c, coupling, 0.5, r_min, **kw)


def test_zero_minima_accepted_only_when_the_others_detect() -> None:
    net = _coupled([0.0, 1.0, 0.0])
    assert not net.is_paper_form and net.budget_range == (1.0, np.inf)
    assert net.check().ok in (True, False)  # the report is computed (subsystems at r = 1)
    _coupled([1.0, 0.0, 1.0])  # sensor 0 sees the unstable x_1 through the coupling (0, 1)
    a, g, c = _blocks()
    with pytest.raises(InvalidInputError, match=r"r_min: .* the mode λ = 0\.4"):
        cr.Network.from_blocks(a, g, c, r_min=[1.0, 0.0, 1.0])  # uncoupled: only c_1 sees it
    stable = cr.Network.from_blocks(
        [[[-1.0]], [[-2.0]]], [[[1.0]], [[1.0]]], [[1.0], [1.0]], r_min=[0.0, 1.0]
    )
    assert not stable.is_paper_form  # unequal minima: not the paper's problem
    with pytest.raises(InvalidInputError, match="r_min"):
        _coupled(0.0)  # every sensor may be off, and A is unstable
    with pytest.raises(InvalidInputError, match=r"r_min\[1\] must be non-negative"):
        _coupled([1.0, -1.0, 1.0])


def test_cost_at_rate_zero_is_the_network_without_that_sensor() -> None:
    net = _coupled([0.0, 1.0, 0.0])
    without = cr.Network(net.a, net.g, [net.sensors[1], net.sensors[2]])
    r = np.array([0.0, 2.0, 3.0])
    assert net.cost(r) == pytest.approx(without.cost(r[1:]), rel=1e-13)
    np.testing.assert_allclose(net.gradient(r)[1:], without.gradient(r[1:]), rtol=1e-11, atol=1e-15)


def test_optimum_switches_a_useless_sensor_off() -> None:
    """Sensor 0 sees its subsystem ten thousand times worse than sensor 3, which watches the same
    state: at the optimum it is off (at its zero minimum, with a positive multiplier), and the rest
    is the optimum of the network without it."""
    a, g, c = _blocks()
    sensors = [np.array([1e-4, 0.0, 0.0])] + [
        np.eye(3)[:, [i]] * float(ci[0, 0]) for i, ci in enumerate(c)
    ]
    amat = np.diag([float(x[0, 0]) for x in a])
    amat[0, 1], amat[2, 0] = 0.15, -0.1
    gmat = np.diag([float(x[0, 0]) for x in g])
    net = cr.Network(amat, gmat, sensors, [0.0, 1.0, 1.0, 1.0])
    res = cr.optimal_allocation(net, 9.0)
    assert res.r[0] == 0.0 and 0 in res.at_minimum
    assert res.lower_multipliers[0] > 0.0
    rest = cr.optimal_allocation(cr.Network(amat, gmat, sensors[1:]), 9.0)
    assert res.eta == pytest.approx(rest.eta, rel=1e-12)
    np.testing.assert_allclose(res.r[1:], rest.r, rtol=1e-8)


def test_optimum_against_the_sdp_and_the_filtration() -> None:
    cp = pytest.importorskip("cvxpy")
    net = _coupled([0.0, 1.0, 0.0], costs=[1.0, 2.0, 0.5])
    budget = 6.0
    res = cr.optimal_allocation(net, budget)
    n = net.n
    y = cp.Variable((n, n), symmetric=True)
    t = cp.Variable((n, n), symmetric=True)
    r = cp.Variable(3)
    info = sum(r[i] * (net.sensors[i] @ net.sensors[i].T) for i in range(3))
    ric = cp.bmat([[y @ net.a + net.a.T @ y - info, y @ net.g], [net.g.T @ y, -np.eye(n)]])
    cons = [
        cp.bmat([[t, np.eye(n)], [np.eye(n), y]]) >> 0,
        (ric + ric.T) / 2 << 0,
        net.costs @ r == budget,
        r >= net.rate_min,
    ]
    prob = cp.Problem(cp.Minimize(cp.trace(t)), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert prob.status == "optimal"
    assert res.eta == pytest.approx(prob.value, rel=1e-7)
    assert res.gap <= 1e-10 * res.eta
    f = cr.filtration(net, budget - net.budget_range[0], progress=False)
    np.testing.assert_allclose(f.rates(budget - net.budget_range[0]), res.r, rtol=1e-7, atol=1e-9)
    for sigma in (0.3, 1.7, 3.1):
        point = cr.optimal_allocation(net, f.budget(sigma))
        np.testing.assert_allclose(f.rates(sigma), point.r, rtol=1e-6, atol=1e-8)


def test_integer_counts_and_files_keep_a_zero_minimum(tmp_path) -> None:
    net = _coupled([0.0, 1.0, 0.0])
    k = cr.integer_allocation(net, 7)
    assert sum(k.counts) <= 7 and min(k.counts) >= 1  # every sensor keeps one sample
    path = tmp_path / "net.toml"
    net.save(path)
    back = cr.Network.load(path)
    assert back == net
    np.testing.assert_array_equal(back.rate_min, [0.0, 1.0, 0.0])


def test_check_reports_the_margin_without_the_off_sensors() -> None:
    net = _coupled([0.0, 1.0, 0.0])
    rep = net.check()
    m = rep.detectability_without_off_sensors
    assert m is not None and m > 1e-8
    assert rep.to_dict()["detectability_without_off_sensors"] == m
    assert "detectable with the zero-minimum sensors off" in str(rep)
    assert _coupled(1.0).check().detectability_without_off_sensors is None


def test_some_sensor_keeps_a_positive_minimum() -> None:
    one = [[1.0]]
    with pytest.raises(InvalidInputError, match="at least one sensor needs a positive minimum"):
        cr.Network.from_blocks([[[-1.0]], [[-2.0]]], [one, one], [[1.0], [1.0]], r_min=0.0)
