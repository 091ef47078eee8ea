"""First-order methods for Theorem 1's problem, gradient only.

* spectral (Barzilai–Borwein) projected gradient with Armijo backtracking along the projection
  arc;
* the paper's Appendix D double-bracket flow ``Ḣ = −σ[H, [H, diag ∇η(σ diag H)]]`` on
  ``H = vvᵀ``, ``‖v‖ = 1``, i.e. the replicator equation ``γ̇_i = −2σ γ_i (g_i − γᵀg/σ)``,
  integrated with an adaptive Dormand–Prince 5(4) pair until the Frank–Wolfe certificate holds.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError, InvalidInputError
from .newton import _armijo
from .oracle import CostOracle, value_gradient
from .simplex import _fix_sum, _Stall, frank_wolfe_gap, project_simplex

__all__ = ["FLOW_TOL", "double_bracket", "projected_gradient"]

F64 = npt.NDArray[np.float64]

#: The double-bracket flow's certificate floor (relative gap): near a breakpoint the replicator
#: moves at a speed proportional to the small γ_i, so tighter gaps cost unbounded time.
FLOW_TOL = 1e-9


def projected_gradient(
    net: CostOracle, r_min: float, sigma: float, tol: float, max_iter: int, g0: F64
) -> tuple[F64, int]:
    gamma = g0.copy()
    stall = _Stall(100)
    f, g = value_gradient(net, gamma + r_min)
    alpha = sigma / max(float(np.max(np.abs(g))), 1e-300)
    for it in range(max_iter):
        if frank_wolfe_gap(gamma, g) <= tol * max(abs(f), 1e-300):
            return gamma, it
        d = project_simplex(gamma - alpha * g, sigma) - gamma
        slope = float((g - g.mean()) @ d)  # Σd = 0: drop μ·Σd, which is pure rounding
        if slope >= 0.0 or stall.stalled(frank_wolfe_gap(gamma, g)):
            return gamma, it
        gamma_new, f_new, ok = _armijo(net, r_min, gamma, d, f, slope)
        if not ok:
            return gamma, it
        gamma_new = _fix_sum(gamma_new, sigma)
        f_new, g_new = value_gradient(net, gamma_new + r_min)
        s, y = gamma_new - gamma, g_new - g
        sy = float(s @ y)
        alpha = float(s @ s) / sy if sy > 0 else alpha * 2.0  # Barzilai–Borwein step
        alpha = min(max(alpha, 1e-12 * sigma), 1e12 * sigma)
        gamma, f, g = gamma_new, f_new, g_new
    raise ConvergenceError(
        f"projected-gradient did not reach the certificate in {max_iter} iterations "
        f"(gap {frank_wolfe_gap(gamma, g):.3e})"
    )


# Dormand–Prince 5(4) tableau.
_DP_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0)
_DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),
)
_DP_B5 = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0)
_DP_B4 = (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40)


def double_bracket(
    net: CostOracle, n_sens: int, r_min: float, sigma: float, tol: float, max_steps: int, g0: F64
) -> tuple[F64, int]:
    """Integrates ``v̇ = −σ (D − (vᵀDv) I) v``, ``D = diag ∇η(r_min + σ v∘v)``, from
    ``v(0) = sqrt(γ0/σ)`` (no zero entry) until the Frank–Wolfe certificate holds."""
    if np.any(g0 <= 0.0):
        raise InvalidInputError("the double-bracket flow needs a start with no zero entry")
    v = np.sqrt(g0 / sigma)

    def rhs(v: F64) -> F64:
        g = np.asarray(net.gradient(sigma * v * v + r_min), dtype=np.float64)
        return -sigma * (g - float(g @ (v * v))) * v

    gam = sigma * v * v
    f, g = value_gradient(net, gam + r_min)
    k1 = -sigma * (g - float(g @ (v * v))) * v
    h = 0.1 / (sigma * max(float(np.max(np.abs(g))), 1e-300))
    rtol, atol = 1e-9, 1e-12
    accepted = 0
    for _ in range(max_steps):
        if frank_wolfe_gap(gam, g) <= tol * max(abs(f), 1e-300):
            return gam, accepted
        ks = [k1]
        for stage in range(1, 7):
            vs = v + h * sum(a * k for a, k in zip(_DP_A[stage], ks, strict=False))
            ks.append(rhs(vs))
        v5 = v + h * sum(b * k for b, k in zip(_DP_B5, ks, strict=True))
        v4 = v + h * sum(b * k for b, k in zip(_DP_B4, ks, strict=True))
        scale = atol + rtol * np.maximum(np.abs(v), np.abs(v5))
        err = float(np.sqrt(np.mean(((v5 - v4) / scale) ** 2)))
        if err <= 1.0:
            v = v5 / np.linalg.norm(v5)  # stay on the unit sphere (H = vvᵀ has unit trace)
            accepted += 1
            gam = sigma * v * v
            f, g = value_gradient(net, gam + r_min)
            k1 = -sigma * (g - float(g @ (v * v))) * v
        factor = 0.9 * err ** (-0.2) if err > 0 else 5.0
        h *= min(5.0, max(0.2, factor))
    raise ConvergenceError(
        f"double-bracket flow did not reach the certificate in {max_steps} steps "
        f"(gap {frank_wolfe_gap(gam, g):.3e})"
    )
