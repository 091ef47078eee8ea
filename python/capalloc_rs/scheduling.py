"""From allocation to schedule: the best concrete schedule at a finite period τ, and the
literature's baselines.

* :func:`round_robin_schedule` — uniform allocation: counts as equal as possible, cyclic order.
* :func:`greedy_schedule` — greedy sensor scheduling: each slot takes the sensor whose measurement
  most reduces the trace of the posterior covariance, run to a periodic steady state.
* :func:`best_schedule` — optimal counts of the fast-sampling problem, evenly interleaved, then a
  local search with the exact finite-τ cost ``η̄(τ, R)`` (:mod:`capalloc_rs.sampled`), seeded with
  the baselines so that it is never worse than either of them.
"""

from __future__ import annotations

import importlib
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from . import _core, limits
from ._arrays import as_count, numerical_errors
from ._progress import Progress, ProgressArg
from ._unchecked import warn_unchecked
from .errors import CapallocError, ConvergenceError, InvalidInputError, ScheduleError
from .limits import check_limit, check_time_limit
from .network import accepts_path
from .sampled import Model, Which, _check_tau, check_existence, model_of, sampled_covariance
from .schedule import Schedule, min_slots

__all__ = [
    "Candidate",
    "BestSchedule",
    "round_robin_schedule",
    "greedy_schedule",
    "initial_counts",
    "best_schedule",
]


@dataclass(frozen=True)
class Candidate:
    """A schedule and its exact finite-τ cost (``inf`` if its steady state does not exist)."""

    name: str
    schedule: Schedule
    eta_bar: float


@dataclass(frozen=True)
class BestSchedule:
    """The result of :func:`best_schedule`.

    Attributes:
        schedule: the best schedule found.
        eta_bar: its exact cost ``η̄(τ, R)`` under ``which``.
        eta_limit: ``η(counts)``, the fast-sampling cost of its counts (``net.cost``; ``nan`` if the
            network has no ``cost`` method) — what the τ → 0 theory predicts for these counts.
        counts: the schedule's counts.
        which: ``"boundary"`` or ``"average"`` (see :mod:`capalloc_rs.sampled`).
        tau: the period.
        start: the name of the candidate the local search started from.
        candidates: every starting candidate by name (``"initial"``, ``"round_robin"``,
            ``"greedy"``) with its exact cost.
        moves: improving moves applied by the local search.
        evaluations: schedules whose exact cost was computed: the starting candidates, every
            neighbour costed by the search (no-op and starving moves, and neighbours skipped
            after ``time_limit``, are not counted) and every extra move verified.
        converged: ``True`` if the search stopped at a local minimum (no improving move), ``False``
            if it hit ``max_moves`` or ``time_limit``.
        stopped: why the search stopped: ``"local_minimum"``, ``"max_moves"`` or
            ``"time_limit"`` (then ``schedule`` is the best found so far, at most as costly as
            every starting candidate).
        elapsed: wall-clock seconds spent.
    """

    schedule: Schedule
    eta_bar: float
    eta_limit: float
    counts: tuple[int, ...]
    which: str
    tau: float
    start: str
    candidates: Mapping[str, Candidate] = field(repr=False)
    moves: int
    evaluations: int
    converged: bool
    stopped: str = "local_minimum"
    elapsed: float = 0.0


def _neighbourhood(
    m: Model, tau: float, s: Schedule, which: str, min_count: int, time_limit: float | None
) -> _core.Neighbourhood:
    """The exact costs of ``s``'s neighbours: one Rust call on the model built once per search
    (:attr:`Model.core`, which keeps the discretisation of ``(tau, r_tot)`` between calls)."""
    return m.core.neighbourhood(tau, s.as_array(), which, min_count, time_limit=time_limit)


def _cost(m: Model, tau: float, s: Schedule, which: str) -> float:
    """Exact cost, ``inf`` when the steady state does not exist for this schedule."""
    try:
        return float(m.core.cost(tau, s.as_array(), which))
    except (ConvergenceError, CapallocError):
        return math.inf


_NO_CAP = 10**10000


def _check_r_tot(m: Model, r_tot: int) -> int:
    # Integral floats (8.0) too, the rule of every slot count; no cap here, so that check_limit
    # below names the limit (capalloc_rs.limits.MAX_SLOTS_PER_PERIOD) however large r_tot is.
    r = as_count("r_tot", r_tot, maximum=_NO_CAP)
    check_limit("r_tot (slots per period)", r, "MAX_SLOTS_PER_PERIOD")
    need = m.n_sensors * min_slots(m.r_min)
    if r < max(1, need):
        raise ScheduleError(
            f"r_tot = {r} slots cannot give each of the {m.n_sensors} sensors its "
            f"{min_slots(m.r_min)} slot(s) (r_min = {m.r_min}): need r_tot >= {max(1, need)}"
        )
    return r


@accepts_path
def round_robin_schedule(net: Any, r_tot: int) -> Schedule:
    """Uniform allocation: every sensor gets ``⌊r_tot/N⌋`` slots (the first ``r_tot mod N`` one
    more), in cyclic order ``0, 1, …, N−1, 0, …`` (:meth:`Schedule.round_robin`)."""
    m = model_of(net)
    r = _check_r_tot(m, r_tot)
    return Schedule.round_robin(m.n_sensors, r)


@accepts_path
@numerical_errors
def greedy_schedule(
    net: Any,
    tau: float,
    r_tot: int,
    *,
    which: Which = "boundary",
    max_rounds: int = 50,
    deadline: float = math.inf,
) -> Schedule:
    """The greedy sensor-scheduling heuristic, run to a periodic steady state.

    One *pass* builds a period slot by slot from a posterior covariance ``Σ``: slot ``l`` predicts
    ``P = E Σ Eᵀ + H`` and takes the sensor ``i`` that minimises ``tr φ_i(Σ)``, i.e. maximises the
    trace reduction ``tr(P c̄_i (I + c̄_iᵀ P c̄_i)⁻¹ c̄_iᵀ P)`` (ties: lowest index), except that
    sensors still owed slots under ``r_min`` are forced once the remaining slots are exactly those
    owed. The first pass starts from the boundary covariance of round robin's steady state; each
    next pass starts from the boundary covariance of the previous pass's schedule's periodic steady
    state, until a schedule repeats (a periodic steady state of the heuristic) or ``max_rounds``
    passes, or once ``time.monotonic()`` passes ``deadline`` (after at least one pass). Returns
    the best schedule (exact cost under ``which``) among the passes.
    """
    m = model_of(net)
    t = _check_tau(tau)
    r = _check_r_tot(m, r_tot)
    need = min_slots(m.r_min)
    rr = Schedule.round_robin(m.n_sensors, r)
    try:
        sigma = sampled_covariance(m, t, rr, check=False).boundary
    except CapallocError:
        sigma = np.eye(m.n)
    seen: set[Schedule] = set()
    best: tuple[float, Schedule] | None = None
    for k in range(as_count("max_rounds", max_rounds, minimum=1)):
        if k > 0 and time.monotonic() >= deadline:
            break
        greedy = m.core.greedy_pass(t, r, np.asarray(sigma), need)
        s = Schedule(greedy.slots, m.n_sensors)
        if s in seen:
            break
        seen.add(s)
        try:
            cov = sampled_covariance(m, t, s, check=False)
        except CapallocError:
            break
        cost = cov.eta(which)
        if best is None or cost < best[0]:
            best = (cost, s)
        sigma = cov.boundary
    if best is None:
        return s
    return best[1]


def _largest_remainder(x: npt.NDArray[np.float64], r_tot: int, lo: int) -> list[int]:
    """Rounds nonnegative ``x`` (``Σx = r_tot``) to integers ``≥ lo`` with the same sum."""
    base = np.maximum(np.floor(x).astype(np.int64), lo)
    rest = r_tot - int(base.sum())
    order = np.argsort(-(x - np.floor(x)), kind="stable")
    k = 0
    while rest > 0:
        base[order[k % len(order)]] += 1
        rest -= 1
        k += 1
    while rest < 0:
        for i in np.argsort(x - base, kind="stable"):
            if base[i] > lo:
                base[i] -= 1
                rest += 1
                break
        else:  # every count is at lo: no rounding reaches r_tot (bounded, never spins)
            raise ScheduleError(
                f"cannot round the allocation to r_tot = {r_tot} slots with at least {lo} each"
            )
    return [int(v) for v in base]


@accepts_path
def initial_counts(net: Any, r_tot: int, *, deadline: float = math.inf) -> tuple[list[int], str]:
    """Starting counts for :func:`best_schedule` and the rule that produced them.

    1. ``capalloc_rs.allocation.integer_allocation(net, r_tot)`` (the optimal integer allocation
       of the fast-sampling problem) when that module exists and returns valid counts;
    2. otherwise, if the network has ``cost(r)`` (``η``), the marginal-greedy allocation: start
       from ``⌈r_min⌉`` slots each and give each further slot to the sensor whose extra slot lowers
       ``η`` most (``N`` cost evaluations per slot; optimal for separable convex η, a good start
       otherwise — the exact local search that follows does not depend on it for its guarantees);
    3. otherwise round robin.

    ``deadline`` (a ``time.monotonic()`` value) cuts rules 1 and 2 short once passed (their
    counts are then feasible but less refined).
    """
    m = model_of(net)
    r = _check_r_tot(m, r_tot)
    lo = min_slots(m.r_min)
    try:
        allocation = importlib.import_module("capalloc_rs.allocation")
        raw = allocation.integer_allocation(
            net, r, deadline=None if math.isinf(deadline) else deadline
        )
        counts_arr = np.asarray(getattr(raw, "counts", raw), dtype=np.float64).ravel()
        if (
            counts_arr.shape == (m.n_sensors,)
            and np.all(np.isfinite(counts_arr))
            and np.all(counts_arr >= lo)
        ):
            counts = _largest_remainder(counts_arr * (r / counts_arr.sum()), r, lo)
            return counts, "allocation.integer_allocation"
    except (ImportError, AttributeError, TypeError, CapallocError):
        pass
    cost = getattr(net, "cost", None)
    if callable(cost):
        counts = [lo] * m.n_sensors
        for _ in range(r - sum(counts)):
            if time.monotonic() >= deadline:
                counts[int(np.argmin(counts))] += 1  # out of time: fill evenly
                continue
            trial = []
            for i in range(m.n_sensors):
                c = np.asarray(counts, dtype=np.float64)
                c[i] += 1
                trial.append(float(cost(c)))
            i = int(np.argmin(trial))
            counts[i] += 1
        return counts, "marginal greedy on net.cost"
    return [int(v) for v in Schedule.round_robin(m.n_sensors, r).counts], "round robin"


#: The share of a ``time_limit`` of :func:`best_schedule` that refining its starting candidates
#: (initial counts, greedy rounds) may use; the rest is left to the local search.
START_SHARE = 0.5

#: Extra moves tried (each verified exactly) per neighbourhood evaluation of :func:`best_schedule`.
BATCH_ATTEMPTS = 32


def _improving_moves(
    cost: float,
    reassign: npt.NDArray[np.float64],
    swap: npt.NDArray[np.float64],
    rotate: npt.NDArray[np.float64],
) -> list[tuple[float, str, int, int]]:
    """Moves whose exact cost is below ``cost`` (relative margin 1e-13), best first:
    ``(cost, kind, a, b)`` with ``kind`` ``"reassign"`` (slot ``a`` to sensor ``b``), ``"swap"``
    (slots ``a``, ``a + 1``) or ``"rotate"`` (start at slot ``a``)."""
    thr = cost - 1e-13 * abs(cost)
    out: list[tuple[float, str, int, int]] = []
    for pos, j in zip(*np.nonzero(reassign < thr), strict=True):
        out.append((float(reassign[pos, j]), "reassign", int(pos), int(j)))
    for at in np.flatnonzero(swap < thr):
        out.append((float(swap[at]), "swap", int(at), 0))
    for k in np.flatnonzero(rotate[1:] < thr):
        out.append((float(rotate[k + 1]), "rotate", int(k) + 1, 0))
    out.sort()
    return out


def _apply_move(s: Schedule, kind: str, a: int, b: int) -> Schedule:
    slots = list(s.slots)
    if kind == "reassign":
        slots[a] = b
    elif kind == "swap":
        slots[a], slots[a + 1] = slots[a + 1], slots[a]
    else:
        slots = slots[a:] + slots[:a]
    return Schedule(slots, s.n_sensors)


@accepts_path
@numerical_errors
def best_schedule(
    net: Any,
    tau: float,
    r_tot: int,
    *,
    counts: Sequence[int] | None = None,
    which: Which = "boundary",
    max_moves: int | None = None,
    time_limit: float | None = None,
    progress: ProgressArg = None,
    check: bool = True,
) -> BestSchedule:
    """The best schedule found for period ``τ`` with ``r_tot`` slots, by exact local search.

    1. Candidates: the evenly interleaved schedule of ``counts`` (default :func:`initial_counts`),
       :func:`round_robin_schedule` and :func:`greedy_schedule`, each with its exact cost
       ``η̄(τ, R)`` under ``which``; the search starts from the cheapest.
    2. Local search (best improvement): the neighbourhood of a schedule is every *exchange move*
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
       rounds stop at ``START_SHARE`` of it (each candidate is still built and costed), and it is
       checked before every neighbourhood, every neighbour and every extra evaluation (so it is
       overrun by about the costing of the candidates and one neighbour per thread; a partly
       evaluated neighbourhood still gives its best improving move). A stopped search is not an
       error: the result has ``converged=False`` and ``stopped="max_moves"``/``"time_limit"``.

    ``progress``: ``None`` (a tqdm bar on stderr if it is a terminal and tqdm is installed),
    ``True``/``False``, or a callable receiving ``{"phase", "moves", "eta_bar", "evaluations",
    "elapsed"}`` when a phase starts (``"initial counts"``, ``"greedy"``; ``eta_bar`` is then
    ``nan``) and after each neighbourhood (``"search"``). Ctrl-C raises ``KeyboardInterrupt``
    within about a second, also inside a neighbourhood evaluation.

    Since the search starts at the best candidate and only accepts improvements, the result is
    never worse than round robin or greedy (``eta_bar ≤ min`` of their costs).

    Raises:
        InvalidInputError, NonFiniteError, ScheduleError: bad τ, ``r_tot``, ``counts``,
            ``max_moves`` or ``time_limit``; ``r_tot`` above ``limits.MAX_SLOTS_PER_PERIOD``.
        UnobservableError, AliasingError: Proposition 1 fails for the network (``check=True``).
    """
    started = time.monotonic()
    m = model_of(net)
    t = _check_tau(tau)
    r = _check_r_tot(m, r_tot)
    move_budget = _check_max_moves(max_moves)
    budget = check_time_limit(limits.BEST_SCHEDULE_TIME_LIMIT if time_limit is None else time_limit)
    deadline = math.inf if budget is None else started + budget
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    if check:
        check_existence(m, t, None)
    else:
        warn_unchecked()
    lo = min_slots(m.r_min)
    with Progress(progress, "best_schedule") as bar:
        return _best_schedule(net, m, t, r, counts, which, lo, move_budget, deadline, bar, started)


def _best_schedule(
    net: Any,
    m: Model,
    t: float,
    r: int,
    counts: Sequence[int] | None,
    which: Which,
    lo: int,
    move_budget: int,
    deadline: float,
    bar: Progress,
    started: float,
) -> BestSchedule:
    """:func:`best_schedule` after its checks: the starting candidates, then the search."""
    # Refining the starting candidates may use half of a time limit; the rest is the search's.
    start_deadline = started + START_SHARE * (deadline - started)
    bar.update(phase="initial counts", moves=0, eta_bar=math.nan, evaluations=0)
    if counts is None:
        c0, _rule = initial_counts(net, r, deadline=start_deadline)
    else:
        if isinstance(counts, str | bytes) or not isinstance(counts, Sequence | np.ndarray):
            raise InvalidInputError(f"counts must be a sequence of integers, got {counts!r}")
        c0 = [as_count(f"counts[{k}]", v) for k, v in enumerate(counts)]
        if len(c0) != m.n_sensors or sum(c0) != r:
            raise ScheduleError(
                f"counts must have one entry per sensor ({m.n_sensors}) summing to r_tot = {r}, "
                f"got {c0}"
            )
    initial = Schedule.from_counts(c0, "interleaved")
    initial.validate(m.n_sensors, m.r_min)
    bar.update(phase="greedy", moves=0, eta_bar=math.nan, evaluations=0)
    starts = {
        "initial": initial,
        "round_robin": round_robin_schedule(m, r),
        "greedy": greedy_schedule(m, t, r, which=which, deadline=start_deadline),
    }
    cands = {k: Candidate(k, s, _cost(m, t, s, which)) for k, s in starts.items()}
    evaluations = len(cands)
    start = min(cands.values(), key=lambda c: c.eta_bar)
    if not math.isfinite(start.eta_bar):
        raise ConvergenceError(
            "no starting schedule has a periodic steady state at this tau (the doubling diverged "
            "for all of them)"
        )
    current, cost = start.schedule, start.eta_bar
    current, cost, moves, evaluations, stopped = _local_search(
        m, t, which, lo, current, cost, evaluations, move_budget, deadline, bar
    )
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
    )


def _check_max_moves(max_moves: int | None) -> int:
    if max_moves is None:
        return int(limits.BEST_SCHEDULE_MAX_MOVES)
    if isinstance(max_moves, bool) or not isinstance(max_moves, (int, np.integer)):
        raise InvalidInputError(f"max_moves must be an integer >= 0, got {max_moves!r}")
    if max_moves < 0:
        raise InvalidInputError(f"max_moves must be >= 0, got {max_moves}")
    return int(max_moves)


def _local_search(
    m: Model,
    t: float,
    which: str,
    lo: int,
    current: Schedule,
    cost: float,
    evaluations: int,
    max_moves: int,
    deadline: float,
    bar: Progress,
) -> tuple[Schedule, float, int, int, str]:
    """The best-improvement local search of :func:`best_schedule`; returns the final schedule,
    its cost, the moves, the evaluations and why it stopped."""
    moves = 0
    while True:
        if moves >= max_moves:
            return current, cost, moves, evaluations, "max_moves"
        if time.monotonic() >= deadline:
            return current, cost, moves, evaluations, "time_limit"
        # A neighbourhood can take longer than the whole budget (N = 50, r_tot = 60: ~3000
        # doublings): candidates that would start after the deadline are skipped (+∞); the
        # evaluated ones are exact, and their best improving move is still taken.
        left = None if math.isinf(deadline) else max(deadline - time.monotonic(), 0.0)
        nb = _neighbourhood(m, t, current, which, lo, time_limit=left)
        # Only the neighbours actually costed: not the no-op/starving moves (+∞ by rule) nor the
        # candidates skipped after the deadline (+∞ too).
        evaluations += int(nb.evaluated)
        cost = float(nb.current)
        bar.update(phase="search", moves=moves, eta_bar=cost, evaluations=evaluations)
        improving = _improving_moves(cost, nb.reassign, nb.swap, nb.rotate)
        if not improving:
            # Only a fully evaluated neighbourhood proves a local minimum.
            why = "local_minimum" if nb.complete else "time_limit"
            return current, cost, moves, evaluations, why
        # The best move's cost is exact: take it. Then try the next-best moves on slots not touched
        # yet, each verified by an exact evaluation (at most BATCH_ATTEMPTS per neighbourhood).
        touched: set[int] = set()
        attempts = 0
        for rank, (val, kind, a, b) in enumerate(improving):
            if moves >= max_moves or attempts >= BATCH_ATTEMPTS:
                break
            if rank > 0 and time.monotonic() >= deadline:
                break
            span = {a} if kind == "reassign" else {a, a + 1} if kind == "swap" else set()
            if rank > 0 and (kind == "rotate" or span & touched):
                continue
            trial = _apply_move(current, kind, a, b)
            if rank > 0 and kind == "reassign" and int(np.min(trial.counts)) < lo:
                # Costed against the schedule before this batch's moves: after another move took
                # a slot from the same sensor, this one would starve it below ⌈r_min⌉.
                continue
            if rank > 0:
                attempts += 1
                evaluations += 1
                val = _cost(m, t, trial, which)
            if val < cost - 1e-13 * abs(cost):
                current, cost = trial, val
                moves += 1
                touched |= span
                if kind == "rotate":
                    break  # every position moved: re-evaluate the neighbourhood
