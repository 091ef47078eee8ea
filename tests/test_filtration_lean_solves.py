"""The filtration's sixth version (the default, ``method="continuation"``) against the fifth
(``"continuation-v5"``): with Hessian-vector products (from 25 sensors on) its linear solves
take fewer products — node tangents to ``LEAN_TANGENT_TOL``, a new face's preconditioner seeded
with the old face's solves at the breakpoint, the first tangent solve of each Newton solve
started from the predicted tangent — and below state order 65 its warm-started points end
without the compensated refinement (``CostPoint.warm(r, compensated=False)``), on the same path.
Costs are checked by counting products (never by wall time); the tangents by an independent route
(central differences of the exact allocation map, ``Filtration.allocation``: corrected points)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from filtration_paths import assert_same_path

from capalloc_rs import Network, errors
from capalloc_rs.allocation import filtration
from capalloc_rs.allocation.kkt_newton import (
    LEAN_TANGENT_TOL,
    PATH_WARM_MIN_ORDER,
    TANGENT_TOL,
)
from capalloc_rs.allocation.optimal import HVP_MIN_SENSORS
from capalloc_rs.allocation.oracle import CountingOracle


@pytest.mark.parametrize(("n_sub", "sigma_max"), [(5, 15.0), (20, 60.0), (35, 60.0)])
def test_lean_solves_trace_the_path_of_the_fifth_version(n_sub: int, sigma_max: float) -> None:
    net = Network.random(n_sub, 2, eps=0.05, seed=3)
    new, old = CountingOracle(net), CountingOracle(net)
    f = filtration(new, sigma_max, progress=False)
    g = filtration(old, sigma_max, progress=False, method="continuation-v5")
    assert_same_path(f, g)
    if n_sub >= HVP_MIN_SENSORS:
        assert new.counts["hvps"] < 0.85 * old.counts["hvps"]
        assert new.counts["hessians"] <= old.counts["hessians"]
        assert new.counts["points"] <= old.counts["points"] + 2
    else:  # the same points (to rounding where warm-started: n ≥ 16) and the same counts
        assert new.counts == old.counts
        # to the path's tolerance (tol = 1e-10 relative to σ_max)
        np.testing.assert_allclose(f.node_gamma, g.node_gamma, rtol=0, atol=1e-10 * sigma_max)
        if net.n < PATH_WARM_MIN_ORDER:
            np.testing.assert_array_equal(f.node_gamma, g.node_gamma)
    # The nodes meet the KKT conditions with the network's own (cold) gradient.
    for k in range(0, f.node_sigma.size, 3):
        gamma, mu = f.node_gamma[k], float(f.node_mu[k])
        active = list(f.active_sets[int(f.node_segment[k])])
        grad = np.asarray(net.gradient(gamma + net.r_min))
        assert np.max(np.abs(grad[active] - mu)) <= 1e-11 * abs(mu)


def test_lean_node_tangents_match_central_differences() -> None:
    # The tangents solved to LEAN_TANGENT_TOL instead of TANGENT_TOL: at every inner node of a
    # segment (both neighbours on it) the derivative against central differences of the
    # exact allocation map (corrected points), and against the fifth version's.
    assert TANGENT_TOL < LEAN_TANGENT_TOL <= 1e-7
    net = Network.random(30, 2, eps=0.05, seed=3)
    f = filtration(net, 60.0, progress=False)
    g = filtration(net, 60.0, progress=False, method="continuation-v5")
    seg = f.node_segment
    inner = np.flatnonzero((seg[1:-1] == seg[:-2]) & (seg[1:-1] == seg[2:])) + 1
    assert inner.size >= 1
    h = 1e-5
    for k in inner:
        s = float(f.node_sigma[k])
        fd = (f.allocation(s + h) - f.allocation(s - h)) / (2 * h)
        np.testing.assert_allclose(f.node_dgamma[k], fd, atol=1e-5)
    if f.node_sigma.size == g.node_sigma.size:
        scale = float(np.max(np.abs(g.node_dgamma)))
        assert float(np.max(np.abs(f.node_dgamma - g.node_dgamma))) <= 1e-5 * scale


def _rel(a: Any, b: Any) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


@pytest.mark.parametrize("move", [1e-6, 1e-3, 0.1])
def test_warm_point_without_compensated_refinement_is_the_cold_point(move: float) -> None:
    # N = 20 (n = 40) at rates where the refinement happens (the path's later points): the
    # point without it agrees with the cold one within both error bounds, its gradient and
    # products to rounding, and takes no more Schur forms than the refined one.
    net = Network.random(20, 2, eps=0.05, seed=3)
    r0 = 1.0 + np.linspace(0.0, 6.0, 20)
    r1 = r0 * (1.0 + move * np.sin(np.arange(20.0)))
    p0 = net.at(r0)
    cold, refined, plain = net.at(r1), p0.warm(r1), p0.warm(r1, compensated=False)
    assert plain.warm_started and plain.warm_fallback is None
    assert _rel(plain.sigma, cold.sigma) <= plain.forward_error + cold.forward_error
    assert abs(plain.value - cold.value) <= plain.value_error + cold.value_error
    assert _rel(plain.gradient, cold.gradient) <= 1e-11
    assert _rel(plain.gradient, refined.gradient) <= 1e-11
    v = np.cos(np.arange(20.0))
    assert _rel(plain.hvp(v), cold.hvp(v)) <= 1e-10
    assert plain.warm_factorizations <= refined.warm_factorizations
    # Its error bound is that of the working-precision floor (1e-11 to 4e-11 here; the cold
    # solve reports 6e-12), where the refined point's is 1e-13: the refinement did happen.
    assert plain.forward_error <= 1e-10
    if move <= 1e-3:
        assert refined.forward_error < 1e-12 < plain.forward_error


@pytest.mark.parametrize("bad", [0, 1, "yes", None, 1.0])
def test_compensated_is_validated(bad: Any) -> None:
    net = Network.random(3, 2, eps=0.05, seed=3)
    p = net.at(np.ones(3))
    with pytest.raises(errors.InvalidInputError, match="compensated"):
        p.warm(np.full(3, 1.1), compensated=bad)
