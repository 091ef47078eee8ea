"""The box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` of the allocation with sample costs, per-sensor minima
and caps, and the optimality certificate on it.

In channel units (``s = b ∘ r``, the channel units per unit time spent on each sensor) the problem
is ``minimise η(s)`` over ``{lo ≤ s ≤ hi, Σ s_i = B}`` with ``lo = b ∘ r_min``, ``hi = b ∘ r_max``
(``inf`` = no cap) and the budget ``B``; with ``γ = s − lo`` it is the box-simplex
``{0 ≤ γ ≤ c, Σγ = σ}``, ``c = hi − lo``, ``σ = B − Σ lo``. Every function here works on γ.

KKT conditions (η convex, g = ∇η in channel units): γ is optimal iff there is μ with

    g_i = μ  where 0 < γ_i < c_i,     g_i ≥ μ  where γ_i = 0,     g_i ≤ μ  where γ_i = c_i;

the bound multipliers per channel unit are ``λ_i = g_i − μ ≥ 0`` at a minimum and
``ν_i = μ − g_i ≥ 0`` at a cap (0 elsewhere). In rates, ``∂η/∂r_i = b_i g_i``.

Certificate: the Frank–Wolfe gap ``gᵀ(γ − γ_FW)`` with ``γ_FW`` minimising ``gᵀγ'`` over the
box-simplex — a fractional knapsack: fill the coordinates of smallest ``g_i`` to their caps until
σ is spent. By convexity ``η(γ*) ≥ η(γ) + gᵀ(γ* − γ) ≥ η(γ) − gᵀ(γ − γ_FW)``, so the gap is a
proven upper bound on ``η(γ) − η*``. With ``c = ∞`` it is the simplex gap
``Σ γ_i (g_i − min g)`` of :mod:`.simplex`.

Also here: the Euclidean projection onto the box-simplex (``x_i = clip(y_i − τ, 0, c_i)`` with the
threshold τ found over the sorted breakpoints) and the convex QP ``min qᵀx + ½xᵀHx`` over the
box-simplex by a primal active-set method with both bounds (finite termination).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .simplex import face_kkt_solve

__all__ = [
    "box_frank_wolfe",
    "box_frank_wolfe_gap",
    "box_kkt",
    "box_qp",
    "fix_sum_box",
    "project_box_simplex",
]

F64 = npt.NDArray[np.float64]
Mask = npt.NDArray[np.bool_]


def fix_sum_box(x: F64, cap: F64, sigma: float) -> F64:
    """``x`` clipped to ``[0, c]`` with the rounding error of ``Σx`` put on the entry strictly
    inside its bounds with the most room in the direction needed (on a bound only when none is
    inside), so that ``Σx == σ`` as far as floating point allows."""
    x = np.minimum(np.maximum(x, 0.0), cap)
    err = sigma - float(np.sum(x))
    if err == 0.0 or x.size == 0:
        return x
    room = (cap - x) if err > 0 else x.copy()
    # Entries on a bound stay exactly there (the active sets read them exactly) when another
    # entry can take the rounding error.
    inside = (x > 0.0) & (x < cap)
    if np.any(inside):
        room[~inside] = -np.inf
    k = int(np.argmax(room))
    x[k] = min(max(x[k] + err, 0.0), cap[k])
    return x


def _filled(y: F64, cap: F64, tau: float) -> float:
    return float(np.sum(np.minimum(np.maximum(y - tau, 0.0), cap)))


def project_box_simplex(y: F64, cap: F64, sigma: float) -> F64:
    """Euclidean projection of ``y`` onto ``{0 ≤ x ≤ c, Σx = σ}`` (``0 ≤ σ ≤ Σc``):
    ``x = clip(y − τ, 0, c)`` with ``φ(τ) = Σ clip(y_i − τ, 0, c_i) = σ``. φ is non-increasing and
    piecewise linear with breakpoints ``y_i`` and ``y_i − c_i``: a bisection over the sorted
    breakpoints (at most ``log2(2N) + 2`` evaluations) finds the segment, on which τ solves a
    linear equation."""
    if y.size == 0:
        return y.copy()
    finite_cap = np.isfinite(cap)
    bps = np.unique(np.concatenate([y, (y - cap)[finite_cap]]))
    f_first = _filled(y, cap, float(bps[0]))
    if f_first < sigma:
        # τ lies left of every breakpoint, where the capped entries are at their caps and the
        # k uncapped ones free: φ(τ) = φ(bps[0]) + k·(bps[0] − τ). k = 0 only if σ ≥ Σc.
        k = int(np.sum(~finite_cap))
        if k == 0:
            return fix_sum_box(cap.copy(), cap, sigma)
        tau = float(bps[0]) - (sigma - f_first) / k
        return fix_sum_box(np.minimum(np.maximum(y - tau, 0.0), cap), cap, sigma)
    lo_i, hi_i = 0, bps.size - 1  # invariant: φ(bps[lo_i]) ≥ σ ≥ φ(bps[hi_i]) = 0
    for _ in range(bps.size.bit_length() + 2):
        if hi_i - lo_i <= 1:
            break
        mid = (lo_i + hi_i) // 2
        if _filled(y, cap, float(bps[mid])) > sigma:
            lo_i = mid
        else:
            hi_i = mid
    t0, t1 = float(bps[lo_i]), float(bps[hi_i])
    f0, f1 = _filled(y, cap, t0), _filled(y, cap, t1)
    # φ is linear on [t0, t1]: interpolate (exact up to rounding).
    tau = t0 + (f0 - sigma) * (t1 - t0) / (f0 - f1) if f0 > f1 else t1
    return fix_sum_box(np.minimum(np.maximum(y - tau, 0.0), cap), cap, sigma)


def box_frank_wolfe(g: F64, cap: F64, sigma: float) -> tuple[F64, int]:
    """``(γ_FW, k)``: the minimiser of ``gᵀγ'`` over the box-simplex (fill the smallest ``g_i``
    to their caps first) and the index ``k`` filled last (partly filled or the last full one);
    ``k = −1`` when ``σ = 0``."""
    out = np.zeros_like(g)
    left = sigma
    last = -1
    for i in np.argsort(g, kind="stable"):
        if left <= 0.0:
            break
        take = min(float(cap[i]), left)
        out[i] = take
        left -= take
        last = int(i)
    return out, last


def box_frank_wolfe_gap(gamma: F64, g: F64, cap: F64, sigma: float) -> float:
    """``gᵀ(γ − γ_FW)`` — an upper bound on ``η(γ) − η*`` for convex η. Summed as
    ``Σ (γ_i − γ_FW,i)(g_i − g_k)`` with ``k`` the index filled last: every term is ≥ 0
    (``γ_FW,i = c_i`` where ``g_i < g_k``, 0 where ``g_i > g_k``), so no cancellation."""
    if gamma.size == 0:
        return 0.0
    fw, last = box_frank_wolfe(g, cap, sigma)
    ref = float(g[last]) if last >= 0 else float(np.min(g))
    return float(np.sum((gamma - fw) * (g - ref)))


def box_kkt(gamma: F64, g: F64, cap: F64, active_tol: float) -> tuple[float, Mask, Mask, float]:
    """``(μ, at minimum, at cap, relative KKT residual)`` at ``γ``: μ is the mean of ``g`` over the
    free set ``{active_tol < γ_i < c_i − active_tol}``; without a free sensor it is ``min g`` over
    the sensors at their minimum (the price of the next channel unit: the right derivative of
    η* in the budget), or ``max g`` over the capped ones when every sensor is capped. The
    residual is ``max(|g_F − μ|, (μ − g_lo)₊, (g_cap − μ)₊) / |μ|``."""
    at_min = gamma <= active_tol
    at_cap = ~at_min & (gamma >= cap - active_tol)
    free = ~at_min & ~at_cap
    if np.any(free):
        mu = float(np.mean(g[free]))
    elif np.any(at_min):
        mu = float(np.min(g[at_min]))
    else:
        mu = float(np.max(g[at_cap])) if g.size else 0.0
    viol = 0.0
    if np.any(free):
        viol = max(viol, float(np.max(np.abs(g[free] - mu))))
    if np.any(at_min):
        viol = max(viol, float(np.max(np.maximum(mu - g[at_min], 0.0))))
    if np.any(at_cap):
        viol = max(viol, float(np.max(np.maximum(g[at_cap] - mu, 0.0))))
    return mu, at_min, at_cap, viol / max(abs(mu), 1e-300)


def _release(grad: F64, lam: float, fixed_lo: Mask, fixed_hi: Mask) -> tuple[int, bool] | None:
    """The most violated bound of the working set at the face's multiplier ``lam`` (a lower
    bound with ``grad_i < lam`` or an upper bound with ``grad_i > lam``), as (index, is_upper);
    ``None`` when every bound multiplier has the right sign."""
    tol = 1e-14 * max(1.0, abs(lam))
    viol_lo = np.where(fixed_lo, lam - grad, -np.inf)
    viol_hi = np.where(fixed_hi, grad - lam, -np.inf)
    i, j = int(np.argmax(viol_lo)), int(np.argmax(viol_hi))
    best = max(float(viol_lo[i]), float(viol_hi[j]))
    if not best > tol:
        return None
    return (i, False) if viol_lo[i] >= viol_hi[j] else (j, True)


def _release_pair(grad: F64, fixed_lo: Mask, fixed_hi: Mask) -> list[int]:
    """With every coordinate on a bound, the face is a point and its multiplier any value in
    ``[max g_cap, min g_lo]``; when that interval is empty, the lower bound of smallest gradient
    and the cap of largest gradient are released together (one alone cannot move)."""
    hi_g = grad[fixed_hi].max() if np.any(fixed_hi) else -np.inf
    lo_g = grad[fixed_lo].min() if np.any(fixed_lo) else np.inf
    if hi_g <= lo_g + 1e-14 * max(1.0, abs(float(lo_g)) if np.isfinite(lo_g) else 1.0):
        return []
    i = int(np.flatnonzero(fixed_lo)[np.argmin(grad[fixed_lo])])
    j = int(np.flatnonzero(fixed_hi)[np.argmax(grad[fixed_hi])])
    return [i, j]


def _ratio_test(x: F64, cap: F64, free: npt.NDArray[np.intp], p: F64) -> tuple[float, int, bool]:
    """The largest ``α ≤ 1`` keeping ``x_F + α p`` in the box, the index blocking there (−1 if
    none) and whether it blocks at its cap."""
    alpha, block, upper = 1.0, -1, False
    for i, pi in zip(free, p, strict=True):
        if pi < 0.0:
            t = -x[i] / pi
        elif pi > 0.0:
            t = (cap[i] - x[i]) / pi
        else:
            continue
        if t < alpha:
            alpha, block, upper = t, int(i), pi > 0.0
    return alpha, block, upper


def box_qp(h: F64, q: F64, x0: F64, cap: F64, sigma: float, max_iter: int) -> F64:
    """Minimises ``qᵀx + ½ xᵀHx`` over ``{0 ≤ x ≤ c, Σx = σ}`` by a primal active-set method
    started at the feasible ``x0``, with working sets for both bounds: each iteration either
    steps on the current face (stopping at the first bound reached, which joins the working set)
    or, at the face's minimum, releases the bound whose multiplier has the wrong sign (lower:
    ``g_i < λ``; cap: ``g_i > λ``). ``H`` must be symmetric positive definite (the caller
    regularises); finite termination as for the simplex QP."""
    x = fix_sum_box(x0.copy(), cap, sigma)
    fixed_lo = x <= 0.0
    fixed_hi = ~fixed_lo & (x >= cap)
    for _ in range(max_iter):
        free = np.flatnonzero(~fixed_lo & ~fixed_hi)
        grad = q + h @ x
        if free.size == 0:
            pair = _release_pair(grad, fixed_lo, fixed_hi)
            if not pair:
                return fix_sum_box(x, cap, sigma)
            fixed_lo[pair] = False
            fixed_hi[pair] = False
            continue
        p_free, lam = face_kkt_solve(h[np.ix_(free, free)], -grad[free], 0.0)
        scale = max(1.0, float(np.max(np.abs(x))))
        if float(np.max(np.abs(p_free))) <= 1e-14 * scale:
            rel = _release(grad, lam, fixed_lo, fixed_hi)
            if rel is None:
                return fix_sum_box(x, cap, sigma)
            fixed_lo[rel[0]] = fixed_hi[rel[0]] = False
            continue
        alpha, block, upper = _ratio_test(x, cap, free, p_free)
        x[free] += alpha * p_free
        if block >= 0:
            x[block] = cap[block] if upper else 0.0
            (fixed_hi if upper else fixed_lo)[block] = True
        x = np.minimum(np.maximum(x, 0.0), cap)
    raise ConvergenceError(f"box-simplex QP did not terminate in {max_iter} iterations")
