"""The filtration by continuation (the default, ``method="continuation"``) against the reference
tracer (``method="reference"``) and against independent routes: the KKT conditions checked with
the network's own gradient at every node, and pointwise optimal allocations. Costs are checked by
counting evaluation points of η (never by wall time)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from filtration_paths import assert_same_path

import capalloc_rs
from capalloc_rs import Network, errors
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.allocation.kkt_newton import PATH_WARM_MIN_ORDER, KKTNewton
from capalloc_rs.allocation.oracle import WARM_START_MIN_ORDER, CountingOracle

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SLOW = os.environ.get("CAPALLOC_SLOW_TESTS") == "1"


def _rel(a: Any, b: Any) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1.0)))


def _same_path(new: Any, ref: Any) -> None:
    """Same events and active sets, breakpoints to 1e-9 relative, and the new nodes on the
    reference's path (its exact evaluation at their σ) to 1e-9."""
    assert [(e.kind, e.sensor) for e in new.events] == [(e.kind, e.sensor) for e in ref.events]
    assert new.active_sets == ref.active_sets and new.entry_order == ref.entry_order
    assert (new.is_monotone, new.is_filtration) == (ref.is_monotone, ref.is_filtration)
    assert _rel(new.breakpoints, ref.breakpoints) <= 1e-9
    for k in np.linspace(0, new.node_sigma.size - 1, 9).astype(int):
        s = float(new.node_sigma[k])
        scale = max(s, 1.0)
        assert np.max(np.abs(new.node_gamma[k] - ref.allocation(s))) <= 1e-9 * scale
        assert abs(new.node_mu[k] - ref.mu(s)) <= 1e-9 * abs(ref.mu(s))


@pytest.mark.parametrize(("n", "sigma_max", "seed"), [(5, 15.0, 3), (5, 20.0, 11), (20, 60.0, 3)])
def test_continuation_traces_the_reference_path(n: int, sigma_max: float, seed: int) -> None:
    net = Network.random(n, 2, eps=0.05, seed=seed)
    new = filtration(net, sigma_max, progress=False)
    ref = filtration(net, sigma_max, progress=False, method="reference")
    assert new.converged and ref.converged and new.breakpoints.size >= 3
    _same_path(new, ref)


@pytest.mark.skipif(not SLOW, reason="the reference takes about a minute (CAPALLOC_SLOW_TESTS=1)")
def test_continuation_traces_the_reference_path_n50() -> None:
    net = Network.random(50, 2, eps=0.05, seed=3)
    _same_path(
        filtration(net, 100.0, progress=False),
        filtration(net, 100.0, progress=False, method="reference"),
    )


def _check_kkt(net: Any, f: Any) -> None:
    """Every node: γ ≥ 0 summing to σ, the gradient (the network's own, recomputed cold) equal
    to μ on the active set and ≥ μ off it (the enter events not yet due), to 1e-12 relative —
    1e-10 for states of order ≥ WARM_START_MIN_ORDER, whose evaluation points along the path
    are warm-started: their gradients agree with cold ones only to about 1e-11 (measured:
    1.2e-11 at N = 50, n = 100; 3.5e-14 cold at N = 30); 1e-11 from PATH_WARM_MIN_ORDER, where
    the default path warm-starts them too (measured: 2.6e-12 at N = 20, n = 40; 6.3e-13 with
    cold points, 5.8e-14 with "continuation-v2")."""
    tol = 1e-10 if net.n >= WARM_START_MIN_ORDER else 1e-12
    if net.n >= PATH_WARM_MIN_ORDER:
        tol = max(tol, 1e-11)
    for k in range(f.node_sigma.size):
        gamma, mu, s = f.node_gamma[k], float(f.node_mu[k]), float(f.node_sigma[k])
        active = list(f.active_sets[int(f.node_segment[k])])
        g = np.asarray(net.gradient(gamma + net.r_min))
        assert np.all(gamma >= 0.0) and abs(gamma.sum() - s) <= 1e-13 * max(s, 1.0)
        assert np.max(np.abs(g[active] - mu)) <= tol * abs(mu), (k, s)
        off = np.setdiff1d(np.arange(len(net.sensors)), active)
        assert np.all(g[off] - mu >= -tol * abs(mu)), (k, s)


@pytest.mark.parametrize(("n", "sigma_max"), [(20, 60.0), (50, 100.0)])
def test_nodes_satisfy_kkt_and_match_pointwise_optima(n: int, sigma_max: float) -> None:
    net = Network.random(n, 2, eps=0.05, seed=3)
    f = filtration(net, sigma_max, progress=False)
    assert f.converged and f.is_filtration and f.is_monotone
    _check_kkt(net, f)
    rng = np.random.default_rng(n)
    for k in rng.choice(f.node_sigma.size, size=3, replace=False):
        s = float(f.node_sigma[k])
        point = optimal_allocation(net, s + n * net.r_min)
        np.testing.assert_allclose(f.node_gamma[k], point.gamma, atol=1e-6 * max(s, 1.0))
    # The derivative at a node against central differences of the exact evaluation.
    seg = f.node_segment
    inner = np.flatnonzero((seg[1:-1] == seg[:-2]) & (seg[1:-1] == seg[2:])) + 1
    k = int(inner[inner.size // 2])  # a node with both neighbours on its segment
    s, h = float(f.node_sigma[k]), 1e-5
    fd = (f.allocation(s + h) - f.allocation(s - h)) / (2 * h)
    np.testing.assert_allclose(f.node_dgamma[k], fd, atol=1e-5)


def test_continuation_evaluates_the_cost_a_few_times_per_breakpoint() -> None:
    # N = 20: every evaluation point forms the Hessian's block on its face (exact Newton), and
    # a node completes its products with the full Hessian by a product or two. The reference
    # needs about 700 points on this path; the continuation about 4 per breakpoint.
    net = Network.random(20, 2, eps=0.05, seed=3)
    new, ref = CountingOracle(net), CountingOracle(net)
    f = filtration(new, 60.0, progress=False)
    filtration(ref, 60.0, progress=False, method="reference")
    events = f.breakpoints.size - 2
    assert events == 18
    assert new.counts["points"] <= 6 * events and new.counts["hvps"] <= 5 * events
    assert new.counts["hessians"] == 0 and new.counts["hessian_blocks"] == new.counts["points"]
    assert new.counts["points"] * 5 <= ref.counts["points"]


@pytest.mark.parametrize(("n_sub", "sigma_max"), [(5, 15.0), (20, 60.0)])
def test_current_continuation_traces_the_path_of_the_previous_version(
    n_sub: int, sigma_max: float
) -> None:
    # Warm-started points, Hessian blocks and the last Newton step judged on both residuals
    # (the default) against the version before them ("continuation-v2": cold points, full
    # Hessians): the same events, active sets and entry order, the breakpoints within 1e-10
    # relative, in no more evaluation points.
    net = Network.random(n_sub, 2, eps=0.05, seed=3)
    new, old = CountingOracle(net), CountingOracle(net)
    f = filtration(new, sigma_max, progress=False)
    g = filtration(old, sigma_max, progress=False, method="continuation-v2")
    assert_same_path(f, g)
    assert new.counts["points"] <= old.counts["points"]
    assert old.counts["hessian_blocks"] == 0 and old.counts["hvps"] == 0
    _check_kkt(net, f)


@pytest.mark.parametrize(("n_sub", "sigma_max"), [(5, 15.0), (20, 60.0)])
def test_longer_steps_trace_the_path_of_the_third_version(n_sub: int, sigma_max: float) -> None:
    # Steps up to σ_max/4 where no event is due and no short last step (the default) against
    # the third version ("continuation-v3": up to σ_max/8): the same events, active sets and
    # entry order, the breakpoints within 1e-10 relative, in fewer evaluation points (measured:
    # 32 → 27 at N = 5, 67 → 63 at N = 20), and the nodes still meet the KKT conditions.
    net = Network.random(n_sub, 2, eps=0.05, seed=3)
    new, old = CountingOracle(net), CountingOracle(net)
    f = filtration(new, sigma_max, progress=False)
    g = filtration(old, sigma_max, progress=False, method="continuation-v3")
    assert_same_path(f, g)
    assert new.counts["points"] < old.counts["points"]
    assert f.node_sigma.size < g.node_sigma.size
    assert np.max(np.diff(f.node_sigma)) <= 1.25 * sigma_max / 4.0 * (1.0 + 1e-12)  # longest step
    _check_kkt(net, f)


def test_continuation_from_25_sensors_forms_few_hessians() -> None:
    # N = 30: no Hessian per Newton iterate; products, and a Hessian now and then as the
    # preconditioner of the conjugate gradients.
    net = CountingOracle(Network.random(30, 2, eps=0.05, seed=3))
    f = filtration(net, 40.0, progress=False)
    assert f.converged and f.is_filtration
    _check_kkt(net, f)
    assert net.counts["hessians"] <= net.counts["points"] // 3
    assert net.counts["hvps"] > 0


def test_continuation_stall_keeps_the_step_contract(monkeypatch: pytest.MonkeyPatch) -> None:
    # A Newton solve that fails for every σ > 0: the path stalls at σ = 0, each retry ¼ of the
    # step before, until the next would be below 1e-14·σ_max (the reference's contract).
    solve = KKTNewton.solve
    tried: list[float] = []

    def failing(self: Any, active: Any, gamma0: Any, mu0: float, side: Any, *caps: Any) -> Any:
        if side.kind != "sigma" or side.value > 0.0:
            tried.append(float(side.value))
            raise errors.ConvergenceError("forced")
        return solve(self, active, gamma0, mu0, side, *caps)

    monkeypatch.setattr(KKTNewton, "solve", failing)
    net = capalloc_rs.model_io.load(EXAMPLES / "three_subsystems.toml")
    with pytest.raises(errors.PathStallError) as info:
        filtration(net, 8.0, progress=False)
    err = info.value
    assert err.sigma == 0.0 and err.min_step == 1e-14 * 8.0 and err.failures >= 2
    assert err.min_step <= err.step < 4 * err.min_step
    steps = np.array([s for s in tried if s > 0.0])
    np.testing.assert_allclose(steps[1:] / steps[:-1], 0.25, rtol=1e-12)


def test_continuation_goes_on_where_the_reference_demands_more_than_rounding_allows() -> None:
    # At rates ~1e8 the gradient is resolved to ~1e-12 only: the reference's corrector, which
    # must measure 1e-13, stalls; the continuation's last Newton steps (from residuals ≤ 1e-7
    # after superlinear convergence) reach the rounding level, checked here independently.
    net = capalloc_rs.model_io.load(EXAMPLES / "three_subsystems.toml")
    with pytest.raises(errors.PathStallError):
        filtration(net, 1e9, progress=False, method="reference")
    f = filtration(net, 1e9, progress=False)
    assert f.converged
    for k in range(f.node_sigma.size):
        g = np.asarray(net.gradient(f.node_gamma[k] + net.r_min))
        active = list(f.active_sets[int(f.node_segment[k])])
        assert np.max(np.abs(g[active] - f.node_mu[k])) <= 1e-11 * abs(f.node_mu[k])


def test_method_is_validated() -> None:
    net = Network.random(3, 2, eps=0.05, seed=1)
    with pytest.raises(errors.InvalidInputError, match="method"):
        filtration(net, 1.0, method="bisection")
