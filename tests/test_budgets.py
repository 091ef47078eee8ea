"""Budgets and progress of the long searches (capalloc-rs issue 12, point 3): ``best_schedule``
and ``filtration`` stop at ``max_moves``/``max_nodes`` or ``time_limit`` with the best result so
far, clearly marked (``converged=False``, ``stopped=…``), and report progress through
``progress=``. No test asserts on wall time: a zero-ish time limit is checked for *what* is
returned, not for how fast.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import capalloc_rs
from capalloc_rs import errors, limits
from capalloc_rs.allocation import filtration
from capalloc_rs.sampled import exhaustive as scheduling


@pytest.fixture(scope="module")
def net() -> capalloc_rs.Network:
    return capalloc_rs.Network.random(4, seed=11)


@pytest.fixture(scope="module")
def full(net: capalloc_rs.Network) -> capalloc_rs.BestSchedule:
    return capalloc_rs.best_schedule(net, 0.8, 12, progress=False)


def test_full_search_reports_a_local_minimum(full: capalloc_rs.BestSchedule) -> None:
    assert full.converged and full.stopped == "local_minimum"
    assert full.moves >= 2  # the budgets below cut a search that does move
    assert full.elapsed > 0


def test_move_budget_returns_the_best_so_far(
    net: capalloc_rs.Network, full: capalloc_rs.BestSchedule
) -> None:
    part = capalloc_rs.best_schedule(net, 0.8, 12, max_moves=1, progress=False)
    assert (part.converged, part.stopped, part.moves) == (False, "max_moves", 1)
    start = min(c.eta_bar for c in part.candidates.values())
    assert full.eta_bar <= part.eta_bar < start
    # The reported cost is the schedule's exact cost (independent evaluation).
    assert part.eta_bar == pytest.approx(capalloc_rs.sampled_cost(net, 0.8, part.schedule), 1e-12)


def test_time_budget_returns_the_best_candidate(net: capalloc_rs.Network) -> None:
    # The budget also cuts the start phase short: the interleaved candidate is built and
    # costed, round robin and greedy no longer fit.
    part = capalloc_rs.best_schedule(net, 0.8, 12, time_limit=1e-9, progress=False)
    assert (part.converged, part.stopped, part.moves) == (False, "time_limit", 0)
    assert set(part.candidates) == {"initial"}
    assert part.eta_bar == min(c.eta_bar for c in part.candidates.values())
    assert sum(part.counts) == 12


def test_default_budgets_come_from_limits(
    net: capalloc_rs.Network, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(limits, "BEST_SCHEDULE_MAX_MOVES", 1)
    assert capalloc_rs.best_schedule(net, 0.8, 12, progress=False).stopped == "max_moves"
    monkeypatch.setattr(limits, "BEST_SCHEDULE_MAX_MOVES", 10_000)
    monkeypatch.setattr(limits, "BEST_SCHEDULE_TIME_LIMIT", 1e-9)
    assert capalloc_rs.best_schedule(net, 0.8, 12, progress=False).stopped == "time_limit"


# 10**400 used to raise a bare OverflowError (float() of a huge int).
@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), "soon", 10**400])
def test_bad_time_limit_is_refused(net: capalloc_rs.Network, bad: Any) -> None:
    with pytest.raises(errors.InvalidInputError, match="time_limit"):
        capalloc_rs.best_schedule(net, 0.8, 12, time_limit=bad)
    with pytest.raises(errors.InvalidInputError, match="time_limit"):
        filtration(net, 2.0, time_limit=bad)


def test_progress_callback_sees_every_neighbourhood(
    net: capalloc_rs.Network, full: capalloc_rs.BestSchedule
) -> None:
    # The exhaustive method: one report per neighbourhood (screened: test_schedule_screened.py).
    seen: list[dict[str, Any]] = []
    best = capalloc_rs.best_schedule(net, 0.8, 12, progress=seen.append, method="exhaustive")
    ref = capalloc_rs.best_schedule(net, 0.8, 12, progress=False, method="exhaustive")
    assert best.schedule == ref.schedule and best.eta_bar <= full.eta_bar * (1 + 1e-12)
    assert [d["phase"] for d in seen[:2]] == ["initial counts", "greedy"]
    search = [d for d in seen if d["phase"] == "search"]
    assert {"moves", "eta_bar", "evaluations", "elapsed"} <= set(search[0])
    etas = [d["eta_bar"] for d in search]
    assert etas == sorted(etas, reverse=True)  # the search only ever improves
    assert search[-1]["eta_bar"] == best.eta_bar and search[-1]["moves"] == best.moves


def test_progress_bar_only_when_asked_or_on_a_terminal(
    net: capalloc_rs.Network, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("tqdm")
    capalloc_rs.best_schedule(net, 0.8, 12)  # stderr is not a terminal here: silent
    assert capsys.readouterr().err == ""
    capalloc_rs.best_schedule(net, 0.8, 12, progress=True)
    assert "best_schedule" in capsys.readouterr().err
    with pytest.raises(errors.InvalidInputError, match="progress"):
        capalloc_rs.best_schedule(net, 0.8, 12, progress="yes")  # type: ignore[arg-type]


def test_filtration_node_budget_returns_the_path_so_far(net: capalloc_rs.Network) -> None:
    f = filtration(net, 6.0, max_nodes=6, progress=False)
    assert (f.converged, f.stopped, f.sigma_requested) == (False, "max_nodes", 6.0)
    assert 0 < f.sigma_max < 6.0 and f.breakpoints[-1] == f.sigma_max
    # The budget counts path nodes: an event adds its located node and the corrected start of
    # the next segment at once, so it may overshoot by 1 — as here, where the sixth node is the
    # breakpoint at which the second sensor enters (σ ≈ 3.91).
    assert f.node_sigma.size == 7 and len(f.events) == 2
    assert f.node_sigma[5] == f.node_sigma[6] == f.events[1].sigma
    # The traced part is exact: compare with the optimum solved directly at σ.
    s = 0.5 * f.sigma_max
    alloc = capalloc_rs.optimal_allocation(net, s + len(net.sensors) * net.r_min)
    assert np.allclose(f.allocation(s) + net.r_min, alloc.r, rtol=1e-7, atol=1e-9)
    with pytest.raises(errors.InvalidInputError):
        f.allocation(0.9 * 6.0)


def test_filtration_time_budget_and_progress(net: capalloc_rs.Network) -> None:
    f = filtration(net, 6.0, time_limit=1e-9, progress=False)
    assert (f.converged, f.stopped, f.sigma_max) == (False, "time_limit", 0.0)
    assert f.allocation(0.0).shape == (len(net.sensors),)
    seen: list[dict[str, Any]] = []
    done = filtration(net, 6.0, progress=seen.append)
    assert (done.converged, done.stopped, done.sigma_max) == (True, "completed", 6.0)
    sigmas = [d["sigma"] for d in seen]
    assert sigmas == sorted(sigmas) and {"nodes", "active", "elapsed"} <= set(seen[0])


def test_partly_evaluated_neighbourhood_is_not_a_local_minimum(
    net: capalloc_rs.Network, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The Rust neighbourhood skips candidates past the deadline (they cost +∞): no improving
    # move among the evaluated ones must not be reported as a local minimum.
    real = scheduling._neighbourhood

    def out_of_time(*args: Any, **kw: Any) -> Any:
        kw["time_limit"] = 0.0
        res = real(*args, **kw)
        assert res.complete is False and np.all(np.isinf(res.reassign))
        return res

    monkeypatch.setattr(scheduling, "_neighbourhood", out_of_time)
    part = capalloc_rs.best_schedule(
        net, 0.8, 12, time_limit=3600, progress=False, method="exhaustive"
    )
    assert (part.converged, part.stopped, part.moves) == (False, "time_limit", 0)


def _movable(slots: np.ndarray, n_sensors: int, min_count: int, which: str) -> int:
    """Neighbours that the rules allow (counted from the schedule, not from any cost): one slot
    given to another sensor if its sensor keeps ``min_count``, a swap of two different adjacent
    slots, and (boundary figure) every non-trivial rotation."""
    counts = np.bincount(slots, minlength=n_sensors)
    reassign = sum(n_sensors - 1 for i in slots if counts[i] > min_count)
    swap = int(np.count_nonzero(slots[1:] != slots[:-1]))
    return reassign + swap + (len(slots) - 1 if which == "boundary" else 0)


@pytest.mark.parametrize("which", ["boundary", "average"])
def test_evaluations_count_only_costed_neighbours(
    net: capalloc_rs.Network, monkeypatch: pytest.MonkeyPatch, which: str
) -> None:
    real = scheduling._neighbourhood
    calls: list[tuple[int, int]] = []

    def counted(*args: Any, **kw: Any) -> Any:
        res = real(*args, **kw)
        slots, min_count = args[2].as_array(), args[4].min_count  # args[4]: ScheduleLimits
        assert res.complete is True  # no deadline: complete
        calls.append((res.evaluated, _movable(slots, len(net.sensors), min_count, which)))
        return res

    monkeypatch.setattr(scheduling, "_neighbourhood", counted)
    res = capalloc_rs.best_schedule(
        net, 0.8, 12, which=which, max_moves=1, progress=False, method="exhaustive"
    )
    assert calls and all(costed == rule for costed, rule in calls)
    # 3 starting candidates + the neighbourhood + at most BATCH_ATTEMPTS verified extra moves
    # (none once the move budget is spent: max_moves = 1 stops after the best move).
    assert res.evaluations == 3 + calls[0][0]


def test_evaluations_do_not_count_skipped_neighbours(
    net: capalloc_rs.Network, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A neighbourhood whose deadline has passed costs no neighbour: the result counts only the
    # three starting candidates (it used to add the neighbourhood's full size, ~70 here).
    real = scheduling._neighbourhood

    def out_of_time(*args: Any, **kw: Any) -> Any:
        kw["time_limit"] = 0.0
        res = real(*args, **kw)
        assert res.complete is False and res.evaluated == 0
        return res

    monkeypatch.setattr(scheduling, "_neighbourhood", out_of_time)
    part = capalloc_rs.best_schedule(
        net, 0.8, 12, time_limit=3600, progress=False, method="exhaustive"
    )
    assert (part.stopped, part.moves, part.evaluations) == ("time_limit", 0, 3)
