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

Each iterate evaluates η once. Small networks form the Hessian at every iterate (exact Newton).
From :data:`~capalloc_rs.allocation.optimal.HVP_MIN_SENSORS` sensors on, where forming the
Hessian costs several Riccati solves, no iterate forms it: the solves with ``η''_JJ`` are
conjugate gradients on Hessian-vector products at the iterate, preconditioned by a reference
Hessian formed at an earlier point (:mod:`.face_hessian`) — an inexact Newton step, solved to the
square root of the residual, and at the node the exact tangent (to 1e-10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .corrector import _Point
from .face_hessian import CG_TOL, ExactFace, KrylovFace, Reference
from .oracle import PointCache

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
SideKind = Literal["sigma", "enter", "leave"]
Face = ExactFace | KrylovFace
#: Relative residual (gradient, side condition) from which one more Newton step is the last
#: (Newton's quadratic convergence puts the next residual near its square, ~1e-14), provided the
#: step is below ``_FINAL_STEP`` relative to the largest share and the residual has just fallen
#: at least to the power 1.5 of the one before (superlinear: not a plateau of rounding errors,
#: where the node must meet the 1e-13 test itself or the path stalls).
_FINAL = 1e-7
#: Relative residual of the linear solves at a node (its tangent ``η''_JJ x' = 1``) and in the
#: last Newton step (iterative only with Hessian-vector products; direct otherwise): the
#: tangent is exact to this, the last step's error is this times the residual ≤ 1e-7.
TANGENT_TOL = 1e-10
_FINAL_STEP = 1e-6


@dataclass(frozen=True)
class Side:
    """The side condition closing the KKT system: ``kind`` and its number (σ, or the sensor)."""

    kind: SideKind
    value: float


@dataclass(frozen=True, eq=False)
class Node:
    """A point of the path (``point``) with what the event functions need there: the full
    gradient ``g``, ``hdg = η''·df/dσ`` (the events' slopes) and the Hessian on faces at this
    point (``face``: a new tangent after an event costs no new evaluation)."""

    point: _Point
    g: F64
    hdg: F64
    face: Face

    @property
    def sigma(self) -> float:
        """σ of the node."""
        return self.point.sigma

    def slopes(self) -> F64:
        """``d(g − μ)/dσ = H·df/dσ − dμ/dσ`` for every sensor (the enter events' slopes)."""
        return np.asarray(self.hdg - self.point.dmu, dtype=np.float64)


def make_node(
    jj: npt.NDArray[np.intp], sigma: float, gamma: F64, mu: float, g: F64, face: Face, its: int
) -> Node:
    """The path node at ``(γ, μ)`` with the exact tangent ``x'/1ᵀx'``, ``x' = [η''_JJ]⁻¹1``, the
    check of Theorem 2's condition (``[η''_JJ]⁻¹`` strictly diagonally dominant) and the event
    slopes ``η''·df/dσ``."""
    xp = face.tangent(jj, TANGENT_TOL)
    dg = np.zeros(gamma.size)
    dg[jj] = xp / xp.sum()
    p = _Point(sigma, gamma.copy(), float(mu), dg, float(1.0 / xp.sum()), face.dominant(jj), its)
    return Node(p, g, face.hvp(dg), face)


class KKTNewton:
    """Newton's method on the KKT system of a face with a side condition (module docstring),
    each iterate one evaluation point of η, warm-started from the last through
    :class:`.oracle.PointCache`. With ``krylov`` (needs ``net.at``) the iterates form no
    Hessian: steps and tangent are solved by preconditioned conjugate gradients on
    Hessian-vector products (:mod:`.face_hessian`); else every iterate forms the Hessian.
    Counts evaluation points and Hessians."""

    def __init__(self, net: Any, krylov: bool, max_newton: int = 30) -> None:
        self.cache = PointCache(net)
        self.r_min = float(net.r_min)
        self.n = len(net.sensors)
        self.max_newton = max_newton
        self.krylov = krylov and self.cache.at is not None
        self.ref = Reference()
        self.evaluations = 0
        self.hessians = 0
        self.last_residual = math.nan

    def _evaluate(self, gamma: F64) -> tuple[F64, Face]:
        self.evaluations += 1
        r = gamma + self.r_min
        if not self.krylov:
            self.hessians += 1
            _, g, h = self.cache.value_gradient_hessian(r)
            return g, ExactFace(h)
        point = self.cache.point(r)
        fresh = self.ref.h is None
        if fresh:
            self.ref.form(point)
        return np.asarray(point.gradient, dtype=np.float64), KrylovFace(point, self.ref, fresh)

    def counts(self) -> dict[str, int]:
        """Evaluation points, Hessians formed (as Newton matrices or references) so far."""
        return {"evaluations": self.evaluations, "hessians": self.hessians + self.ref.formed}

    def retangent(self, node: Node, active: list[int]) -> Node:
        """The same point with the tangent of another active set (after an event): no new
        evaluation of η."""
        jj = np.array(active, dtype=np.intp)
        p = node.point
        return make_node(jj, p.sigma, p.gamma, p.mu, node.g, node.face, 0)

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
        previous = 0.0  # the last iterate's relative residual
        for it in range(self.max_newton):
            if not np.all(gamma[jj] > -0.5 * self.r_min):
                break  # rates r = γ + r_min stay above r_min/2: η is evaluated only there
            g, face = self._evaluate(gamma)
            resid = g[jj] - mu
            sigma = self._sigma(gamma, jj, side)
            scale_g = max(abs(mu), float(np.max(np.abs(g[jj]))), 1e-300)
            self.last_residual = float(np.max(np.abs(resid))) / scale_g
            if self._converged(resid, scale_g, gamma, g, mu, jj, side):
                return make_node(jj, sigma, gamma, mu, g, face, it)
            # The last step only after converging superlinearly (not on a rounding plateau).
            final = previous**1.5 >= self.last_residual and self._final(
                resid, scale_g, gamma, g, mu, jj, side
            )
            previous = self.last_residual
            # Inexact Newton: the linear solves to the square root of the residual (≤ 0.1).
            tol = TANGENT_TOL if final else min(1e-1, max(self.last_residual**0.5, CG_TOL))
            try:
                step, dmu = self._step(face, jj, resid, (gamma, g, mu), side, tol)
            except np.linalg.LinAlgError:
                break
            gamma[jj] += step
            mu += dmu
            if side.kind == "leave":
                gamma[int(side.value)] = 0.0
            big = max(float(np.max(np.abs(gamma[jj]))), self.r_min)
            if final and float(np.max(np.abs(step))) <= _FINAL_STEP * big:
                # The last step, from a residual ≤ 1e-7: its result has residual about the
                # square (Newton), so it is not evaluated again; the gradient there to second
                # order, g + η''·δγ, and the tangent with the Hessian one step back.
                full = np.zeros(self.n)
                full[jj] = step
                g_new = g + face.hvp(full)
                return make_node(jj, self._sigma(gamma, jj, side), gamma, mu, g_new, face, it + 1)
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
    def _final(
        resid: F64, scale_g: float, gamma: F64, g: F64, mu: float, jj: Any, side: Side
    ) -> bool:
        """Every residual ≤ :data:`_FINAL` (relative): the next Newton step is the last."""
        if float(np.max(np.abs(resid))) > _FINAL * scale_g:
            return False
        if side.kind == "sigma":
            return abs(float(gamma[jj].sum()) - side.value) <= _FINAL * max(side.value, 1.0)
        if side.kind == "enter":
            return abs(float(g[int(side.value)]) - mu) <= _FINAL * scale_g
        return abs(float(gamma[int(side.value)])) <= _FINAL * max(float(gamma[jj].sum()), 1.0)

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
        face: Face,
        jj: npt.NDArray[np.intp],
        resid: F64,
        state: tuple[F64, F64, float],
        side: Side,
        tol: float,
    ) -> tuple[F64, float]:
        """The Newton step ``(δγ_J, δμ)`` (module docstring); the solves with ``η''_JJ`` to
        relative accuracy ``tol`` (inexact Newton with Hessian-vector products)."""
        gamma, g, mu = state
        xp, z = face.tangent(jj, tol), face.solve(jj, resid, tol)
        sol = np.column_stack([xp, z])
        if side.kind == "sigma":
            dmu = (float(z.sum()) - (float(gamma[jj].sum()) - side.value)) / float(xp.sum())
        elif side.kind == "enter":
            hx, hz = face.row(int(side.value), jj, sol, exact=tol <= TANGENT_TOL)
            dmu = (hz - (float(g[int(side.value)]) - mu)) / (hx - 1.0)
        else:
            k = int(np.flatnonzero(jj == int(side.value))[0])
            dmu = (float(z[k]) - float(gamma[int(side.value)])) / float(xp[k])
        if not math.isfinite(dmu):
            raise np.linalg.LinAlgError("singular side condition")
        return dmu * xp - z, dmu
