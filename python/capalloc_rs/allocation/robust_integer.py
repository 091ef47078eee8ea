"""Integer sample counts for the robust objectives: minimise ``Σ_k w_k η_k(k)`` or
``max_k η_k(k)`` over integer counts ``k_lo,i ≤ k_i ≤ k_hi,i`` with ``Σ b_i k_i ≤ B``
(``k_lo,i = max(1, ⌈r_min,i⌉)``, ``k_hi,i = ⌊r_max,i⌋``; with unit costs and an integer budget
the counts sum to it).

The search is :mod:`.integer_budget`'s, on the robust objective instead of one model's η: greedy
marginal allocation by decrease per channel unit from the floor of the continuous robust optimum
(so the greedy adds at most about ``N`` samples), then exchanges until none
improves, each candidate evaluated for every model by ``cost_many`` (in parallel in Rust). Both
objectives are decreasing in every count, as η is. The result is a local optimum: no optimality
is claimed. Its ``lower_bound`` is the continuous robust optimum's proven lower bound (at the
budget, or at the largest feasible one ``Σ b_i r_max,i`` if smaller): every feasible integer
vector is feasible for the continuous problem with ``Σ b_i r_i ≤ B``, whose optimum is at
``Σ b_i r_i = B`` since the objectives decrease in every rate.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arrays import as_real, numerical_errors
from ..errors import InvalidInputError
from .integer_budget import ExchangeSearch, count_limits, exchange_descent
from .model_set import ModelSet
from .robust import Objective, robust_allocation, robust_problem
from .robust_result import RobustIntegerAllocation

__all__ = ["robust_integer_allocation"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


class _RobustCost:
    """The robust objective of integer count vectors, with the ``cost_many`` of a network."""

    def __init__(self, ms: ModelSet, w: F64, objective: str) -> None:
        self.ms, self.w, self.objective = ms, w, objective

    def per_model(self, rows: F64) -> F64:
        return self.ms.costs_many(rows)

    def cost_many(self, rows: F64) -> F64:
        vals = self.per_model(rows)
        out: F64 = self.w @ vals if self.objective == "mean" else np.max(vals, axis=0)
        return out


def _start(cont: Any, b: F64, budget: float, k_lo: I64, k_hi: I64) -> I64:
    """The floor of the continuous optimum (clipped to the limits) when it fits, else the
    minima."""
    k = np.clip(np.floor(np.asarray(cont.r) + 1e-9).astype(np.int64), k_lo, k_hi)
    return k if float(b @ k) <= budget else k_lo.copy()


@numerical_errors
def robust_integer_allocation(
    models: Any,
    budget: float,
    *,
    objective: Objective = "mean",
    weights: Any = None,
    num_models: int | None = None,
    seed: int | None = None,
) -> RobustIntegerAllocation:
    """Integer counts for the mean or worst-case error over K models (see
    :mod:`capalloc_rs.allocation.robust_integer`): greedy plus exchanges, with the continuous
    optimum's proven lower bound; no optimality is claimed.

    Args:
        models, objective, weights, num_models, seed: as in :func:`robust_allocation`.
        budget: ``B`` in channel units (with unit costs: the number of slots ``r_tot``).

    Raises:
        InvalidInputError: as :func:`robust_allocation`; a sensor without an integer count
            between its limits, or a budget below ``Σ b_i k_lo,i``.
    """
    nets, w, goal, _ = robust_problem(models, budget, objective, weights, num_models, seed)
    b = np.asarray(nets[0].costs, dtype=np.float64)
    k_lo, k_hi = count_limits(nets[0])
    total = as_real("budget", budget, nonnegative=True)
    least = float(b @ k_lo)
    if total < least * (1 - 1e-12):
        raise InvalidInputError(
            f"infeasible budget: budget = {total:g} < Σ b_i·max(1, ⌈r_min,i⌉) = {least:g}"
        )
    if total / float(np.min(b)) > limits.MAX_INTEGER_ALLOCATION_SLOTS:
        raise InvalidInputError(
            f"budget = {total:g} allows more than {limits.MAX_INTEGER_ALLOCATION_SLOTS} samples"
        )
    high = float(nets[0].budget_range[1])
    cont = robust_allocation(
        nets, min(total, high), objective=goal, weights=None if goal == "worst" else w
    )
    with ModelSet(nets) as ms:
        cost = _RobustCost(ms, w, goal)
        search = ExchangeSearch(cost, b, total, k_hi)
        k = _start(cont, b, total, k_lo, k_hi)
        k, best = search.fill(k, float(search.eta(k[None, :])[0]), None)
        k, best, done = exchange_descent(search, k, best, k_lo, None)
        per = cost.per_model(k[None, :].astype(np.float64))[:, 0]
    counts = np.asarray(k, dtype=np.int64)
    counts.setflags(write=False)
    return RobustIntegerAllocation(
        counts=counts,
        objective=goal,
        value=best,
        eta_per_model=tuple(float(v) for v in per),
        weights=tuple(float(v) for v in w),
        lower_bound=min(cont.lower_bound, best),
        exchanges=done,
        evaluations=search.evaluations * len(nets),
        budget=total,
        spent=float(b @ counts),
    )
