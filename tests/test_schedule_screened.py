"""The screened schedule search (``best_schedule``'s default ``method="screened"``) against the
exhaustive one and against independent routes: the first-order screen against finite differences
of exact costs, the exact candidate costs against ``sampled_cost``, the enumerated optimum of small
cases, the baselines, budgets and progress."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import Network, best_schedule, greedy_schedule, round_robin_schedule, sampled_cost
from capalloc_rs.errors import InvalidInputError
from capalloc_rs.sampled import exhaustive, sampled_system


@dataclass(frozen=True)
class _Model:
    """A duck-typed network: ``A``, ``G``, ``sensors``, ``r_min``."""

    A: Any
    G: Any
    sensors: list[Any]
    r_min: float = 0.0


def _twin_model(eps: float) -> _Model:
    """Three sensors of a 3-state system; sensor 2 is sensor 0 scaled by ``1 + eps``."""
    rng = np.random.default_rng(5)
    a = rng.standard_normal((3, 3)) * 0.4 - 0.5 * np.eye(3)
    c0 = rng.standard_normal((3, 1))
    return _Model(a, np.eye(3), [c0, rng.standard_normal((3, 1)), c0 * (1 + eps)])


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_screen_is_the_derivative_of_the_exact_cost(which: str) -> None:
    # Giving one of sensor 0's slots to its (1 + eps)-twin perturbs that slot's update by O(eps):
    # the exact change of η̄ (two doublings, subtracted) is eps·D + O(eps²), the screen eps·D.
    tau, slots = 0.7, np.array([0, 1, 0, 1, 0, 1, 1, 0], dtype=np.int64)
    for eps in (1e-3, 1e-4):
        m = sampled_system(_twin_model(eps))
        sc = m.core.screen(tau, slots, which, 1)
        base = sampled_cost(m, tau, list(slots), which=which, check=False)
        assert sc.current == pytest.approx(base, rel=1e-13)
        for pos in np.flatnonzero(slots == 0):
            moved = slots.copy()
            moved[pos] = 2
            exact = sampled_cost(m, tau, list(moved), which=which, check=False) - base
            assert exact < 0
            assert sc.reassign[pos, 2] == pytest.approx(exact, rel=20 * eps)


def test_rotation_screens_are_exact_boundary_costs() -> None:
    net = Network.random(4, seed=2)
    m = sampled_system(net)
    slots = [0, 1, 2, 3, 1, 0, 2, 3, 3, 1]
    sc = m.core.screen(0.6, np.asarray(slots, dtype=np.int64), "boundary", 1)
    for k in range(len(slots)):
        rot = slots[k:] + slots[:k]
        assert sc.rotate[k] == pytest.approx(sampled_cost(net, 0.6, rot, check=False), rel=1e-12)


def test_candidate_costs_equal_the_cost_of_each_schedule() -> None:
    net = Network.random(5, seed=6)
    m = sampled_system(net)
    base = list(round_robin_schedule(net, 15))
    m.core.screen(0.4, np.asarray(base, dtype=np.int64), "average", 1)  # keeps base's tree
    cands = [base, base[3:] + base[:3]] + [
        base[:k] + [(base[k] + 1) % 5] + base[k + 1 :] for k in range(15)
    ]
    arrays = [np.asarray(c, dtype=np.int64) for c in cands]
    for which in ("boundary", "average"):
        cc = m.core.candidate_costs(0.4, arrays, which)
        assert cc.complete and cc.evaluated == len(cands)
        direct = [m.core.cost(0.4, a, which) for a in arrays]
        assert list(cc.costs) == direct  # the same star products in the same order
    assert m.core.candidate_costs(0.4, arrays, time_limit=0.0).evaluated == 0
    with pytest.raises(InvalidInputError, match="slots"):
        m.core.candidate_costs(0.4, [arrays[0], arrays[0][:5]])


def test_incumbent_cuts_only_candidates_that_cannot_improve() -> None:
    net = Network.random(5, seed=6)
    m = sampled_system(net)
    base = list(round_robin_schedule(net, 15))
    cands = [base] + [base[:k] + [(base[k] + 1) % 5] + base[k + 1 :] for k in range(15)]
    arrays = [np.asarray(c, dtype=np.int64) for c in cands]
    direct = [m.core.cost(0.4, a, "boundary") for a in arrays]
    for incumbent in (direct[0], float(np.median(direct)), min(direct) * 0.5):
        cc = m.core.candidate_costs(0.4, arrays, "boundary", incumbent=incumbent)
        for exact, got in zip(direct, cc.costs, strict=True):
            # Every candidate that could be taken keeps its exact cost; a dearer one may be cut.
            assert got == exact if exact <= incumbent else got in (exact, math.inf)
    cut = m.core.candidate_costs(0.4, arrays, "boundary", incumbent=min(direct) * 0.5)
    assert all(math.isinf(v) for v in cut.costs)
    # The average objective is not bounded: exact costs whatever the incumbent.
    avg = m.core.candidate_costs(0.4, arrays, "average", incumbent=1e-9)
    assert list(avg.costs) == [m.core.cost(0.4, a, "average") for a in arrays]


def test_cut_short_costings_take_the_same_moves(monkeypatch: pytest.MonkeyPatch) -> None:
    from capalloc_rs.sampled import screened

    net = Network.random(8, seed=4)
    runs = []
    for prune in (False, True):
        monkeypatch.setattr(screened, "PRUNE", prune)
        runs.append(best_schedule(net, 0.3, 24, progress=False))
    assert list(runs[0].schedule.slots) == list(runs[1].schedule.slots)
    assert runs[0].eta_bar == runs[1].eta_bar
    assert runs[0].moves == runs[1].moves


CASES = [(seed, tau) for seed in range(6) for tau in (0.3, 0.8, 1.5, 3.0)]


@pytest.fixture(scope="module")
def enumerated() -> list[tuple[float, Any, Any]]:
    """For 24 small cases (3 sensors, 7 slots, each sensor ≥ 1 slot): the global optimum by
    enumeration of all schedules, and both searches' results."""
    out = []
    for seed, tau in CASES:
        net = Network.random(3, n=2, p=1, eps=0.3, seed=seed)
        best = min(
            sampled_cost(net, tau, list(s), check=False)
            for s in itertools.product(range(3), repeat=7)
            if len(set(s)) == 3
        )
        new = best_schedule(net, tau, 7, progress=False)
        ref = best_schedule(net, tau, 7, progress=False, method="exhaustive")
        out.append((best, new, ref))
    return out


def test_screened_finds_the_global_optimum_as_often_as_exhaustive(
    enumerated: list[tuple[float, Any, Any]],
) -> None:
    def hits(k: int) -> int:
        return sum(r[k].eta_bar <= r[0] * (1 + 1e-12) for r in enumerated)

    assert hits(1) >= hits(2) and hits(1) == len(enumerated) == 24  # 22 before the screened search
    for best, new, _ref in enumerated:
        assert best <= new.eta_bar * (1 + 1e-12)


def test_screened_proves_minima_no_worse_than_exhaustive(
    enumerated: list[tuple[float, Any, Any]],
) -> None:
    for _best, new, ref in enumerated:
        assert new.stopped == "local_minimum" and new.converged  # small: always confirmed
        assert new.eta_bar <= ref.eta_bar * (1 + 1e-12)


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_screened_is_never_worse_than_the_baselines(which: str) -> None:
    net = Network.random(6, seed=9)
    res = best_schedule(net, 0.5, 18, which=which, progress=False)
    for s in (round_robin_schedule(net, 18), greedy_schedule(net, 0.5, 18, which=which)):
        assert res.eta_bar <= sampled_cost(net, 0.5, s, which=which, check=False) * (1 + 1e-12)
    # The reported cost is the schedule's exact cost, by an independent evaluation.
    assert res.eta_bar == pytest.approx(
        sampled_cost(net, 0.5, res.schedule, which=which, check=False), rel=1e-12
    )
    ref = best_schedule(net, 0.5, 18, which=which, progress=False, method="exhaustive")
    assert res.eta_bar <= ref.eta_bar * (1 + 1e-12) or res.stopped == "local_minimum"


def test_unconfirmed_minimum_is_reported_as_such() -> None:
    net = Network.random(5, seed=3)
    res = best_schedule(net, 0.5, 15, progress=False, confirm=False)
    assert (res.stopped, res.converged) == ("screened_minimum", False)
    assert res.to_dict()["stopped"] == "screened_minimum"
    confirmed = best_schedule(net, 0.5, 15, progress=False, confirm=True)
    assert confirmed.stopped == "local_minimum" and confirmed.eta_bar <= res.eta_bar


def test_progress_reports_moves_current_and_best() -> None:
    net = Network.random(5, seed=3)
    seen: list[dict[str, Any]] = []
    res = best_schedule(net, 0.5, 15, progress=seen.append)
    search = [d for d in seen if d["phase"] in ("search", "confirm")]
    assert search and {"moves", "eta_bar", "best", "evaluations", "elapsed"} <= set(search[0])
    # Small: the search runs from every start, so the current cost may rise at a new start; the
    # best so far never does, and is never above the current one.
    # (A confirmation recomputes the current cost by another composition: rounding apart.)
    bests = [d["best"] for d in search]
    assert all(b <= a * (1 + 1e-13) for a, b in itertools.pairwise(bests))
    assert all(d["best"] <= d["eta_bar"] * (1 + 1e-13) for d in search)
    assert [d["moves"] for d in search] == sorted(d["moves"] for d in search)
    assert search[-1]["best"] == pytest.approx(res.eta_bar, rel=1e-12)
    # One start only (no confirmation): the current cost itself only falls.
    seen.clear()
    one = best_schedule(Network.random(12, seed=3), 0.3, 36, progress=seen.append, confirm=False)
    etas = [d["eta_bar"] for d in seen if d["phase"] == "search"]
    assert etas == sorted(etas, reverse=True) and etas[-1] == one.eta_bar


def test_time_limit_and_move_budget() -> None:
    net = Network.random(8, seed=3)
    part = best_schedule(net, 0.5, 24, progress=False, time_limit=1e-9)
    assert (part.stopped, part.converged, part.moves) == ("time_limit", False, 0)
    assert part.eta_bar == min(c.eta_bar for c in part.candidates.values())
    one = best_schedule(net, 0.5, 24, progress=False, max_moves=3)
    assert one.stopped == "max_moves" and one.moves <= 3


def test_confirmation_step_is_the_exhaustive_neighbourhood(monkeypatch: pytest.MonkeyPatch) -> None:
    net = Network.random(4, seed=11)
    calls: list[bool] = []
    real = exhaustive._neighbourhood

    def spy(*args: Any, **kw: Any) -> Any:
        nb = real(*args, **kw)
        calls.append(bool(nb.complete))
        return nb

    monkeypatch.setattr(exhaustive, "_neighbourhood", spy)
    res = best_schedule(net, 0.8, 12, progress=False)
    assert calls and all(calls) and res.stopped == "local_minimum"


@pytest.mark.parametrize(
    ("kw", "match"),
    [({"method": "fast"}, "method"), ({"method": 1}, "method"), ({"confirm": "yes"}, "confirm")],
)
def test_bad_method_or_confirm_is_refused(kw: dict[str, Any], match: str) -> None:
    net = Network.random(3, seed=4)
    with pytest.raises(InvalidInputError, match=match):
        best_schedule(net, 0.5, 6, **kw)


def test_to_dict_is_plain_json() -> None:
    import json

    res = best_schedule(Network.random(3, seed=4), 0.5, 6, progress=False)
    d = json.loads(json.dumps(res.to_dict()))
    assert d["stopped"] == "local_minimum" and math.isfinite(d["eta_bar"])
    assert capalloc_rs.sampled.rounded_counts(Network.random(3, seed=4), 6)[1].startswith("alloc")


@pytest.mark.parametrize(("n", "tau"), [(8, 0.5), (12, 0.3)])
def test_adaptive_order_is_no_worse_than_the_fixed_order(n: int, tau: float) -> None:
    """The adaptive order of the exact costings (``method="screened-v3"``) against the fixed
    order of before (``method="screened_fixed"``), both unconfirmed: the same or a cheaper
    schedule with fewer evaluations; each result's cost is its schedule's, by an independent
    evaluation."""
    net = Network.random(n, seed=3)
    new = best_schedule(net, tau, 3 * n, progress=False, confirm=False, method="screened-v3")
    old = best_schedule(net, tau, 3 * n, progress=False, confirm=False, method="screened_fixed")
    assert new.eta_bar <= old.eta_bar * (1 + 1e-12)
    assert new.evaluations <= old.evaluations
    for res in (new, old):
        assert res.eta_bar == pytest.approx(
            sampled_cost(net, tau, res.schedule, check=False), rel=1e-12
        )


def test_rounds_cost_the_hot_kind_first() -> None:
    """While both kinds' batches are taken, both together come first (the fixed order); after
    only one kind's batch was taken, its whole batch comes alone, then the other and both."""
    from capalloc_rs.sampled.screened import _Move, _rounds

    slots = [0, 1, 2, 0, 1, 2, 0, 1]
    reassign = [_Move(-1.0, "reassign", 0, 1), _Move(-0.5, "reassign", 3, 2)]
    swaps = [_Move(-1.0, "swap", 1, 0), _Move(-0.5, "swap", 4, 0), _Move(-0.1, "swap", 6, 0)]
    ranked = (reassign, swaps)
    kinds = [
        [[c[2] for c in rnd] for rnd in _rounds(slots, ranked, [reassign, swaps], [2, 3], hot)][:2]
        for hot in ((True, True), (False, True), (True, False), (False, False))
    ]
    assert kinds == [[[2], [0, 1]], [[1], [0, 2]], [[0], [1, 2]], [[0, 1], [2]]]
