"""The best concrete schedule at a finite period τ: exact local search from the best of the
starting schedules (:mod:`capalloc_rs.sampled.baselines`).

:func:`best_schedule` takes the optimal counts of the fast-sampling problem, evenly interleaved,
round robin and greedy as candidates, then improves the cheapest by a local search with the exact
finite-τ cost ``η̄(τ, R)`` (:mod:`capalloc_rs.sampled.system`), so that it is never worse than
either baseline: the screened search (:mod:`capalloc_rs.sampled.screened`, moves ranked by the
first-order sensitivity of ``η̄``) by default, the exhaustive best-improvement search
(:mod:`capalloc_rs.sampled.exhaustive`) on request.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial
from types import MappingProxyType
from typing import Any

import numpy as np

from .. import limits
from .._arrays import numerical_errors
from .._progress import Progress, ProgressArg
from .._unchecked import warn_unchecked
from ..errors import ConvergenceError, InvalidInputError
from ..limits import check_time_limit
from ..network import accepts_path
from .baselines import (
    _check_r_tot,
    greedy_schedule,
    initial_counts,
    round_robin_schedule,
)
from .best_result import BestSchedule, Candidate
from .channel import ScheduleLimits, schedule_limits
from .exact import MAX_KERNEL_SENSORS, equal_costs, exact_search
from .exhaustive import SearchContext, _exhaustive_step, _local_search, _SearchState
from .grouped import grouped_lower_bound
from .relaxation import relaxed_lower_bound
from .schedule import Schedule
from .screened import (
    PORTFOLIO_MAX_NEIGHBOURS,
    ScreenedOptions,
    neighbours,
    screened_confirms,
    screened_search,
)
from .starts import greedy_rounds, initial_counts_of, is_large, start_candidates
from .system import SampledSystem, Which, _check_tau, check_existence, sampled_system

__all__ = [
    "Candidate",
    "BestSchedule",
    "round_robin_schedule",
    "greedy_schedule",
    "initial_counts",
    "best_schedule",
]


#: The share of a ``time_limit`` of :func:`best_schedule` that refining its starting candidates
#: (initial counts, greedy rounds) may use; the rest is left to the local search.
START_SHARE = 0.5

#: The search methods of :func:`best_schedule`.
METHODS = ("screened", "screened-v3", "screened_fixed", "exhaustive", "exact")

#: The longest shift of the default screened search (``ScreenedOptions.max_shift``;
#: ``"screened-v3"`` and ``"screened_fixed"``: 1, adjacent swaps only).
MAX_SHIFT = 1_000

#: Default node budget of ``method="exact"`` (its ``node_limit``) for the searches in Python
#: (unequal sample costs): about 40 s at 5 000 nodes/s.
EXACT_NODE_LIMIT = 200_000
#: Default node budget of ``method="exact"`` for the Rust kernel (equal sample costs, at most
#: ``exact.MAX_KERNEL_SENSORS`` sensors): about the same seconds at its 20 000 nodes/s; 4 sensors
#: × 12 slots need up to 834 000 nodes.
EXACT_KERNEL_NODE_LIMIT = 2_000_000


@accepts_path
@numerical_errors
def best_schedule(
    net: Any,
    tau: float,
    r_tot: int | float,
    *,
    counts: Sequence[int] | None = None,
    which: Which = "boundary",
    max_moves: int | None = None,
    time_limit: float | None = None,
    progress: ProgressArg = None,
    check: bool = True,
    method: str = "screened",
    confirm: bool | None = None,
    node_limit: int | None = None,
    certify: bool | str = True,
) -> BestSchedule:
    """The best schedule found for period ``τ`` with ``r_tot`` slots, by exact local search.

    With sample costs, per-sensor minima or caps on the network (``net.costs``,
    ``net.rate_min``, ``net.rate_max``), ``r_tot`` is the budget ``B`` in channel units per
    period (any positive number; for unit costs both coincide): every schedule considered has
    counts within ``[⌈r_min,i⌉, ⌊r_max,i⌋]`` and uses at most ``B`` units (the rest of the
    period is idle); the starting counts are :func:`~capalloc_rs.sampled.budget_counts`', round
    robin and greedy respect the budget (see their docs), a reassignment move is taken only if
    the budget and the limits still hold (swaps and rotations always), and ``η̄`` is costed with
    the idle time. With an error weight every cost is ``tr(M ·)``.

    1. Candidates: the evenly interleaved schedule of ``counts`` (default: ``method="screened"``,
       :func:`~capalloc_rs.sampled.rounded_counts`, the optimal real allocation rounded;
       ``"exhaustive"``, :func:`~capalloc_rs.sampled.initial_counts`, the optimal integer one),
       :func:`~capalloc_rs.round_robin_schedule` and :func:`~capalloc_rs.greedy_schedule` (at most
       ``starts.SCREENED_GREEDY_ROUNDS`` passes under ``"screened"``, one above
       ``starts.LARGE_NEIGHBOURS`` neighbours), each with its exact cost ``η̄(τ, R)`` under
       ``which``; the search starts from the cheapest.
    2. ``method="screened"`` (default; :mod:`capalloc_rs.sampled.screened`): the moves below are
       ranked by the first-order change of ``η̄`` they are predicted to make (one Stein equation
       per schedule), and only batches of the best ones and the best single moves are costed
       exactly; an exact improvement (relative margin 1e-13) is taken. The batch of the kind of
       move (reassignments, swaps) taken last is costed first, both kinds together only while
       both are being taken; ``method="screened_fixed"`` keeps the fixed order of before (both
       kinds together first at every screen: the same kind of search, about twice the exact
       costings at N = 50). The default also moves one sample by several slots at once
       (*shifts*, the samples in between one slot back; predicted from the swaps'
       sensitivities, :mod:`capalloc_rs.sampled.shifts`), the adjacent swaps coming after
       them; above ``screened.DISPLACE_NEIGHBOURS`` neighbours (N = 100, r_tot = 300) each
       screen first tries *displacement steps* (every sample moved along its predicted one-slot
       gain and the period re-sorted, two step lengths costed exactly) and the search stops as
       ``"stalled"`` once ``screened.STALL_SCREENS`` screens together lowered ``η̄`` by less
       than ``screened.STALL_RTOL`` (relative; ``converged=False``). ``method="screened-v3"``
       is the screened search before shifts and displacement steps (adjacent swaps only; the
       default until then). When no screened move
       improves, the exhaustive neighbourhood of one step of ``"exhaustive"`` confirms the local
       minimum (``confirm=True``; ``None``, the default: when it has at most
       ``screened.CONFIRM_MAX_NEIGHBOURS`` neighbours; ``False``: never) or gives the next move;
       unconfirmed, the search stops with ``stopped="screened_minimum"`` (``converged=False``).
       A confirmed result is a local minimum of the exhaustive neighbourhood, as ``"exhaustive"``'s.
       On problems small enough to confirm, the search runs from every starting candidate (best
       kept); on tiny ones (at most ``screened.PORTFOLIO_MAX_NEIGHBOURS`` neighbours) the
       candidates are the exhaustive method's and its search runs too, so that the result is
       never worse than ``method="exhaustive"``'s there.
    3. ``method="exhaustive"`` (the reference, today's algorithm): best improvement; the
       neighbourhood of a schedule is every *exchange move*
       (one slot given to another sensor, keeping every sensor at ``⌈r_min⌉`` slots or more), every
       *swap* of two adjacent slots and, for ``which="boundary"``, every *rotation* (the boundary
       figure depends on where the period starts). All neighbours are evaluated exactly in the
       Rust core (prefix/suffix star products + one doubling each, in parallel); the best one is
       taken, then up to ``BATCH_ATTEMPTS`` of the next-best improving moves on untouched slots,
       each accepted only if an exact evaluation confirms it lowers the cost (relative margin
       1e-13). Stops at a local minimum (no improving neighbour), after ``max_moves`` moves
       (default ``capalloc_rs.limits.BEST_SCHEDULE_MAX_MOVES``) or once ``time_limit`` seconds
       have passed (default ``capalloc_rs.limits.BEST_SCHEDULE_TIME_LIMIT``, ``None``: no limit).
       The time limit covers the whole call: the refinement of the initial counts and the greedy
       rounds stop at ``START_SHARE`` of it; the interleaved candidate is always built and
       costed, round robin and greedy only while the time left exceeds one and
       ``starts.GREEDY_COSTINGS`` times that costing's time (a tiny limit keeps ``"initial"``
       alone); it is checked before every neighbourhood, every neighbour and every extra
       evaluation (a partly evaluated neighbourhood still gives its best improving move). A
       stopped search is not an error: the result has ``converged=False`` and
       ``stopped="max_moves"``/``"time_limit"``. The same budgets and stopping rules hold for
       ``"screened"``, whose screens and exact costings also stop inside the Rust core once the
       deadline passes (before each star product of a candidate, between the parts of a
       screen): the call returns within the largest of one costing of the interleaved
       candidate, one Rust call of the start phase and a fraction of a second of the limit
       (N = 100, r_tot = 300: ≈ 1–2 s), plus the certificate below (≈ 0.5 s there).

    4. ``method="exact"``: the screened search's result is the incumbent of a depth-first
       branch-and-bound over all schedules (:mod:`capalloc_rs.sampled.exact`: each partial
       schedule bounded by relaxing its free slots to a slot with the information of every
       sensor that may go there; with unequal sample costs
       :mod:`capalloc_rs.sampled.exact_grid`: the rest of the period relaxed on the cost grid,
       an update at every time a completion's slot may end); an exhausted
       tree proves the result optimal (``proven_optimal=True``, ``gap = 0``). ``node_limit``
       (default ``EXACT_KERNEL_NODE_LIMIT`` for equal costs, ``EXACT_NODE_LIMIT`` otherwise)
       bounds the nodes and ``time_limit`` the whole call; at
       either the best schedule found is returned with the proven bound of the open nodes. Meant
       for small instances (3–4 sensors, up to ~12 slots).

    **Certificate.** Every certificate is a proven lower bound ``lower_bound`` on ``η̄`` over
    every schedule within the budget and the count limits, with ``gap = eta_bar − lower_bound``
    (with ``"exact"``: the larger of it and the branch-and-bound's bound).
    ``certify="relaxed"`` (the certificate before the cheap grouped bound existed): the relaxed
    period of :mod:`capalloc_rs.sampled.relaxation` (every possible update time given the
    information of all sensors; any costs and limits; loose, 31–40 % of ``η̄`` on the benchmark
    networks). ``certify=True`` (default): the larger of that and, in the paper's case (unit
    costs, one minimum, no caps), the cheap bound of :mod:`capalloc_rs.sampled.grouped` (the
    error split by state coordinate, each part relaxed around its key sensor, whose positions
    are enumerated up to ``grouped.CHEAP_SETS`` sets per count, covered by blocks or by the
    longest gap beyond; the counts by a knapsack; skipped when a round of it may need more
    than ``grouped.CHEAP_WORK / (L n³)`` trajectories: it runs up to about N = 10 subsystems
    of two states with 20 slots, adding ≈ 0.5–1 s there).
    ``certify="grouped"``: the same with up to ``grouped.MAX_SETS`` sets (tighter, seconds to
    a minute at N = 10–20). ``False``: no bound.

    ``progress``: ``None`` (a tqdm bar on stderr if it is a terminal and tqdm is installed),
    ``True``/``False``, or a callable receiving ``{"phase", "moves", "eta_bar", "best",
    "evaluations", "elapsed"}`` when a phase starts (``"initial counts"``, ``"greedy"``;
    ``eta_bar`` is then ``nan``), after each neighbourhood or screen (``"search"``) and before a
    confirmation (``"confirm"``); ``eta_bar`` is the current schedule's exact cost and ``best``
    the best found so far (equal: only improvements are taken). Ctrl-C raises
    ``KeyboardInterrupt`` within about a second, also inside a Rust evaluation.

    Since the search starts at the best candidate and only accepts improvements, the result is
    never worse than round robin or greedy (``eta_bar ≤ min`` of their costs).

    Raises:
        InvalidInputError, NonFiniteError, ScheduleError: bad τ, ``r_tot``, ``counts``,
            ``max_moves``, ``time_limit``, ``method``, ``confirm``, ``node_limit`` or
            ``certify``; ``r_tot`` above ``limits.MAX_SLOTS_PER_PERIOD``.
        UnobservableError, AliasingError: Proposition 1 fails for the network (``check=True``).
        ConvergenceError: no starting schedule has a periodic steady state (a candidate without
            one costs ``inf``; every other error of an evaluation propagates).
    """
    started = time.monotonic()
    m = sampled_system(net)
    t = _check_tau(tau)
    r = _check_r_tot(m, r_tot)
    move_budget = _check_max_moves(max_moves)
    budget = check_time_limit(limits.BEST_SCHEDULE_TIME_LIMIT if time_limit is None else time_limit)
    deadline = math.inf if budget is None else started + budget
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    if not isinstance(method, str) or method not in METHODS:
        raise InvalidInputError(f"method must be one of {METHODS}, got {method!r}")
    if confirm is not None and not isinstance(confirm, bool):
        raise InvalidInputError(f"confirm must be True, False or None, got {confirm!r}")
    order = "fixed" if method == "screened_fixed" else "adaptive"
    shift = MAX_SHIFT if method in ("screened", "exact") else 1
    screened = method in ("screened", "screened-v3", "screened_fixed")
    plan = _Plan("screened" if screened else method, ScreenedOptions(confirm, order, shift))
    nodes = _check_node_limit(node_limit)
    if not isinstance(certify, bool) and certify not in ("relaxed", "grouped"):
        raise InvalidInputError(
            f"certify must be True, False, 'relaxed' or 'grouped', got {certify!r}"
        )
    if check:
        check_existence(m, t, None)
    else:
        warn_unchecked()
    lim = schedule_limits(m, r)
    with Progress(progress, "best_schedule") as bar:
        res = _best_schedule(
            net, m, t, r, counts, which, lim, move_budget, deadline, bar, started, plan
        )
    return _certified(net, m, t, which, lim, res, plan, nodes, deadline, certify, started)


def _certified(
    net: Any,
    m: SampledSystem,
    t: float,
    which: Which,
    lim: ScheduleLimits,
    res: BestSchedule,
    plan: _Plan,
    node_limit: int | None,
    deadline: float,
    certify: bool | str,
    started: float,
) -> BestSchedule:
    """The result with its lower bound and gap (and, for ``"exact"``, the branch-and-bound)."""
    lower = relaxed_lower_bound(m, t, lim, which) if certify else math.nan
    if certify is True or certify == "grouped":
        grouped = grouped_lower_bound(m, t, lim, which, deadline, cheap=certify is True)
        lower = lower if math.isnan(grouped) else max(lower, grouped)
    if plan.method != "exact":
        if math.isnan(lower):
            return res
        return replace(
            res,
            lower_bound=min(lower, res.eta_bar),
            gap=max(res.eta_bar - lower, 0.0),
            proven_optimal=lower >= res.eta_bar,
            elapsed=time.monotonic() - started,
        )
    if node_limit is None:
        kernel = equal_costs(m) and m.n_sensors <= MAX_KERNEL_SENSORS
        node_limit = EXACT_KERNEL_NODE_LIMIT if kernel else EXACT_NODE_LIMIT
    ex = exact_search(m, t, which, lim, res.schedule, res.eta_bar, node_limit, deadline)
    if ex.schedule != res.schedule or ex.eta_bar != res.eta_bar:
        res = replace(
            res,
            schedule=ex.schedule,
            eta_bar=ex.eta_bar,
            counts=tuple(int(v) for v in ex.schedule.counts),
            budget_used=float(ex.schedule.budget_used(m.costs)),
            eta_limit=_eta_limit(net, ex.schedule),
        )
    bounds = [v for v in (ex.lower_bound, lower) if not math.isnan(v)]
    bound = max(bounds) if bounds else math.nan
    bound = min(bound, ex.eta_bar)
    return replace(
        res,
        lower_bound=bound,
        gap=ex.eta_bar - bound,
        proven_optimal=ex.complete or bound >= ex.eta_bar,
        nodes=ex.nodes,
        elapsed=time.monotonic() - started,
    )


@dataclass(frozen=True)
class _Plan:
    """The search method of :func:`best_schedule` and the screened search's options."""

    method: str
    screened: ScreenedOptions


def _best_schedule(
    net: Any,
    m: SampledSystem,
    t: float,
    r: int | float,
    counts: Sequence[int] | None,
    which: Which,
    lim: ScheduleLimits,
    move_budget: int,
    deadline: float,
    bar: Progress,
    started: float,
    plan: _Plan,
) -> BestSchedule:
    """:func:`best_schedule` after its checks: the starting candidates, then the search."""
    # Refining the starting candidates may use half of a time limit; the rest is the search's.
    start_deadline = started + START_SHARE * (deadline - started)
    bar.update(phase="initial counts", moves=0, eta_bar=math.nan, evaluations=0)
    c0, tiny = initial_counts_of(net, m, r, counts, which, lim, plan.method, start_deadline)
    initial = Schedule.from_counts(c0, "interleaved")
    if lim.plain:
        initial.validate(m.n_sensors, m.r_min)
    bar.update(phase="greedy", moves=0, eta_bar=math.nan, evaluations=0)
    large = is_large(m, r, which, plan.method)
    rounds = greedy_rounds(large, plan.method, tiny)
    cands = start_candidates(m, t, r, which, lim, initial, rounds, large, deadline, start_deadline)
    evaluations = len(cands)
    start = min(cands.values(), key=lambda c: c.eta_bar)
    if not math.isfinite(start.eta_bar):
        raise ConvergenceError(
            "no starting schedule has a periodic steady state at this tau (the doubling diverged "
            "for all of them)"
        )
    if plan.method == "exhaustive":
        state = _SearchState(start.schedule, start.eta_bar, 0, evaluations)
        stopped = _local_search(SearchContext(m, t, which, lim, move_budget, deadline, bar), state)
    else:
        order = sorted(
            (c for c in cands.values() if math.isfinite(c.eta_bar)), key=lambda c: c.eta_bar
        )
        ctx = SearchContext(m, t, which, lim, move_budget, deadline, bar)
        state, stopped, start = _screened(ctx, order, evaluations, plan)
    current, cost, moves, evaluations = state.current, state.cost, state.moves, state.evaluations
    final_counts = tuple(int(v) for v in current.counts)
    eta_fn = getattr(net, "cost", None)
    eta_limit = (
        float(eta_fn(np.asarray(final_counts, dtype=np.float64))) if callable(eta_fn) else math.nan
    )
    return BestSchedule(
        schedule=current,
        eta_bar=cost,
        eta_limit=eta_limit,
        counts=final_counts,
        which=which,
        tau=t,
        start=start.name,
        candidates=MappingProxyType(dict(cands)),
        moves=moves,
        evaluations=evaluations,
        converged=stopped == "local_minimum",
        stopped=stopped,
        elapsed=time.monotonic() - started,
        budget=float(lim.budget),
        budget_used=float(current.budget_used(m.costs)),
    )


def _screened(
    ctx: SearchContext, order: list[Candidate], evaluations: int, plan: _Plan
) -> tuple[_SearchState, str, Candidate]:
    """The screened search from the cheapest candidate and, on the small problems whose minima
    it confirms, from each other one too (budgets shared); the best result, why its search
    stopped and its start."""
    m, which = ctx.m, ctx.which
    starts = (
        order
        if screened_confirms(m, len(order[0].schedule.slots), which, plan.screened)
        else order[:1]
    )
    best: tuple[_SearchState, str, Candidate] | None = None
    moves, best_cost = 0, math.inf
    for cand in starts:
        if best is not None and (time.monotonic() >= ctx.deadline or moves >= ctx.max_moves):
            break
        state = _SearchState(cand.schedule, cand.eta_bar, moves, evaluations, best_cost)
        stopped = screened_search(ctx, state, plan.screened, partial(_exhaustive_step, ctx, state))
        moves, evaluations = state.moves, state.evaluations
        best_cost = min(best_cost, state.cost)
        if best is None or state.cost < best[0].cost:
            best = (state, stopped, cand)
    assert best is not None  # order has the finite start at least
    if neighbours(m, len(order[0].schedule.slots), which) <= PORTFOLIO_MAX_NEIGHBOURS:
        # Tiny: the exhaustive search from the cheapest start too (the exhaustive method's run).
        state = _SearchState(order[0].schedule, order[0].eta_bar, moves, evaluations, best_cost)
        stopped = _local_search(ctx, state)
        moves, evaluations = state.moves, state.evaluations
        if state.cost < best[0].cost:
            best = (state, stopped, order[0])
    state = best[0]
    state.moves, state.evaluations = moves, evaluations
    return best


def _eta_limit(net: Any, s: Schedule) -> float:
    """``η(counts)`` of a schedule (``nan`` if the network has no ``cost`` method)."""
    fn = getattr(net, "cost", None)
    return float(fn(np.asarray(s.counts, dtype=np.float64))) if callable(fn) else math.nan


def _check_node_limit(node_limit: int | None) -> int | None:
    """The validated ``node_limit``; ``None`` (the default of the search that runs) stays."""
    if node_limit is None:
        return None
    if isinstance(node_limit, bool) or not isinstance(node_limit, (int, np.integer)):
        raise InvalidInputError(f"node_limit must be an integer >= 1, got {node_limit!r}")
    if node_limit < 1:
        raise InvalidInputError(f"node_limit must be >= 1, got {node_limit}")
    return int(node_limit)


def _check_max_moves(max_moves: int | None) -> int:
    if max_moves is None:
        return int(limits.BEST_SCHEDULE_MAX_MOVES)
    if isinstance(max_moves, bool) or not isinstance(max_moves, (int, np.integer)):
        raise InvalidInputError(f"max_moves must be an integer >= 0, got {max_moves!r}")
    if max_moves < 0:
        raise InvalidInputError(f"max_moves must be >= 0, got {max_moves}")
    return int(max_moves)
