"""Newton's method on the mean error and sequential quadratic programming on the worst-case error
of K models, on the weighted box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` in channel units
(:mod:`.box_simplex`).

Mean. ``F(γ) = Σ_k w_k η_k(lo + γ)`` is convex (a non-negative sum of convex functions), with the
exact gradient ``Σ w_k ∇η_k`` and Hessian ``Σ w_k ∇²η_k`` from the per-model evaluations. Each
step minimises the quadratic model over the box-simplex exactly (:func:`~.box_simplex.box_qp`),
then an Armijo search on F, as :mod:`.box_newton` for one model. It stops on the Frank–Wolfe gap
of F, a proven bound on ``F(γ) − F*``.

Worst case. ``Φ(γ) = max_k η_k(lo + γ)`` is convex but not smooth. Each step solves the epigraph
QP of :mod:`.minimax_qp` with the Hessian of the Lagrangian ``H = Σ λ_k ∇²η_k`` at the previous
multipliers λ (Han's SQP for minimax problems): ``d`` and the new λ. Its predicted decrease
``δ = t − Φ ≤ −½ dᵀHd`` bounds the directional derivative of Φ along d, and the Armijo search
asks ``Φ(γ + αd) ≤ Φ + 10⁻⁴ α δ``. Certificate: for every λ in the simplex,

    min_γ max_k η_k ≥ min_γ Σ λ_k η_k ≥ Σ λ_k η_k(γ̂) − FW_λ(γ̂)

(weak duality, then convexity of the λ-mixture with ``FW_λ`` its Frank–Wolfe gap at any γ̂): the
best such bound over the QP multipliers at every iterate is the lower bound, and the loop stops
when ``Φ(γ) − bound ≤ tol·|Φ|``. Both loops are bounded by ``max_iter`` steps, each line search
by 60 halvings.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .box_newton import _armijo_box
from .box_simplex import box_frank_wolfe_gap, box_qp, fix_sum_box
from .minimax_qp import minimax_qp
from .model_set import ModelSet
from .newton import NOISE_DECREASE, _slope
from .simplex import _Stall, regularised_hessian

__all__ = ["SolverState", "lower_bound", "mean_newton", "worst_sqp"]

F64 = npt.NDArray[np.float64]


@dataclass
class SolverState:
    """Where a robust solver stopped: the point, the steps, the per-model values and gradients
    there, the weights of the certificate and the best lower bound found."""

    gamma: F64
    iterations: int
    values: F64
    gradients: F64
    weights: F64
    bound: float


def lower_bound(lam: F64, f: F64, grads: F64, gamma: F64, cap: F64, sigma: float) -> float:
    """``Σ λ_k f_k − FW(Σ λ_k g_k)``: a lower bound on ``min Σ λ_k η_k`` over the box-simplex
    (convexity), hence on the worst-case optimum when λ is in the simplex."""
    return float(lam @ f) - box_frank_wolfe_gap(gamma, lam @ grads, cap, sigma)


def mean_newton(
    ms: ModelSet,
    w: F64,
    lo: F64,
    cap: F64,
    sigma: float,
    tol: float,
    max_iter: int,
    g0: F64,
) -> SolverState:
    """Newton's method on ``Σ w_k η_k`` from ``g0`` until its Frank–Wolfe gap ≤ ``tol·|F|``.

    Raises:
        ConvergenceError: more than ``max_iter`` steps.
    """
    gamma = g0.copy()
    stall = _Stall(3)

    def mean(s: F64) -> float:
        return float(w @ ms.values(s))

    for it in range(max_iter):
        f, grads, hess = ms.values_gradients_hessians(gamma + lo)
        big, g = float(w @ f), w @ grads
        gap = box_frank_wolfe_gap(gamma, g, cap, sigma)
        state = SolverState(gamma, it, f, grads, w, big - gap)
        if gap <= tol * max(abs(big), 1e-300):
            return state
        h = regularised_hessian(np.einsum("k,kij->ij", w, hess))
        x = box_qp(h, g - h @ gamma, gamma, cap, sigma, max_iter=20 * g.size + 100)
        d = x - gamma
        slope = _slope(g, d)
        if slope >= 0.0 or stall.stalled(gap):
            return state
        gamma_new, _, ok = _armijo_box(mean, lo, cap, sigma, gamma, d, big, slope, newton_step=True)
        if not ok:
            return state
        gamma = gamma_new
    raise ConvergenceError(f"robust mean: Newton did not converge in {max_iter} iterations")


def _line_search(
    worst: Callable[[F64], float],
    gamma: F64,
    d: F64,
    big: float,
    delta: float,
    cap: F64,
    sigma: float,
) -> F64 | None:
    """Armijo on Φ along ``γ + αd`` (α = 1, ½, …, at most 60 halvings); a predicted change at
    the rounding level of Φ takes the full step. ``None`` when no step is accepted, or when the
    QP predicts an increase beyond rounding (it was not solved)."""
    noise = NOISE_DECREASE * max(abs(big), 1e-300)
    if delta > noise:
        return None
    if -delta <= noise:
        return fix_sum_box(gamma + d, cap, sigma)
    alpha = 1.0
    for _ in range(60):
        trial = fix_sum_box(gamma + alpha * d, cap, sigma)
        if np.array_equal(trial, gamma):
            return None
        if worst(trial) <= big + 1e-4 * alpha * delta:
            return trial
        alpha *= 0.5
    return None


def worst_sqp(
    ms: ModelSet,
    lo: F64,
    cap: F64,
    sigma: float,
    tol: float,
    max_iter: int,
    g0: F64,
    lam0: F64,
) -> SolverState:
    """SQP on ``max_k η_k`` from ``g0`` with initial multipliers ``lam0`` until the certified
    gap ``Φ − bound ≤ tol·|Φ|`` (see the module docstring).

    Raises:
        ConvergenceError: more than ``max_iter`` steps.
    """
    gamma, lam = g0.copy(), lam0.copy()
    best, best_lam = -math.inf, lam0.copy()
    stall = _Stall(3)

    def worst(gam: F64) -> float:
        return float(np.max(ms.values(gam + lo)))

    for it in range(max_iter):
        f, grads, hess = ms.values_gradients_hessians(gamma + lo)
        big = float(np.max(f))
        h = regularised_hessian(np.einsum("k,kij->ij", lam, hess))
        d, t, lam_new = minimax_qp(f, grads, h, gamma, cap, sigma)
        for cand in (lam_new, lam):
            bound = lower_bound(cand, f, grads, gamma, cap, sigma)
            if bound > best:
                best, best_lam = bound, cand.copy()
        state = SolverState(gamma, it, f, grads, best_lam, best)
        gap = big - best
        if gap <= tol * max(abs(big), 1e-300) or stall.stalled(gap):
            return state
        lam = lam_new
        # A predicted change at the rounding level of Φ takes the full step, as Newton's does.
        gamma_new = _line_search(worst, gamma, d, big, t - big, cap, sigma)
        if gamma_new is None:
            return state
        gamma = gamma_new
    raise ConvergenceError(f"robust worst case: SQP did not converge in {max_iter} iterations")
