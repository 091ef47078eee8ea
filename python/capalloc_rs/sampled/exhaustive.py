"""The exhaustive best-improvement local search of :func:`~capalloc_rs.best_schedule`
(``method="exhaustive"``, the reference) and its one step, which also confirms the minima of the
screened search (:mod:`capalloc_rs.sampled.screened`).

The neighbourhood of a schedule is every reassignment of one slot to another sensor (keeping every
sensor at ``⌈r_min⌉`` slots or more), every swap of two adjacent slots and, for the boundary
figure, every rotation; each neighbour's exact cost ``η̄`` is computed in the Rust core
(prefix/suffix star products + one doubling each, in parallel). The best improving move is taken,
then up to ``BATCH_ATTEMPTS`` next-best moves on untouched slots, each verified exactly.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .. import _core
from .._progress import Progress
from ..errors import ConvergenceError
from .channel import ScheduleLimits
from .schedule import Schedule
from .system import SampledSystem

__all__ = ["BATCH_ATTEMPTS", "SearchContext"]


def _neighbourhood(
    m: SampledSystem,
    tau: float,
    s: Schedule,
    which: str,
    lim: ScheduleLimits,
    time_limit: float | None,
) -> _core.Neighbourhood:
    """The exact costs of ``s``'s neighbours: one Rust call on the system built once per search
    (:attr:`SampledSystem.core`, which keeps the discretisation of ``(tau, budget)`` between
    calls); reassignments outside the count limits or the budget cost ``inf``."""
    return m.core.neighbourhood(
        tau, s.as_array(), which, lim.min_count, time_limit=time_limit, **lim.core_kwargs()
    )


def _cost(m: SampledSystem, tau: float, s: Schedule, which: str, lim: ScheduleLimits) -> float:
    """Exact cost, ``inf`` when the steady state does not exist for this schedule."""
    try:
        if lim.core_budget is None:  # the paper's case: the call of before sample costs
            return float(m.core.cost(tau, s.as_array(), which))
        return float(m.core.cost(tau, s.as_array(), which, budget=lim.core_budget))
    except ConvergenceError:
        # The core's Convergence error, and only it, means "no periodic steady state for this
        # schedule": the doubling overflowed or did not settle (a mode the schedule does not
        # detect grows), or its limit is not stabilising. Every other error (invalid input,
        # KeyboardInterrupt on cancellation, a singular update) propagates.
        return math.inf


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


@dataclass
class _SearchState:
    """Where the local search is: the current schedule, its exact cost, the moves applied and
    the schedules costed so far; ``best``: the best cost of earlier searches of the same call
    (the screened search's other starts), for the progress report."""

    current: Schedule
    cost: float
    moves: int
    evaluations: int
    best: float = math.inf


@dataclass(frozen=True)
class SearchContext:
    """What every step of a schedule search works with: the system ``m``, the period ``t``, the
    figure ``which``, the count limits and budget ``lim``, the move budget ``max_moves``, the
    ``deadline`` (``time.monotonic()`` seconds; ``inf``: none) and the progress ``bar``."""

    m: SampledSystem
    t: float
    which: str
    lim: ScheduleLimits
    max_moves: int
    deadline: float
    bar: Progress

    def time_left(self) -> float | None:
        """Seconds to the deadline (at least 0; ``None``: no deadline)."""
        return None if math.isinf(self.deadline) else max(self.deadline - time.monotonic(), 0.0)


def _local_search(ctx: SearchContext, state: _SearchState) -> str:
    """The best-improvement local search of :func:`best_schedule` (``method="exhaustive"``), from
    and into ``state``; returns why it stopped (``"local_minimum"``, ``"max_moves"`` or
    ``"time_limit"``)."""
    while True:
        if state.moves >= ctx.max_moves:
            return "max_moves"
        if time.monotonic() >= ctx.deadline:
            return "time_limit"
        stopped = _exhaustive_step(ctx, state)
        if stopped is not None:
            return stopped


def _exhaustive_step(ctx: SearchContext, state: _SearchState) -> str | None:
    """One step of the exhaustive search: every neighbour costed, the best improving moves taken
    (``None``), or why there is none (``"local_minimum"``, ``"time_limit"``)."""
    # A neighbourhood can take longer than the whole budget (N = 50, r_tot = 60: ~3000
    # doublings): candidates that would start after the deadline are skipped (+∞); the
    # evaluated ones are exact, and their best improving move is still taken.
    nb = _neighbourhood(ctx.m, ctx.t, state.current, ctx.which, ctx.lim, time_limit=ctx.time_left())
    # Only the neighbours actually costed: not the no-op/starving moves (+∞ by rule) nor the
    # candidates skipped after the deadline (+∞ too).
    state.evaluations += int(nb.evaluated)
    state.cost = float(nb.current)
    ctx.bar.update(
        phase="search",
        moves=state.moves,
        eta_bar=state.cost,
        best=min(state.best, state.cost),
        evaluations=state.evaluations,
    )
    improving = _improving_moves(state.cost, nb.reassign, nb.swap, nb.rotate)
    if not improving:
        # Only a fully evaluated neighbourhood proves a local minimum.
        return "local_minimum" if nb.complete else "time_limit"
    _take_moves(ctx, state, improving)
    return None


def _span(kind: str, a: int) -> set[int]:
    """The slots a move changes (a rotation: every slot, recorded as none)."""
    return {a} if kind == "reassign" else {a, a + 1} if kind == "swap" else set()


def _take_moves(
    ctx: SearchContext, state: _SearchState, improving: list[tuple[float, str, int, int]]
) -> None:
    """Applies the best move of a neighbourhood (its cost is exact), then the next-best moves on
    slots not touched yet, each verified by an exact evaluation (at most ``BATCH_ATTEMPTS``)."""
    touched: set[int] = set()
    attempts = 0
    for rank, (val, kind, a, b) in enumerate(improving):
        if state.moves >= ctx.max_moves or attempts >= BATCH_ATTEMPTS:
            break
        if rank > 0 and time.monotonic() >= ctx.deadline:
            break
        span = _span(kind, a)
        if rank > 0 and (kind == "rotate" or span & touched):
            continue
        trial = _apply_move(state.current, kind, a, b)
        if rank > 0:
            if kind == "reassign" and not ctx.lim.fits(trial.counts):
                # Costed against the schedule before this batch's moves: after another move took
                # a slot from the same sensor, this one would starve it below ⌈r_min⌉ (or
                # exceed a cap or the budget).
                continue
            attempts += 1
            state.evaluations += 1
            val = _cost(ctx.m, ctx.t, trial, ctx.which, ctx.lim)
        if val < state.cost - 1e-13 * abs(state.cost):
            state.current, state.cost = trial, val
            state.moves += 1
            touched |= span
            if kind == "rotate":
                break  # every position moved: re-evaluate the neighbourhood
