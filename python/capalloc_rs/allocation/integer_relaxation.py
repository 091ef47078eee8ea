"""The convex relaxation of the integer allocation on a box of integer bounds, with a proven lower
bound, and the rounding of its optimum to feasible counts.

The integer problem (P1 with the constraints of sample costs and limits): minimise η(k) over
integer vectors ``lo ≤ k ≤ hi`` with ``Σ k_i = r_tot`` (the paper's case) or ``Σ b_i k_i ≤ B``
(with costs or limits). A node of the branch-and-bound is a box ``[lo, hi]`` of integer bounds;
its relaxation drops integrality:

    minimise η(r)   over   {lo ≤ r ≤ hi,  Σ b_i r_i = B'},

with ``B' = r_tot`` in the paper's case and ``B' = min(B, Σ b_i hi_i)`` with a budget: η is
non-increasing in every rate, so from any point with ``Σ b r ≤ B`` raising rates up to ``B'``
never increases η, and the relaxation with ``≤`` has the optimum of the one with ``=`` at
``B'``. In channel units ``s = b ∘ r`` it is the box-simplex of :mod:`.box_simplex`, solved by
:func:`~.box_newton.box_newton` from a warm start (the parent's optimum projected onto the box).

Lower bound. η is convex, so at the computed point ``r̂`` with the Frank–Wolfe gap ``g(r̂)``
(:func:`~.box_simplex.box_frank_wolfe_gap`), ``η* ≥ η_exact(r̂) − g(r̂)``; with the Riccati
solver's certified error ``e(r̂) ≥ |η(r̂) − η_exact(r̂)|`` the bound

    L = η(r̂) − g(r̂) − e(r̂)

is at most the relaxation's optimum, hence at most η at every integer point of the box, whatever
the accuracy the solver reached (a stalled solve gives a weaker bound, never a false one). The
gap is computed from the computed gradient; the gradient's own rounding is not bounded here.

Rounding. ``⌊r̂⌋`` (within the global bounds), then one more sample to the sensors of largest
remainder ``r̂_i − ⌊r̂_i⌋`` while they fit (the budget; in the paper's case until ``Σ k = r_tot``):
a feasible point, hence an upper bound.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .box_newton import box_newton
from .box_simplex import box_frank_wolfe_gap, project_box_simplex
from .budgeted import _start as box_start
from .newton import _Points
from .optimal import DECOUPLED_WARM_MIN_ORDER
from .result import BoxProblem

__all__ = ["CountProblem", "Relaxation", "relax", "round_relaxed", "tighten"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Relative Frank–Wolfe gap at which a node's relaxation stops (Newton converges quadratically,
#: so the last step is cheap; the node bound is valid whatever gap is reached).
RELAXATION_TOL = 1e-12

#: Newton steps per node relaxation (a node whose solve does not finish keeps its parent's bound).
RELAXATION_MAX_ITER = 100

#: A node that cannot close stops its relaxation once the Frank–Wolfe gap is below this fraction
#: of ``threshold − η`` (its bound then within that fraction of the relaxation's optimum).
EARLY_STOP = 1e-3

#: The state order from which a relaxation's evaluation points are warm-started from the
#: previous one (its steps are short).
WARM_ORDER: int | None = DECOUPLED_WARM_MIN_ORDER


@dataclass(frozen=True)
class CountProblem:
    """The integer problem: the network in channel units ``cu`` (rates ``s = b ∘ r``; ``net``
    itself in the paper's case), costs ``b``, global count bounds ``k_lo ≤ k ≤ k_hi``, the budget
    ``B`` (``r_tot`` in the paper's case), ``equality`` (``Σ k = r_tot``, the paper's case) and the
    Newton variant ``mode`` of the relaxations."""

    cu: Any
    b: F64
    k_lo: I64
    k_hi: I64
    budget: float
    equality: bool
    mode: str

    @property
    def slack_tol(self) -> float:
        """Rounding tolerance of the budget test ``Σ b k ≤ B``."""
        return 1e-12 * max(self.budget, 1.0)


@dataclass(frozen=True)
class Relaxation:
    """A node's relaxed optimum: rates ``r`` (``s = b ∘ r`` in channel units), ``η(r)``, the
    Frank–Wolfe gap, the certified error of η and the lower bound ``η − gap − error``."""

    r: F64
    s: F64
    eta: float
    gap: float
    eta_error: float
    lower_bound: float


def tighten(prob: CountProblem, lo: I64, hi: I64) -> tuple[I64, I64] | None:
    """The box ``[lo, hi]`` with each upper bound lowered to what the others' lower bounds leave
    (``r_tot − Σ_{j≠i} lo_j``, or ``⌊(B − Σ_{j≠i} b_j lo_j)/b_i⌋``) and, in the paper's case, each
    lower bound raised to ``r_tot − Σ_{j≠i} hi_j``; ``None`` when the box holds no feasible
    point."""
    used = float(prob.b @ lo)
    if used > prob.budget + prob.slack_tol:
        return None
    room = (prob.budget - used + prob.slack_tol) / prob.b
    hi = np.minimum(hi, lo + np.floor(room).astype(np.int64))
    if prob.equality:
        total = int(round(prob.budget))
        if int(hi.sum()) < total:
            return None
        lo = np.maximum(lo, total - (int(hi.sum()) - hi))
    if np.any(lo > hi):
        return None
    return lo, hi


def _box(prob: CountProblem, lo: I64, hi: I64) -> BoxProblem:
    lo_s = prob.b * lo
    cap = prob.b * (hi - lo)
    top = float(np.sum(prob.b * hi))
    target = prob.budget if prob.equality else min(prob.budget, top)
    sigma = min(max(target - float(np.sum(lo_s)), 0.0), float(np.sum(cap)))
    return BoxProblem(net=prob.cu, lo=lo_s, cap=cap, sigma=sigma, costs=prob.b, budget=target)


def _start(box: BoxProblem, start_s: F64 | None) -> F64:
    if start_s is None:
        return box_start(box, None, "auto", "newton", RELAXATION_TOL)
    return project_box_simplex(start_s - box.lo, box.cap, box.sigma)


def _early_stop(threshold: float) -> Any:
    """Newton's early stop for a node against the incumbent's ``threshold = η_inc − tol``: the
    bound ``η − gap`` already closes the node, or the node cannot close (``η < threshold``:
    the relaxation's optimum is below it) and the gap is below 1e-3 of the distance."""

    def stop(_r: F64, f: float, gap: float) -> bool:
        return f - gap >= threshold or (f < threshold and gap <= EARLY_STOP * (threshold - f))

    return stop


def relax(
    prob: CountProblem,
    lo: I64,
    hi: I64,
    start_s: F64 | None = None,
    threshold: float | None = None,
) -> tuple[Relaxation | None, int]:
    """The relaxation of the box ``[lo, hi]`` (already :func:`tighten` ed) from the warm start
    ``start_s`` (channel units; ``None``: the start of :func:`~.optimal.optimal_allocation`), and
    the Newton steps it took; ``None`` when Newton did not finish in
    :data:`RELAXATION_MAX_ITER` steps (:class:`~capalloc_rs.errors.ConvergenceError`). With
    ``threshold`` (the incumbent's η less the tolerance) Newton stops as soon as its iterate
    decides the node (:func:`_early_stop`): the bound is valid at every iterate."""
    box = _box(prob, lo, hi)
    n = lo.size
    free = box.sigma > 0.0 and box.sigma < float(np.sum(box.cap)) and n > 1
    if free:
        g0 = _start(box, start_s)
        try:
            gamma, steps, pts = box_newton(
                prob.cu, box.lo, box.cap, box.sigma, RELAXATION_TOL, RELAXATION_MAX_ITER, g0,
                prob.mode, WARM_ORDER,
                stop=None if threshold is None else _early_stop(threshold),
            )  # fmt: skip
        except ConvergenceError:
            return None, RELAXATION_MAX_ITER
    else:
        gamma = np.zeros(n) if box.sigma == 0.0 else np.minimum(box.cap, box.sigma)
        steps, pts = 0, _Points(prob.cu)
    s = box.lo + gamma
    eta, g = pts.value_gradient(s)
    gap = box_frank_wolfe_gap(gamma, np.asarray(g, dtype=np.float64), box.cap, box.sigma)
    err = pts.value_error(s)
    bound = float(eta) - max(gap, 0.0) - err
    return Relaxation(s / prob.b, s, float(eta), gap, err, bound), steps


def round_relaxed(prob: CountProblem, r: F64) -> I64:
    """Feasible counts near the relaxed rates ``r``: ``⌊r⌋`` within the global bounds (in the
    paper's case samples of the smallest remainders removed while ``Σ k > r_tot``, which rounding
    of ``r`` can cause), then, in order of largest remainder ``r_i − k_i``, one more sample for
    each sensor that still fits (the budget; in the paper's case until ``Σ k = r_tot``). The
    caller fills what is left greedily."""
    k = np.clip(np.floor(r + 1e-9).astype(np.int64), prob.k_lo, prob.k_hi)
    if prob.equality:
        total = int(round(prob.budget))
        for i in np.argsort(r - k, kind="stable"):
            if int(k.sum()) <= total:
                break
            k[i] -= min(int(k.sum()) - total, int(k[i] - prob.k_lo[i]))
    if float(prob.b @ k) > prob.budget + prob.slack_tol:
        return prob.k_lo.copy()
    for i in np.argsort(-(r - k), kind="stable"):
        slack = prob.budget - float(prob.b @ k)
        if k[i] < prob.k_hi[i] and prob.b[i] <= slack + prob.slack_tol:
            k[i] += 1
    return k
