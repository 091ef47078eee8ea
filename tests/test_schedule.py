"""Schedules, the baselines, and best_schedule."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from capalloc_rs import (
    ConvergenceError,
    InvalidInputError,
    Network,
    Schedule,
    ScheduleError,
    SingularProblemError,
    _core,
    best_schedule,
    greedy_schedule,
    integer_allocation,
    limits,
    round_robin_schedule,
    sampled_cost,
)
from capalloc_rs.sampled import initial_counts

# -- Schedule ---------------------------------------------------------------------------------


def cyclic_gaps(s: Schedule, i: int) -> list[int]:
    pos = [k for k, j in enumerate(s) if j == i]
    return [(pos[(k + 1) % len(pos)] - pos[k]) % s.r_tot or s.r_tot for k in range(len(pos))]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(min_value=0, max_value=12), min_size=1, max_size=6))
def test_interleaved_keeps_counts_and_spreads_slots(counts: list[int]) -> None:
    if sum(counts) == 0:
        with pytest.raises(ScheduleError):
            Schedule.from_counts(counts)
        return
    s = Schedule.from_counts(counts, "interleaved")
    assert s.r_tot == sum(counts)
    assert list(s.counts) == counts
    for i, ri in enumerate(counts):
        if ri >= 2:
            ideal = s.r_tot / ri
            # Every gap between consecutive slots of sensor i (cyclically) is within ±N of the
            # ideal spacing r_tot / r_i (ties with the other sensors shift a slot by < N).
            assert all(abs(g - ideal) <= len(counts) for g in cyclic_gaps(s, i)), (s, i)


def test_interleaved_examples() -> None:
    assert Schedule.from_counts([2, 2, 2]).slots == (0, 1, 2, 0, 1, 2)
    assert Schedule.from_counts([1, 3]).slots == (1, 0, 1, 1)
    s = Schedule.from_counts([6, 2])
    assert s.slots == (0, 0, 1, 0, 0, 0, 1, 0)  # sensor 1 four apart; ties go to sensor 0
    assert cyclic_gaps(s, 1) == [4, 4]


def test_blocked_and_round_robin() -> None:
    assert Schedule.from_counts([2, 0, 3], "blocked").slots == (0, 0, 2, 2, 2)
    assert Schedule.round_robin(3, 7).slots == (0, 1, 2, 0, 1, 2, 0)
    assert list(Schedule.round_robin(3, 7).counts) == [3, 2, 2]
    with pytest.raises(ScheduleError, match="order"):
        Schedule.from_counts([1, 1], "random")  # type: ignore[arg-type]


def test_schedule_value_semantics() -> None:
    s = Schedule([0, 2, 1, 2], 3)
    assert s == Schedule(np.array([0, 2, 1, 2]), 3)
    assert hash(s) == hash(Schedule((0, 2, 1, 2), 3))
    assert s != Schedule([0, 2, 1, 2], 4)
    assert len(s) == 4 and list(s) == [0, 2, 1, 2] and s[1] == 2 and s[1:3] == (2, 1)
    assert s.rotated(1).slots == (2, 1, 2, 0)
    assert s.rotated(-1).slots == (2, 0, 2, 1)
    c = s.counts
    c[0] = 99  # a fresh array: the schedule is unchanged
    assert list(s.counts) == [1, 1, 2]
    assert Schedule([1, 1]).n_sensors == 2
    assert "n_sensors=3" in repr(s)
    with pytest.raises(AttributeError):
        s.slots = (1,)  # type: ignore[misc]


@pytest.mark.parametrize(
    ("slots", "n", "match"),
    [
        ([0, 3], 3, "sensor 3"),
        ([0, -1], 3, ">= 0"),
        ([], 3, "non-empty"),
        ([[0, 1]], 3, "1-D"),
        ([0.5, 1], 3, "integer"),
        ([True, False], 3, "integer"),
        ([0, 1], 0, "n_sensors"),
    ],
)
def test_schedule_rejects_bad_input(slots: list[object], n: int, match: str) -> None:
    with pytest.raises(ScheduleError, match=match):
        Schedule(slots, n)  # type: ignore[arg-type]


def test_validate_names_starved_sensors() -> None:
    s = Schedule([0, 0, 1, 0], 3)
    with pytest.raises(ScheduleError, match="sensor 2 is starved"):
        s.validate(3, 1.0)
    s.validate(3, 0.0)
    with pytest.raises(ScheduleError, match="sensor 1 is starved"):
        s.validate(3, 1.5)  # ⌈1.5⌉ = 2 slots needed
    with pytest.raises(ScheduleError, match="network has 2"):
        s.validate(2, 0.0)


# -- baselines and best_schedule --------------------------------------------------------------


@pytest.fixture(scope="module")
def net() -> Network:
    return Network.random(3, n=2, p=1, eps=0.2, seed=11)


def test_round_robin_schedule(net: Network) -> None:
    s = round_robin_schedule(net, 10)
    assert s.slots == (0, 1, 2, 0, 1, 2, 0, 1, 2, 0)
    with pytest.raises(ScheduleError, match="need r_tot >= 3"):
        round_robin_schedule(net, 2)


def test_greedy_schedule_is_valid_and_reasonable(net: Network) -> None:
    tau, r = 0.5, 12
    g = greedy_schedule(net, tau, r)
    assert g.r_tot == r
    g.validate(3, net.r_min)
    # Better than the worst blocked schedule with the same counts.
    assert sampled_cost(net, tau, g) <= sampled_cost(
        net, tau, Schedule.from_counts(g.counts, "blocked")
    )


def test_greedy_respects_r_min() -> None:
    # Sensor 2 is nearly useless: greedy would never choose it, but r_min = 2 forces two slots.
    base = Network.random(3, n=2, p=1, eps=0.2, seed=11)
    sensors = [np.array(c) for c in base.sensors]
    sensors[2] = sensors[2] * 1e-3
    weak = Network(base.a, base.g, sensors, r_min=2.0)
    g = greedy_schedule(weak, 0.5, 9)
    assert g.counts[2] == 2
    assert all(c >= 2 for c in g.counts)


def test_initial_counts_use_the_integer_allocation(net: Network) -> None:
    counts, rule = initial_counts(net, 20)
    assert rule == "allocation.integer_allocation"
    assert sum(counts) == 20 and min(counts) >= 1
    from capalloc_rs.allocation import integer_allocation

    assert counts == [int(v) for v in integer_allocation(net, 20).counts]


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_best_schedule_beats_or_ties_both_baselines(net: Network, which: str) -> None:
    tau, r = 0.5, 12
    res = best_schedule(net, tau, r, which=which)  # type: ignore[arg-type]
    assert res.converged
    assert res.schedule.r_tot == r
    res.schedule.validate(3, net.r_min)
    assert res.eta_bar == pytest.approx(sampled_cost(net, tau, res.schedule, which), rel=1e-12)  # type: ignore[arg-type]
    rr = sampled_cost(net, tau, round_robin_schedule(net, r), which)  # type: ignore[arg-type]
    gr = sampled_cost(net, tau, greedy_schedule(net, tau, r, which=which), which)  # type: ignore[arg-type]
    assert res.eta_bar <= rr * (1 + 1e-12)
    assert res.eta_bar <= gr * (1 + 1e-12)
    assert res.candidates["round_robin"].eta_bar == pytest.approx(rr, rel=1e-12)
    assert res.candidates["greedy"].eta_bar == pytest.approx(gr, rel=1e-12)
    assert res.eta_limit == pytest.approx(net.cost(np.array(res.counts, dtype=float)))
    assert tuple(res.schedule.counts) == res.counts


def test_best_schedule_is_a_local_minimum(net: Network) -> None:
    tau, r = 0.8, 9
    res = best_schedule(net, tau, r)
    s = list(res.schedule)
    rng = np.random.default_rng(0)
    for _ in range(30):
        t = s.copy()
        kind = rng.integers(3)
        if kind == 0:
            pos, j = int(rng.integers(r)), int(rng.integers(3))
            t[pos] = j
        elif kind == 1:
            pos = int(rng.integers(r - 1))
            t[pos], t[pos + 1] = t[pos + 1], t[pos]
        else:
            k = int(rng.integers(1, r))
            t = t[k:] + t[:k]
        cand = Schedule(t, 3)
        if min(cand.counts) < 1:
            continue
        assert sampled_cost(net, tau, cand) >= res.eta_bar * (1 - 1e-12)


@settings(max_examples=8, deadline=None)
@given(
    seed=st.integers(min_value=0, max_value=10_000),
    nsub=st.integers(min_value=2, max_value=4),
    extra=st.integers(min_value=0, max_value=8),
    tau=st.sampled_from([0.05, 0.3, 1.0]),
    which=st.sampled_from(["boundary", "average"]),
)
def test_best_schedule_never_worse_than_baselines_on_random_networks(
    seed: int, nsub: int, extra: int, tau: float, which: str
) -> None:
    net = Network.random(nsub, n=2, p=1, eps=0.3, seed=seed)
    r = nsub + extra
    res = best_schedule(net, tau, r, which=which)  # type: ignore[arg-type]
    for base in (round_robin_schedule(net, r), greedy_schedule(net, tau, r, which=which)):  # type: ignore[arg-type]
        assert res.eta_bar <= sampled_cost(net, tau, base, which) * (1 + 1e-12)  # type: ignore[arg-type]


def test_best_schedule_with_given_counts_and_errors(net: Network) -> None:
    res = best_schedule(net, 0.5, 8, counts=[2, 3, 3], max_moves=0)
    # No move allowed: the search returns its start, the cheapest of the three candidates (each
    # costed independently here), without claiming a local minimum.
    costs = {k: sampled_cost(net, 0.5, c.schedule) for k, c in res.candidates.items()}
    start = min(costs, key=costs.__getitem__)
    assert res.moves == 0 and not res.converged and res.evaluations == 3
    assert res.start == start and res.schedule == res.candidates[start].schedule
    assert res.eta_bar == pytest.approx(costs[start], rel=1e-14)
    assert res.candidates["initial"].schedule == Schedule.from_counts([2, 3, 3])
    with pytest.raises(ScheduleError, match="summing to r_tot"):
        best_schedule(net, 0.5, 8, counts=[2, 3, 2])
    with pytest.raises(ScheduleError, match="starved"):
        best_schedule(net, 0.5, 8, counts=[0, 4, 4])
    with pytest.raises(ScheduleError, match="need r_tot"):
        best_schedule(net, 0.5, 2)


def test_best_schedule_gain_over_baselines_is_reported(net: Network) -> None:
    res = best_schedule(net, 1.0, 10)
    costs = {k: c.eta_bar for k, c in res.candidates.items()}
    assert res.eta_bar <= min(costs.values())
    assert all(math.isfinite(v) for v in costs.values())


@pytest.mark.parametrize("seed", [0, 3])
@pytest.mark.parametrize("tau", [0.3, 1.5])
def test_best_schedule_is_near_the_exhaustive_optimum(seed: int, tau: float) -> None:
    """Against all 3^7 schedules of a 3-sensor network with r_tot = 7 (each sensor ≥ 1 slot): the
    local search found the global optimum in 22 of 24 such cases tried and was within 0.2 % in the
    others; require 1 %."""
    import itertools

    net = Network.random(3, n=2, p=1, eps=0.3, seed=seed)
    best = min(
        sampled_cost(net, tau, list(s), check=False)
        for s in itertools.product(range(3), repeat=7)
        if len(set(s)) == 3
    )
    res = best_schedule(net, tau, 7)
    assert best <= res.eta_bar * (1 + 1e-12)
    assert res.eta_bar <= best * 1.01


# -- which errors mean "no steady state" (cost +∞) and which propagate ------------------------


class _CostFails:
    """A ``_core.SampledModel`` whose ``cost`` raises ``exc`` for the schedules ``when`` accepts
    (everything else is the real model's)."""

    def __init__(self, real: Any, exc: BaseException, when: Any) -> None:
        self._real, self._exc, self._when = real, exc, when

    def cost(self, tau: float, slots: Any, *args: Any) -> float:
        if self._when(list(slots)):
            raise self._exc
        return float(self._real.cost(tau, slots, *args))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


def _cost_fails(monkeypatch: pytest.MonkeyPatch, exc: BaseException, when: Any) -> None:
    real = _core.SampledModel
    monkeypatch.setattr(_core, "SampledModel", lambda *a: _CostFails(real(*a), exc, when))


def test_a_schedule_without_steady_state_costs_infinity(monkeypatch: pytest.MonkeyPatch) -> None:
    net = Network.random(3, seed=4)
    rr = list(round_robin_schedule(net, 7))
    _cost_fails(monkeypatch, ConvergenceError("the doubling diverged"), lambda s: s == rr)
    b = best_schedule(net, 0.5, 7, progress=False)
    assert b.candidates["round_robin"].eta_bar == math.inf
    assert b.start != "round_robin" and math.isfinite(b.eta_bar)
    assert b.eta_bar == pytest.approx(sampled_cost(net, 0.5, b.schedule), rel=1e-12)


@pytest.mark.parametrize(
    "exc",
    [
        InvalidInputError("slot 3 names sensor 9"),
        SingularProblemError("innovation covariance is not positive definite"),
        KeyboardInterrupt("cancelled"),
    ],
)
def test_other_errors_of_the_cost_propagate(
    monkeypatch: pytest.MonkeyPatch, exc: BaseException
) -> None:
    # Only ConvergenceError means "no steady state": anything else is not turned into +∞.
    net = Network.random(3, seed=4)
    _cost_fails(monkeypatch, exc, lambda s: True)
    with pytest.raises(type(exc), match=str(exc)):
        best_schedule(net, 0.5, 7, progress=False)


class _SteadyStateFails:
    """A ``_core.SampledModel`` whose ``steady_state`` always raises ``exc``."""

    def __init__(self, real: Any, exc: BaseException) -> None:
        self._real, self._exc = real, exc

    def steady_state(self, *args: Any) -> Any:
        raise self._exc

    def __getattr__(self, name: str) -> Any:
        return getattr(self._real, name)


def test_greedy_only_skips_schedules_without_steady_state(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    net = Network.random(3, seed=4)
    real = _core.SampledModel
    for exc in (InvalidInputError("bad"), SingularProblemError("not positive definite")):
        monkeypatch.setattr(_core, "SampledModel", lambda *a, e=exc: _SteadyStateFails(real(*a), e))
        with pytest.raises(type(exc)):
            greedy_schedule(net, 0.5, 7)
    # No steady state anywhere: the first pass starts from Σ = I and its schedule is returned.
    no_ss = ConvergenceError("no steady state")
    monkeypatch.setattr(_core, "SampledModel", lambda *a: _SteadyStateFails(real(*a), no_ss))
    s = greedy_schedule(net, 0.5, 7)
    assert s.r_tot == 7 and min(s.counts) >= 1


def test_initial_counts_rules(monkeypatch: pytest.MonkeyPatch) -> None:
    net = Network.random(3, seed=4)
    counts, rule = initial_counts(net, 7)
    assert rule == "allocation.integer_allocation"
    assert counts == [int(c) for c in integer_allocation(net, 7).counts]
    # More slots than integer_allocation takes (its InvalidInputError: no integer allocation):
    # the marginal greedy rule on η takes over, with the same counts here (η is separable
    # enough for the greedy to reach the exchange optimum at 7 slots).
    monkeypatch.setattr(limits, "MAX_INTEGER_ALLOCATION_SLOTS", 5)
    with pytest.raises(InvalidInputError, match="r_tot"):
        integer_allocation(net, 7)
    greedy, rule = initial_counts(net, 7)
    assert rule == "marginal greedy on net.cost" and sum(greedy) == 7 and min(greedy) >= 1
