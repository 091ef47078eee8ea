"""Projected preconditioned conjugate gradients on a face of the box-simplex — the inner solver
of Newton–CG on the simplex (:mod:`.newton`) and on the box-simplex (:mod:`.box_newton`).

It approximately minimises the quadratic model ``gᵀd + ½ dᵀHd`` over
``{Σd = 0, 0 ≤ γ + d ≤ c, d = 0 off the free set F}`` (``c = +∞`` on the simplex), with ``H``
available only through products. CG runs on the face with the diagonal preconditioner ``D``
(``dinv`` = the diagonal of ``D⁻¹``) and is truncated at ``‖P r‖ ≤ forcing·‖P g_F‖``
(``P`` the projection onto ``Σ = 0``); a step that would leave the box stops at the bound it
reaches, fixes that coordinate there, and CG restarts on the smaller face.

The residual ``r = g_F + H d_F`` is kept free of its multiplier part — after each update
``r ← r − λ1`` with ``λ = (1ᵀD⁻¹r)/(1ᵀD⁻¹1)`` (Gould–Hribar–Nocedal's residual update) — so the
preconditioned projection ``z = D⁻¹r`` does not cancel the O(|μ|) constant against the
O(‖P g‖) rest, which would stall CG near the optimum.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

__all__ = ["boundary_step", "deflate", "face_cg", "projected_norm"]

F64 = npt.NDArray[np.float64]


def projected_norm(r: F64) -> float:
    """The Euclidean norm of the projected residual ``r − mean(r)·1``."""
    return float(np.linalg.norm(r - r.mean()))


def deflate(r: F64, w: F64) -> F64:
    """``r − λ1`` with ``1ᵀD⁻¹(r − λ1) = 0`` (``w`` the diagonal of ``D⁻¹``)."""
    # Twice: the first pass cancels |μ| ≫ ‖P r‖ and leaves an error of ε|μ| in every entry,
    # which would make Σz, hence Σd, wrong at the level that matters near the optimum.
    for _ in range(2):
        r = r - float((w * r).sum()) / float(w.sum())
    return r


def boundary_step(cur: F64, cap: F64, p: F64) -> tuple[float, int, bool]:
    """The largest ``α`` with ``0 ≤ cur + αp ≤ cap``, the index (into ``p``) reaching a bound
    there and whether it is the cap; ``(inf, −1, False)`` when no bound is reached."""
    with np.errstate(divide="ignore", invalid="ignore"):
        down = np.where(p < 0.0, np.maximum(cur, 0.0) / -p, np.inf)
        up = np.where(p > 0.0, np.maximum(cap - cur, 0.0) / p, np.inf)
    ratios = np.minimum(down, up)
    if ratios.size == 0:
        return math.inf, -1, False
    k = int(np.argmin(ratios))
    if not np.isfinite(ratios[k]):
        return math.inf, -1, False
    return float(ratios[k]), k, bool(up[k] < down[k])


def face_cg(
    hvp: Callable[[F64], F64],
    g: F64,
    gamma: F64,
    cap: F64 | None,
    free: npt.NDArray[np.intp],
    dinv: F64,
    forcing: float,
    budget: int,
) -> tuple[F64, int]:
    """The truncated CG step of the module docstring from ``d = 0``; ``cap`` ``None`` on the
    simplex (no upper bounds). Returns the step (on all coordinates) and the number of products
    used (≤ ``budget``)."""
    n = g.size
    caps = np.full(n, np.inf) if cap is None else cap
    d = np.zeros(n)
    r = g[free].copy()  # gradient of the model at d = 0, restricted to the face
    target = forcing * projected_norm(r)
    used, restart = 0, True
    w = p = z = r
    rz = 0.0
    while used < budget and free.size >= 2:
        if restart:
            w = dinv[free]
            r = deflate(r, w)
            if projected_norm(r) <= target:
                break
            z = w * r
            p, rz, restart = -z, float(r @ z), False
            if rz <= 0.0:
                break
        p_full = np.zeros(n)
        p_full[free] = p
        hp = hvp(p_full)[free]
        used += 1
        kappa = float(p @ hp)
        alpha_b, hit, upper = boundary_step(gamma[free] + d[free], caps[free], p)
        if kappa <= 0.0:  # no positive curvature (rounding on a convex η): to the boundary
            if hit >= 0 and not np.any(d):
                d[free] += alpha_b * p
                d[free[hit]] = (caps[free[hit]] if upper else 0.0) - gamma[free[hit]]
            break
        alpha = rz / kappa
        if alpha_b < alpha:  # the step leaves the box: stop at the bound, fix the index there
            d[free] += alpha_b * p
            d[free[hit]] = (caps[free[hit]] if upper else 0.0) - gamma[free[hit]]
            r = r + alpha_b * hp
            keep = np.arange(free.size) != hit
            free, r, restart = free[keep], r[keep], True
            continue
        d[free] += alpha * p
        r = deflate(r + alpha * hp, w)
        if projected_norm(r) <= target:
            break
        z = w * r
        rz_new = float(r @ z)
        if rz_new <= 0.0:
            break
        p = -z + (rz_new / rz) * p
        rz = rz_new
    return d, used
