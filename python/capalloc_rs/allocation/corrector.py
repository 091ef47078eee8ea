"""The predictor–corrector of the optimal allocation path on a fixed active set ``J``
(Proposition 5): Newton's method on the KKT system ``∂η/∂γ_J = μ·1``, ``1ᵀγ_J = σ``,
``γ_{J^c} = 0`` (bordered solve ``[[η''_JJ, −1], [1ᵀ, 0]] [δγ; δμ] = −[g_J − μ1; 1ᵀγ_J − σ]``),
the tangent ``df_J/dσ = x'/(1ᵀx')``, ``dμ/dσ = 1/(1ᵀx')`` with ``x' = [η''_JJ]⁻¹ 1``, and the
event functions whose sign changes are the breakpoints of Theorem 2.

On the box-simplex of :mod:`.channel_box` the sensors at their caps ``U`` are held at
``γ_U = c_U``: the face is the free set ``J`` and its sum condition ``1ᵀγ_J = σ − 1ᵀc_U``; the
event functions gain ``(μ − g_j)/|μ|`` for ``j ∈ U`` (it leaves its cap at 0) and a third block
``c_i − γ_i`` for ``i ∈ J`` (it reaches its cap at 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .channel_box import ChannelBox, channel_box
from .oracle import PointCache
from .simplex import face_kkt_solve

__all__: list[str] = []

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class _Point:
    sigma: float
    gamma: F64
    mu: float
    dgamma: F64  # right derivative df/dσ with the active set of the segment
    dmu: float  # dμ/dσ = 1/(1ᵀx')
    dd: bool  # [η''_JJ]⁻¹ strictly diagonally dominant here
    iterations: int


class _Tracer:
    """Newton corrector and tangent for a fixed active set."""

    def __init__(
        self, net: Any, tol: float, max_newton: int = 30, *, box: ChannelBox | None = None
    ) -> None:
        box = channel_box(net) if box is None else box
        self.net = box.net
        self.box = box
        self.lo, self.cap = box.lo, box.cap
        # consecutive corrector points are close: warm starts
        self.oracle = PointCache(box.net)
        self.r_min = box.r_min
        self.n = len(box.net.sensors)
        self.tol = tol
        self.max_newton = max_newton
        # Diagnostics of the last corrector call (for the stall message).
        self.last_residual = math.nan
        self.last_mu = math.nan

    def correct(
        self, active: list[int], sigma: float, gamma0: F64, mu0: float, capped: Any = ()
    ) -> _Point:
        """The path point at ``sigma`` on the free set ``active`` (the sensors ``capped`` at
        their caps) by Newton from ``(gamma0, mu0)``.

        Raises:
            ConvergenceError: no convergence within ``max_newton`` iterations.
        """
        jj = np.array(active, dtype=np.intp)
        gamma = np.zeros(self.n)
        gamma[jj] = gamma0[jj]
        uu = np.array(capped, dtype=np.intp)
        free_sum = sigma
        if uu.size:
            gamma[uu] = self.cap[uu]
            free_sum = sigma - float(self.cap[uu].sum())
        mu = mu0
        for it in range(self.max_newton):
            if not np.all((gamma[jj] > -0.5 * self.lo[jj]) | (gamma[jj] >= 0.0)):
                break  # the rates γ + r_min must stay positive (and finite): η is defined there
            _, g, h = self.oracle.value_gradient_hessian(gamma + self.lo)
            resid = np.concatenate([g[jj] - mu, [gamma[jj].sum() - free_sum]])
            k = jj.size
            scale_g = max(abs(mu), float(np.max(np.abs(g[jj]))), 1e-300)
            self.last_residual = float(np.max(np.abs(resid[:k]))) / scale_g
            self.last_mu = mu
            converged = float(np.max(np.abs(resid[:k]))) <= 1e-13 * scale_g and abs(
                resid[k]
            ) <= 1e-14 * max(sigma, 1.0)
            if converged or it == self.max_newton - 1:
                if not converged:
                    break
                return self._point(jj, sigma, gamma, mu, h, it)
            hjj = h[np.ix_(jj, jj)]
            try:
                step, dmu = face_kkt_solve(0.5 * (hjj + hjj.T), -resid[:k], -resid[k])
            except np.linalg.LinAlgError:
                break
            gamma[jj] += step
            mu += dmu
            if not np.all(np.isfinite(gamma)) or np.any(gamma[jj] < -0.5 * max(sigma, 1e-300)):
                break
            if (
                float(np.max(np.abs(step))) <= 1e-15 * max(sigma, 1.0)
                and float(np.max(np.abs(resid[:k]))) <= 1e-10 * scale_g
            ):
                return self._point(jj, sigma, gamma, mu, h, it + 1)
        raise ConvergenceError(f"path corrector did not converge at σ = {sigma:.6g}")

    def _point(
        self, jj: npt.NDArray[np.intp], sigma: float, gamma: F64, mu: float, h: F64, its: int
    ) -> _Point:
        hjj = 0.5 * (h[np.ix_(jj, jj)] + h[np.ix_(jj, jj)].T)
        minv = np.linalg.inv(hjj)
        xp = minv @ np.ones(jj.size)
        dg = np.zeros(self.n)
        dg[jj] = xp / xp.sum()
        off = np.sum(np.abs(minv), axis=1) - np.abs(np.diag(minv))
        dd = bool(np.all(np.abs(np.diag(minv)) > off)) if jj.size > 1 else True
        return _Point(sigma, gamma.copy(), float(mu), dg, float(1.0 / xp.sum()), dd, its)

    def events(self, active: list[int], p: _Point, capped: Any = ()) -> F64:
        """Event functions at p (positive = nothing happened): for j ∉ J, (g_j − μ)/|μ|
        ((μ − g_j)/|μ| for the capped j); for i ∈ J, γ_i/σ_scale and the derivative df_i/dσ;
        with finite caps a third block, c_i − γ_i for i ∈ J."""
        _, g = self.oracle.value_gradient(p.gamma + self.lo)
        caps = self.box.has_caps
        out = np.empty((3 if caps else 2) * self.n)
        mask = np.zeros(self.n, dtype=bool)
        mask[active] = True
        scale = max(abs(p.mu), 1e-300)
        out[: self.n] = np.where(mask, p.gamma, (g - p.mu) / scale)
        out[self.n : 2 * self.n] = np.where(mask, p.dgamma, 1.0)
        if caps:
            up = np.zeros(self.n, dtype=bool)
            up[list(capped)] = True
            out[: self.n] = np.where(up, (p.mu - g) / scale, out[: self.n])
            room = mask & np.isfinite(self.cap)
            out[2 * self.n :] = np.where(room, self.cap - p.gamma, 1.0)
        return out
