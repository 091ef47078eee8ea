"""The shadow price −μ ≥ 0 along the filtration and the plot over the budget r_tot: the price
checked against central differences of the optimum η*(r_tot) (another route than the path's
multiplier) and against the pointwise optimum's own price; the plot's x data shifted by N·r_min;
``capalloc trace --budget``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_helpers import MODEL, assert_user_error, has, run

from capalloc_rs import Filtration, InvalidInputError, Network
from capalloc_rs.allocation import filtration, optimal_allocation

SIGMA_MAX = 6.0
#: σ on the path: inside each of its three segments (breakpoints near 0.28 and 1.81) and near
#: the end.
SIGMAS = [0.1, 1.0, 3.0, 5.5]


@pytest.fixture(scope="module")
def net() -> Network:
    return Network.load(MODEL)


@pytest.fixture(scope="module")
def path(net: Network) -> Filtration:
    return filtration(net, SIGMA_MAX, progress=False)


@pytest.mark.parametrize("sigma", SIGMAS)
def test_shadow_price_is_minus_the_derivative_of_the_optimum(
    net: Network, path: Filtration, sigma: float
) -> None:
    r_tot = sigma + net.num_sensors * float(net.r_min)
    h = 1e-4 * r_tot
    eta_plus = optimal_allocation(net, r_tot + h).eta
    eta_minus = optimal_allocation(net, r_tot - h).eta
    by_differences = -(eta_plus - eta_minus) / (2 * h)
    price = float(path.shadow_price(sigma))
    assert price > 0
    assert price == pytest.approx(by_differences, rel=1e-6)
    assert price == pytest.approx(optimal_allocation(net, r_tot).shadow_price, rel=1e-8)
    assert price == -float(path.mu(sigma))


def test_shadow_price_has_the_shapes_of_mu(path: Filtration) -> None:
    grid = np.array([[0.5, 2.0], [4.0, 6.0]])
    prices = path.shadow_price(grid)
    assert prices.shape == grid.shape
    np.testing.assert_array_equal(prices, -path.mu(grid))
    # capacity is worth less the more there is: the price falls along the path
    flat = path.shadow_price(np.linspace(0.0, SIGMA_MAX, 7))
    assert np.all(np.diff(flat) < 0)
    with pytest.raises(InvalidInputError):
        path.shadow_price(SIGMA_MAX + 1.0)


def test_events_carry_the_shadow_price_where_they_happen(net: Network, path: Filtration) -> None:
    assert [e.kind for e in path.events] == ["enter"] * 3
    for e in path.events:
        r_tot = e.sigma + net.num_sensors * float(net.r_min)
        assert e.shadow_price == -e.mu
        expected = optimal_allocation(net, r_tot).shadow_price
        assert e.shadow_price == pytest.approx(expected, rel=1e-7)
        d = e.to_dict()
        assert d["mu"] == e.mu and d["shadow_price"] == e.shadow_price


def _plot(path: Filtration, **kw: Any) -> Any:
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    return path.plot(**kw)


def test_plot_over_the_budget_shifts_x_by_n_r_min(net: Network, path: Filtration) -> None:
    import matplotlib.pyplot as plt

    over_sigma = _plot(path)
    over_budget = _plot(path, budget=True)
    shift = net.num_sensors * float(net.r_min)
    assert shift == 3.0
    lines_s, lines_b = over_sigma.get_lines(), over_budget.get_lines()
    assert len(lines_s) == len(lines_b) > 0
    for ls, lb in zip(lines_s, lines_b, strict=True):
        np.testing.assert_allclose(np.asarray(lb.get_xdata()), np.asarray(ls.get_xdata()) + shift)
        np.testing.assert_array_equal(lb.get_ydata(), ls.get_ydata())
    # the sensor curves start at r_tot = N·r_min and end at σ_max + N·r_min
    first = np.asarray(lines_b[0].get_xdata())
    assert first[0] == shift and first[-1] == pytest.approx(SIGMA_MAX + shift)
    assert over_budget.get_xlim() == pytest.approx((shift, SIGMA_MAX + shift))
    assert "budget r_tot" in over_budget.get_xlabel()
    assert "budget" not in over_sigma.get_xlabel()
    # the breakpoint labels move with their lines
    xs_s = sorted(t.xy[0] for t in over_sigma.texts)
    xs_b = sorted(t.xy[0] for t in over_budget.texts)
    np.testing.assert_allclose(xs_b, np.array(xs_s) + shift)
    plt.close("all")


@pytest.mark.parametrize("bad", ["yes", 1, None])
def test_plot_budget_is_validated(path: Filtration, bad: object) -> None:
    with pytest.raises(InvalidInputError, match="budget"):
        path.plot(budget=bad)


def test_cli_trace_budget_plot_and_shadow_prices(tmp_path: Path) -> None:
    plot = tmp_path / "f.png"
    p = run("trace", MODEL, "--sigma-max", "6", "--plot", str(plot), "--budget", "--no-progress")
    assert p.returncode == 0, p.stderr
    assert "−μ at start" in p.stdout and "shadow price" in p.stdout
    if has("matplotlib"):
        assert plot.stat().st_size > 1000
    p = run("trace", MODEL, "--sigma-max", "6", "--json", "--no-progress")
    assert p.returncode == 0, p.stderr
    events = json.loads(p.stdout)["events"]
    assert all(e["shadow_price"] == -e["mu"] > 0 for e in events)
    # --budget only sets the plot's axis: without --plot it is a clear error, no traceback
    assert_user_error(run("trace", MODEL, "--sigma-max", "6", "--budget"), "--budget", "--plot")
