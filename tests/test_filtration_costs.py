"""The filtration with sample costs and rate caps (issue 15, point 3) against the closed form of
decoupled scalar subsystems (tests/scalar_costs_model.py: each rate is ``clip(η_i'⁻¹(μ b_i),
r_min,i, r_max,i)``, sensor i enters at ``μ = η_i'(r_min,i)/b_i`` and is capped at
``μ = η_i'(r_max,i)/b_i``; no Rust needed), and the paper's case through the general path."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scalar_costs_model import CostedScalarNetwork
from scalar_model import random_scalar_network

from capalloc_rs import errors
from capalloc_rs.allocation import filtration

METHODS = ("continuation", "reference")


def random_costed(seed: int, n: int = 6, all_capped: bool = False) -> CostedScalarNetwork:
    """Scalar subsystems with unequal costs and minima; about half the sensors capped (every
    one with ``all_capped``)."""
    rng = np.random.default_rng(seed)
    lo = rng.uniform(0.5, 1.5, n)
    capped = rng.uniform(size=n) < 0.5
    capped[0] = True
    capped[-1] = all_capped
    hi = np.where(capped | all_capped, lo * rng.uniform(1.5, 4.0, n), np.inf)
    return CostedScalarNetwork(
        a=rng.uniform(-2, 1, n),
        c=rng.uniform(0.3, 2, n),
        q=rng.uniform(0.2, 3, n),
        b=rng.uniform(0.5, 3, n),
        r_lo=lo,
        r_hi=hi,
    )


def emptying() -> CostedScalarNetwork:
    """Sensor 1 is worth most but reaches its cap before any other enters: the free set is
    empty at σ = 2.4 and μ jumps up to sensor 2's gradient there."""
    return CostedScalarNetwork(
        a=np.array([-1.0, 0.5, -0.3]),
        c=np.array([1.5, 0.5, 1.0]),
        q=np.array([2.0, 1.0, 1.0]),
        b=np.array([1.0, 2.0, 0.7]),
        r_lo=np.array([1.0, 0.8, 1.2]),
        r_hi=np.array([1.3, 2.0, 2.0]),
    )


def traced(f):
    """(σ, kind, sensor, μ) of the active-set changes of a traced filtration."""
    return [(e.sigma, e.kind, e.sensor, e.mu) for e in f.events if e.kind != "monotonicity-lost"]


def check_against_closed_form(net: CostedScalarNetwork, sigma_max: float, method: str) -> None:
    exact = [e for e in net.events() if e[0] < sigma_max * (1 - 1e-9)]
    f = filtration(net, sigma_max, tol=1e-12, method=method, progress=False)
    got = traced(f)
    assert [(k, i) for _, k, i, _ in got] == [(k, i) for _, k, i, _ in exact]
    np.testing.assert_allclose([s for s, *_ in got], [s for s, *_ in exact], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose([m for *_, m in got], [m for *_, m in exact], rtol=1e-9)
    # The budget beside σ: B = σ + Σ b_i r_min,i.
    for e in f.events:
        assert e.budget == pytest.approx(e.sigma + net.budget_range[0], rel=1e-15)
    # Theorem 2 generalised: decoupled subsystems give a monotone filtration, entered in the
    # order of the marginal values η_i'(r_min,i)/b_i.
    assert f.is_monotone and f.is_filtration
    order = np.argsort([net.eta_prime(i, net.r_lo[i]) / net.b[i] for i in range(net.a.size)])
    assert list(f.entry_order) == [int(i) for i in order[: len(f.entry_order)]]
    # The free and capped sets between breakpoints, from the closed form at the midpoints.
    for k, (free, capped) in enumerate(zip(f.active_sets, f.capped_sets, strict=True)):
        lo, hi = f.breakpoints[k], f.breakpoints[k + 1]
        if hi - lo < 1e-9:
            continue
        r = net.rates_of_mu(net.mu_of_sigma(0.5 * (lo + hi)))
        assert set(capped) == {i for i in range(r.size) if r[i] >= net.r_hi[i]}
        assert set(free) == {i for i in range(r.size) if net.r_lo[i] < r[i] < net.r_hi[i]}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_breakpoints_match_closed_form(seed, method):
    net = random_costed(seed)
    events = net.events()
    assert any(kind == "capped" for _, kind, _, _ in events)
    check_against_closed_form(net, events[-1][0] + 3.0, method)


@pytest.mark.parametrize("method", METHODS)
def test_every_sensor_capped_up_to_the_whole_box(method):
    net = random_costed(7, 5, all_capped=True)
    width = net.budget_range[1] - net.budget_range[0]
    check_against_closed_form(net, width, method)
    f = filtration(net, width, method=method, progress=False)
    np.testing.assert_allclose(f.rates(width), net.r_hi, rtol=1e-12)
    np.testing.assert_allclose(f.rates(0.0), net.r_lo, rtol=1e-15)


@pytest.mark.parametrize("method", METHODS)
def test_free_set_emptied_by_a_cap(method):
    net = emptying()
    exact = net.events()
    assert [(k, i) for _, k, i, _ in exact[1:3]] == [("capped", 1), ("enter", 2)]
    assert exact[1][0] == exact[2][0]  # at the same σ: μ jumps there
    check_against_closed_form(net, 3.2, method)
    f = filtration(net, 3.2, method=method, progress=False)
    assert f.active_sets[1] == () and f.capped_sets[1] == (1,)
    # μ jumps from sensor 1's marginal value at its cap up to sensor 2's at its minimum.
    assert f.mu(2.4 - 1e-6) == pytest.approx(exact[1][3], rel=1e-5)
    assert f.mu(2.4 + 1e-6) == pytest.approx(exact[2][3], rel=1e-5)


@pytest.mark.parametrize("method", METHODS)
def test_rates_along_the_path_match_closed_form(method):
    net = random_costed(2)
    sigma_max = net.events()[-1][0] + 3.0
    f = filtration(net, sigma_max, method=method, progress=False)
    for s in np.linspace(0.0, sigma_max, 17):
        mu = net.mu_of_sigma(float(s)) if s > 0 else net.events()[0][3]
        r = net.rates_of_mu(mu)
        np.testing.assert_allclose(f.rates(s), r, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(f.allocation(s), net.b * (r - net.r_lo), atol=1e-9)
        assert f.mu(s) == pytest.approx(mu, rel=1e-9)
        assert float(net.b @ f.rates(s)) == pytest.approx(f.budget(s), rel=1e-12)
    assert f.rates(np.array([1.0, 2.0])).shape == (2, net.a.size)


def test_shadow_price_is_minus_d_eta_d_budget():
    # −μ against −dη*/dB by central differences on the path (η* = Σ η_i(r*_i) in rates).
    net = random_costed(3)
    f = filtration(net, net.events()[-1][0] + 3.0, progress=False)
    h = 1e-4
    for s in np.linspace(0.5, f.sigma_max - 0.5, 9):
        if np.min(np.abs(f.breakpoints - s)) < 2 * h:
            continue
        slope = (net.cost(f.rates(s + h)) - net.cost(f.rates(s - h))) / (2 * h)
        assert f.shadow_price(s) == pytest.approx(-slope, rel=1e-6)
        assert f.shadow_price(s) == pytest.approx(-f.mu(s), rel=0)


def test_to_dict_has_the_new_event_kinds_and_the_budget():
    f = filtration(emptying(), 3.2, progress=False)
    d = f.to_dict()
    kinds = {e["kind"] for e in d["events"]}
    assert kinds == {"enter", "capped"}
    assert d["capped_sets"][1] == [1]
    assert d["budget_min"] == pytest.approx(float(emptying().budget_range[0]))
    for e in d["events"]:
        assert e["budget"] == pytest.approx(e["sigma"] + d["budget_min"])
        assert e["shadow_price"] == -e["mu"]


def test_sigma_max_beyond_every_cap_is_refused():
    net = random_costed(7, 5, all_capped=True)
    width = net.budget_range[1] - net.budget_range[0]
    for method in METHODS:
        with pytest.raises(errors.InvalidInputError, match="sigma_max") as info:
            filtration(net, width * (1 + 1e-9), method=method, progress=False)
        assert f"{width:.17g}" in str(info.value)


def as_general(plain) -> CostedScalarNetwork:
    """The paper-form scalar network, presented as one with costs and limits (all costs 1, a
    common minimum, no cap) so that the filtration takes the general path."""
    n = plain.a.size
    return CostedScalarNetwork(
        plain.a, plain.c, plain.q, np.ones(n), np.full(n, plain.r_min), np.full(n, math.inf)
    )


@pytest.mark.parametrize("method", METHODS)
def test_paper_case_through_the_general_path_is_bitwise_the_same(method):
    plain = random_scalar_network(4, 6)
    general = as_general(plain)
    f = filtration(plain, 30.0, method=method, progress=False)
    g = filtration(general, 30.0, method=method, progress=False)
    assert f.breakpoints.tobytes() == g.breakpoints.tobytes()
    assert f.node_gamma.tobytes() == g.node_gamma.tobytes()
    assert f.node_mu.tobytes() == g.node_mu.tobytes()
    assert f.events == g.events
    assert f.active_sets == g.active_sets
    assert f.allocation(7.5).tobytes() == g.allocation(7.5).tobytes()
    assert f.rates(7.5).tobytes() == (f.allocation(7.5) + plain.r_min).tobytes()
    assert all(c == () for c in f.capped_sets)
    # In the paper's case the budget is r_tot = σ + N·r_min.
    assert [e.budget for e in f.events] == [e.sigma + 6 * plain.r_min for e in f.events]
