"""Integer slot counts: minimise η(r) over integer vectors ``r_i ≥ ⌈r_min⌉`` with ``Σr_i = r_tot``
by greedy marginal allocation and single-slot exchanges (exact for decoupled networks by discrete
convexity, exchange-optimal otherwise).
"""

from __future__ import annotations

import itertools
import time
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arrays import as_count, as_real, numerical_errors
from ..errors import InvalidInputError
from ..limits import min_slots
from ..network import accepts_path
from .budgeted import is_paper_form
from .integer_budget import budgeted_integer_allocation
from .optimal import optimal_allocation
from .oracle import num_sensors
from .result import IntegerAllocation

__all__ = ["integer_allocation"]

F64 = npt.NDArray[np.float64]


@accepts_path
@numerical_errors
def integer_allocation(net: Any, r_tot: int, *, deadline: float | None = None) -> IntegerAllocation:
    """Integer slot counts ``r_i ≥ r_min`` with ``Σ r_i = r_tot`` minimising ``η(r)``.

    ``r_tot`` is an integer (an integral float such as ``8.0`` is accepted, ``8.5`` refused). A
    non-integer ``r_min`` follows the rule of schedules: each count is at least ``⌈r_min⌉`` (the
    least integer with ``r_i ≥ r_min``), and at least 1 since ``η`` needs positive rates.

    Greedy marginal allocation (each remaining slot goes to the sensor whose extra slot lowers η
    most), started from the floor of the continuous optimum when σ is large, followed by
    single-slot exchanges ``r − e_i + e_j`` until none improves. For a decoupled network η is a
    sum of convex functions of one count each, and exchange-optimality is global optimality
    (discrete convexity), so the result is exact; for coupled networks it is exchange-optimal.
    Candidate moves are evaluated in parallel with ``net.cost_many``.

    ``deadline`` (a ``time.monotonic()`` value) cuts both phases short once passed (remaining slots
    are then spread evenly, and no more exchanges are tried): the counts are feasible but maybe
    not exchange-optimal (``best_schedule`` uses it for its ``time_limit``).

    With sample costs or per-sensor limits (``not net.is_paper_form``), ``r_tot`` is the budget
    ``B`` in channel units (any real number ≥ 0) and the counts satisfy
    ``max(1, ⌈r_min,i⌉) ≤ k_i ≤ ⌊r_max,i⌋`` and ``Σ b_i k_i ≤ B``: greedy by decrease per
    channel unit, then exchanges (one sample of ``i`` out, as many of ``j`` in as fit), see
    :mod:`capalloc_rs.allocation.integer_budget`. That is a knapsack; the result is
    exchange-optimal, not claimed optimal.

    Raises:
        InvalidInputError: infeasible capacity or budget, a sensor without an integer count
            between its limits, ``r_tot`` not an integer (paper's case) or too large.
    """
    if not is_paper_form(net):
        return budgeted_integer_allocation(net, r_tot, deadline=deadline)
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
