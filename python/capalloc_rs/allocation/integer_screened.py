"""A good first incumbent for the integer allocation, cheaply: the continuous optimum rounded to
feasible counts, then exchanges screened by the second-order model of η.

Rounding. The relaxed optimum ``r̂`` of the whole feasible box becomes feasible counts by
:func:`~.integer_relaxation.round_relaxed` (largest remainders within the limits and the budget),
with what the budget still allows filled greedily.

Screened exchanges. At counts ``k`` with ``η(k)``, gradient ``g`` and exact Hessian ``H`` (one
evaluation point), each exchange ``k + d`` (:meth:`~.integer_budget.ExchangeSearch.exchanges`:
one sample of ``i`` out and as many of ``j`` in as fit, or one of ``j`` in and as few of ``i``
out as pay for it) has the predicted change ``gᵀd + ½ dᵀHd`` (Taylor to second order). The moves
are costed exactly in order of prediction, a batch of ``max(N, 10)`` at a time, and the best
exact improvement of a batch is taken (then the budget is refilled greedily); when
:data:`SCREEN_BATCHES` batches in a row hold no improvement, or no predicted move is left, the
search stops. Only exact improvements are accepted, so η decreases strictly and the counts stay
feasible; the screening decides only which moves are costed (a move ranked low by the model is
not tried), so the end point is exchange-optimal among the screened moves, not necessarily among
all ``N(N−1)``. Each round costs one Hessian and at most ``SCREEN_BATCHES·max(N, 10)``
evaluations, where the plain exchange search costs every move (``N(N−1)`` evaluations a round).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import numpy.typing as npt

from .integer_budget import ExchangeSearch
from .integer_relaxation import CountProblem, round_relaxed
from .oracle import value_gradient_hessian

__all__ = ["SCREEN_BATCHES", "rounded_start", "screened_exchanges"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Batches of predicted moves costed without an improvement before the search stops.
SCREEN_BATCHES = 2


def _predicted(net: Any, k: I64, moves: I64) -> F64:
    """``gᵀd + ½dᵀHd`` for each row ``k + d`` of ``moves`` (η's second-order model at ``k``)."""
    _, g, h = value_gradient_hessian(net, k.astype(np.float64))
    d = (moves - k).astype(np.float64)
    return np.asarray(d @ g + 0.5 * np.einsum("mi,ij,mj->m", d, h, d), dtype=np.float64)


def _improving_move(
    search: ExchangeSearch, k: I64, best: float, k_lo: I64, deadline: float | None
) -> tuple[I64, float] | None:
    """The best exact improvement among the first batches of exchanges from ``k`` in order of
    their predicted change, or ``None``."""
    moves = search.exchanges(k, k_lo)
    if moves.shape[0] == 0:
        return None
    order = np.argsort(_predicted(search.net, k, moves), kind="stable")
    batch = max(k.size, 10)
    for start in range(0, min(order.size, SCREEN_BATCHES * batch), batch):
        if deadline is not None and time.monotonic() >= deadline:
            return None
        rows = moves[order[start : start + batch]]
        vals = search.eta(rows)
        m = int(np.argmin(vals))
        if vals[m] < best - 1e-13 * abs(best):
            return rows[m], float(vals[m])
    return None


def screened_exchanges(
    search: ExchangeSearch, k: I64, best: float, k_lo: I64, deadline: float | None
) -> tuple[I64, float, int]:
    """Screened exchanges from ``k`` (η ``best``) while one improves (see the module docstring),
    at most ``10·Σ(k − k_lo) + 100`` times or until ``deadline``; returns the counts, their η and
    the exchanges applied."""
    exchanges = 0
    for _ in range(10 * int(np.sum(k - k_lo)) + 100):
        if deadline is not None and time.monotonic() >= deadline:
            break
        step = _improving_move(search, k, best, k_lo, deadline)
        if step is None:
            break
        k, best = search.fill(step[0], step[1], deadline)
        exchanges += 1
    return np.asarray(k, dtype=np.int64), best, exchanges


def rounded_start(
    prob: CountProblem, search: ExchangeSearch, r_hat: F64, deadline: float | None
) -> tuple[I64, float, int]:
    """The rounded relaxed optimum ``r̂`` (budget filled greedily), improved by screened
    exchanges; returns the counts, their η and the exchanges applied."""
    k = round_relaxed(prob, r_hat)
    k, eta = search.fill(k, float(search.eta(k[None, :])[0]), deadline)
    return screened_exchanges(search, k, eta, prob.k_lo, deadline)
