"""Integer slot counts (the paper's problem P1): minimise η(k) over integer vectors
``k_i ≥ max(1, ⌈r_min⌉)`` with ``Σ k_i = r_tot`` (with sample costs or limits:
``max(1, ⌈r_min,i⌉) ≤ k_i ≤ ⌊r_max,i⌋``, ``Σ b_i k_i ≤ B``), with a proven lower bound.

Two methods: ``"greedy"`` — greedy marginal allocation and single-slot exchanges (exact for
decoupled networks by discrete convexity, exchange-optimal otherwise; with costs or limits
:mod:`.integer_budget`); ``"branch-and-bound"`` — the continuous optimum rounded and improved by
exchanges screened by η's second-order model (:mod:`.integer_screened`) as the first incumbent,
then branch-and-bound on the convex relaxation (:mod:`.branch_and_bound`,
:mod:`.integer_relaxation`) until the incumbent is proven optimal. Both return the certified
lower bound (the greedy: the root relaxation's).
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import replace
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arrays import as_count, as_real, numerical_errors
from ..errors import InvalidInputError
from ..limits import min_slots
from ..network import accepts_path
from .branch_and_bound import branch_and_bound, root_bound
from .budgeted import is_paper_form
from .integer_budget import (
    ExchangeSearch,
    budgeted_integer_allocation,
    checked_budget,
    count_limits,
)
from .integer_relaxation import CountProblem, Relaxation
from .integer_screened import rounded_start, screened_exchanges
from .optimal import HVP_MIN_SENSORS, optimal_allocation
from .oracle import num_sensors
from .result import IntegerAllocation

__all__ = ["INTEGER_METHODS", "INTEGER_STARTS", "integer_allocation"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: The methods of :func:`integer_allocation`.
INTEGER_METHODS = ("greedy", "branch-and-bound")

#: The first incumbents of the branch-and-bound (``start``).
INTEGER_STARTS = ("rounded", "greedy")

#: Default node limit of the branch-and-bound (``max_nodes``).
DEFAULT_MAX_NODES = 100_000


@accepts_path
@numerical_errors
def integer_allocation(
    net: Any,
    r_tot: int,
    *,
    method: str = "greedy",
    tol: float = 1e-9,
    max_nodes: int | None = None,
    time_limit: float | None = None,
    deadline: float | None = None,
    start: str = "rounded",
) -> IntegerAllocation:
    """Integer slot counts ``r_i ≥ r_min`` with ``Σ r_i = r_tot`` minimising ``η(r)``, with a
    proven lower bound on the least η over all such counts.

    ``r_tot`` is an integer (an integral float such as ``8.0`` is accepted, ``8.5`` refused). A
    non-integer ``r_min`` follows the rule of schedules: each count is at least ``⌈r_min⌉`` (the
    least integer with ``r_i ≥ r_min``), and at least 1 since ``η`` needs positive rates.

    With sample costs or per-sensor limits (``not net.is_paper_form``), ``r_tot`` is the budget
    ``B`` in channel units (any real number ≥ 0) and the counts satisfy
    ``max(1, ⌈r_min,i⌉) ≤ k_i ≤ ⌊r_max,i⌋`` and ``Σ b_i k_i ≤ B`` (a knapsack).

    ``method="greedy"`` (default; the algorithm before branch-and-bound existed): greedy marginal
    allocation (each remaining slot goes to the sensor whose extra slot lowers η most), started
    from the floor of the continuous optimum when σ is large, followed by single-slot exchanges
    ``r − e_i + e_j`` until none improves. For a decoupled network η is a sum of convex functions
    of one count each, and exchange-optimality is global optimality (discrete convexity); for
    coupled networks it is exchange-optimal. Candidate moves are evaluated in parallel with
    ``net.cost_many``. With costs or limits: greedy by decrease per channel unit, then exchanges
    (one sample of ``i`` out, as many of ``j`` in as fit), or the exact knapsack program for a
    decoupled network, see :mod:`capalloc_rs.allocation.integer_budget`. Its ``lower_bound`` is
    the root relaxation's (one continuous solve).

    ``method="branch-and-bound"``: the first incumbent is the root relaxation's optimum rounded
    (largest remainders within the limits and the budget) and improved by exchanges screened by
    η's gradient and exact Hessian (only the moves the second-order model ranks best are costed;
    only exact improvements are taken, :mod:`.integer_screened`); then best-first
    branch-and-bound on the convex relaxation (:mod:`.branch_and_bound`): every node's bound is
    ``η(r̂) − gap(r̂) − e(r̂)`` at its relaxed optimum (Frank–Wolfe gap, certified error of η),
    rounding each relaxed optimum gives further incumbents. It ends with
    ``proven_optimal=True`` (then within ``tolerance`` of the optimum, so never worse than
    ``"greedy"`` by more) unless a limit stops it. Not the default: its work grows quickly with
    N (measured in ``benches/certified_integer.py``: proven optimal in about 5 s at N = 20,
    r_tot = 60; at N = 50 a minute proves a gap of about 3e-4·η: the relaxation's bound rises
    slowly when ~N coordinates are fractional), and callers such as ``best_schedule`` must not
    spend their time budget here; the greedy stays the default.

    Both: ``lower_bound`` is proven (η convex; the evaluation error of η included), ``gap =
    eta − lower_bound ≥ 0``, and ``proven_optimal`` is ``gap ≤ tolerance`` with ``tolerance =
    tol·|η|`` plus twice the largest certified error of η met (for ``"greedy"`` also True when
    the exact knapsack program ran). Ctrl-C raises ``KeyboardInterrupt`` (the search is a
    Python loop; the Rust evaluations check for it).

    Args:
        net: the network.
        r_tot: the total slots (the budget ``B`` with costs or limits).
        method: ``"greedy"`` (default) or ``"branch-and-bound"``.
        start: the branch-and-bound's first incumbent: ``"rounded"`` (default: the rounded
            relaxed optimum and screened exchanges) or ``"greedy"`` (greedy plus exchanges, the
            start before the screened one existed; at N = 50 it costs minutes). Ignored by
            ``method="greedy"``.
        tol: relative tolerance of the proof (``0 < tol < 1``, default 1e-9): nodes whose bound
            is within ``tolerance`` of the incumbent are closed.
        max_nodes: most relaxations the branch-and-bound solves (default 100 000, at least 1).
        time_limit: seconds the call may take (``> 0``; default none).
        deadline: a ``time.monotonic()`` value; the earlier of it and ``time_limit`` cuts the
            search short, and once passed also the greedy (remaining slots are then spread
            evenly, no more exchanges are tried, the exact knapsack program is not started):
            the counts are feasible with a proven ``gap``, ``stopped="time_limit"``
            (``best_schedule`` uses it for its ``time_limit``). The root relaxation is always
            solved (it gives the lower bound).

    Raises:
        InvalidInputError: infeasible capacity or budget, a sensor without an integer count
            between its limits, ``r_tot`` not an integer (paper's case) or too large, a bad
            ``method``, ``start``, ``tol``, ``max_nodes`` or ``time_limit``.
    """
    nodes_cap, stop_at = _check_search_options(method, tol, max_nodes, time_limit, deadline)
    if not isinstance(start, str) or start not in INTEGER_STARTS:
        raise InvalidInputError(f"start must be 'rounded' or 'greedy', got {start!r}")
    if method == "greedy" or start == "greedy":
        first, prob = _greedy_start(net, r_tot, stop_at)
        root, _ = root_bound(prob)
        if method == "greedy":
            return _with_root_bound(first, root, tol)
        search = ExchangeSearch(net, prob.b, prob.budget, prob.k_hi)
        before = first.evaluations
    else:
        if is_paper_form(net):
            prob = _paper_problem(net, _paper_total(net, r_tot))
        else:
            prob = _budget_problem(net, checked_budget(net, r_tot))
        root, _ = root_bound(prob)
        search = ExchangeSearch(net, prob.b, prob.budget, prob.k_hi)
        first = _start(prob, search, root, stop_at)
        before = 0
    out = branch_and_bound(
        prob,
        search,
        np.array(first.counts, dtype=np.int64),
        first.eta,
        root=root,
        rtol=tol,
        max_nodes=nodes_cap,
        deadline=stop_at,
    )
    counts = out.counts
    counts.setflags(write=False)
    return replace(
        first,
        counts=counts,
        eta=out.eta,
        evaluations=before + search.evaluations,
        spent=None if first.budget is None else float(prob.b @ counts),
        proven_optimal=bool(out.eta - out.lower_bound <= out.tolerance),
        lower_bound=out.lower_bound,
        method="branch-and-bound",
        nodes=out.nodes,
        tolerance=out.tolerance,
        stopped=out.stopped,
    )


def _greedy_start(
    net: Any, r_tot: Any, deadline: float | None
) -> tuple[IntegerAllocation, CountProblem]:
    """Greedy plus exchanges (:func:`_greedy`, or :mod:`.integer_budget` with costs or limits)
    and the integer problem it solved."""
    if not is_paper_form(net):
        greedy = budgeted_integer_allocation(net, r_tot, deadline=deadline)
        return greedy, _budget_problem(net, float(r_tot))
    greedy = _greedy(net, r_tot, deadline)
    return greedy, _paper_problem(net, int(greedy.counts.sum()))


def _start(
    prob: CountProblem, search: ExchangeSearch, root: Relaxation | None, deadline: float | None
) -> IntegerAllocation:
    """The branch-and-bound's first incumbent: the root relaxation's optimum rounded, then
    screened exchanges (:mod:`.integer_screened`); without a root relaxation the least counts
    filled greedily, then screened exchanges."""
    if root is not None:
        k, eta, exchanges = rounded_start(prob, search, root.r, deadline)
    else:
        k0 = prob.k_lo.copy()
        k, eta = search.fill(k0, float(search.eta(k0[None, :])[0]), deadline)
        k, eta, exchanges = screened_exchanges(search, k, eta, prob.k_lo, deadline)
    budget = None if prob.equality else prob.budget
    return IntegerAllocation(
        counts=k,
        eta=eta,
        exchanges=exchanges,
        evaluations=search.evaluations,
        budget=budget,
        spent=None if budget is None else float(prob.b @ k),
    )


def _check_search_options(
    method: Any, tol: Any, max_nodes: Any, time_limit: Any, deadline: float | None
) -> tuple[int, float | None]:
    """Validates the keywords; returns the node limit and the deadline (the earlier of
    ``deadline`` and now + ``time_limit``)."""
    if not isinstance(method, str) or method not in INTEGER_METHODS:
        raise InvalidInputError(f"method must be 'greedy' or 'branch-and-bound', got {method!r}")
    rtol = as_real("tol", tol, positive=True)
    if not rtol < 1.0:
        raise InvalidInputError(f"tol must be < 1, got {rtol:g}")
    nodes = DEFAULT_MAX_NODES if max_nodes is None else as_count("max_nodes", max_nodes, minimum=1)
    stop_at = deadline
    if time_limit is not None:
        seconds = as_real("time_limit", time_limit, positive=True)
        limit_at = time.monotonic() + seconds
        stop_at = limit_at if stop_at is None else min(stop_at, limit_at)
    return nodes, stop_at


def _relaxation_mode(cu: Any, n_sens: int) -> str:
    """Newton–CG from :data:`~.optimal.HVP_MIN_SENSORS` sensors on when ``cu.at`` exists."""
    return "hvp" if callable(getattr(cu, "at", None)) and n_sens >= HVP_MIN_SENSORS else "exact"


def _paper_problem(net: Any, total: int) -> CountProblem:
    n = num_sensors(net)
    r_min = max(1, min_slots(float(net.r_min)))
    return CountProblem(
        cu=net,
        b=np.ones(n),
        k_lo=np.full(n, r_min, dtype=np.int64),
        k_hi=np.full(n, total, dtype=np.int64),
        budget=float(total),
        equality=True,
        mode=_relaxation_mode(net, n),
    )


def _budget_problem(net: Any, budget: float) -> CountProblem:
    k_lo, k_hi = count_limits(net)
    cu = net.in_channel_units()
    return CountProblem(
        cu=cu,
        b=np.asarray(net.costs, dtype=np.float64),
        k_lo=k_lo,
        k_hi=k_hi,
        budget=budget,
        equality=False,
        mode=_relaxation_mode(cu, k_lo.size),
    )


def _with_root_bound(
    greedy: IntegerAllocation, root: Relaxation | None, tol: float
) -> IntegerAllocation:
    """The greedy's result with the root relaxation's bound (``-inf`` without one)."""
    err = root.eta_error if root is not None and math.isfinite(root.eta_error) else 0.0
    bound = -math.inf if root is None else min(root.lower_bound, greedy.eta)
    tolerance = tol * abs(greedy.eta) + 2.0 * err
    proven = bool(greedy.proven_optimal) or greedy.eta - bound <= tolerance
    return replace(
        greedy,
        proven_optimal=proven,
        lower_bound=bound,
        method="greedy",
        nodes=0 if root is None else 1,
        tolerance=tolerance,
    )


def _paper_total(net: Any, r_tot: Any) -> int:
    """``r_tot`` as an int, checked against ``N·max(1, ⌈r_min⌉)`` and the count limit.

    Raises:
        InvalidInputError: a negative ``r_min``, ``r_tot`` not an integer, too large or too
            small for every sensor's least count.
    """
    n_sens = num_sensors(net)
    # The one rule for slot counts (as for schedules): a sensor needs ⌈r_min⌉ slots to satisfy
    # r_i ≥ r_min, and at least one here, since η(r) is defined for positive rates only.
    r_min_f = as_real("net.r_min", net.r_min)
    if r_min_f < 0:
        raise InvalidInputError(f"net.r_min must be >= 0, got {r_min_f:g}")
    r_min = max(1, min_slots(r_min_f))
    total = as_count("r_tot", r_tot, maximum=limits.MAX_INTEGER_ALLOCATION_SLOTS)
    if total < n_sens * r_min:
        raise InvalidInputError(
            f"infeasible capacity: r_tot = {total} < N·r_min = {n_sens * r_min}"
        )
    return total


def _greedy(net: Any, r_tot: Any, deadline: float | None) -> IntegerAllocation:
    """Today's greedy plus single-slot exchanges in the paper's case (see
    :func:`integer_allocation`)."""
    n_sens = num_sensors(net)
    total = _paper_total(net, r_tot)
    r_min = max(1, min_slots(float(net.r_min)))
    spare = total - n_sens * r_min
    evaluations = 0

    def costs(rows: npt.NDArray[np.int64]) -> F64:
        nonlocal evaluations
        evaluations += rows.shape[0]
        return np.asarray(net.cost_many(rows.astype(np.float64)), dtype=np.float64)

    counts = np.full(n_sens, r_min, dtype=np.int64)
    if spare > 4 * n_sens:
        cont = optimal_allocation(net, float(total))
        counts = r_min + np.floor(cont.gamma + 1e-9).astype(np.int64)
    eye = np.eye(n_sens, dtype=np.int64)
    while counts.sum() < total:
        if deadline is not None and time.monotonic() >= deadline:
            counts[np.argmin(counts)] += 1  # out of time: fill the rest evenly
            continue
        cand = counts + eye
        counts = cand[int(np.argmin(costs(cand)))]
    best = float(costs(counts[None, :])[0])
    pairs = [(i, j) for i, j in itertools.permutations(range(n_sens), 2)]
    exchanges = 0
    for _ in range(10 * spare + 100):
        if deadline is not None and time.monotonic() >= deadline:
            break
        moves = [(i, j) for i, j in pairs if counts[i] > r_min]
        if not moves:
            break
        cand = np.array([counts - eye[i] + eye[j] for i, j in moves])
        vals = costs(cand)
        k = int(np.argmin(vals))
        if not vals[k] < best - 1e-13 * abs(best):
            break
        counts, best = cand[k], float(vals[k])
        exchanges += 1
    counts.setflags(write=False)
    return IntegerAllocation(counts=counts, eta=best, exchanges=exchanges, evaluations=evaluations)
