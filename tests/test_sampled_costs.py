"""The sampled system with sample costs (slots of unequal length, a budget, idle time): the exact
cost against a plain fixed-point iteration written here, Corollary 1 with costs, Monte Carlo,
the schedule search and its baselines within the budget and the count limits, and the paper's
case bitwise unchanged."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _sampled_reference import fixed_point

from capalloc_rs import Network, Schedule, ScheduleError, sampled_cost, sampled_covariance, simulate
from capalloc_rs.errors import InvalidInputError
from capalloc_rs.sampled import (
    best_schedule,
    greedy_schedule,
    round_robin_schedule,
    sampled_system,
)

COSTS = [1.0, 2.0, 0.5]


def _net(costs=COSTS, r_max=None, seed: int = 5, weight=None) -> Network:
    rng = np.random.default_rng(seed)
    n = 3
    a = rng.standard_normal((n, n)) * 0.5 - 0.3 * np.eye(n)
    g = rng.standard_normal((n, n)) * 0.4
    sensors = [rng.standard_normal((n, 1)) for _ in range(3)]
    return Network(a, g, sensors, r_min=1.0, costs=costs, r_max=r_max, weight=weight)


def _reference(net: Network, tau: float, slots: list[int], budget: float) -> tuple[float, float]:
    q = net.g @ net.g.T
    return fixed_point(
        net.a, q, list(net.sensors), [float(b) for b in net.costs], tau, slots, budget
    )


@pytest.mark.parametrize("budget", [None, 9.0, 13.5])
@pytest.mark.parametrize("slots", [[0, 1, 2, 0, 2, 1], [2, 2, 0, 1, 2]])
def test_unequal_slots_match_the_fixed_point_of_the_slot_maps(slots, budget) -> None:
    """η̄ (both conventions) with slots of lengths b_i τ₀ and an idle tail equals the plain
    fixed-point iteration of the slot maps (Van Loan by expm, information form) to 1e-10."""
    net = _net()
    b = budget if budget is not None else sum(COSTS[i] for i in slots)
    ref = _reference(net, 0.4, slots, b)
    for which, want in zip(("boundary", "average"), ref, strict=True):
        got = sampled_cost(net, 0.4, slots, which, budget=budget)
        assert got == pytest.approx(want, rel=1e-10)
    cov = sampled_covariance(net, 0.4, slots, budget=budget)
    assert cov.idle == pytest.approx(b - sum(COSTS[i] for i in slots), abs=1e-12)
    assert cov.residual < 1e-12


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_corollary_1_with_costs_is_first_order(which) -> None:
    """η̄(τ, R) → η(counts) as τ → 0 with costs and idle time, observed order 1.0 ± 0.1: the
    counts are the rates whatever the slot lengths."""
    net = _net()
    slots = [2, 0, 1, 2, 0, 2]  # counts (2, 1, 3): 2 + 2 + 1.5 = 5.5 of a budget of 7
    limit = net.cost([2.0, 1.0, 3.0])
    errs = [
        abs(sampled_cost(net, tau, slots, which, budget=7.0) - limit)
        for tau in (0.01, 0.005, 0.0025, 0.00125)
    ]
    orders = np.log2(np.asarray(errs[:-1]) / np.asarray(errs[1:]))
    assert np.all(np.abs(orders - 1.0) < 0.1), orders


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_monte_carlo_of_the_unequal_slot_system_contains_the_exact_cost(which) -> None:
    net = _net()
    mc = simulate(
        net, 0.4, [0, 1, 2, 0, 2, 1], 600, seed=7, runs=16, which=which, budget=9.0, progress=False
    )
    assert mc.contains(mc.predicted)
    assert mc.predicted == pytest.approx(
        sampled_cost(net, 0.4, [0, 1, 2, 0, 2, 1], which, budget=9.0)
    )


def test_schedule_knows_its_budget() -> None:
    s = Schedule([0, 1, 2, 0], 3)
    assert s.budget_used() == 4.0
    assert s.budget_used(COSTS) == 1.0 + 2.0 + 0.5 + 1.0
    s.validate(3, 1.0, costs=COSTS, budget=4.5, r_max=[np.inf, 1, 1])
    with pytest.raises(ScheduleError, match="budget"):
        s.validate(3, 1.0, costs=COSTS, budget=4.0)
    with pytest.raises(ScheduleError, match="r_max"):
        s.validate(3, 1.0, r_max=[1, 1, 1])
    with pytest.raises(ScheduleError, match="costs"):
        s.budget_used([1.0, -1.0, 1.0])


def test_bad_budgets_and_schedules_over_budget_are_refused() -> None:
    net = _net()
    with pytest.raises(InvalidInputError, match="budget"):
        sampled_cost(net, 0.4, [0, 1, 2], budget=-1.0)
    with pytest.raises(ScheduleError, match="budget"):
        sampled_cost(net, 0.4, [0, 1, 2], budget=3.0)
    with pytest.raises(ScheduleError, match="r_max"):
        sampled_cost(_net(r_max=[np.inf, 1.5, np.inf]), 0.4, [0, 1, 1, 2])
    with pytest.raises(ScheduleError):
        best_schedule(net, 0.4, 2.0, progress=False)  # the minima need 3.5 channel units


def _within(net: Network, s: Schedule, budget: float) -> bool:
    counts = s.counts
    ok_min = np.all(counts >= np.ceil(net.rate_min - 1e-9))
    ok_max = np.all(counts <= np.floor(net.rate_max + 1e-9))
    return bool(ok_min and ok_max and s.budget_used(net.costs) <= budget * (1 + 1e-12))


@pytest.mark.parametrize("which", ["boundary", "average"])
@pytest.mark.parametrize("budget", [7.5, 12.0])
def test_best_schedule_respects_budget_and_limits_and_beats_baselines(which, budget) -> None:
    """Screened and exhaustive searches stay within the budget and the count limits, screened is
    never worse than exhaustive on these small problems, and both are no worse than round robin
    and greedy (their exact costs at the same budget)."""
    net = _net(r_max=[np.inf, 3.0, 6.0])
    scr = best_schedule(net, 0.4, budget, which=which, progress=False)
    exh = best_schedule(net, 0.4, budget, which=which, method="exhaustive", progress=False)
    for res in (scr, exh):
        assert _within(net, res.schedule, budget)
        assert res.eta_bar == pytest.approx(
            sampled_cost(net, 0.4, res.schedule, which, budget=budget), rel=1e-12
        )
    assert scr.eta_bar <= exh.eta_bar * (1 + 1e-12)
    for base in (round_robin_schedule(net, budget), greedy_schedule(net, 0.4, budget)):
        assert _within(net, base, budget)
        cost = sampled_cost(net, 0.4, base, which, budget=budget)
        assert exh.eta_bar <= cost * (1 + 1e-12)
        assert scr.eta_bar <= cost * (1 + 1e-12)


def test_search_uses_the_budget_better_than_unit_thinking() -> None:
    """Cheap samples are worth more: with sensor 2 at half a unit, the best schedule spends the
    budget differently from the unit-cost network, and its counts pay exactly within B."""
    res = best_schedule(_net(), 0.3, 10.0, progress=False)
    assert res.schedule.budget_used(COSTS) <= 10.0
    assert math.isfinite(res.eta_limit)
    assert res.eta_limit == pytest.approx(_net().cost(np.asarray(res.counts, dtype=float)))


#: Numbers of the paper's case computed by main's build before sample costs existed (commit
#: 5158759, this machine) for ``_net(costs=None, seed=3)``: η̄ at τ = 0.4 as exact hex floats, and
#: the searches' results at τ = 0.5, r_tot = 7 (schedule, η̄, evaluations, moves).
PAPER = {
    ((0, 1, 2, 0, 1), "boundary"): "0x1.8d70144df9631p-1",
    ((0, 1, 2, 0, 1), "average"): "0x1.b018e5e8f7c26p-1",
    ((2, 2, 1, 0, 0, 1, 0), "boundary"): "0x1.7c3894f8f85bbp-1",
    ((2, 2, 1, 0, 0, 1, 0), "average"): "0x1.91f440be6d6eep-1",
    ((0, 1, 2), "boundary"): "0x1.295283632e074p+0",
    ((0, 1, 2), "average"): "0x1.1a7e43cbf2c30p+0",
}
PAPER_SEARCH = {
    ("screened-v3", "boundary"): ((2, 2, 0, 1, 1, 1, 1), "0x1.3912311f600f8p-1", 165, 18),
    ("exhaustive", "average"): ((1, 0, 1, 1, 2, 1, 1), "0x1.5055059cfbf37p-1", 32, 1),
}


def test_paper_case_is_bitwise_main() -> None:
    """The paper's case gives main's numbers bit for bit (stored above): the costs, the two
    searches (same schedule, cost, evaluations and moves: the same path) and greedy."""
    net = _net(costs=None, seed=3)
    for (slots, which), want in PAPER.items():
        assert sampled_cost(net, 0.4, list(slots), which).hex() == want
    for (method, which), (slots, eta, evaluations, moves) in PAPER_SEARCH.items():
        res = best_schedule(net, 0.5, 7, which=which, method=method, progress=False)
        assert (res.schedule.slots, res.eta_bar.hex()) == (slots, eta)
        assert (res.evaluations, res.moves) == (evaluations, moves)
    assert greedy_schedule(net, 0.5, 8).slots == (1, 1, 1, 1, 1, 1, 0, 2)


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_unit_costs_given_explicitly_take_the_paper_path_bitwise(which) -> None:
    """Costs of 1 (and a budget equal to the slot count) are the paper's case: the same numbers,
    bit for bit, as a network without costs — the same code path (unit costs are dropped by
    ``sampled_system``, the Rust core sees the model of today)."""
    plain, unit = _net(costs=None), _net(costs=[1.0, 1.0, 1.0])
    assert sampled_system(unit).costs is None
    for slots in ([0, 1, 2, 0, 1], [2, 2, 1, 0, 0, 1, 0]):
        a = sampled_cost(plain, 0.4, slots, which)
        assert sampled_cost(unit, 0.4, slots, which) == a
        assert sampled_cost(plain, 0.4, slots, which, budget=len(slots)) == a
    bp = best_schedule(plain, 0.5, 7, which=which, progress=False)
    bu = best_schedule(unit, 0.5, 7, which=which, progress=False)
    assert bp.schedule == bu.schedule and bp.eta_bar == bu.eta_bar
    assert bp.evaluations == bu.evaluations
    runs = [
        simulate(n, 0.4, [0, 1, 2, 0, 1], 50, seed=1, runs=4, which=which, progress=False)
        for n in (plain, unit)
    ]
    assert runs[0].mse == runs[1].mse and runs[0].predicted == runs[1].predicted


def test_cli_schedule_and_simulate_take_a_budget(tmp_path, capsys) -> None:
    """``capalloc schedule/simulate --budget`` on a model file with sample costs and caps: the
    schedule printed stays within the budget and the limits, the Monte Carlo is of the idle-time
    system (its prediction is η̄ at that budget); bad budgets are one-line errors (exit 2)."""
    import json

    from capalloc_rs.cli import main

    net = _net(r_max=[np.inf, 3.0, 6.0])
    path = str(tmp_path / "costs.json")
    net.save(path)
    assert main(["schedule", path, "--tau", "0.4", "--budget", "9", "--json", "--no-progress"]) == 0
    d = json.loads(capsys.readouterr().out)
    s = Schedule(d["schedule"], 3)
    assert _within(net, s, 9.0) and d["budget"] == 9.0
    assert d["budget_used"] == pytest.approx(s.budget_used(net.costs))
    argv = ["simulate", path, "--tau", "0.4", "--schedule", "0,1,2,2", "--budget", "7"]
    assert main([*argv, "--periods", "50", "--runs", "4", "--json", "--no-progress"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["eta_bar"] == sampled_cost(net, 0.4, [0, 1, 2, 2], budget=7.0)
    for bad in (["--budget", "2"], ["--budget", "-1"], []):
        try:
            rc = main(
                ["schedule" if bad else "simulate", path, "--tau", "0.4", *bad, "--no-progress"]
            )
        except SystemExit as exc:  # argparse's own refusals
            rc = exc.code
        assert rc == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.count("\n") == 1
