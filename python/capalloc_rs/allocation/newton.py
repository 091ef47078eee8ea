"""Newton's method on the simplex for Theorem 1's problem, in two variants, with an Armijo line
search on η.

* exact Hessian: sequential quadratic programming, each step solving the quadratic model
  ``gᵀd + ½dᵀ∇²η d`` over the simplex exactly (:func:`~.simplex.simplex_qp`); once the active set
  is identified this is Newton's method on the face (quadratic convergence);
* Newton–CG: the face-restricted Newton system solved by projected preconditioned conjugate
  gradients with Hessian-vector products (two Lyapunov solves each), truncated by the
  Eisenstat–Walker forcing term ``min(0.1, gap/|η|)``, preconditioned by the decoupled (ε = 0)
  curvatures ``η_i''(r_i)`` of a block network.

See :mod:`capalloc_rs.allocation` for the method's description.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .. import _core
from ..errors import ConvergenceError, NumericalError
from .face_cg import face_cg
from .oracle import (
    WARM_START_MIN_ORDER,
    CostOracle,
    PointCache,
    num_sensors,
    value_gradient_hessian,
)
from .simplex import _fix_sum, _Stall, frank_wolfe_gap, regularised_hessian, simplex_qp

__all__ = ["CORE_NEWTON_MAX_SENSORS", "NOISE_DECREASE", "core_model", "newton", "newton_in_core"]

F64 = npt.NDArray[np.float64]

#: Predicted decreases below ``NOISE_DECREASE·|η|`` are at the rounding level of η.
NOISE_DECREASE = 1e3 * float(np.finfo(np.float64).eps)


def _armijo(
    net: CostOracle,
    r_min: float,
    gamma: F64,
    d: F64,
    f0: float,
    slope: float,
    full_step_in_noise: bool = False,
    first: Any = None,
    sigma: float | None = None,
) -> tuple[F64, float, bool]:
    """Backtracking on η along ``γ + t d`` (feasible for t ∈ [0, 1]); returns the new point.

    For Newton steps (``full_step_in_noise``): when the predicted decrease ``−gᵀd`` is at the
    rounding level of η itself, comparing η values measures noise, so the full step is taken;
    progress is then judged by the certificate. ``first`` (rates ↦ η) evaluates the full step
    (t = 1) instead of ``net.cost``; with ``sigma`` each trial is put exactly on the simplex
    (:func:`_fix_sum`) before it is evaluated, so the point returned is the point evaluated."""
    cost_first = net.cost if first is None else first

    def feasible(x: F64) -> F64:
        x = np.maximum(x, 0.0)
        return x if sigma is None else _fix_sum(x, sigma)

    if full_step_in_noise and -slope <= NOISE_DECREASE * max(abs(f0), 1e-300):
        trial = feasible(gamma + d)
        return trial, float(cost_first(trial + r_min)), True
    t = 1.0
    start = feasible(gamma.copy())
    for k in range(60):
        trial = feasible(gamma + t * d)
        if np.array_equal(trial, start):
            break  # t·d no longer moves γ: no decrease is representable (η would compare equal)
        f = float((cost_first if k == 0 else net.cost)(trial + r_min))
        if f <= f0 + 1e-4 * t * slope:
            return trial, f, True
        t *= 0.5
    return gamma, f0, False


class _Points(PointCache):
    """Value, gradient and second-order information at rates ``r`` for the Newton variants.

    With ``net.at`` (a :class:`~capalloc_rs.network.CostPoint` per rate vector) one Riccati solve
    serves the value, the gradient and every product or the Hessian at that point, and the last
    point is kept (each new one warm-started from it, see :class:`.oracle.PointCache`): the line
    search's first trial (usually accepted) is the next step's point. Without it, falls back to
    ``value_gradient_hessian``. Counts the products it computes."""

    def __init__(self, net: CostOracle, warm_min_order: int | None = None) -> None:
        super().__init__(net, warm_min_order)
        self.hvps = 0

    def seed(self, r: F64, start: F64) -> None:
        """Makes the point at ``r`` the one reached from the matrix ``start`` (near ``Σ(r)``) by
        Newton–Kleinman instead of a cold solve (``net.at(r, start=...)``)."""
        if self.at is not None:
            self.last = (r.tobytes(), self.at(r, start=start))

    def point(self, r: F64) -> Any:
        """As :meth:`PointCache.point`; once a warm start has fallen back to the cold solve
        (e.g. no certificate at very large rates), the later points are solved cold at once
        instead of repeating the attempt."""
        p = super().point(r)
        if self.warm and getattr(p, "warm_fallback", None) is not None:
            self.warm = False
        return p

    def hessian(self, r: F64) -> F64:
        if self.at is None:
            return value_gradient_hessian(self.net, r)[2]
        return np.asarray(self.point(r).hessian(), dtype=np.float64)

    def hvp(self, r: F64, v: F64) -> F64:
        self.hvps += 1
        return np.asarray(self.point(r).hvp(v), dtype=np.float64)

    def value_error(self, r: F64) -> float:
        """The bound on ``|η − η_exact|`` at ``r`` (0 without ``net.at``)."""
        if self.at is None:
            return 0.0
        return float(getattr(self.point(r), "value_error", 0.0))

    def trial_cost(self, r: F64) -> float:
        """η at a trial point; the first trial of each search goes through ``at``."""
        if self.at is None:
            return float(self.net.cost(r))
        return float(self.point(r).value)


def _decoupled_curvature(net: Any) -> Any:
    """For a block network, ``r ↦ (η_i''(r_i))_i`` of the decoupled network (ε = 0): one small
    Riccati problem ``(A_i, G_i, c_i)`` per subsystem — the diagonal of ``∇²η`` up to O(ε).
    ``None`` for other networks."""
    st = getattr(net, "structure", None)
    if st is None or len(st.a_blocks) != num_sensors(net):
        return None
    models = [
        _core.CostModel(a, g, [c])
        for a, g, c in zip(st.a_blocks, st.g_blocks, st.c_blocks, strict=True)
    ]

    def curvature(r: F64) -> F64:
        out = np.empty(len(models))
        for i, m in enumerate(models):
            try:
                h = m.evaluate(r[i : i + 1], 2, 1).hessian
            except NumericalError:  # a subsystem alone at rate 0 may have no steady state
                return np.full(len(models), np.nan)  # (the preconditioner is then the identity)
            assert h is not None
            out[i] = h[0, 0]
        return out

    return curvature


#: The decoupled curvatures of :class:`_Preconditioner` are recomputed when some rate moved by
#: more than this fraction since they were formed.
PRECONDITIONER_RTOL = 0.1


class _Preconditioner:
    """``D⁻¹`` of projected CG: ``1/η_i''(r_i)`` of the decoupled network (floored at 1e-6 of the
    largest curvature) for block networks, ones otherwise. The curvatures are formed again only
    when some rate moved by more than :data:`PRECONDITIONER_RTOL` (relative) since they were
    formed: after the decoupled start Newton's steps move the rates by ``O(ε)``, and so the
    curvatures, so one set of ``N`` small Riccati solves serves the whole solve (a preconditioner
    changes CG's iterates, not the Newton step it converges to)."""

    def __init__(self, net: Any, n_sens: int) -> None:
        self.curvature = _decoupled_curvature(net)
        self.formed_at: F64 | None = None
        self.dinv = np.ones(n_sens)

    def __call__(self, r: F64) -> F64:
        """``D⁻¹`` at rates ``r``."""
        if self.curvature is None:
            return self.dinv
        last = self.formed_at
        if last is not None and np.all(np.abs(r - last) <= PRECONDITIONER_RTOL * last):
            return self.dinv
        h0 = self.curvature(r)
        self.formed_at = r.copy()
        if np.all(np.isfinite(h0)) and float(np.max(h0)) > 0.0:
            self.dinv = 1.0 / np.maximum(h0, 1e-6 * float(np.max(h0)))
        else:
            self.dinv = np.ones(r.size)
        return self.dinv


def _forcing(rel_gap: float) -> float:
    """The CG truncation ``η_k = min(0.1, gap/|η|)``: proportional to the certificate, hence to
    the projected gradient, so inexact Newton keeps quadratic local convergence. The cap 0.1
    (rather than the usual 0.5) saved one Newton step — one Riccati solve, worth ~20 products — at
    N = 20–200 in ``benches/compare_allocation.py`` for the same number of products."""
    return min(0.1, rel_gap)


def _slope(g: F64, d: F64) -> float:
    """``gᵀd`` for a step with ``Σd = 0``, as ``(g − c1)ᵀd`` with ``c`` the ``|d|``-weighted mean
    of g. Mathematically any ``c`` gives the same value, but ``Σd`` carries rounding of order
    ``ulp(σ)``, which ``c`` multiplies: near the optimum the plain mean of g (inactive sensors
    included) turns that into an error larger than the true slope and stops Newton early (with
    gap/η ≈ 1e-10 at N = 50); on the step's own support ``g − c`` is of the size of the gap."""
    w = np.abs(d)
    total = float(w.sum())
    c = float(w @ g) / total if total > 0.0 else float(g.mean())
    return float((g - c) @ d)


def newton(
    net: CostOracle,
    n_sens: int,
    r_min: float,
    sigma: float,
    tol: float,
    max_iter: int,
    g0: F64,
    mode: str,
    warm_min_order: int | None = None,
    start_sigma: F64 | None = None,
) -> tuple[F64, int, _Points]:
    """Newton's method from ``g0`` (variant ``mode``, ``"exact"`` or ``"hvp"``) until the
    certificate ``gap ≤ tol·|η|``; returns ``(γ, steps, the point cache)``. Each evaluation point
    is warm-started from the previous one from order ``warm_min_order`` on (default
    :data:`~.oracle.WARM_START_MIN_ORDER`); the first one from ``start_sigma`` (a matrix near
    ``Σ(r_min + g0)``) when given."""
    pts = _Points(net, warm_min_order)
    if start_sigma is not None:
        pts.seed(g0 + r_min, start_sigma)
    precondition = _Preconditioner(net, n_sens) if mode == "hvp" else None
    gamma = g0.copy()
    stall = _Stall(3)
    for it in range(max_iter):
        r = gamma + r_min
        f, g = pts.value_gradient(r)
        gap = frank_wolfe_gap(gamma, g)
        if gap <= tol * max(abs(f), 1e-300):
            return gamma, it, pts
        if precondition is not None:
            mu = float(gamma @ g) / sigma
            free = np.flatnonzero((gamma > 0.0) | (g < mu))
            dinv = precondition(r)
            forcing = _forcing(gap / max(abs(f), 1e-300))
            d, _ = face_cg(
                lambda v: pts.hvp(r, v),  # noqa: B023
                g,
                gamma,
                None,
                free,
                dinv,
                forcing,
                budget=max(free.size, 1),
            )
        else:
            h = regularised_hessian(pts.hessian(r))
            # QP in the variable x = γ + d: minimise (g − Hγ)ᵀx + ½ xᵀHx over the simplex.
            x = simplex_qp(h, g - h @ gamma, gamma, sigma, max_iter=20 * n_sens + 100)
            d = x - gamma
        slope = _slope(g, d)
        if slope >= 0.0 or stall.stalled(gap):
            return gamma, it, pts  # no descent left, or the certificate is at its rounding floor
        gamma_new, _, ok = _armijo(
            net,
            r_min,
            gamma,
            d,
            f,
            slope,
            full_step_in_noise=True,
            first=pts.trial_cost,
            sigma=sigma,
        )
        if not ok:  # no decrease representable in floating point
            return gamma, it, pts
        gamma = gamma_new
    raise ConvergenceError(f"newton did not converge in {max_iter} iterations")


#: ``engine="auto"`` runs the exact-Hessian Newton loop in the Rust core (one call, no Python
#: round trip per evaluation) up to this many sensors; above it the Python loop, whose Hessian
#: spreads its ``N`` solves over every core.
CORE_NEWTON_MAX_SENSORS = 24


def core_model(net: Any) -> Any:
    """The Rust cost model behind ``net`` (a :class:`capalloc_rs.Network`), else ``None``."""
    model = getattr(net, "_model", None)
    return model if isinstance(model, _core.CostModel) else None


def newton_in_core(
    net: Any,
    r_min: float,
    sigma: float,
    tol: float,
    max_iter: int,
    g0: F64,
    warm_min_order: int | None,
) -> tuple[F64, int, tuple[float, F64], float]:
    """:func:`newton` with ``mode="exact"``, the whole loop in Rust
    (``CostModel.newton_exact``: the same steps, QP, line search and stopping rules); returns
    ``(γ, steps, (η, ∇η) at γ, the bound on |η − η_exact|)``.

    Raises:
        ConvergenceError: more than ``max_iter`` steps.
    """
    model = core_model(net)
    assert model is not None
    threshold = WARM_START_MIN_ORDER if warm_min_order is None else warm_min_order
    res = model.newton_exact(
        r_min, sigma, g0, tol, max_iter, int(getattr(net, "n", 0)) >= threshold
    )
    gamma = np.array(res.gamma, dtype=np.float64)
    grad = np.array(res.gradient, dtype=np.float64)
    return gamma, int(res.iterations), (float(res.value), grad), float(res.value_error)
