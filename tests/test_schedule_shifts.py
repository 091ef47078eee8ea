"""The shift moves and displacement steps of the default screened search
(:mod:`capalloc_rs.sampled.shifts`) against independent routes: the chain predictions against
their double sums, the displacement step against the one-slot derivatives solved from the swap
predictions, the exact cost of a shift against ``sampled_cost``; the default search against the
previous one (``method="screened-v3"``) on the benchmark networks, and its stop when it stalls."""

from __future__ import annotations

import math

import numpy as np
import pytest

from capalloc_rs import Network, best_schedule, sampled_cost
from capalloc_rs.sampled import sampled_system, screened
from capalloc_rs.sampled.schedule import Schedule
from capalloc_rs.sampled.shifts import best_shifts, displaced


def _chain(w: list[float], a: int, b: int) -> float:
    """``P(a → b)`` by its double sum (``w`` with ``+∞`` as 0)."""
    ww = [0.0 if math.isinf(x) else x for x in w]
    if b > a:
        return sum(sum(ww[m] for m in range(a, a + j)) for j in range(1, b - a + 1))
    return sum(sum(ww[m] for m in range(a - j, a)) for j in range(1, a - b + 1))


def test_best_shifts_are_the_chain_sums() -> None:
    rng = np.random.default_rng(1)
    slots = [int(v) for v in rng.integers(0, 4, size=17)]
    w = [math.inf if slots[i] == slots[i + 1] else float(rng.normal()) for i in range(16)]
    got = best_shifts(w, slots, 6)
    want = []
    for a in range(17):
        options = [
            (_chain(w, a, b), b)
            for b in range(max(a - 6, 0), min(a + 7, 17))
            if b != a and slots[b] != slots[a] and b != a - 1
        ]
        p, b = min(options, default=(0.0, -1))
        if p < 0.0:
            want.append((p, a, b))
    assert [(a, b) for _, a, b in got] == [(a, b) for _, a, b in sorted(want)]
    for (p, _, _), (q, _, _) in zip(got, sorted(want), strict=True):
        assert p == pytest.approx(q, rel=1e-12, abs=1e-12)


def test_a_shift_by_one_is_the_screens_swap() -> None:
    net = Network.random(4, seed=2)
    m = sampled_system(net)
    slots = [0, 1, 2, 3, 0, 1, 2, 3, 0, 1]
    sc = m.core.screen(0.3, np.asarray(slots, dtype=np.int64), "boundary", 1)
    got = best_shifts(sc.swap, slots, 1)
    assert sorted(a for _, a, _ in got) == [int(a) for a in np.flatnonzero(np.asarray(sc.swap) < 0)]
    for p, a, b in got:
        assert b == a + 1 and p == pytest.approx(sc.swap[a], rel=1e-12)


def test_the_top_shift_prediction_is_close_to_its_exact_change() -> None:
    """The chain model (first order, additive over the samples) on the benchmark network at
    N = 10: the best predicted shift lowers the exact cost by about the predicted amount."""
    net = Network.random(10, 2, eps=0.05, seed=3)
    m = sampled_system(net)
    slots = [int(v) for v in Schedule.from_counts([3] * 10, "interleaved").slots]
    sc = m.core.screen(0.2, np.asarray(slots, dtype=np.int64), "boundary", 1)
    p, a, b = best_shifts(sc.swap, slots, 29)[0]
    moved = list(slots)
    moved.insert(b, moved.pop(a))
    exact = sampled_cost(net, 0.2, moved, check=False) - sampled_cost(net, 0.2, slots, check=False)
    assert abs(b - a) > 1 and exact < 0.0
    assert exact == pytest.approx(p, rel=0.25)


def test_displaced_is_a_permutation_with_its_prediction() -> None:
    """Every slot a different sensor (so the permutation is read off the new schedule): the
    step's prediction is ``Σ d_l (π(l) − l)`` with ``d`` solved from ``w_l = d_l − d_{l+1}``
    slot by slot, and no sample moves more than ``2K`` slots."""
    rng = np.random.default_rng(5)
    slots = [int(v) for v in rng.permutation(40)]
    w = [float(x) for x in rng.normal(size=39)]
    step = displaced(w, slots, 8)
    assert step is not None
    new, predicted = step
    assert sorted(new) == sorted(slots) and new != slots
    d = [0.0]
    for x in w:
        d.append(d[-1] - x)
    where = [new.index(s) for s in slots]
    assert predicted < 0.0
    assert predicted == pytest.approx(sum(d[i] * (where[i] - i) for i in range(40)), rel=1e-12)
    assert max(abs(where[i] - i) for i in range(40)) <= 2 * 8
    assert displaced([0.0] * 39, slots, 8) is None  # no gradient: no step


@pytest.mark.parametrize(("n", "r_tot"), [(5, 15), (10, 30), (20, 60)])
def test_default_is_no_worse_than_screened_v3_on_the_benchmark_networks(n: int, r_tot: int) -> None:
    net = Network.random(n, 2, eps=0.05, seed=3)
    new = best_schedule(net, 0.2, r_tot, progress=False, certify=False)
    old = best_schedule(net, 0.2, r_tot, progress=False, certify=False, method="screened-v3")
    assert new.eta_bar <= old.eta_bar * (1 + 1e-12)
    assert new.eta_bar == pytest.approx(
        sampled_cost(net, 0.2, new.schedule, check=False), rel=1e-12
    )
    assert sorted(new.counts) and sum(new.counts) == r_tot


def test_displacement_steps_and_the_stall_stop(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the displacement steps and the stall rule switched on at a small size: the search
    reports its progress, never goes up, stops ``"stalled"`` (not converged), and its cost is
    its schedule's."""
    monkeypatch.setattr(screened, "DISPLACE_NEIGHBOURS", 0)
    monkeypatch.setattr(screened, "STALL_SCREENS", 2)
    monkeypatch.setattr(screened, "STALL_RTOL", 0.5)
    net = Network.random(8, 2, eps=0.05, seed=3)
    seen: list[dict[str, float]] = []
    res = best_schedule(net, 0.2, 24, progress=seen.append, certify=False, confirm=False)
    costs = [d["eta_bar"] for d in seen if d["phase"] == "search"]
    assert len(costs) == 3 and all(b <= a for a, b in zip(costs, costs[1:], strict=False))
    assert res.stopped == "stalled" and not res.converged
    assert res.eta_bar == costs[-1] <= res.candidates["initial"].eta_bar
    assert res.eta_bar == pytest.approx(
        sampled_cost(net, 0.2, res.schedule, check=False), rel=1e-12
    )


def test_displacement_steps_without_the_stall_reach_a_screened_minimum(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(screened, "DISPLACE_NEIGHBOURS", 0)
    monkeypatch.setattr(screened, "STALL_RTOL", 0.0)
    net = Network.random(8, 2, eps=0.05, seed=3)
    res = best_schedule(net, 0.2, 24, progress=False, certify=False, confirm=False)
    assert res.stopped == "screened_minimum"
    assert res.eta_bar == pytest.approx(
        sampled_cost(net, 0.2, res.schedule, check=False), rel=1e-12
    )
