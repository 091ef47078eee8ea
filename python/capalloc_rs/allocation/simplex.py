"""The simplex ``{γ ≥ 0, Σγ = σ}`` of Theorem 1 and the optimality certificate on it: Euclidean
projection, the convex QP ``min cᵀx + ½xᵀHx`` over the simplex (primal active set), the bordered
KKT solve of a step on a face, the KKT residual and the Frank–Wolfe gap

    gap(γ) = Σ_i γ_i (g_i − min_j g_j) = max_{γ' ∈ simplex} ∇η(γ)ᵀ(γ − γ')  ≥  η(γ) − η*,

a certificate for convex η that needs no threshold.

With sample costs, per-sensor minima and caps the feasible set becomes the weighted box-simplex
``{0 ≤ γ ≤ c, Σγ = σ}`` in channel units; its projection, QP (both bounds), KKT conditions
(``g_i ≥ μ`` at a minimum, ``g_i ≤ μ`` at a cap) and Frank–Wolfe gap (a fractional knapsack,
``gᵀ(γ − γ_FW)``) are in :mod:`.box_simplex`; with ``c = ∞`` they reduce to the ones here.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError

__all__ = [
    "STAGNATION_GAP",
    "face_kkt_solve",
    "frank_wolfe_gap",
    "kkt",
    "project_simplex",
    "regularised_hessian",
    "simplex_qp",
]

F64 = npt.NDArray[np.float64]


#: A method that can make no further progress in floating point returns its point if the certified
#: gap is at most this (relative to η), and raises ConvergenceError otherwise.
STAGNATION_GAP = 1e-8


class _Stall:
    """Detects a certificate at its rounding floor: the best Frank–Wolfe gap has not halved in
    ``window`` consecutive iterations (the gradient is accurate to ~1e-12 relative, so the gap
    cannot go below that however many steps are taken)."""

    def __init__(self, window: int) -> None:
        self.window = window
        self.best = math.inf
        self.since = 0

    def stalled(self, gap: float) -> bool:
        if gap < 0.5 * self.best:
            self.best, self.since = gap, 0
        else:
            self.since += 1
        return self.since >= self.window


def project_simplex(y: F64, sigma: float) -> F64:
    """Euclidean projection of ``y`` onto ``{x ≥ 0, Σx = σ}`` (sort-based, Held–Wolfe–Crowder)."""
    if sigma == 0.0:
        return np.zeros_like(y)
    u = np.sort(y)[::-1]
    css = np.cumsum(u) - sigma
    ind = np.arange(1, y.size + 1)
    cond = u - css / ind > 0
    rho = int(ind[cond][-1])
    theta = css[rho - 1] / rho
    x = np.maximum(y - theta, 0.0)
    return _fix_sum(x, sigma)


def _fix_sum(x: F64, sigma: float) -> F64:
    """Puts the rounding error of ``Σx`` on the largest entry so that ``Σx == σ`` to the last bit
    as far as possible, keeping ``x ≥ 0``."""
    x = np.maximum(x, 0.0)
    k = int(np.argmax(x))
    x[k] += sigma - float(np.sum(x))
    x[k] = max(x[k], 0.0)
    return x


def frank_wolfe_gap(gamma: F64, g: F64) -> float:
    """``Σ γ_i (g_i − min_j g_j)`` — an upper bound on ``η(γ) − η*`` for convex η."""
    return float(np.dot(gamma, g - np.min(g))) if gamma.size else 0.0


def kkt(
    gamma: F64, g: F64, sigma: float, active_tol: float
) -> tuple[float, npt.NDArray[np.bool_], float]:
    """Returns ``(μ, active mask, relative KKT residual)``."""
    active = gamma > active_tol
    if not np.any(active):
        mu = float(np.min(g))
        return mu, active, 0.0
    mu = float(np.mean(g[active]))
    viol_active = float(np.max(np.abs(g[active] - mu)))
    viol_inactive = float(np.max(np.maximum(mu - g[~active], 0.0))) if np.any(~active) else 0.0
    return mu, active, max(viol_active, viol_inactive) / max(abs(mu), 1e-300)


def face_kkt_solve(h_ff: F64, top: F64, bottom: float) -> tuple[F64, float]:
    """Solves the bordered system of a step on a face of the simplex,
    ``[[H_FF, −1], [1ᵀ, 0]] [p; λ] = [top; bottom]``, and returns ``(p, λ)``. Shared by the QP
    below and the filtration's KKT corrector. Raises ``numpy.linalg.LinAlgError`` if singular."""
    k = top.size
    kkt = np.zeros((k + 1, k + 1))
    kkt[:k, :k] = h_ff
    kkt[:k, k] = -1.0
    kkt[k, :k] = 1.0
    sol = np.linalg.solve(kkt, np.concatenate([top, [bottom]]))
    return sol[:k], float(sol[k])


def regularised_hessian(h: F64) -> F64:
    """The model Hessian of a QP step, ``(H + Hᵀ)/2 + 10⁻¹²·max_i |H_ii|·I``: η is convex but its
    Hessian may be singular (non-regular triplets), and the QP needs a positive definite one."""
    h = 0.5 * (h + h.T)
    return h + (1e-12 * max(float(np.max(np.abs(np.diag(h)))), 1e-300)) * np.eye(h.shape[0])


def simplex_qp(h: F64, c: F64, x0: F64, sigma: float, max_iter: int) -> F64:
    """Minimises ``cᵀx + ½ xᵀHx`` over ``{x ≥ 0, Σx = σ}`` by a primal active-set method started at
    the feasible ``x0``. ``H`` must be symmetric positive definite (the caller regularises)."""
    n = c.size
    x = x0.copy()
    fixed = x <= 0.0  # working set: bounds held at zero
    x[fixed] = 0.0
    for _ in range(max_iter):
        free = np.flatnonzero(~fixed)
        grad = c + h @ x
        # Equality-constrained step on the face: H_FF p − λ1 = −grad_F, 1ᵀp = 0.
        p_free, lam = face_kkt_solve(h[np.ix_(free, free)], -grad[free], 0.0)
        scale = max(1.0, float(np.max(np.abs(x))))
        if float(np.max(np.abs(p_free))) <= 1e-14 * scale:
            nu = grad - lam  # bound multipliers for the fixed indices
            cand = np.flatnonzero(fixed & (nu < -1e-14 * max(1.0, abs(lam))))
            if cand.size == 0:
                return _fix_sum(x, sigma)
            fixed[cand[np.argmin(nu[cand])]] = False
            continue
        alpha, block = 1.0, -1
        for i, pi in zip(free, p_free, strict=True):
            if pi < 0.0:
                t = -x[i] / pi
                if t < alpha:
                    alpha, block = t, int(i)
        x[free] += alpha * p_free
        if block >= 0:
            x[block] = 0.0
            fixed[block] = True
        x = np.maximum(x, 0.0)
    raise ConvergenceError(f"simplex QP did not terminate in {max_iter} iterations (n = {n})")
