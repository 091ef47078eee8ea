"""The quadratic subproblem of the worst-case (minimax) allocation, solved by a primal–dual
interior-point method.

At a point γ of the box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` with model values ``f_k``, gradients
``g_k`` and a positive definite ``H`` (the Hessian of the Lagrangian ``Σ λ_k ∇²η_k``), the step
``d`` of the sequential quadratic programming method of :mod:`.robust` solves the epigraph QP

    minimise  t + ½ dᵀHd   subject to   f_k + g_kᵀd ≤ t  (k = 1 … K),
                                        0 ≤ γ + d ≤ c,   Σ d = 0.

Its multipliers ``λ_k ≥ 0`` of the K model rows sum to 1 (stationarity in t): they are the weights
of the models that are worst at the solution. The QP is convex; it is scaled (``d = σu``,
``t = F + |F|τ`` with ``F = max f_k``) so that every quantity is of order one, and solved by
Mehrotra's predictor–corrector method from an infeasible start: each iteration one dense
``(N + 2)``-square linear solve of the reduced KKT system
``[[P + GᵀZS⁻¹G, Aᵀ], [A, 0]]``. Bounded: at most :data:`MAX_IPM_ITER` iterations, then the
current (feasible to rounding, maybe not optimal) point is returned — the caller certifies its
iterates independently of the QP, so an inexact QP costs steps, never correctness.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["MAX_IPM_ITER", "minimax_qp"]

F64 = npt.NDArray[np.float64]

#: Interior-point iterations per QP at most.
MAX_IPM_ITER = 100


def _max_step(v: F64, dv: F64) -> float:
    """The largest ``α ≤ 1`` with ``v + α dv ≥ 0``."""
    neg = dv < 0
    if not np.any(neg):
        return 1.0
    return float(min(1.0, np.min(-v[neg] / dv[neg])))


class _Qp:
    """``min ½xᵀPx + qᵀx`` s.t. ``aᵀx = 0`` (one row) and ``Gx ≤ h``."""

    def __init__(self, p: F64, q: F64, a: F64, g: F64, h: F64) -> None:
        self.p, self.q, self.a, self.g, self.h = p, q, a, g, h
        self.n = q.size

    def residuals(self, x: F64, y: float, z: F64, s: F64) -> tuple[F64, float, F64]:
        r_d = self.p @ x + self.q + self.a * y + self.g.T @ z
        return r_d, float(self.a @ x), self.g @ x + s - self.h

    def solve(
        self, s: F64, z: F64, res: tuple[F64, float, F64], r_c: F64
    ) -> tuple[F64, float, F64, F64]:
        """The Newton direction ``(Δx, Δy, Δz, Δs)`` for residuals ``res`` and complementarity
        residual ``r_c`` (``ZΔs + SΔz = −r_c``)."""
        r_d, r_p, r_i = res
        w = z / s
        n = self.n
        kkt = np.zeros((n + 1, n + 1))
        kkt[:n, :n] = self.p + (self.g.T * w) @ self.g
        kkt[:n, n] = kkt[n, :n] = self.a
        rhs = np.concatenate([-r_d - self.g.T @ ((-r_c + z * r_i) / s), [-r_p]])
        try:
            sol = np.linalg.solve(kkt, rhs)
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
        dx, dy = sol[:n], float(sol[n])
        ds = -r_i - self.g @ dx
        dz = (-r_c - z * ds) / s
        return dx, dy, dz, ds


def _build(
    f: F64, grads: F64, h: F64, gamma: F64, cap: F64, sigma: float
) -> tuple[_Qp, float, float]:
    """The scaled QP in ``x = (u, τ)``, ``d = σu``, ``t = F + scale·τ``; returns it with
    ``F`` and ``scale``."""
    k_models, n = grads.shape
    big = float(np.max(f))
    scale = max(abs(big), 1e-300)
    capped = np.flatnonzero(np.isfinite(cap))
    rows = k_models + n + capped.size
    g = np.zeros((rows, n + 1))
    hv = np.zeros(rows)
    g[:k_models, :n] = grads * (sigma / scale)
    g[:k_models, n] = -1.0
    hv[:k_models] = (big - f) / scale
    g[k_models : k_models + n, :n] = -np.eye(n)
    hv[k_models : k_models + n] = gamma / sigma
    g[k_models + n + np.arange(capped.size), capped] = 1.0
    hv[k_models + n :] = (cap[capped] - gamma[capped]) / sigma
    p = np.zeros((n + 1, n + 1))
    p[:n, :n] = h * (sigma * sigma / scale)
    q = np.zeros(n + 1)
    q[n] = 1.0
    a = np.concatenate([np.ones(n), [0.0]])
    return _Qp(p, q, a, g, hv), big, scale


def minimax_qp(
    f: F64, grads: F64, h: F64, gamma: F64, cap: F64, sigma: float, tol: float = 1e-13
) -> tuple[F64, float, F64]:
    """``(d, t, λ)``: the step, the model's worst linearised value ``t`` and the multipliers of
    the K model rows (normalised to sum 1) of the epigraph QP in the module docstring.

    Args:
        f: ``(K,)`` model values at γ.
        grads: ``(K, N)`` gradients (channel units).
        h: ``N × N`` symmetric positive definite matrix.
        gamma: the current point on the box-simplex.
        cap: the caps (``inf`` for none).
        sigma: ``σ > 0``.
        tol: stop when the scaled residuals and the mean complementarity are below it.
    """
    qp, big, scale = _build(f, grads, h, gamma, cap, sigma)
    k_models, n = grads.shape
    x = np.zeros(n + 1)
    x[n] = 1.0
    y = 0.0
    s = np.maximum(qp.h - qp.g @ x, 1.0)
    z = np.ones_like(s)
    for _ in range(MAX_IPM_ITER):
        res = qp.residuals(x, y, z, s)
        mu = float(s @ z) / s.size
        err = max(float(np.max(np.abs(res[0]))), abs(res[1]), float(np.max(np.abs(res[2]))))
        if err <= tol and mu <= tol:
            break
        dx, dy, dz, ds = qp.solve(s, z, res, s * z)
        alpha = min(_max_step(s, ds), _max_step(z, dz))
        mu_aff = float((s + alpha * ds) @ (z + alpha * dz)) / s.size
        centre = (mu_aff / mu) ** 3 if mu > 0 else 0.0
        r_c = s * z + ds * dz - centre * mu
        dx, dy, dz, ds = qp.solve(s, z, res, r_c)
        alpha = min(1.0, 0.99 * min(_max_step(s, ds), _max_step(z, dz)))
        x, y, z, s = x + alpha * dx, y + alpha * dy, z + alpha * dz, s + alpha * ds
    lam = np.maximum(z[:k_models], 0.0)
    total = float(np.sum(lam))
    lam = lam / total if total > 0 else np.full(k_models, 1.0 / k_models)
    return x[:n] * sigma, big + scale * float(x[n]), lam
