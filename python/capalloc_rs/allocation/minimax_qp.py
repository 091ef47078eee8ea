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
best iterate seen (feasible to rounding, maybe not optimal) is returned — the caller certifies its
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
    f: F64, grads: F64, h: F64, gamma: F64, cap: F64, sigma: float, tol: float = 1e-11
) -> tuple[F64, float, F64]:
    """``(d, t, λ)``: the step, the worst linearised value ``t = max_k (f_k + g_kᵀd)`` at it
    and the multipliers of the K model rows (normalised to sum 1) of the epigraph QP in the
    module docstring.

    The iteration stops when the scaled residuals are below ``tol`` and the mean
    complementarity below ``tol²``; in floating point the residuals stall near the rounding of
    the data and the system becomes ill-conditioned as the complementarity vanishes, so the
    iterate with the smallest ``max(residual, complementarity)`` seen is returned.

    Args:
        f: ``(K,)`` model values at γ.
        grads: ``(K, N)`` gradients (channel units).
        h: ``N × N`` symmetric positive definite matrix.
        gamma: the current point on the box-simplex.
        cap: the caps (``inf`` for none).
        sigma: ``σ > 0``.
        tol: the residual tolerance (scaled problem).
    """
    qp, _, _ = _build(f, grads, h, gamma, cap, sigma)
    k_models, n = grads.shape
    x = np.zeros(n + 1)
    x[n] = 1.0
    y = 0.0
    s = np.maximum(qp.h - qp.g @ x, 1.0)
    z = np.ones_like(s)
    best, best_x, best_z = np.inf, x, z
    for _ in range(MAX_IPM_ITER):
        res = qp.residuals(x, y, z, s)
        mu = float(s @ z) / s.size
        err = max(float(np.max(np.abs(res[0]))), abs(res[1]), float(np.max(np.abs(res[2]))))
        if max(err, mu) < best:
            best, best_x, best_z = max(err, mu), x, z
        if (err <= tol and mu <= tol * tol) or not np.isfinite(err):
            break
        dx, dy, dz, ds = qp.solve(s, z, res, s * z)
        alpha = min(_max_step(s, ds), _max_step(z, dz))
        mu_aff = float((s + alpha * ds) @ (z + alpha * dz)) / s.size
        centre = (mu_aff / mu) ** 3 if mu > 0 else 0.0
        r_c = s * z + ds * dz - centre * mu
        dx, dy, dz, ds = qp.solve(s, z, res, r_c)
        alpha = min(1.0, 0.99 * min(_max_step(s, ds), _max_step(z, dz)))
        x, y, z, s = x + alpha * dx, y + alpha * dy, z + alpha * dz, s + alpha * ds
    lam = np.maximum(best_z[:k_models], 0.0)
    total = float(np.sum(lam))
    lam = lam / total if total > 0 else np.full(k_models, 1.0 / k_models)
    d = best_x[:n] * sigma
    polished = _polish(f, grads, h, gamma, cap, sigma, d, lam)
    if polished is not None:
        return polished
    return d, float(np.max(f + grads @ d)), lam


def _model(f: F64, grads: F64, h: F64, d: F64) -> float:
    return float(np.max(f + grads @ d)) + 0.5 * float(d @ h @ d)


def _polish(
    f: F64, grads: F64, h: F64, gamma: F64, cap: F64, sigma: float, d: F64, lam: F64
) -> tuple[F64, float, F64] | None:
    """The exact solution of the QP on the active set the interior point identified (models
    with ``λ_k > 10⁻⁹``, coordinates within ``10⁻⁹σ`` of a bound): one linear KKT solve, kept
    when it is feasible, its multipliers non-negative and its objective no worse than the
    interior point's (else ``None``). The interior point alone is accurate to about 10⁻¹¹ of
    the data, too little for the last Newton steps."""
    tiny = 1e-9 * sigma
    x = gamma + d
    lower, upper = x <= tiny, (cap - x) <= tiny
    fixed = lower | upper
    free = np.flatnonzero(~fixed)
    act = np.flatnonzero(lam > 1e-9)
    m, a = free.size, act.size
    d_b = np.where(lower, -gamma, np.where(upper, cap - gamma, 0.0))
    kkt = np.zeros((m + a + 2, m + a + 2))
    rhs = np.zeros(m + a + 2)
    kkt[:m, :m] = h[np.ix_(free, free)]
    kkt[:m, m + 1 : m + 1 + a] = grads[np.ix_(act, free)].T
    kkt[:m, m + a + 1] = 1.0
    rhs[:m] = -h[free] @ d_b
    kkt[m, m + 1 : m + 1 + a] = 1.0
    rhs[m] = 1.0
    kkt[m + 1 : m + 1 + a, :m] = grads[np.ix_(act, free)]
    kkt[m + 1 : m + 1 + a, m] = -1.0
    rhs[m + 1 : m + 1 + a] = -f[act] - grads[act] @ d_b
    kkt[m + a + 1, :m] = 1.0
    rhs[m + a + 1] = -float(np.sum(d_b))
    try:
        sol = np.linalg.solve(kkt, rhs)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(sol)):
        return None
    dp = d_b.copy()
    dp[free] = sol[:m]
    t, lam_a = float(sol[m]), sol[m + 1 : m + 1 + a]
    slack = 1e-12 * max(abs(t), 1.0)
    feasible = (
        np.all(lam_a >= -1e-12)
        and np.all(f + grads @ dp <= t + slack)
        and np.all(gamma + dp >= -tiny)
        and np.all(gamma + dp <= cap + tiny)
    )
    if not feasible or _model(f, grads, h, dp) > _model(f, grads, h, d) + slack:
        return None
    lam_p = np.zeros_like(lam)
    lam_p[act] = np.maximum(lam_a, 0.0)
    lam_p /= float(np.sum(lam_p))
    return dp, float(np.max(f + grads @ dp)), lam_p
