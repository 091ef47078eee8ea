"""Branch-and-bound for the integer allocation (P1): the least η(k) over integer counts in a box
with ``Σ k = r_tot`` or ``Σ b k ≤ B``, with a proven lower bound.

A node is a box ``[lo, hi]`` of integer bounds. Its bound is the relaxation's certified lower
bound ``η(r̂) − gap(r̂) − e(r̂)`` (:mod:`.integer_relaxation`: η convex, so the Frank–Wolfe gap
bounds ``η(r̂) − η*`` of the box; ``e`` the certified error of η), valid for every integer point
of the box. Upper bounds: the incumbent (the rounded root optimum improved by screened exchanges,
:mod:`.integer_screened`), improved by rounding each node's relaxed optimum (largest remainder
within the budget, the rest filled greedily) and, when that beats the incumbent, by screened
exchanges from it. Branching on a
coordinate ``i`` of ``r̂`` not fixed, chosen by pseudo-costs (:mod:`.branching`: the observed
rises of the bound per squared distance predict which split raises both children most), splits
the box into ``k_i ≤ t`` and ``k_i ≥ t + 1`` (``t = ⌊r̂_i⌋`` within ``[lo_i, hi_i − 1]``), a
partition of its integer points;
each child's bounds are tightened (:func:`~.integer_relaxation.tighten`) and its relaxation starts
from the parent's optimum. Nodes are taken best first (least parent bound) and closed when their
bound is at least ``incumbent − tol``, with ``tol = rtol·|η| + 2e_max`` (``e_max`` the largest
certified error of η met so far, so that a box of one point closes).

Whatever stops the search, the integer optimum is at least the least bound of the boxes of the
partition not yet searched or closed without their optimum (each is a valid bound for its box),
and at most the incumbent: that least bound (capped at the incumbent's η) is the returned lower
bound, and the counts are proven optimal to ``tol`` when the difference is at most ``tol``. Every
box has finitely many integer points and each branching removes the parent, so the search ends;
``max_nodes`` and the deadline bound it further.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .branching import PseudoCosts
from .integer_budget import ExchangeSearch
from .integer_relaxation import CountProblem, Relaxation, relax, round_relaxed, tighten
from .integer_screened import screened_exchanges

__all__ = ["SearchOutcome", "branch_and_bound", "root_bound"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@dataclass(frozen=True)
class SearchOutcome:
    """The search's result: the best counts, their η, the proven lower bound on the integer
    optimum, the tolerance of the proof, relaxations solved (``nodes``), Newton steps, and what
    stopped it (``None``: finished; ``"max_nodes"`` or ``"time_limit"``)."""

    counts: I64
    eta: float
    lower_bound: float
    tolerance: float
    nodes: int
    newton_steps: int
    stopped: str | None


def root_bound(prob: CountProblem) -> tuple[Relaxation | None, int]:
    """The relaxation of the whole feasible box (``None`` when Newton did not finish) and its
    Newton steps."""
    box = tighten(prob, prob.k_lo, prob.k_hi)
    if box is None:  # callers check feasibility first
        return None, 0
    return relax(prob, *box)


#: How a node was made: the coordinate split, whether it is the up child, and the distance of
#: the parent's relaxed optimum from the child's box in that coordinate.
Branch = tuple[int, bool, float]


class _Search:
    """The mutable state of one branch-and-bound run."""

    def __init__(
        self, prob: CountProblem, search: ExchangeSearch, counts: I64, eta: float, rtol: float
    ) -> None:
        self.prob, self.search, self.rtol = prob, search, rtol
        self.counts, self.eta = counts, eta
        self.err_max = 0.0
        self.closed = math.inf  # least bound of the boxes closed without their optimum known
        self.heap: list[tuple[float, int, I64, I64, F64 | None, Branch | None]] = []
        self.costs = PseudoCosts(prob.k_lo.size)
        self.tie = itertools.count()
        self.nodes = 0
        self.steps = 0
        self.offered: set[bytes] = {np.asarray(counts, dtype=np.int64).tobytes()}

    @property
    def tol(self) -> float:
        return self.rtol * abs(self.eta) + 2.0 * self.err_max

    def push(
        self, bound: float, lo: I64, hi: I64, start: F64 | None, branch: Branch | None
    ) -> None:
        box = tighten(self.prob, lo, hi)
        if box is not None:
            heapq.heappush(self.heap, (bound, next(self.tie), box[0], box[1], start, branch))

    def offer(self, k: I64, deadline: float | None) -> None:
        """Makes the counts ``k`` (after filling the budget greedily, and exchanges when they
        beat the incumbent) the incumbent if they are better; counts offered before are skipped
        (nodes near each other often round to the same point)."""
        key = k.tobytes()
        if key in self.offered:
            return
        self.offered.add(key)
        eta_k = float(self.search.eta(k[None, :])[0])
        k, eta_k = self.search.fill(k, eta_k, deadline)
        if eta_k < self.eta:
            k, eta_k, _ = screened_exchanges(self.search, k, eta_k, self.prob.k_lo, deadline)
        if eta_k < self.eta:
            self.counts, self.eta = np.asarray(k, dtype=np.int64), eta_k

    def expand(
        self,
        key: float,
        lo: I64,
        hi: I64,
        start: F64 | None,
        branch: Branch | None,
        deadline: float | None,
    ) -> None:
        """Solves the node's relaxation (from ``start``), records the bound's rise for the
        pseudo-costs of the split that made the node, then settles the node."""
        rel, steps = relax(self.prob, lo, hi, start, self.eta - self.tol)
        self.nodes += 1
        self.steps += steps
        if branch is not None and rel is not None and math.isfinite(key):
            self.costs.record(*branch, rel.lower_bound - key)
        self.settle(key, rel, lo, hi, start, deadline)

    def settle(
        self,
        key: float,
        rel: Relaxation | None,
        lo: I64,
        hi: I64,
        start: F64 | None,
        deadline: float | None,
    ) -> None:
        """Offers the rounding of the node's relaxed optimum, then closes or branches the node
        (``rel`` ``None``: no certificate, the parent's bound ``key`` still holds)."""
        bound, r, s = key, (lo + hi) / 2.0, start
        if rel is not None:
            if math.isfinite(rel.eta_error):
                self.err_max = max(self.err_max, rel.eta_error)
            bound, r, s = max(key, rel.lower_bound), rel.r, rel.s
            if bound < self.eta - self.tol:
                self.offer(round_relaxed(self.prob, r), deadline)
        i = self.costs.choose(r, lo, hi)
        if bound >= self.eta - self.tol or i is None:
            self.closed = min(self.closed, bound)
            return
        t = int(min(max(math.floor(r[i]), lo[i]), hi[i] - 1))
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[i], right_lo[i] = t, t + 1
        self.push(bound, lo, left_hi, s, (i, False, float(r[i]) - t))
        self.push(bound, right_lo, hi, s, (i, True, t + 1 - float(r[i])))

    def lower_bound(self) -> float:
        """The least bound of the boxes not closed with their optimum, capped at the incumbent."""
        return min([self.closed, self.eta] + [h[0] for h in self.heap])


def branch_and_bound(
    prob: CountProblem,
    search: ExchangeSearch,
    counts: I64,
    eta: float,
    *,
    root: Relaxation | None,
    rtol: float,
    max_nodes: int,
    deadline: float | None,
) -> SearchOutcome:
    """Best-first branch-and-bound from the incumbent ``counts`` (η ``eta``) and the root's
    relaxation ``root`` (already solved, it counts as the first node; ``None``: solved here);
    see the module docstring."""
    run = _Search(prob, search, counts, eta, rtol)
    box = tighten(prob, prob.k_lo, prob.k_hi)
    assert box is not None
    if root is None:
        run.push(-math.inf, box[0], box[1], None, None)
    else:
        run.nodes = 1
        run.settle(-math.inf, root, box[0], box[1], None, deadline)
    stopped = None
    for _ in range(max_nodes + 1):
        if not run.heap or run.heap[0][0] >= run.eta - run.tol:
            break  # best first: every open box closes
        if run.nodes >= max_nodes:
            stopped = "max_nodes"
            break
        if deadline is not None and time.monotonic() >= deadline:
            stopped = "time_limit"
            break
        key, _, lo, hi, start, branch = heapq.heappop(run.heap)
        run.expand(key, lo, hi, start, branch, deadline)
    counts = np.asarray(run.counts, dtype=np.int64)
    return SearchOutcome(counts, run.eta, run.lower_bound(), run.tol, run.nodes, run.steps, stopped)
