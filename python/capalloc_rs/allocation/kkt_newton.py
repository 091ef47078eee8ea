"""Newton's method on the KKT system of a face of the simplex with one side condition — the
corrector of the path following in :mod:`.continuation`.

On a fixed active set ``J`` the optimal allocation solves ``g_J(γ) = μ·1`` (``g = ∂η/∂γ``,
``γ_{J^c} = 0``). These ``|J|`` equations in ``|J| + 1`` unknowns ``(γ_J, μ)`` are closed by one
side condition, which picks the point of the path we want:

* ``("sigma", σ)`` — the node at height σ: ``1ᵀγ_J = σ``;
* ``("enter", j)`` — the breakpoint where the inactive sensor ``j`` enters: ``g_j(γ) = μ``
  (σ is then an unknown, ``σ = 1ᵀγ_J``);
* ``("leave", i)`` — the breakpoint where the active sensor ``i`` leaves: ``γ_i = 0``;
* ``("cap", i)`` — the breakpoint where the active sensor ``i`` reaches its cap: ``γ_i = c_i``.

On the box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` (:mod:`.channel_box`) the sensors at their caps ``U``
are held at ``γ_U = c_U`` like the inactive ones at 0: the face is the free set ``J``, the
``σ`` condition reads ``1ᵀγ_J = σ − 1ᵀc_U`` and a capped sensor ``j`` leaves its cap where
``g_j = μ`` — the ``"enter"`` condition again.

With ``H = η''_JJ``, ``x' = H⁻¹1`` and ``z = H⁻¹(g_J − μ1)``, every Newton step is
``δγ_J = δμ·x' − z`` with the scalar ``δμ`` fixed by the linearised side condition:
``δμ = (1ᵀz − (1ᵀγ_J − σ))/1ᵀx'``, ``δμ = (H_jJ·z − (g_j − μ))/(H_jJ·x' − 1)`` and
``δμ = (z_i − (γ_i − t))/x'_i`` (``t = 0`` or ``c_i``) respectively. So the event is found
by Newton's method on the KKT system extended by the event function — quadratically, from the
tangent data — instead of by bracketing with pointwise solves. At the solution ``x'`` is the
exact tangent of Proposition 5: ``df_J/dσ = x'/1ᵀx'``, ``dμ/dσ = 1/1ᵀx'``.

Each iterate evaluates η once. Small networks form the Hessian at every iterate (exact Newton);
with ``quick`` (the current path follower) only its principal block on the face and the entering
sensor (``|J| + 1`` Lyapunov solves instead of ``N``; a node completes the products it records,
the events' slopes, with one or two Hessian-vector products), and every evaluation point is
warm-started from the last one (:class:`.oracle.PointCache`).
From :data:`~capalloc_rs.allocation.optimal.HVP_MIN_SENSORS` sensors on, where forming the
Hessian costs several Riccati solves, no iterate forms it: the solves with ``η''_JJ`` are
conjugate gradients on Hessian-vector products at the iterate, preconditioned by a reference
Hessian formed at an earlier point (:mod:`.face_hessian`) — an inexact Newton step, solved to the
residual (forcing term ``ρ``: still quadratic), and at the node the exact tangent (to 1e-10). The
conjugate gradients carry the full product ``η''·x`` along, so the enter condition's row, the
event slopes ``η''·df/dσ`` and the gradient after the last (unevaluated) step cost no product.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from ..errors import ConvergenceError
from .channel_box import ChannelBox, channel_box
from .corrector import _Point
from .face_hessian import CG_TOL, BlockFace, ExactFace, KrylovFace, Reference, Solved
from .oracle import PointCache

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
SideKind = Literal["sigma", "enter", "leave", "cap"]
Face = ExactFace | KrylovFace | BlockFace
#: Relative residual (gradient, side condition) from which one more Newton step may be the last,
#: namely when the quadratic model of the residuals, ``ρ_{k+1} ≈ C·ρ_k²`` with ``C`` measured on
#: the last two (``C = ρ_k/ρ_{k−1}²``), predicts at most :data:`_PREDICTED` after it, the
#: residual has just fallen at least to the power 1.5 of the one before (superlinear: not a
#: plateau of rounding errors, where the node must meet the 1e-13 test itself or the path
#: stalls) and the step is below ``_FINAL_STEP`` relative to the largest share.
_FINAL = 1e-5
_PREDICTED = 1e-13
#: With ``quick`` (:class:`KKTNewton`) the residual of that model is the larger of the gradient's
#: and the side condition's (both relative): a step that mainly moves along the path (the side
#: condition off, the KKT residual already small) is then judged by what it will change, and the
#: last step may be taken from a predicted residual of this (about 1e-2 of the default
#: ``tol = 1e-10`` of the breakpoints, :func:`~capalloc_rs.allocation.filtration.filtration`).
_PREDICTED_QUICK = 1e-12
#: With ``quick``, the evaluation points of the path are warm-started from the last one
#: (:class:`.oracle.PointCache`) from this state order on: consecutive Newton iterates and path
#: nodes are close. Replaying the points of the path (process time, best of 2): the warm starts
#: cost 0.69 of the cold solves at order 40 (N = 20; 15 of its 67 points take 3–8 ms in the
#: compensated refinement after a stalled warm iteration, the others about 0.9 ms against 1.9),
#: 0.85 at order 20, 1.0 at order 10.
PATH_WARM_MIN_ORDER = 16
#: From the path's fifth version on, each warm start first takes up to this many chord
#: corrections on the last point's Schur form (:meth:`CostPoint.warm`): a point close to the
#: last then needs one Schur form instead of one per Newton–Kleinman correction ...
PATH_CHORD_STEPS = 8
#: ... from this state order on (above the orders where a stalled warm iteration is refined with
#: compensated residuals). Below it the Schur forms saved cost less than the chord's solves:
#: N = 20 (n = 40), process time, best of 5: 153 ms without, 166 ms with.
PATH_CHORD_MIN_ORDER = 65
#: With ``quick``, from this many sensors on (and below
#: :data:`~capalloc_rs.allocation.optimal.HVP_MIN_SENSORS`) each iterate forms only the block of
#: the Hessian on its face and entering sensor (:class:`.face_hessian.BlockFace`): at N = 20 and
#: half the sensors free it costs half the full Hessian; below, the Hessian-vector products the
#: block needs at a node cost more than the solves saved.
BLOCK_MIN_SENSORS = 8
#: Relative residual of the linear solves at a node (its tangent ``η''_JJ x' = 1``) and in the
#: last Newton step (iterative only with Hessian-vector products; direct otherwise): the
#: tangent is exact to this, the last step's error is this times its starting residual
#: (≤ :data:`_FINAL`, and small enough that the quadratic model predicts ≤ :data:`_PREDICTED`).
TANGENT_TOL = 1e-10
#: With ``lean`` (the path's sixth version) the node's tangent is solved to this instead: it is
#: the tangent at the last evaluated iterate, up to a last step of relative size ≤ the residual
#: there (≤ :data:`_FINAL`), so its own error is of that order anyway; in the last step ``x'``
#: is solved to ``min(LEAN_TANGENT_TOL, 1e-13/ρ)`` (its error times ``δμ ~ ρ`` stays below
#: 1e-13 in the step, as ``z``'s does).
LEAN_TANGENT_TOL = 1e-7
_FINAL_STEP = 1e-6
#: Newton iterates are kept within this factor of the solve's scale (the largest starting share,
#: the σ asked for, the largest minimum): a path step or an event near it never moves the shares
#: that far, and beyond it the cost may not even be computable (an iterate of an event that is
#: not there, predicted from a poor model, runs off to huge rates). The solve then fails as a
#: corrector failure, and the step is retried shorter.
_RUNAWAY = 1e3
#: The forcing term of the inexact Newton steps before the last: the solves to ``FORCING·ρ``
#: (``ρ`` the relative residual), so that each step is a quadratic Newton step.
FORCING = 1.0


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
    jj: npt.NDArray[np.intp],
    state: tuple[float, F64, float, F64],
    face: Face,
    its: int,
    tangent: Solved | None = None,
    tol: float = TANGENT_TOL,
) -> Node:
    """The path node at ``state = (σ, γ, μ, g)`` with the exact tangent ``x'/1ᵀx'``, ``x' =
    [η''_JJ]⁻¹1`` (``tangent``: ``x'`` and ``η''_{:,J}x'`` if already solved at ``face``, else
    solved to the relative residual ``tol``), the check of Theorem 2's condition
    (``[η''_JJ]⁻¹`` strictly diagonally dominant) and the event slopes ``η''·df/dσ`` (from the
    solve's product: no further product)."""
    sigma, gamma, mu, g = state
    xp, hxp = face.tangent(jj, tol) if tangent is None else tangent
    hxp = face.complete(jj, xp, hxp)
    total = float(xp.sum())
    dg = np.zeros(gamma.size)
    dg[jj] = xp / total
    p = _Point(sigma, gamma.copy(), float(mu), dg, 1.0 / total, face.dominant(jj), its)
    return Node(p, g, hxp / total, face)


class KKTNewton:
    """Newton's method on the KKT system of a face with a side condition (module docstring),
    each iterate one evaluation point of η, warm-started from the last through
    :class:`.oracle.PointCache`. With ``krylov`` (needs ``net.at``) the iterates form no
    Hessian: steps and tangent are solved by preconditioned conjugate gradients on
    Hessian-vector products (:mod:`.face_hessian`); else every iterate forms the Hessian.
    Counts evaluation points and Hessians."""

    def __init__(
        self,
        net: Any,
        krylov: bool,
        max_newton: int = 30,
        *,
        box: ChannelBox | None = None,
        quick: bool = False,
        chord_steps: int = 0,
        lean: bool = False,
    ) -> None:
        box = channel_box(net) if box is None else box
        chord = chord_steps if int(getattr(box.net, "n", 0)) >= PATH_CHORD_MIN_ORDER else 0
        self.cache = PointCache(
            box.net, PATH_WARM_MIN_ORDER if quick else None, chord, compensated=not lean
        )
        #: The last-step rule on the larger of both residuals, to :data:`_PREDICTED_QUICK`.
        self.quick = quick
        self.lo, self.cap = box.lo, box.cap
        self.r_min = box.r_min
        self.n = len(box.net.sensors)
        self.blocks = quick and self.cache.at is not None and self.n >= BLOCK_MIN_SENSORS
        self.max_newton = max_newton
        self.krylov = krylov and self.cache.at is not None
        #: The sixth version (``lean``): node tangents to :data:`LEAN_TANGENT_TOL`, a new face's
        #: preconditioner seeded from the old face's solves, the first tangent solve started
        #: from a predicted tangent, warm starts without compensated refinement.
        self.lean = lean
        self.node_tol = LEAN_TANGENT_TOL if lean else TANGENT_TOL
        self.ref = Reference(seed_faces=lean)
        self.evaluations = 0
        self.hessians = 0
        self.last_residual = math.nan

    def _evaluate(self, gamma: F64, need: npt.NDArray[np.intp]) -> tuple[F64, Face]:
        """The gradient and the Hessian at ``γ``: the block on the sensors ``need`` (the face
        and an entering sensor) with ``quick``, else all of it or, with ``krylov``, products."""
        self.evaluations += 1
        r = gamma + self.lo
        if not self.krylov and self.blocks:
            point = self.cache.point(r)
            if getattr(point, "hessian_block", None) is not None:
                self.hessians += 1
                return np.asarray(point.gradient, dtype=np.float64), BlockFace(point, need)
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
        evaluation of η. After an enter the solves just made at this point on the old face
        (the old tangent among their vectors) give the new solve its Galerkin start and
        preconditioner (:mod:`.face_hessian`)."""
        jj = np.array(active, dtype=np.intp)
        p = node.point
        return make_node(jj, (p.sigma, p.gamma, p.mu, node.g), node.face, 0, tol=self.node_tol)

    def solve(
        self,
        active: list[int],
        gamma0: F64,
        mu0: float,
        side: Side,
        capped: Any = (),
        tangent0: F64 | None = None,
    ) -> Node:
        """The path point on ``active`` meeting ``side``, by Newton from ``(gamma0, mu0)``, the
        sensors ``capped`` held at their caps; ``tangent0`` (length N): a predicted tangent
        ``x'`` on the face, where the first tangent solve starts (with products only).

        Raises:
            ConvergenceError: no convergence within ``max_newton`` iterations, a rate below
                ``r_min/2`` (outside where η is evaluated), or a singular system.
        """
        jj = np.array(active, dtype=np.intp)
        gamma = np.zeros(self.n)
        gamma[jj] = gamma0[jj]
        uu = np.array(capped, dtype=np.intp)
        fixed, requested = 0.0, float(side.value)
        if uu.size:
            gamma[uu] = self.cap[uu]
            fixed = float(self.cap[uu].sum())
            if side.kind == "sigma":  # the free shares make up what the capped ones leave
                side = Side("sigma", side.value - fixed)
        mu = float(mu0)
        previous = 0.0  # the last iterate's relative residual
        scale = max(float(np.max(np.abs(gamma[jj]), initial=0.0)), float(np.max(self.lo)))
        ceiling = _RUNAWAY * max(scale, abs(requested) if side.kind == "sigma" else 0.0)
        need = np.union1d(jj, [int(side.value)] if side.kind == "enter" else []).astype(np.intp)
        self._start(jj, tangent0)
        for it in range(self.max_newton):
            if not np.all((gamma[jj] > -0.5 * self.lo[jj]) | (gamma[jj] >= 0.0)):
                break  # rates stay above r_min/2 (≥ 0 at a zero minimum): η is evaluated there
            g, face = self._evaluate(gamma, need)
            resid = g[jj] - mu
            sigma = self._sigma(gamma, jj, side, fixed, requested)
            scale_g = max(abs(mu), float(np.max(np.abs(g[jj]))), 1e-300)
            self.last_residual = float(np.max(np.abs(resid))) / scale_g
            if self._converged(resid, scale_g, gamma, g, mu, jj, side):
                return make_node(jj, (sigma, gamma, mu, g), face, it, tol=self.node_tol)
            # The last step only after converging superlinearly (not on a rounding plateau).
            rho = self._progress(scale_g, gamma, g, mu, jj, side)
            final = self._last_step(rho, previous) and self._final(
                resid, scale_g, gamma, g, mu, jj, side
            )
            previous = rho
            tol = self._forcing(final)
            try:
                step, dmu, h_step, tangent = self._step(face, jj, resid, (gamma, g, mu), side, tol)
            except np.linalg.LinAlgError:
                break
            gamma[jj] += step
            mu += dmu
            if side.kind in ("leave", "cap"):
                gamma[int(side.value)] = self._target(side)
            big = max(float(np.max(np.abs(gamma[jj]))), self.r_min)
            if final and float(np.max(np.abs(step))) <= _FINAL_STEP * big:
                # The last step, from a residual ≤ _FINAL whose quadratic model predicts
                # ≤ _PREDICTED after it (Newton), so it is not evaluated again; the gradient
                # there to second order, g + η''·δγ (the product from the step's solves), and
                # the tangent with the Hessian one step back (solved for the step).
                sigma = self._sigma(gamma, jj, side, fixed, requested)
                state = (sigma, gamma, mu, g + face.complete(jj, step, h_step))
                return make_node(jj, state, face, it + 1, tangent)
            if not (np.all(np.isfinite(gamma)) and math.isfinite(mu)):
                break
            if float(np.max(gamma[jj])) > ceiling:
                break  # a runaway iterate (see _RUNAWAY)
            if np.any(gamma[jj] < -0.5 * max(sigma, 1e-300)) and side.kind == "sigma":
                break
        raise ConvergenceError(
            f"path corrector did not converge ({side.kind} {side.value:.6g}, "
            f"relative residual {self.last_residual:.1e})"
        )

    def _start(self, jj: npt.NDArray[np.intp], tangent0: F64 | None) -> None:
        """The first tangent solve on the face ``jj`` starts from ``tangent0`` (if given and
        finite; with Hessian-vector products only)."""
        if tangent0 is not None and self.krylov and bool(np.all(np.isfinite(tangent0[jj]))):
            self.ref.start(jj, tangent0[jj])

    def _forcing(self, final: bool) -> tuple[float, float]:
        """The relative accuracies of the solves ``(x', z)`` in a Newton step (inexact Newton):
        before the last step both to the residual ``ρ`` (≤ 0.1; the next residual is then about
        ``2ρ²``, still quadratic); in the last step ``x'`` (the node's tangent) to
        :data:`TANGENT_TOL` (with ``lean`` to ``min(``:data:`LEAN_TANGENT_TOL` ``, 1e-13/ρ)``)
        and ``z`` (of size ``ρ ≤`` :data:`_FINAL`) to ``1e-14/ρ``, which leaves an error
        ``1e-14`` in the gradient."""
        rho = self.last_residual
        if final and self.lean:
            lean = max(min(LEAN_TANGENT_TOL, 1e-13 / max(rho, 1e-300)), TANGENT_TOL)
            return lean, min(1e-1, max(1e-14 / max(rho, 1e-300), TANGENT_TOL))
        if final:
            return TANGENT_TOL, min(1e-1, max(1e-14 / max(rho, 1e-300), TANGENT_TOL))
        forced = min(1e-1, max(FORCING * rho, CG_TOL))
        return forced, forced

    @staticmethod
    def _sigma(
        gamma: F64, jj: npt.NDArray[np.intp], side: Side, fixed: float, requested: float
    ) -> float:
        """σ at ``γ``: the σ asked for (``requested``), or the free shares' sum plus ``fixed``,
        the capped shares' sum."""
        if side.kind == "sigma":
            return requested
        s = float(gamma[jj].sum())
        return s + fixed if fixed else s

    def _target(self, side: Side) -> float:
        """The value a ``"leave"`` (0) or ``"cap"`` (``c_i``) condition puts ``γ_i`` at."""
        return float(self.cap[int(side.value)]) if side.kind == "cap" else 0.0

    def _last_step(self, rho: float, previous: float) -> bool:
        """Whether the residuals fell superlinearly to ``rho`` from ``previous`` and the quadratic
        model predicts at most :data:`_PREDICTED` (with ``quick`` :data:`_PREDICTED_QUICK`)
        after one more step."""
        target = _PREDICTED_QUICK if self.quick else _PREDICTED
        return previous**1.5 >= rho and rho**3 <= target * previous**2

    def _progress(
        self, scale_g: float, gamma: F64, g: F64, mu: float, jj: Any, side: Side
    ) -> float:
        """The residual the last-step rule follows: the gradient's (relative), with ``quick``
        the larger of it and the side condition's (scaled as in :meth:`_final`)."""
        if not self.quick:
            return self.last_residual
        if side.kind == "sigma":
            off = abs(float(gamma[jj].sum()) - side.value) / max(side.value, 1.0)
        elif side.kind == "enter":
            off = abs(float(g[int(side.value)]) - mu) / scale_g
        else:
            off = abs(float(gamma[int(side.value)]) - self._target(side))
            off /= max(float(gamma[jj].sum()), 1.0)
        return max(self.last_residual, off)

    def _final(
        self, resid: F64, scale_g: float, gamma: F64, g: F64, mu: float, jj: Any, side: Side
    ) -> bool:
        """Every residual ≤ :data:`_FINAL` (relative): the next Newton step is the last."""
        if float(np.max(np.abs(resid))) > _FINAL * scale_g:
            return False
        if side.kind == "sigma":
            return abs(float(gamma[jj].sum()) - side.value) <= _FINAL * max(side.value, 1.0)
        if side.kind == "enter":
            return abs(float(g[int(side.value)]) - mu) <= _FINAL * scale_g
        off = float(gamma[int(side.value)]) - self._target(side)
        return abs(off) <= _FINAL * max(float(gamma[jj].sum()), 1.0)

    def _converged(
        self, resid: F64, scale_g: float, gamma: F64, g: F64, mu: float, jj: Any, side: Side
    ) -> bool:
        if float(np.max(np.abs(resid))) > 1e-13 * scale_g:
            return False
        if side.kind == "sigma":
            return abs(float(gamma[jj].sum()) - side.value) <= 1e-14 * max(side.value, 1.0)
        if side.kind == "enter":
            return abs(float(g[int(side.value)]) - mu) <= 1e-13 * scale_g
        return bool(gamma[int(side.value)] == self._target(side))

    def _step(
        self,
        face: Face,
        jj: npt.NDArray[np.intp],
        resid: F64,
        state: tuple[F64, F64, float],
        side: Side,
        tol: tuple[float, float],
    ) -> tuple[F64, float, F64, Solved]:
        """The Newton step ``(δγ_J, δμ)`` (module docstring), with ``η''_{:,J}·δγ_J`` and the
        tangent solve ``(x', η''_{:,J}x')``; the solves with ``η''_JJ`` to relative accuracy
        ``tol = (for x', for z)`` (inexact Newton with Hessian-vector products). The enter
        condition's row ``η''_jJ`` is read off the solves' products: exact, at no extra
        product."""
        gamma, g, mu = state
        tangent = face.tangent(jj, tol[0])
        (xp, hxp), (z, hz) = tangent, face.solve(jj, resid, tol[1])
        if side.kind == "sigma":
            dmu = (float(z.sum()) - (float(gamma[jj].sum()) - side.value)) / float(xp.sum())
        elif side.kind == "enter":
            j = int(side.value)
            dmu = (float(hz[j]) - (float(g[j]) - mu)) / (float(hxp[j]) - 1.0)
        else:
            k = int(np.flatnonzero(jj == int(side.value))[0])
            off = float(gamma[int(side.value)]) - self._target(side)
            dmu = (float(z[k]) - off) / float(xp[k])
        if not math.isfinite(dmu):
            raise np.linalg.LinAlgError("singular side condition")
        return dmu * xp - z, dmu, dmu * hxp - hz, tangent
