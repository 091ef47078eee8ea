"""The starting candidates of :func:`~capalloc_rs.sampled.best_schedule`: the counts of the
interleaved schedule (the optimal real allocation rounded, the optimal integer one, or given),
round robin and the greedy heuristic (:mod:`capalloc_rs.sampled.baselines`), each with its exact
finite-τ cost ``η̄(τ, R)``, built only while a time limit leaves time for them.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._arrays import as_count
from ..errors import InvalidInputError, ScheduleError
from .baselines import (
    budget_counts,
    greedy_run,
    initial_counts,
    round_robin_schedule,
    rounded_counts,
)
from .best_result import Candidate
from .channel import ScheduleLimits
from .exhaustive import _cost
from .schedule import Schedule
from .screened import PORTFOLIO_MAX_NEIGHBOURS, neighbours
from .system import SampledSystem, Which

__all__ = [
    "GREEDY_COSTINGS",
    "LARGE_NEIGHBOURS",
    "SCREENED_GREEDY_ROUNDS",
    "greedy_rounds",
    "initial_counts_of",
    "is_large",
    "start_candidates",
]

#: Greedy passes of the starting candidate ``"greedy"`` under ``method="screened"`` (each pass
#: costs a steady state; ``method="exhaustive"`` runs :func:`greedy_schedule`'s default 50).
SCREENED_GREEDY_ROUNDS = 2

#: Above this many neighbours (``screened.neighbours``; N = 100, r_tot = 300: 30 599) the
#: screened search's greedy candidate makes one pass only: at that size a pass and its steady
#: state cost ~3.7 s, and the interleaved rounded optimum is the cheapest start on every
#: benchmarked network (N = 20, 50, 100: 1–2.5 % below the greedy one).
LARGE_NEIGHBOURS = 10_000

#: Under a time limit, a starting candidate after the first is built only if the time left
#: exceeds this many times what the first one's costing took (round robin: one costing; greedy:
#: round robin's steady state, a pass and its steady state, about ``GREEDY_COSTINGS``).
GREEDY_COSTINGS = 5


def initial_counts_of(
    net: Any,
    m: SampledSystem,
    r: int | float,
    counts: Sequence[int] | None,
    which: str,
    lim: ScheduleLimits,
    method: str,
    start_deadline: float,
) -> tuple[list[int], bool]:
    """The initial counts of :func:`best_schedule` and whether the problem is tiny (at most
    ``PORTFOLIO_MAX_NEIGHBOURS`` neighbours)."""
    if not lim.plain:
        if counts is None:
            c0, _rule = budget_counts(net, m, lim, deadline=start_deadline)
        else:
            c0 = _given_counts(m, counts)
            if not lim.fits(c0):
                raise ScheduleError(
                    f"counts {c0} are outside the sensors' count limits or above the budget "
                    f"{lim.budget:g} channel units (they use {lim.used(c0):g})"
                )
        return c0, neighbours(m, max(sum(c0), 1), which) <= PORTFOLIO_MAX_NEIGHBOURS
    r = int(r)
    tiny = neighbours(m, r, which) <= PORTFOLIO_MAX_NEIGHBOURS
    if counts is None and method == "screened" and not tiny:
        c0, _rule = rounded_counts(net, r, deadline=start_deadline)
    elif counts is None:
        c0, _rule = initial_counts(net, r, deadline=start_deadline)
    else:
        c0 = _given_counts(m, counts)
        if sum(c0) != r:
            raise ScheduleError(
                f"counts must have one entry per sensor ({m.n_sensors}) summing to r_tot = {r}, "
                f"got {c0}"
            )
    return c0, tiny


def _given_counts(m: SampledSystem, counts: Any) -> list[int]:
    if isinstance(counts, str | bytes) or not isinstance(counts, Sequence | np.ndarray):
        raise InvalidInputError(f"counts must be a sequence of integers, got {counts!r}")
    c0 = [as_count(f"counts[{k}]", v) for k, v in enumerate(counts)]
    if len(c0) != m.n_sensors:
        raise ScheduleError(f"counts must have one entry per sensor ({m.n_sensors}), got {c0}")
    return c0


def is_large(m: SampledSystem, r: int | float, which: str, method: str) -> bool:
    """Whether the screened search's problem has more than ``LARGE_NEIGHBOURS`` neighbours."""
    return method == "screened" and neighbours(m, max(int(r), 1), which) > LARGE_NEIGHBOURS


def greedy_rounds(large: bool, method: str, tiny: bool) -> int:
    """The greedy candidate's passes (see ``SCREENED_GREEDY_ROUNDS``, ``LARGE_NEIGHBOURS``)."""
    if method != "screened" or tiny:
        return 50
    return 1 if large else SCREENED_GREEDY_ROUNDS


def start_candidates(
    m: SampledSystem,
    t: float,
    r: int | float,
    which: Which,
    lim: ScheduleLimits,
    initial: Schedule,
    rounds: int,
    reuse: bool,
    deadline: float,
    start_deadline: float,
) -> dict[str, Candidate]:
    """The starting candidates with their exact costs: the interleaved ``initial`` always; round
    robin and greedy (``rounds`` passes, stopped at ``start_deadline``) only while the
    ``deadline`` leaves time for them, judged by the first costing's time (one costing for
    round robin, ``GREEDY_COSTINGS`` for greedy). On large problems (``reuse``) the greedy
    heuristic's steady states give round robin's cost and its own
    (:func:`~capalloc_rs.sampled.baselines.greedy_run`: the same steady states, the trace summed
    by numpy, equal to the last bits); otherwise each is costed by the core."""
    began = time.monotonic()
    cands = {"initial": Candidate("initial", initial, _cost(m, t, initial, which, lim))}
    took = time.monotonic() - began
    rr = round_robin_schedule(m, r)
    if time.monotonic() + GREEDY_COSTINGS * took < deadline:
        gr, gr_cost, rr_cost = greedy_run(m, t, r, which, rounds, start_deadline)
        if not reuse:
            rr_cost, gr_cost = _cost(m, t, rr, which, lim), _cost(m, t, gr, which, lim)
        cands["round_robin"] = Candidate("round_robin", rr, rr_cost)
        cands["greedy"] = Candidate("greedy", gr, gr_cost)
    elif time.monotonic() + took < deadline:
        cands["round_robin"] = Candidate("round_robin", rr, _cost(m, t, rr, which, lim))
    return cands
