"""The traced filtration against the closed-form decoupled scalar model (no Rust needed).

For decoupled scalar subsystems the optimal allocation has the closed form
``γ_i(μ) = max(0, g_i⁻¹(μ) − r_min)`` with ``Σγ_i(μ) = σ``, and sensor j enters when μ reaches
``g_j(r_min)``: the breakpoint is ``σ_j = Σ_i γ_i(g_j(r_min))`` (see tests/scalar_model.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from scalar_model import ScalarNetwork, random_scalar_network

from capalloc_rs import errors
from capalloc_rs.allocation import filtration, optimal_allocation


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_breakpoints_match_closed_form(seed):
    net = random_scalar_network(seed, 6)
    exact = net.breakpoints()
    sigma_max = exact[-1][0] + 5.0  # every sensor enters
    f = filtration(net, sigma_max, tol=1e-12)
    assert f.entry_order == tuple(j for _, j in exact)
    np.testing.assert_allclose(f.breakpoints[1:-1], [s for s, _ in exact[1:]], rtol=1e-9)
    assert f.breakpoints[0] == 0.0 and f.breakpoints[-1] == sigma_max
    assert f.is_monotone and f.is_filtration and f.diagonally_dominant
    # Nested, growing active sets.
    for before, after in zip(f.active_sets, f.active_sets[1:], strict=False):
        assert set(before) < set(after)


@pytest.mark.parametrize("seed", [0, 5])
def test_path_agrees_with_pointwise_optimum(seed):
    net = random_scalar_network(seed, 5)
    f = filtration(net, 40.0)
    for s in np.linspace(0.0, 40.0, 23):
        alloc = optimal_allocation(net, s + 5 * net.r_min)
        np.testing.assert_allclose(f.allocation(s), alloc.gamma, atol=1e-9 * max(s, 1.0))
        if s > 0:
            assert f.mu(s) == pytest.approx(alloc.mu, rel=1e-9)
    grid = np.array([1.0, 2.0, 3.0])
    assert f.allocation(grid).shape == (3, 5)
    assert f.mu(grid).shape == (3,)


def test_derivative_matches_finite_differences():
    net = random_scalar_network(3, 5)
    f = filtration(net, 30.0)
    interior = [s for s in np.linspace(0.5, 29.5, 15) if np.min(np.abs(f.breakpoints - s)) > 1e-3]
    for s in interior:
        h = 1e-5
        fd = (f.allocation(s + h) - f.allocation(s - h)) / (2 * h)
        np.testing.assert_allclose(f.derivative(s), fd, atol=1e-6)
        assert f.derivative(s).sum() == pytest.approx(1.0, rel=1e-12)
    # Right derivative at a breakpoint: the entering sensor already moves.
    k = 1
    s_k = f.breakpoints[k]
    entering = f.events[k].sensor
    assert f.derivative(s_k)[entering] > 0
    fd_right = (f.allocation(s_k + 1e-6) - f.allocation(s_k)) / 1e-6
    np.testing.assert_allclose(f.derivative(s_k), fd_right, atol=1e-4)


def test_breakpoints_agree_with_bracketing_on_pointwise_solutions():
    net = random_scalar_network(1, 4)
    f = filtration(net, 25.0)
    # All three later sensors enter below σ = 25 (closed form: 0.068, 2.88, 7.63).
    assert [s for s, _ in net.breakpoints()][-1] < 25.0
    assert f.breakpoints.size == len(net.breakpoints()) + 1 == 5
    for k, s_k in enumerate(f.breakpoints[1:-1], start=1):
        j = f.events[k].sensor  # the sensor entering at s_k
        lo, hi = s_k - 0.5, s_k + 0.5
        for _ in range(60):  # bisection on "is j active in the pointwise optimum?"
            mid = 0.5 * (lo + hi)
            gamma = optimal_allocation(net, mid + 4).gamma
            lo, hi = (lo, mid) if gamma[j] > 1e-9 else (mid, hi)
        assert s_k == pytest.approx(0.5 * (lo + hi), abs=1e-6)


def test_inputs_and_range():
    net = random_scalar_network(0, 3)
    with pytest.raises(errors.InvalidInputError):
        filtration(net, -1.0)
    with pytest.raises(errors.InvalidInputError):
        filtration(net, float("nan"))
    f = filtration(net, 2.0)
    with pytest.raises(errors.InvalidInputError, match="outside"):
        f.allocation(3.0)
    single = ScalarNetwork(a=np.array([0.2]), c=np.array([1.0]), q=np.array([1.0]))
    fs = filtration(single, 5.0)
    assert fs.active_sets == ((0,),) and fs.breakpoints.tolist() == [0.0, 5.0]
    np.testing.assert_allclose(fs.allocation(2.5), [2.5])


def test_plot_draws_every_sensor(tmp_path):
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    net = random_scalar_network(2, 4)
    f = filtration(net, 20.0)
    ax = f.plot()
    assert len(ax.get_lines()) >= 4
    labels = [t.get_text() for t in ax.texts]
    assert any(lbl.startswith("+") for lbl in labels)
    out = tmp_path / "filtration.png"
    ax.figure.savefig(out)
    assert out.stat().st_size > 1000
