"""The best concrete schedule at a finite period τ: exact local search from the best of the
starting schedules (:mod:`capalloc_rs.sampled.baselines`).

:func:`best_schedule` takes the optimal counts of the fast-sampling problem, evenly interleaved,
round robin and greedy as candidates, then improves the cheapest by a best-improvement local
search with the exact finite-τ cost ``η̄(τ, R)`` (:mod:`capalloc_rs.sampled.system`), so that it is
never worse than either baseline.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import _core, limits
from .._arrays import as_count, numerical_errors
from .._json import ints, plain
from .._progress import Progress, ProgressArg
from .._unchecked import warn_unchecked
from ..errors import ConvergenceError, InvalidInputError, ScheduleError
from ..limits import check_time_limit, min_slots
from ..network import accepts_path
from .baselines import _check_r_tot, greedy_schedule, initial_counts, round_robin_schedule
from .schedule import Schedule
from .system import SampledSystem, Which, _check_tau, check_existence, sampled_system

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

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "schedule" (the slots), "eta_bar"}`` as plain JSON-ready values."""
        out: dict[str, Any] = plain(
            {"name": self.name, "schedule": self.schedule.slots, "eta_bar": self.eta_bar}
        )
        return out

    def __repr__(self) -> str:
        return f"Candidate({self.name!r}, r_tot={self.schedule.r_tot}, eta_bar={self.eta_bar:.6g})"


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

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (non-finite numbers as ``None``): the keys of the
        CLI's ``--json`` — ``r_tot``, ``error_vs_limit`` (``eta_bar − eta_limit``),
        ``relative_error_vs_limit`` (divided by ``eta_limit``) and ``baselines`` (each
        candidate's ``eta_bar`` by name) included — plus ``start`` and ``elapsed``.

        Returns:
            ``{"tau", "r_tot", "schedule", "counts", "which", "eta_bar", "eta_limit",
            "error_vs_limit", "relative_error_vs_limit", "converged", "stopped", "moves",
            "evaluations", "baselines", "start", "elapsed"}``.
        """
        error = self.eta_bar - self.eta_limit
        out: dict[str, Any] = plain(
            {
                "tau": self.tau,
                "r_tot": self.schedule.r_tot,
                "schedule": list(self.schedule.slots),
                "counts": ints(self.counts),
                "which": self.which,
                "eta_bar": self.eta_bar,
                "eta_limit": self.eta_limit,
                "error_vs_limit": error,
                "relative_error_vs_limit": error / self.eta_limit if self.eta_limit else math.nan,
                "converged": self.converged,
                "stopped": self.stopped,
                "moves": self.moves,
                "evaluations": self.evaluations,
                "baselines": {k: c.eta_bar for k, c in self.candidates.items()},
                "start": self.start,
                "elapsed": self.elapsed,
            }
        )
        return out

    def __repr__(self) -> str:
        return (
            f"BestSchedule(tau={self.tau:g}, r_tot={self.schedule.r_tot}, "
            f"eta_bar={self.eta_bar:.6g}, eta_limit={self.eta_limit:.6g}, start={self.start!r}, "
            f"moves={self.moves}, stopped={self.stopped!r})"
        )


def _neighbourhood(
    m: SampledSystem, tau: float, s: Schedule, which: str, min_count: int, time_limit: float | None
) -> _core.Neighbourhood:
    """The exact costs of ``s``'s neighbours: one Rust call on the system built once per search
    (:attr:`SampledSystem.core`, which keeps the discretisation of ``(tau, r_tot)`` between
    calls)."""
    return m.core.neighbourhood(tau, s.as_array(), which, min_count, time_limit=time_limit)


def _cost(m: SampledSystem, tau: float, s: Schedule, which: str) -> float:
    """Exact cost, ``inf`` when the steady state does not exist for this schedule."""
    try:
        return float(m.core.cost(tau, s.as_array(), which))
    except ConvergenceError:
        # The core's Convergence error, and only it, means "no periodic steady state for this
        # schedule": the doubling overflowed or did not settle (a mode the schedule does not
        # detect grows), or its limit is not stabilising. Every other error (invalid input,
        # KeyboardInterrupt on cancellation, a singular update) propagates.
        return math.inf


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

    1. Candidates: the evenly interleaved schedule of ``counts`` (default
       :func:`~capalloc_rs.sampled.initial_counts`), :func:`~capalloc_rs.round_robin_schedule` and
       :func:`~capalloc_rs.greedy_schedule`, each with its exact cost
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
    if check:
        check_existence(m, t, None)
    else:
        warn_unchecked()
    lo = min_slots(m.r_min)
    with Progress(progress, "best_schedule") as bar:
        return _best_schedule(net, m, t, r, counts, which, lo, move_budget, deadline, bar, started)


def _best_schedule(
    net: Any,
    m: SampledSystem,
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
    state = _SearchState(start.schedule, start.eta_bar, 0, evaluations)
    stopped = _local_search(m, t, which, lo, state, move_budget, deadline, bar)
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
    )


def _check_max_moves(max_moves: int | None) -> int:
    if max_moves is None:
        return int(limits.BEST_SCHEDULE_MAX_MOVES)
    if isinstance(max_moves, bool) or not isinstance(max_moves, (int, np.integer)):
        raise InvalidInputError(f"max_moves must be an integer >= 0, got {max_moves!r}")
    if max_moves < 0:
        raise InvalidInputError(f"max_moves must be >= 0, got {max_moves}")
    return int(max_moves)


@dataclass
class _SearchState:
    """Where the local search is: the current schedule, its exact cost, the moves applied and
    the schedules costed so far."""

    current: Schedule
    cost: float
    moves: int
    evaluations: int


def _local_search(
    m: SampledSystem,
    t: float,
    which: str,
    lo: int,
    state: _SearchState,
    max_moves: int,
    deadline: float,
    bar: Progress,
) -> str:
    """The best-improvement local search of :func:`best_schedule`, from and into ``state``;
    returns why it stopped (``"local_minimum"``, ``"max_moves"`` or ``"time_limit"``)."""
    while True:
        if state.moves >= max_moves:
            return "max_moves"
        if time.monotonic() >= deadline:
            return "time_limit"
        # A neighbourhood can take longer than the whole budget (N = 50, r_tot = 60: ~3000
        # doublings): candidates that would start after the deadline are skipped (+∞); the
        # evaluated ones are exact, and their best improving move is still taken.
        left = None if math.isinf(deadline) else max(deadline - time.monotonic(), 0.0)
        nb = _neighbourhood(m, t, state.current, which, lo, time_limit=left)
        # Only the neighbours actually costed: not the no-op/starving moves (+∞ by rule) nor the
        # candidates skipped after the deadline (+∞ too).
        state.evaluations += int(nb.evaluated)
        state.cost = float(nb.current)
        bar.update(
            phase="search", moves=state.moves, eta_bar=state.cost, evaluations=state.evaluations
        )
        improving = _improving_moves(state.cost, nb.reassign, nb.swap, nb.rotate)
        if not improving:
            # Only a fully evaluated neighbourhood proves a local minimum.
            return "local_minimum" if nb.complete else "time_limit"
        _take_moves(m, t, which, lo, state, improving, max_moves, deadline)


def _span(kind: str, a: int) -> set[int]:
    """The slots a move changes (a rotation: every slot, recorded as none)."""
    return {a} if kind == "reassign" else {a, a + 1} if kind == "swap" else set()


def _take_moves(
    m: SampledSystem,
    t: float,
    which: str,
    lo: int,
    state: _SearchState,
    improving: list[tuple[float, str, int, int]],
    max_moves: int,
    deadline: float,
) -> None:
    """Applies the best move of a neighbourhood (its cost is exact), then the next-best moves on
    slots not touched yet, each verified by an exact evaluation (at most ``BATCH_ATTEMPTS``)."""
    touched: set[int] = set()
    attempts = 0
    for rank, (val, kind, a, b) in enumerate(improving):
        if state.moves >= max_moves or attempts >= BATCH_ATTEMPTS:
            break
        if rank > 0 and time.monotonic() >= deadline:
            break
        span = _span(kind, a)
        if rank > 0 and (kind == "rotate" or span & touched):
            continue
        trial = _apply_move(state.current, kind, a, b)
        if rank > 0:
            if kind == "reassign" and int(np.min(trial.counts)) < lo:
                # Costed against the schedule before this batch's moves: after another move took
                # a slot from the same sensor, this one would starve it below ⌈r_min⌉.
                continue
            attempts += 1
            state.evaluations += 1
            val = _cost(m, t, trial, which)
        if val < state.cost - 1e-13 * abs(state.cost):
            state.current, state.cost = trial, val
            state.moves += 1
            touched |= span
            if kind == "rotate":
                break  # every position moved: re-evaluate the neighbourhood
