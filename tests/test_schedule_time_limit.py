"""The time limit of ``best_schedule``: the Rust screen and costings stop at their deadline, the
start phase keeps only what fits, and a stopped search returns the best schedule found with
``stopped="time_limit"`` (checked against an independent exact cost). No assertion on wall time
beyond "it returns, and says why"."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

from capalloc_rs import (
    Network,
    best_schedule,
    greedy_schedule,
    round_robin_schedule,
    sampled_cost,
)
from capalloc_rs.sampled import sampled_system, starts


def test_screen_with_a_past_deadline_is_none_and_with_time_left_the_full_screen() -> None:
    net = Network.random(5, seed=6)
    m = sampled_system(net)
    slots = np.asarray(list(round_robin_schedule(net, 15)), dtype=np.int64)
    assert m.core.screen(0.4, slots, "boundary", 1, time_limit=0.0) is None
    full = m.core.screen(0.4, slots, "boundary", 1)
    timed = m.core.screen(0.4, slots, "boundary", 1, time_limit=3600.0)
    assert full is not None and timed is not None
    assert timed.current == full.current
    assert np.array_equal(timed.reassign, full.reassign)
    assert np.array_equal(timed.swap, full.swap)
    # A past deadline also stops the costings: nothing is costed, nothing is claimed complete.
    cc = m.core.candidate_costs(0.4, [slots, slots[::-1].copy()], time_limit=0.0)
    assert (cc.evaluated, cc.complete) == (0, False) and np.all(np.isinf(cc.costs))


def test_a_tiny_limit_on_a_mid_size_case_returns_the_interleaved_start() -> None:
    net = Network.random(20, 2, eps=0.05, seed=3)
    res = best_schedule(net, 0.2, 60, time_limit=1e-6, progress=False)
    assert (res.stopped, res.converged, res.moves) == ("time_limit", False, 0)
    # Only the interleaved candidate fits: round robin and greedy were not started.
    assert set(res.candidates) == {"initial"}
    assert res.schedule == res.candidates["initial"].schedule
    assert res.eta_bar == pytest.approx(sampled_cost(net, 0.2, res.schedule), rel=1e-12)


def test_a_limit_reached_during_the_search_keeps_the_best_schedule_found(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The deadline is made to pass right after the first screen that moves (the progress
    # callback waits for it), so the run is deterministic whatever the machine's speed.
    net = Network.random(20, 2, eps=0.05, seed=3)
    limit = 2.0
    began = time.monotonic()
    seen: list[dict[str, Any]] = []

    def wait_past_deadline(d: dict[str, Any]) -> None:
        seen.append(d)
        if d["phase"] == "search" and d["moves"] > 0:
            while time.monotonic() < began + limit + 0.05:
                time.sleep(0.01)

    # All three candidates are wanted: the start phase is judged by its first costing only.
    monkeypatch.setattr(starts, "GREEDY_COSTINGS", 0)
    res = best_schedule(net, 0.2, 60, time_limit=limit, progress=wait_past_deadline)
    assert res.stopped == "time_limit" and not res.converged
    assert res.moves > 0
    assert set(res.candidates) == {"initial", "round_robin", "greedy"}
    assert res.eta_bar < min(c.eta_bar for c in res.candidates.values())
    assert res.eta_bar == pytest.approx(sampled_cost(net, 0.2, res.schedule), rel=1e-12)
    moves = [d["moves"] for d in seen if d["phase"] == "search"]
    assert moves and moves[-1] == res.moves


def test_large_problems_reuse_the_greedy_steady_states(monkeypatch: pytest.MonkeyPatch) -> None:
    # Above starts.LARGE_NEIGHBOURS the greedy candidate makes one pass and its steady states
    # give round robin's cost and its own: the same schedules, the costs of sampled_cost.
    net = Network.random(6, 2, eps=0.05, seed=3)
    monkeypatch.setattr(starts, "LARGE_NEIGHBOURS", 0)
    res = best_schedule(net, 0.2, 18, max_moves=0, progress=False, confirm=False)
    assert set(res.candidates) == {"initial", "round_robin", "greedy"}
    gr = greedy_schedule(net, 0.2, 18, max_rounds=1)
    assert res.candidates["greedy"].schedule == gr
    assert res.candidates["round_robin"].schedule == round_robin_schedule(net, 18)
    for c in res.candidates.values():
        assert c.eta_bar == pytest.approx(sampled_cost(net, 0.2, c.schedule), rel=1e-13)
