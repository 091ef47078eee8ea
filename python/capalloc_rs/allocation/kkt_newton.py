"""Newton's method on the KKT system of a face of the simplex with one side condition — the
corrector of the path following in :mod:`.continuation`.

On a fixed active set ``J`` the optimal allocation solves ``g_J(γ) = μ·1`` (``g = ∂η/∂γ``,
``γ_{J^c} = 0``). These ``|J|`` equations in ``|J| + 1`` unknowns ``(γ_J, μ)`` are closed by one
side condition, which picks the point of the path we want:

* ``("sigma", σ)`` — the node at height σ: ``1ᵀγ_J = σ``;
* ``("enter", j)`` — the breakpoint where the inactive sensor ``j`` enters: ``g_j(γ) = μ``
  (σ is then an unknown, ``σ = 1ᵀγ_J``);
* ``("leave", i)`` — the breakpoint where the active sensor ``i`` leaves: ``γ_i = 0``.

With ``H = η''_JJ``, ``x' = H⁻¹1`` and ``z = H⁻¹(g_J − μ1)``, every Newton step is
``δγ_J = δμ·x' − z`` with the scalar ``δμ`` fixed by the linearised side condition:
``δμ = (1ᵀz − (1ᵀγ_J − σ))/1ᵀx'``, ``δμ = (H_jJ·z − (g_j − μ))/(H_jJ·x' − 1)`` and
``δμ = (z_i − γ_i)/x'_i`` respectively. So the event is found by Newton's method on the KKT
system extended by the event function — quadratically, from the tangent data — instead of by
bracketing with pointwise solves. At the solution ``x'`` is the exact tangent of Proposition 5:
``df_J/dσ = x'/1ᵀx'``, ``dμ/dσ = 1/1ᵀx'``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .corrector import _Point
from .oracle import PointCache

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
SideKind = Literal["sigma", "enter", "leave"]


@dataclass(frozen=True)
class Side:
    """The side condition closing the KKT system: ``kind`` and its number (σ, or the sensor)."""

    kind: SideKind
    value: float


@dataclass(frozen=True, eq=False)
class Node:
    """A point of the path (``point``) with what the event functions need there: the full
    gradient ``g`` and Hessian ``h`` of η (``h`` gives ``H·df/dσ``, the events' slopes)."""

    point: _Point
    g: F64
    h: F64

    @property
    def sigma(self) -> float:
        """σ of the node."""
        return self.point.sigma

    def slopes(self) -> F64:
        """``d(g − μ)/dσ = H·df/dσ − dμ/dσ`` for every sensor (the enter events' slopes)."""
        return np.asarray(self.h @ self.point.dgamma - self.point.dmu, dtype=np.float64)


def tangent_point(
    jj: npt.NDArray[np.intp], sigma: float, gamma: F64, mu: float, h: F64, its: int
) -> _Point:
    """The path point at ``(γ, μ)`` with the exact tangent ``x'/1ᵀx'``, ``x' = [η''_JJ]⁻¹1``, and
    the check of Theorem 2's condition (``[η''_JJ]⁻¹`` strictly diagonally dominant)."""
    n = gamma.size
    hjj = 0.5 * (h[np.ix_(jj, jj)] + h[np.ix_(jj, jj)].T)
    minv = np.linalg.inv(hjj)
    xp = minv @ np.ones(jj.size)
    dg = np.zeros(n)
    dg[jj] = xp / xp.sum()
    off = np.sum(np.abs(minv), axis=1) - np.abs(np.diag(minv))
    dd = bool(np.all(np.abs(np.diag(minv)) > off)) if jj.size > 1 else True
    return _Point(sigma, gamma.copy(), float(mu), dg, float(1.0 / xp.sum()), dd, its)


class KKTNewton:
    """Newton's method on the KKT system of a face with a side condition (module docstring),
    each iterate one evaluation point (value, gradient, Hessian) of η, warm-started from the
    last through :class:`.oracle.PointCache`. Counts the evaluation points it asks for."""

    def __init__(self, net: Any, max_newton: int = 30) -> None:
        self.cache = PointCache(net)
        self.r_min = float(net.r_min)
        self.n = len(net.sensors)
        self.max_newton = max_newton
        self.evaluations = 0
        self.last_residual = math.nan

    def _evaluate(self, gamma: F64) -> tuple[F64, F64]:
        self.evaluations += 1
        _, g, h = self.cache.value_gradient_hessian(gamma + self.r_min)
        return g, h

    def retangent(self, node: Node, active: list[int]) -> Node:
        """The same point with the tangent of another active set (after an event): no new
        evaluation, the Hessian is the node's."""
        jj = np.array(active, dtype=np.intp)
        p = node.point
        return Node(tangent_point(jj, p.sigma, p.gamma, p.mu, node.h, 0), node.g, node.h)

    def solve(self, active: list[int], gamma0: F64, mu0: float, side: Side) -> Node:
        """The path point on ``active`` meeting ``side``, by Newton from ``(gamma0, mu0)``.

        Raises:
            ConvergenceError: no convergence within ``max_newton`` iterations, a rate below
                ``r_min/2`` (outside where η is evaluated), or a singular system.
        """
        jj = np.array(active, dtype=np.intp)
        gamma = np.zeros(self.n)
        gamma[jj] = gamma0[jj]
        mu = float(mu0)
        for it in range(self.max_newton):
            if not np.all(gamma[jj] > -0.5 * self.r_min):
                break  # rates r = γ + r_min stay above r_min/2: η is evaluated only there
            g, h = self._evaluate(gamma)
            resid = g[jj] - mu
            sigma = self._sigma(gamma, jj, side)
            scale_g = max(abs(mu), float(np.max(np.abs(g[jj]))), 1e-300)
            self.last_residual = float(np.max(np.abs(resid))) / scale_g
            if self._converged(resid, scale_g, gamma, g, mu, jj, side):
                return Node(tangent_point(jj, sigma, gamma, mu, h, it), g, h)
            try:
                step, dmu = self._step(h, jj, resid, gamma, g, mu, side)
            except np.linalg.LinAlgError:
                break
            gamma[jj] += step
            mu += dmu
            if side.kind == "leave":
                gamma[int(side.value)] = 0.0
            if not (np.all(np.isfinite(gamma)) and math.isfinite(mu)):
                break
            if np.any(gamma[jj] < -0.5 * max(sigma, 1e-300)) and side.kind == "sigma":
                break
        raise ConvergenceError(
            f"path corrector did not converge ({side.kind} {side.value:.6g}, "
            f"relative residual {self.last_residual:.1e})"
        )

    @staticmethod
    def _sigma(gamma: F64, jj: npt.NDArray[np.intp], side: Side) -> float:
        return float(side.value) if side.kind == "sigma" else float(gamma[jj].sum())

    @staticmethod
    def _converged(
        resid: F64, scale_g: float, gamma: F64, g: F64, mu: float, jj: Any, side: Side
    ) -> bool:
        if float(np.max(np.abs(resid))) > 1e-13 * scale_g:
            return False
        if side.kind == "sigma":
            return abs(float(gamma[jj].sum()) - side.value) <= 1e-14 * max(side.value, 1.0)
        if side.kind == "enter":
            return abs(float(g[int(side.value)]) - mu) <= 1e-13 * scale_g
        return bool(gamma[int(side.value)] == 0.0)

    @staticmethod
    def _step(
        h: F64, jj: npt.NDArray[np.intp], resid: F64, gamma: F64, g: F64, mu: float, side: Side
    ) -> tuple[F64, float]:
        """The Newton step ``(δγ_J, δμ)`` (module docstring)."""
        hjj = 0.5 * (h[np.ix_(jj, jj)] + h[np.ix_(jj, jj)].T)
        sol = np.linalg.solve(hjj, np.column_stack([np.ones(jj.size), resid]))
        xp, z = sol[:, 0], sol[:, 1]
        if side.kind == "sigma":
            dmu = (float(z.sum()) - (float(gamma[jj].sum()) - side.value)) / float(xp.sum())
        elif side.kind == "enter":
            row = h[int(side.value), jj]
            dmu = (float(row @ z) - (float(g[int(side.value)]) - mu)) / (float(row @ xp) - 1.0)
        else:
            k = int(np.flatnonzero(jj == int(side.value))[0])
            dmu = (float(z[k]) - float(gamma[int(side.value)])) / float(xp[k])
        if not math.isfinite(dmu):
            raise np.linalg.LinAlgError("singular side condition")
        return dmu * xp - z, dmu
