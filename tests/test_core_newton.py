"""Newton with the exact Hessian run entirely in the Rust core (``engine="core"``) against the
Python loop (``engine="python"``, one Rust call per evaluation): the same optimum (η to 1e-13,
the same active set, both certified) from the same starts, on coupled, decoupled, badly scaled
and large-rate networks; and the keyword's validation."""

from __future__ import annotations

import numpy as np
import pytest

import capalloc_rs as ca
from capalloc_rs.allocation import optimal_allocation


def _agree(core: ca.Allocation, py: ca.Allocation, tol: float = 1e-13) -> None:
    assert abs(core.eta - py.eta) <= tol * py.eta + core.eta_error + py.eta_error
    assert list(core.active) == list(py.active)
    np.testing.assert_allclose(core.gamma, py.gamma, rtol=0, atol=1e-6 * py.sigma)
    assert core.r.sum() == pytest.approx(py.r_tot, rel=1e-14) and np.all(core.gamma >= 0)
    for res in (core, py):
        assert res.gap <= max(1e-12 * res.eta, 10 * res.eta_error)
    assert core.hessian == py.hessian == "exact" and core.hvp_count == 0


@pytest.mark.parametrize(
    ("n_sens", "eps", "seed", "start"),
    [
        (3, 0.1, 1, "uniform"),
        (5, 0.05, 3, "auto"),
        (5, 0.05, 3, "uniform"),
        (8, 0.3, 2, "auto"),
        (12, 0.0, 4, "uniform"),
        (20, 0.05, 3, "auto"),
    ],
)
def test_core_and_python_loops_reach_the_same_optimum(
    n_sens: int, eps: float, seed: int, start: str
) -> None:
    net = ca.Network.random(n_sens, 2, eps=eps, seed=seed)
    r_tot = 3.0 * n_sens
    core = optimal_allocation(net, r_tot, engine="core", start=start)  # type: ignore[arg-type]
    py = optimal_allocation(net, r_tot, engine="python", start=start)  # type: ignore[arg-type]
    _agree(core, py)
    assert abs(core.iterations - py.iterations) <= 1
    auto = optimal_allocation(net, r_tot, start=start)  # type: ignore[arg-type]
    assert auto.eta == core.eta and np.array_equal(auto.gamma, core.gamma)


@pytest.mark.parametrize(("r_min", "r_tot"), [(1e6, 3e12), (1e-3, 0.1), (1.0, 1e5)])
def test_core_loop_on_badly_scaled_and_large_rates(r_min: float, r_tot: float) -> None:
    net = ca.Network.random(5, 2, eps=0.05, seed=6, r_min=r_min)
    core = optimal_allocation(net, r_tot, engine="core")
    py = optimal_allocation(net, r_tot, engine="python")
    _agree(core, py, tol=1e-12)
    warm = optimal_allocation(net, r_tot, engine="core", warm=True)
    _agree(warm, py, tol=1e-12)


def test_core_loop_with_an_inactive_sensor_and_a_gamma0() -> None:
    net = ca.Network.random(6, 2, eps=0.1, seed=9)
    r_tot = 6 * net.r_min + 0.05  # little capacity: some sensors stay at r_min
    core = optimal_allocation(net, r_tot, engine="core")
    py = optimal_allocation(net, r_tot, engine="python")
    _agree(core, py)
    assert core.active.size < 6
    g0 = np.array([0.05, 0, 0, 0, 0, 0.0])
    _agree(
        optimal_allocation(net, r_tot, engine="core", gamma0=g0),
        optimal_allocation(net, r_tot, engine="python", gamma0=g0),
    )


def test_engine_is_validated() -> None:
    net = ca.Network.random(5, 2, eps=0.05, seed=3)
    with pytest.raises(ca.InvalidInputError, match="engine"):
        optimal_allocation(net, 15.0, engine="rust")  # type: ignore[arg-type]
    with pytest.raises(ca.InvalidInputError, match="engine='core'"):
        optimal_allocation(net, 15.0, engine="core", hessian="hvp")
    # The other methods ignore it.
    pg = optimal_allocation(net, 15.0, method="projected-gradient", engine="core")
    assert pg.method == "projected-gradient"
    with pytest.raises(ca.ConvergenceError):
        optimal_allocation(net, 15.0, engine="core", start="uniform", max_iter=1, tol=1e-15)
