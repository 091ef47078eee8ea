"""The filtration of coupled networks with sample costs, per-sensor minima and rate caps
(issue 15, point 3): the two tracers against each other, the KKT conditions of the weighted
box-simplex checked in rates with the network's own gradient (``∂η/∂r_i = μ b_i`` free, ``≥`` at
the minimum, ``≤`` at the cap), the shadow price against ``−dη*/dB``, pointwise optimal
allocations (once ``optimal_allocation`` solves such networks) and ``capalloc trace`` on a model
file with costs and caps."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run

from capalloc_rs import Network, errors
from capalloc_rs.allocation import filtration, optimal_allocation
from capalloc_rs.network.constructors import random_blocks


def costed_network(eps: float, seed: int, n: int = 5) -> Network:
    """A random coupled block network with unequal costs and minima, and caps on some sensors."""
    rng = np.random.default_rng(seed)
    a, g, c, coupling, e, _ = random_blocks(n, 2, 1, eps, seed, 1.0)
    costs = rng.uniform(0.5, 2.5, n)
    r_min = rng.uniform(0.6, 1.4, n)
    r_max = np.where(rng.uniform(size=n) < 0.6, r_min * rng.uniform(1.8, 3.0, n), np.inf)
    r_max[0] = r_min[0] * 2.0
    r_max[-1] = np.inf
    return Network.from_blocks(a, g, c, coupling, e, list(r_min), costs=costs, r_max=r_max)


CASES = [(0.05, 3, 25.0), (0.1, 3, 25.0), (0.2, 5, 20.0)]


def kinds(f):
    return [(e.kind, e.sensor) for e in f.events]


@pytest.mark.parametrize(("eps", "seed", "sigma_max"), CASES)
def test_continuation_and_reference_trace_the_same_path(eps, seed, sigma_max):
    net = costed_network(eps, seed)
    new = filtration(net, sigma_max, progress=False)
    ref = filtration(net, sigma_max, progress=False, method="reference")
    assert any(k == "capped" for k, _ in kinds(new))
    assert kinds(new) == kinds(ref)
    assert new.active_sets == ref.active_sets and new.capped_sets == ref.capped_sets
    np.testing.assert_allclose(new.breakpoints, ref.breakpoints, rtol=1e-7, atol=1e-9)
    for s in np.linspace(0.0, sigma_max, 11):
        np.testing.assert_allclose(new.rates(s), ref.rates(s), rtol=1e-7)
        assert new.mu(s) == pytest.approx(ref.mu(s), rel=1e-7)


def check_box_kkt(net: Network, f, sigmas) -> None:
    """The KKT conditions of the weighted box-simplex at the path's points, in rates with the
    network's own gradient: ``∂η/∂r_i = μ b_i`` for the free sensors, ``≥`` at the minimum,
    ``≤`` at the cap, and the budget spent."""
    b, lo, hi = net.costs, net.rate_min, net.rate_max
    for s in sigmas:
        r = f.rates(s)
        mu = f.mu(s)
        grad = np.asarray(net.gradient(r))  # ∂η/∂r in rates, the network's own gradient
        assert float(b @ r) == pytest.approx(f.budget(s), rel=1e-12)
        assert np.all(r >= lo * (1 - 1e-12)) and np.all(r <= hi * (1 + 1e-12))
        k = f._segment(float(s))
        free = list(f.active_sets[k])
        capped = list(f.capped_sets[k])
        at_min = [i for i in range(r.size) if i not in free and i not in capped]
        scale = abs(mu) * 1e-9
        np.testing.assert_allclose(grad[free], mu * b[free], rtol=1e-9)
        assert np.all(grad[at_min] >= mu * b[at_min] - scale * b[at_min])
        assert np.all(grad[capped] <= mu * b[capped] + scale * b[capped])
        np.testing.assert_array_equal(r[capped], hi[capped])


@pytest.mark.parametrize(("eps", "seed", "sigma_max"), CASES)
def test_nodes_meet_the_box_kkt_conditions_in_rates(eps, seed, sigma_max):
    net = costed_network(eps, seed)
    f = filtration(net, sigma_max, progress=False)
    check_box_kkt(net, f, np.linspace(0.0, sigma_max, 13))


def redundant_sensors(seed: int) -> Network:
    """Three sensors of one coupled 2-state system with costs and caps (from a scan): a capped
    sensor's value falls as the others grow, and it leaves its cap (``"uncapped"``)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(2, 2)) - 0.5 * np.eye(2)
    g = np.eye(2) * rng.uniform(0.5, 1.5, 2)
    sensors = [rng.normal(size=2) for _ in range(3)]
    costs = rng.uniform(0.5, 2, 3)
    r_max = [0.1 * rng.uniform(1.5, 20) if rng.uniform() < 0.8 else np.inf for _ in range(3)]
    r_max[-1] = r_max[-1] if not all(np.isfinite(r_max)) else np.inf
    return Network(a, g, sensors, r_min=0.1, costs=costs, r_max=r_max)


@pytest.mark.parametrize("seed", [218, 226, 374])
def test_a_sensor_leaving_its_cap(seed):
    net = redundant_sensors(seed)
    new = filtration(net, 15.0, progress=False)
    ref = filtration(net, 15.0, progress=False, method="reference")
    assert "uncapped" in {k for k, _ in kinds(new)}
    assert kinds(new) == kinds(ref) and new.capped_sets == ref.capped_sets
    np.testing.assert_allclose(new.breakpoints, ref.breakpoints, rtol=1e-7, atol=1e-9)
    assert not new.is_monotone  # a share falls from its cap
    check_box_kkt(net, new, np.linspace(0.0, 15.0, 16))
    for e in new.events:
        if e.kind == "uncapped":  # at its cap just before, below it just after
            i, hi = e.sensor, net.rate_max[e.sensor]
            assert new.rates(e.sigma - 1e-4)[i] == hi
            assert new.rates(e.sigma + 1e-4)[i] < hi
            check_box_kkt(net, new, [e.sigma - 1e-4, e.sigma + 1e-4])


def test_continuation_with_hessian_vector_products_traces_the_reference_path():
    # From 25 sensors on the continuation forms no Hessian per iterate (Krylov faces).
    net = costed_network(0.05, 3, n=25)
    new = filtration(net, 15.0, progress=False)
    ref = filtration(net, 15.0, progress=False, method="reference")
    assert sum(k == "capped" for k, _ in kinds(new)) >= 3
    assert kinds(new) == kinds(ref) and new.capped_sets == ref.capped_sets
    np.testing.assert_allclose(new.breakpoints, ref.breakpoints, rtol=1e-7, atol=1e-9)
    for s in (0.5, 7.0, 14.5):
        np.testing.assert_allclose(new.rates(s), ref.rates(s), rtol=1e-7)


def strongly_coupled(seed: int) -> Network:
    """Three scalar subsystems coupled at ε = 1 (couplings ~ N(0, 1.5²)), r_min = 0.1, random
    costs and caps: μ changes by orders of magnitude along the path and the free set empties at
    a cap (the free sensor is capped before the next one enters)."""
    rng = np.random.default_rng(seed)
    a, g, c = (rng.uniform(lo, hi, 3) for lo, hi in ((-1.5, 0.5), (0.3, 2.0), (0.2, 1.5)))
    coupling = rng.normal(size=(3, 3)) * 1.5
    r_max = [0.1 * rng.uniform(2, 30) if rng.uniform() < 0.7 else np.inf for _ in range(3)]
    r_max[-1] = r_max[-1] if not all(np.isfinite(r_max)) else np.inf
    costs = rng.uniform(0.5, 2, 3)
    blocks = {(i, j): coupling[i : i + 1, j : j + 1] for i in range(3) for j in range(3) if i != j}
    return Network.from_blocks(
        [np.array([[v]]) for v in a],
        [np.array([[v]]) for v in g],
        [np.array([[v]]) for v in c],
        couplings=blocks,
        eps=1.0,
        r_min=0.1,
        costs=costs,
        r_max=r_max,
    )


@pytest.mark.parametrize("seed", [5, 8, 68, 79, 83, 102])
def test_strong_coupling_both_tracers_agree(seed):
    # Found by a scan of 120 such networks (all now agree): seed 5 sent an event's Newton
    # iterates to rates of 1e35 (the cost is not computable there), 68 and the others stalled
    # at σ = 0 on a crossing of a cubic event model that is not there.
    net = strongly_coupled(seed)
    new = filtration(net, 20.0, progress=False)
    ref = filtration(net, 20.0, progress=False, method="reference")
    assert kinds(new) == kinds(ref)
    np.testing.assert_allclose(new.breakpoints, ref.breakpoints, rtol=1e-7, atol=1e-9)
    for s in (0.05, 1.0, 7.0, 19.0):
        np.testing.assert_allclose(new.rates(s), ref.rates(s), rtol=1e-7)


def test_shadow_price_is_minus_d_eta_d_budget():
    net = costed_network(0.1, 3)
    f = filtration(net, 25.0, progress=False)
    h = 1e-4
    for s in np.linspace(0.5, 24.5, 9):
        if np.min(np.abs(f.breakpoints - s)) < 2 * h:
            continue
        slope = (net.cost(f.rates(s + h)) - net.cost(f.rates(s - h))) / (2 * h)
        assert f.shadow_price(s) == pytest.approx(-slope, rel=1e-6)


@pytest.mark.parametrize(("eps", "seed", "sigma_max"), CASES)
def test_rates_match_pointwise_optimal_allocation(eps, seed, sigma_max):
    net = costed_network(eps, seed)
    f = filtration(net, sigma_max, progress=False)
    for s in np.linspace(0.25, sigma_max, 9):
        a = optimal_allocation(net, f.budget(s))
        np.testing.assert_allclose(f.rates(s), a.r, rtol=1e-7, atol=1e-9)
        assert f.mu(s) == pytest.approx(a.mu, rel=1e-7)


def test_sigma_max_beyond_the_budget_range_is_refused():
    a, g, c, coupling, e, _ = random_blocks(3, 2, 1, 0.1, 1, 1.0)
    net = Network.from_blocks(a, g, c, coupling, e, 1.0, costs=[1.0, 2.0, 0.5], r_max=3.0)
    lo, hi = net.budget_range
    with pytest.raises(errors.InvalidInputError, match="sigma_max") as info:
        filtration(net, (hi - lo) * 1.01, progress=False)
    assert f"{hi - lo:.17g}" in str(info.value)


MODEL_WITH_LIMITS = """\
format = "capalloc-network"
version = 1
r_min = 1.0
eps = 0.1

[[subsystems]]
A = [[0.0, 1.0], [-4.0, -0.4]]
G = [[0.5, 0.0], [0.0, 1.0]]
c = [1.0, 0.0]
cost = 2.0
r_max = 3.0

[[subsystems]]
A = [[0.2, 1.0, 0.0], [0.0, -0.5, 1.0], [0.0, 0.0, -1.0]]
G = [[1.0, 0.0, 0.0], [0.3, 1.0, 0.0], [0.0, 0.3, 1.0]]
c = [[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]]
cost = 0.5
r_min = 0.5
r_max = 4.0

[[subsystems]]
A = [[-0.3]]
G = [[2.0]]
c = [0.5]

[[couplings]]
i = 0
j = 1
A = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
"""


def test_cli_trace_on_a_model_with_costs_and_caps(tmp_path: Path) -> None:
    model = tmp_path / "limits.toml"
    model.write_text(MODEL_WITH_LIMITS)
    net = Network.load(model)
    assert not net.is_paper_form
    f = filtration(net, 12.0, progress=False)
    assert ("capped", 1) in kinds(f)
    p = run("trace", str(model), "--sigma-max", "12", "--no-progress")
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    assert "capped (sensor 1)" in p.stdout
    assert "free / capped" in p.stdout and "[2] / [1]" in p.stdout
    d = json.loads(run("trace", str(model), "--sigma-max", "12", "--json").stdout)
    assert [(e["kind"], e["sensor"]) for e in d["events"]] == kinds(f)
    assert d["breakpoints"] == f.breakpoints.tolist()
    assert d["capped_sets"] == [list(s) for s in f.capped_sets]
    for e in d["events"]:
        assert e["budget"] == pytest.approx(e["sigma"] + net.budget_range[0])
    plot = tmp_path / "f.png"
    p = run("trace", str(model), "--sigma-max", "12", "--plot", str(plot), "--budget", "--rates")
    assert p.returncode == 0, p.stderr
    # Every sensor capped: σ_max beyond the budget range is a user error, not a traceback.
    capped_all = MODEL_WITH_LIMITS.replace("c = [0.5]\n", "c = [0.5]\nr_max = 2.0\n")
    model.write_text(capped_all)
    p = run("trace", str(model), "--sigma-max", "100")
    assert p.returncode != 0 and "sigma_max" in p.stderr and "Traceback" not in p.stderr


def test_sweep_filtration_row_on_a_network_with_costs_and_caps() -> None:
    pytest.importorskip("pyarrow")
    from capalloc_rs import SerialExecutor
    from capalloc_rs.sweep import sweep

    net = costed_network(0.1, 3)
    budget = net.budget_range[0] + 12.0
    table = sweep([net], [budget], compute="filtration", executor=SerialExecutor(), progress=False)
    (row,) = table.to_pylist()
    assert row["error"] is None
    f = filtration(net, 12.0, progress=False)
    assert row["breakpoints"] == f.breakpoints.tolist()
    assert row["capped_sets"] == [list(s) for s in f.capped_sets]
    assert [(e["kind"], e["sensor"]) for e in row["events"]] == kinds(f)
    np.testing.assert_allclose(row["r"], f.rates(12.0), rtol=1e-12)
    assert float(net.costs @ np.array(row["r"])) == pytest.approx(budget, rel=1e-12)
    assert row["shadow_price"] == -row["mu"] == pytest.approx(f.shadow_price(12.0), rel=1e-12)
    assert row["eta"] == pytest.approx(net.cost(f.rates(12.0)), rel=1e-12)
