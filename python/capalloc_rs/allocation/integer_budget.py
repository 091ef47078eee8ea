"""Integer sample counts under a budget with sample costs and per-sensor limits: minimise η(k)
over integer vectors with ``k_lo,i ≤ k_i ≤ k_hi,i`` and ``Σ b_i k_i ≤ B``, where
``k_lo,i = max(1, ⌈r_min,i⌉)`` and ``k_hi,i = ⌊r_max,i⌋``.

Greedy marginal allocation by value per channel unit, from the floor of the continuous optimum
when the budget is large (the next sample goes to the sensor whose
extra sample lowers η most per channel unit, among those that fit under the budget and their
cap), then exchanges until none improves: for ``i ≠ j``, remove one sample of ``i`` and add as
many samples of ``j`` as the budget and ``j``'s cap allow (η is decreasing in every count, so more
samples of ``j`` never hurt), or add one sample of ``j`` and remove as few samples of ``i`` as pay
for it; after each exchange the leftover budget is refilled greedily. With unit costs this is the
single-slot exchange of :mod:`.integer`. With unequal costs the problem is a knapsack (separable
for decoupled networks), and exchange-optimality is only a local optimum: on random cases with
N ≤ 4 it missed the optimum in 2 of 200 decoupled and 1 of 100 coupled ones. So for a decoupled
network (η separable) the counts come instead from the exact Pareto dynamic program of
:mod:`.knapsack` when it fits its bounds, and the result says ``proven_optimal=True``; otherwise
(coupled networks, or the program too large) it is the exchange-optimal point, with
``proven_optimal=False``: no optimality is claimed.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import limits
from .._arrays import as_real
from ..errors import InvalidInputError
from .knapsack import is_decoupled, separable_knapsack
from .optimal import optimal_allocation
from .oracle import num_sensors
from .result import IntegerAllocation

__all__ = [
    "ExchangeSearch",
    "budgeted_integer_allocation",
    "checked_budget",
    "count_limits",
    "exchange_descent",
]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


def count_limits(net: Any) -> tuple[I64, I64]:
    """``(k_lo, k_hi)``: ``max(1, ⌈r_min,i⌉)`` and ``⌊r_max,i⌋`` (relative tolerance 1e-12, as
    :func:`~capalloc_rs.limits.min_slots`; no cap: :data:`~capalloc_rs.limits.MAX_INTEGER`).

    Raises:
        InvalidInputError: a sensor has no integer count between its minimum and its cap.
    """
    rmin = np.asarray(net.rate_min, dtype=np.float64)
    rmax = np.asarray(net.rate_max, dtype=np.float64)
    k_lo = np.array([max(1, limits.min_slots(float(v))) for v in rmin], dtype=np.int64)
    big = limits.MAX_INTEGER_ALLOCATION_SLOTS
    k_hi = np.array(
        [min(math.floor(v * (1 + 1e-12)), big) if math.isfinite(v) else big for v in rmax],
        dtype=np.int64,
    )
    bad = np.flatnonzero(k_lo > k_hi)
    if bad.size:
        i = int(bad[0])
        raise InvalidInputError(
            f"no integer count for sensor {i}: net.r_min = {rmin[i]:g} and net.r_max = "
            f"{rmax[i]:g} allow no integer k with max(1, ⌈r_min⌉) ≤ k ≤ ⌊r_max⌋"
        )
    return k_lo, k_hi


class ExchangeSearch:
    """The state of the search: counts, their cost and what the budget still allows."""

    def __init__(self, net: Any, costs: F64, budget: float, k_hi: I64) -> None:
        self.net, self.b, self.budget, self.k_hi = net, costs, budget, k_hi
        self.slack_tol = 1e-12 * max(budget, 1.0)
        self.evaluations = 0

    def eta(self, rows: I64) -> F64:
        self.evaluations += rows.shape[0]
        return np.asarray(self.net.cost_many(rows.astype(np.float64)), dtype=np.float64)

    def slack(self, k: I64) -> float:
        return self.budget - float(self.b @ k)

    def fits(self, k: I64) -> npt.NDArray[np.bool_]:
        """Sensors that can take one more sample from ``k``."""
        return (k < self.k_hi) & (self.b <= self.slack(k) + self.slack_tol)

    def fill(self, k: I64, eta_k: float, deadline: float | None) -> tuple[I64, float]:
        """Greedy: adds the sample of best decrease per channel unit until none fits (each round
        adds a sample, so at most ``B / min b`` rounds)."""
        bound = int(self.budget / float(np.min(self.b))) + 1
        eye = np.eye(k.size, dtype=np.int64)
        for _ in range(bound):
            idx = np.flatnonzero(self.fits(k))
            if idx.size == 0:
                break
            if deadline is not None and time.monotonic() >= deadline:
                j = int(idx[np.argmin(k[idx])])  # out of time: the least-served sensor that fits
                k = k + eye[j]
                eta_k = float(self.eta(k[None, :])[0])
                continue
            cand = k + eye[idx]
            vals = self.eta(cand)
            j = int(np.argmax((eta_k - vals) / self.b[idx]))
            k, eta_k = cand[j], float(vals[j])
        return k, eta_k

    def exchanges(self, k: I64, k_lo: I64) -> I64:
        """The exchange candidates from ``k``, for each pair ``i ≠ j``: one sample of ``i`` out
        and as many of ``j`` in as the budget and ``j``'s cap allow; and one sample of ``j`` in
        with as few of ``i`` out as pay for it (both reduce to the single-slot exchange for equal
        costs)."""
        rows = []
        slack = self.slack(k)
        for i in np.flatnonzero(k > k_lo):
            bi = float(self.b[i])
            for j in np.flatnonzero(k < self.k_hi):
                if j == i:
                    continue
                bj = float(self.b[j])
                m_in = min(int((slack + bi + self.slack_tol) // bj), int(self.k_hi[j] - k[j]))
                m_out = max(1, math.ceil((bj - slack - self.slack_tol) / bi))
                for out, inn in {(1, m_in), (m_out, 1)}:
                    if inn >= 1 and k[i] - out >= k_lo[i]:
                        row = k.copy()
                        row[i] -= out
                        row[j] += inn
                        rows.append(row)
        return np.array(rows, dtype=np.int64).reshape(-1, k.size)


def exchange_descent(
    search: ExchangeSearch, k: I64, best: float, k_lo: I64, deadline: float | None
) -> tuple[I64, float, int]:
    """The best exchange of :meth:`ExchangeSearch.exchanges` (then the greedy refill) while it
    lowers η by more than 1e-13 relative, at most ``10·Σ(k − k_lo) + 100`` times or until
    ``deadline``; returns the counts, their η and the exchanges applied."""
    exchanges = 0
    for _ in range(10 * int(np.sum(k - k_lo)) + 100):
        if deadline is not None and time.monotonic() >= deadline:
            break
        cand = search.exchanges(k, k_lo)
        if cand.shape[0] == 0:
            break
        vals = search.eta(cand)
        m = int(np.argmin(vals))
        if not vals[m] < best - 1e-13 * abs(best):
            break
        k, best = search.fill(cand[m], float(vals[m]), deadline)
        exchanges += 1
    return np.asarray(k, dtype=np.int64), best, exchanges


def _warm_counts(net: Any, b: F64, budget: float, k_lo: I64, k_hi: I64) -> I64:
    """The greedy's start: the floor of the continuous optimum (clipped to the count limits) when
    the budget pays for more than ``4N`` samples above the minima and that point fits the budget,
    else the minima (as :mod:`.integer` does for unit costs)."""
    n = k_lo.size
    if budget - float(b @ k_lo) <= 4 * n * float(np.mean(b)):
        return k_lo.copy()
    high = float(net.budget_range[1])
    cont = optimal_allocation(net, min(budget, high))
    k = np.clip(np.floor(cont.r + 1e-9).astype(np.int64), k_lo, k_hi)
    return k if float(b @ k) <= budget else k_lo.copy()


def checked_budget(net: Any, budget: Any) -> float:
    """The budget ``B`` as a float, checked: it pays every sensor's least count and allows at
    most :data:`~capalloc_rs.limits.MAX_INTEGER_ALLOCATION_SLOTS` samples.

    Raises:
        InvalidInputError: a budget below ``Σ b_i k_lo,i``, too large, or not a number.
    """
    b = np.asarray(net.costs, dtype=np.float64)
    k_lo, _ = count_limits(net)
    total = as_real("r_tot", budget, nonnegative=True)
    least = float(b @ k_lo)
    if total < least * (1 - 1e-12):
        raise InvalidInputError(
            f"infeasible budget: r_tot = {total:g} < Σ b_i·max(1, ⌈r_min,i⌉) = {least:g} "
            "(the budget B in channel units must pay every sensor's least integer count)"
        )
    if total / float(np.min(b)) > limits.MAX_INTEGER_ALLOCATION_SLOTS:
        raise InvalidInputError(
            f"r_tot = {total:g} allows more than {limits.MAX_INTEGER_ALLOCATION_SLOTS} samples"
        )
    return total


def budgeted_integer_allocation(
    net: Any, budget: Any, *, deadline: float | None = None
) -> IntegerAllocation:
    """Integer counts for a network with costs or limits (see the module docstring); ``budget``
    is ``B`` in channel units (any real number; the argument is named ``r_tot``). ``deadline``
    (a ``time.monotonic()`` value) as in :func:`~.integer.integer_allocation`: once passed, the
    exact program is not started, the greedy fills the least-served sensors and no more exchanges
    are tried (the counts stay feasible).

    Raises:
        InvalidInputError: a sensor without an integer count in its limits, or a budget below
            ``Σ b_i k_lo,i`` (or so large that the counts exceed
            :data:`~capalloc_rs.limits.MAX_INTEGER_ALLOCATION_SLOTS`).
    """
    n_sens = num_sensors(net)
    b = np.asarray(net.costs, dtype=np.float64)
    k_lo, k_hi = count_limits(net)
    total = checked_budget(net, budget)
    search = ExchangeSearch(net, b, total, k_hi)
    in_time = deadline is None or time.monotonic() < deadline
    if in_time and is_decoupled(net, n_sens):
        exact = separable_knapsack(search.eta, b, total, k_lo, k_hi)
        if exact is not None:
            exact.setflags(write=False)
            return IntegerAllocation(
                counts=exact,
                eta=float(search.eta(exact[None, :])[0]),
                exchanges=0,
                evaluations=search.evaluations,
                budget=total,
                spent=float(b @ exact),
                proven_optimal=True,
            )
    k = _warm_counts(net, b, total, k_lo, k_hi)
    k, best = search.fill(k, float(search.eta(k[None, :])[0]), deadline)
    k, best, exchanges = exchange_descent(search, k, best, k_lo, deadline)
    k.setflags(write=False)
    return IntegerAllocation(
        counts=k,
        eta=best,
        exchanges=exchanges,
        evaluations=search.evaluations,
        budget=total,
        spent=float(b @ k),
        proven_optimal=False,
    )
