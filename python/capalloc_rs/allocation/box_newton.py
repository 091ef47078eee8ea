"""Newton's method and projected gradient on the box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` of the
allocation with sample costs, minima and caps (:mod:`.box_simplex`), in channel units: the cost is
``η(lo + γ)`` of the network in channel units (``Network.in_channel_units()``).

* exact Hessian: sequential quadratic programming, each step minimising the quadratic model
  ``gᵀd + ½dᵀ∇²η d`` over the box-simplex exactly (:func:`~.box_simplex.box_qp`, a primal
  active-set method with both bounds, finite), then an Armijo search on η;
* Newton–CG: with the multiplier estimate μ (the mean gradient over the coordinates strictly
  inside their box, else the Frank–Wolfe threshold), the free set is
  ``{0 < γ_i < c_i} ∪ {γ_i = 0, g_i < μ} ∪ {γ_i = c_i, g_i > μ}`` (the bounds whose multiplier
  has the wrong sign are released); the face-restricted Newton system is solved by projected
  preconditioned CG (:mod:`.face_cg`, as for the simplex), and a CG step that would cross either
  bound stops there and fixes that coordinate at the bound it reached (CG restarts on the smaller
  face); at most ``|F|`` products per step;
* projected gradient: Barzilai–Borwein steps with Armijo backtracking along the projection arc,
  the projection onto the box-simplex of :func:`~.box_simplex.project_box_simplex`.

Every method stops on the box-simplex Frank–Wolfe gap ``≤ tol·|η|``
(:func:`~.box_simplex.box_frank_wolfe_gap`), or when it can make no further progress in floating
point (the caller checks the gap then).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .box_simplex import (
    box_frank_wolfe,
    box_frank_wolfe_gap,
    box_qp,
    fix_sum_box,
    project_box_simplex,
)
from .face_cg import face_cg
from .newton import NOISE_DECREASE, _forcing, _Points, _Preconditioner, _slope
from .oracle import CostOracle, value_gradient
from .simplex import _Stall, regularised_hessian

__all__ = ["box_newton", "box_projected_gradient"]

F64 = npt.NDArray[np.float64]


def _armijo_box(
    cost: Any,
    lo: F64,
    cap: F64,
    sigma: float,
    gamma: F64,
    d: F64,
    f0: float,
    slope: float,
    *,
    newton_step: bool,
    first: Any = None,
) -> tuple[F64, float, bool]:
    """Backtracking on η along ``γ + t d`` (t = 1, ½, …, at most 60 halvings), each trial put
    exactly on the box-simplex (:func:`fix_sum_box`). As :func:`.newton._armijo`: a Newton step
    whose predicted decrease is at the rounding level of η is taken in full; ``first`` evaluates
    the first trial (``cost`` the others)."""
    cost_first = cost if first is None else first
    if newton_step and -slope <= NOISE_DECREASE * max(abs(f0), 1e-300):
        trial = fix_sum_box(gamma + d, cap, sigma)
        return trial, float(cost_first(trial + lo)), True
    t = 1.0
    start = fix_sum_box(gamma.copy(), cap, sigma)
    for k in range(60):
        trial = fix_sum_box(gamma + t * d, cap, sigma)
        if np.array_equal(trial, start):
            break
        f = float((cost_first if k == 0 else cost)(trial + lo))
        if f <= f0 + 1e-4 * t * slope:
            return trial, f, True
        t *= 0.5
    return gamma, f0, False


def _multiplier(gamma: F64, g: F64, cap: F64, sigma: float) -> float:
    """The estimate of μ for the free set: mean ``g`` over the coordinates strictly inside their
    box, else the Frank–Wolfe threshold (the ``g`` of the coordinate filled last)."""
    inside = (gamma > 0.0) & (gamma < cap)
    if np.any(inside):
        return float(np.mean(g[inside]))
    _, last = box_frank_wolfe(g, cap, sigma)
    return float(g[last]) if last >= 0 else float(np.min(g))


def _exact_step(pts: _Points, r: F64, g: F64, gamma: F64, cap: F64, sigma: float) -> F64:
    """The exact-Hessian SQP step: the box-simplex QP of the quadratic model."""
    n = g.size
    h = regularised_hessian(pts.hessian(r))
    x = box_qp(h, g - h @ gamma, gamma, cap, sigma, max_iter=20 * n + 100)
    return x - gamma


def _cg_step(
    pts: _Points,
    precondition: _Preconditioner,
    r: F64,
    g: F64,
    gamma: F64,
    cap: F64,
    sigma: float,
    rel_gap: float,
) -> F64:
    """The Newton–CG step on the free set (bounds with wrong-sign multipliers released)."""
    mu = _multiplier(gamma, g, cap, sigma)
    inside = (gamma > 0.0) & (gamma < cap)
    free = np.flatnonzero(inside | ((gamma <= 0.0) & (g < mu)) | ((gamma >= cap) & (g > mu)))
    d, _ = face_cg(
        lambda v: pts.hvp(r, v),
        g,
        gamma,
        cap,
        free,
        precondition(r),
        _forcing(rel_gap),
        budget=max(free.size, 1),
    )
    return d


def box_newton(
    net: CostOracle,
    lo: F64,
    cap: F64,
    sigma: float,
    tol: float,
    max_iter: int,
    g0: F64,
    mode: str,
    warm_min_order: int | None = None,
    stop: Callable[[F64, float, float], bool] | None = None,
) -> tuple[F64, int, _Points]:
    """Newton's method (``mode`` ``"exact"`` or ``"hvp"``) on the box-simplex from ``g0`` for the
    network ``net`` in channel units (rates ``lo + γ``) until ``gap ≤ tol·|η|``, or earlier when
    ``stop(r, η, gap)`` is true at an iterate (the branch-and-bound's early stop); returns
    ``(γ, steps, the point cache)``.

    Raises:
        ConvergenceError: more than ``max_iter`` steps.
    """
    pts = _Points(net, warm_min_order)
    precondition = _Preconditioner(net, g0.size) if mode == "hvp" else None
    gamma = g0.copy()
    stall = _Stall(3)
    for it in range(max_iter):
        r = gamma + lo
        f, g = pts.value_gradient(r)
        gap = box_frank_wolfe_gap(gamma, g, cap, sigma)
        if gap <= tol * max(abs(f), 1e-300) or (stop is not None and stop(r, f, gap)):
            return gamma, it, pts
        if precondition is None:
            d = _exact_step(pts, r, g, gamma, cap, sigma)
        else:
            rel = gap / max(abs(f), 1e-300)
            d = _cg_step(pts, precondition, r, g, gamma, cap, sigma, rel)
        slope = _slope(g, d)
        if slope >= 0.0 or stall.stalled(gap):
            return gamma, it, pts
        gamma_new, _, ok = _armijo_box(
            net.cost, lo, cap, sigma, gamma, d, f, slope, newton_step=True, first=pts.trial_cost
        )
        if not ok:
            return gamma, it, pts
        gamma = gamma_new
    raise ConvergenceError(f"newton did not converge in {max_iter} iterations")


def box_projected_gradient(
    net: CostOracle, lo: F64, cap: F64, sigma: float, tol: float, max_iter: int, g0: F64
) -> tuple[F64, int]:
    """Spectral projected gradient on the box-simplex from ``g0`` until ``gap ≤ tol·|η|``;
    returns ``(γ, steps)``.

    Raises:
        ConvergenceError: more than ``max_iter`` steps.
    """
    gamma = g0.copy()
    stall = _Stall(100)
    f, g = value_gradient(net, gamma + lo)
    alpha = sigma / max(float(np.max(np.abs(g))), 1e-300)
    for it in range(max_iter):
        gap = box_frank_wolfe_gap(gamma, g, cap, sigma)
        if gap <= tol * max(abs(f), 1e-300):
            return gamma, it
        d = project_box_simplex(gamma - alpha * g, cap, sigma) - gamma
        slope = float((g - g.mean()) @ d)
        if slope >= 0.0 or stall.stalled(gap):
            return gamma, it
        gamma_new, _, ok = _armijo_box(
            net.cost, lo, cap, sigma, gamma, d, f, slope, newton_step=False
        )
        if not ok:
            return gamma, it
        f_new, g_new = value_gradient(net, gamma_new + lo)
        s, y = gamma_new - gamma, g_new - g
        sy = float(s @ y)
        alpha = float(s @ s) / sy if sy > 0 else alpha * 2.0
        alpha = min(max(alpha, 1e-12 * sigma), 1e12 * sigma)
        gamma, f, g = gamma_new, f_new, g_new
    raise ConvergenceError(
        f"projected-gradient did not reach the certificate in {max_iter} iterations "
        f"(gap {box_frank_wolfe_gap(gamma, g, cap, sigma):.3e})"
    )
