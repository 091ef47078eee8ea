"""Optimal capacity allocation on the simplex (the paper's Theorem 1) and its integer version.

Problem (fast-sampling limit). With rates ``r = r_min + γ`` the cost is ``η(r) = tr Σ(r)``; the
optimal allocation solves

    minimise η(r_min + γ)   subject to   γ ≥ 0,  Σ γ_i = σ = r_tot − N·r_min.

Theorem 1 (KKT): γ* is optimal iff there is ``μ ≤ 0`` with ``∂η/∂γ_i = μ`` where ``γ_i > 0`` and
``∂η/∂γ_j ≥ μ`` where ``γ_j = 0``. Because η is convex, the Frank–Wolfe gap

    gap(γ) = Σ_i γ_i (g_i − min_j g_j) = max_{γ' ∈ simplex} ∇η(γ)ᵀ(γ − γ')  ≥  η(γ) − η*

is a certificate that needs no threshold: every method here stops on it.

Methods (all reach the same optimum):

* ``"newton"`` — Newton's method on the simplex, in one of two variants (``hessian=``):

  - ``"exact"``: sequential quadratic programming with the exact Hessian (``N`` Lyapunov solves
    per step): each step solves the quadratic model ``gᵀd + ½ dᵀ∇²η d`` over the simplex exactly
    (primal active-set QP, finite), then an Armijo line search on η. Once the active set is
    identified this is Newton's method on the face: quadratic convergence.
  - ``"hvp"``: Newton–CG, which never forms the Hessian. At γ with gradient g and the multiplier
    estimate ``μ = γᵀg/σ``, the free set is ``F = {i : γ_i > 0} ∪ {j : γ_j = 0, g_j < μ}``. The
    face-restricted Newton system ``min gᵀd + ½ dᵀ∇²η d`` over ``{d_F ⊥ 1, d_j = 0 off F}`` is
    solved by projected preconditioned conjugate gradients: the residual is projected on the null
    space of ``1ᵀ`` in the preconditioner's metric, ``z = D⁻¹r − D⁻¹1·(1ᵀD⁻¹r)/(1ᵀD⁻¹1)``
    (``D = I`` gives ``P = I − 11ᵀ/k``), with ``D`` the diagonal of the decoupled (ε = 0)
    Hessian ``η_i''(r_i)`` for block networks (one small Riccati problem per subsystem) and
    ``I`` otherwise. Products ``∇²η p`` come from one cached :meth:`Network.at` point (two
    Lyapunov solves each). CG is truncated when ``‖P r‖ ≤ η_k ‖P g_F‖`` with the forcing term
    ``η_k = min(0.1, gap_k/|η|)`` (Eisenstat–Walker: η_k = O(‖g_F − μ1‖) keeps the local
    convergence quadratic, as for the exact Newton step; the √-forcing of order 1.5 saved only 2
    products of 20–35 at N = 50–100, same step counts). If a CG step would make some
    ``γ_i + d_i`` negative, it stops at the boundary, fixes ``i`` at zero and CG restarts on the
    smaller face (projected search as in TRON); on a direction of non-positive curvature the
    first iteration steps to the boundary and later ones stop. At most ``|F|`` products per
    step. Then the same Armijo search and certificate as ``"exact"``.
  - ``"auto"`` (default): ``"exact"`` below :data:`HVP_MIN_SENSORS` sensors, ``"hvp"`` from
    there on (the crossover measured with ``benches/compare_allocation.py``).
* ``"projected-gradient"`` — spectral (Barzilai–Borwein) projected gradient with Armijo backtracking
  along the projection arc; gradient only.
* ``"double-bracket"`` — the paper's Appendix D flow ``Ḣ = −σ[H, [H, diag ∇η(σ diag H)]]`` on
  ``H = vvᵀ``, ``‖v‖ = 1``; on rank-one H it is ``v̇_i = −σ (g_i − Σ_j g_j v_j²) v_i``, i.e. the
  replicator equation ``γ̇_i = −2σ γ_i (g_i − γᵀg/σ)``. Integrated with an adaptive Dormand–Prince
  5(4) pair (error control on v, v renormalised after each step) until the certificate holds.
  Inactive entries only decay exponentially, so it is slow: it is here for fidelity to the paper.

The network is any object with ``r_min``, ``sensors`` (length N) and ``cost``, ``gradient``,
``hessian`` (and ``cost_many`` for the integer allocation) methods of rates ``r`` — in practice a
:class:`capalloc_rs.Network`. Newton–CG also needs ``at(r)`` returning an evaluation point with
``value``, ``gradient`` and ``hvp`` (:class:`capalloc_rs.network.CostPoint`); when it is there,
both Newton variants take the value, gradient and Hessian (or products) from one point per step
and the line search's first trial point becomes the next step's point.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass
from typing import Any, Literal, Protocol, get_args

import numpy as np
import numpy.typing as npt

from . import limits
from ._arrays import as_count, as_float_array, as_real, numerical_errors, require_attrs
from ._netarg import accepts_path
from .errors import ConvergenceError, InvalidInputError
from .limits import min_slots

__all__ = [
    "Allocation",
    "IntegerAllocation",
    "optimal_allocation",
    "integer_allocation",
    "project_simplex",
    "frank_wolfe_gap",
    "value_gradient",
    "value_gradient_hessian",
]

F64 = npt.NDArray[np.float64]

#: The double-bracket flow's certificate floor (relative gap): near a breakpoint the replicator
#: moves at a speed proportional to the small γ_i, so tighter gaps cost unbounded time.
FLOW_TOL = 1e-9

#: Predicted decreases below ``NOISE_DECREASE·|η|`` are at the rounding level of η.
NOISE_DECREASE = 1e3 * float(np.finfo(np.float64).eps)


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


#: A method that can make no further progress in floating point returns its point if the certified
#: gap is at most this (relative to η), and raises ConvergenceError otherwise.
STAGNATION_GAP = 1e-8

Method = Literal["newton", "projected-gradient", "double-bracket"]
HessianMode = Literal["auto", "exact", "hvp"]
#: The values of ``method`` and ``hessian`` (for validation elsewhere: sweeps, the CLI).
METHODS: tuple[str, ...] = get_args(Method)
HESSIAN_MODES: tuple[str, ...] = get_args(HessianMode)


def one_of(choices: tuple[str, ...]) -> str:
    """``'a', 'b' or 'c'``: the choices of an argument, for error messages."""
    quoted = [repr(c) for c in choices]
    return ", ".join(quoted[:-1]) + " or " + quoted[-1]


#: ``hessian="auto"`` runs Newton–CG (``"hvp"``) from this many sensors on and the exact Hessian
#: below. Measured with ``benches/compare_allocation.py --cg`` (``Network.random(N, 2, eps=0.05)``,
#: r_tot = 3N, one BLAS thread, 2 cores), exact time / Newton–CG time over six networks per size:
#: 1.02–1.14× at N = 10–15 and 0.99–1.23× at N = 20 (a few ms either way; the exact QP is the more
#: robust there), 1.18–1.51× at N = 25, 1.37× at 30, 1.6–1.7× at 50, 2.3× at 100, 2.2–3.6× at 200.
HVP_MIN_SENSORS = 25


class CostModel(Protocol):
    """What the allocation needs from a network: η(r), ∇η(r), ∇²η(r) for rates r (length N)."""

    @property
    def r_min(self) -> float: ...

    @property
    def sensors(self) -> Any: ...

    def cost(self, r: Any) -> float: ...

    def gradient(self, r: Any) -> F64: ...

    def hessian(self, r: Any) -> F64: ...


class CostPointModel(Protocol):
    """An evaluation point (``Network.at(r)``): what Newton–CG needs at one rate vector."""

    @property
    def value(self) -> float: ...

    @property
    def gradient(self) -> Any: ...

    def hvp(self, v: Any) -> Any: ...

    def hessian(self) -> Any: ...


@dataclass(frozen=True)
class Allocation:
    """An optimal allocation with its certificate.

    Attributes:
        r: rates ``r_min + γ`` (each ≥ r_min, summing to r_tot).
        gamma: ``γ = r − r_min`` on the simplex of height ``sigma``.
        sigma: ``σ = r_tot − N·r_min``.
        r_tot: total capacity.
        eta: ``η(r) = tr Σ(r)``.
        gradient: ``∂η/∂γ_i = ∂η/∂r_i`` at the solution.
        mu: the KKT multiplier of Theorem 1 (mean gradient over the active set; ``min g`` if none).
        active: indices with ``γ_i > 0``.
        kkt_residual: ``max(max_{active} |g_i − μ|, max_{inactive} (μ − g_j)₊) / |μ|``.
        gap: Frank–Wolfe duality gap, an upper bound on ``η(r) − η*`` computed from the computed
            gradient.
        eta_error: an upper bound on ``|η − η_exact|`` at ``r`` from the Riccati solver's error
            bound (0 when the network cannot provide one, ``inf`` when the solver could not
            establish one).
        certified: the gap is a certificate: ``gap ≥ eta_error``. When False, the gap is below
            the accuracy of η itself and optimality holds only to within ``eta_error`` (at very
            large rates, for example); :attr:`optimality` says how far from optimal ``r`` may be.
        iterations: outer iterations (Newton steps, gradient steps, or accepted ODE steps).
        method: the method used.
        hessian: for ``method="newton"`` the variant that ran, ``"exact"`` or ``"hvp"``
            (``"auto"`` resolved); ``None`` for the other methods.
        hvp_count: Hessian-vector products used (Newton–CG), else 0.
    """

    r: F64
    gamma: F64
    sigma: float
    r_tot: float
    eta: float
    gradient: F64
    mu: float
    active: npt.NDArray[np.intp]
    kkt_residual: float
    gap: float
    iterations: int
    method: str
    hessian: str | None = None
    hvp_count: int = 0
    eta_error: float = 0.0

    @property
    def certified(self) -> bool:
        """``gap ≥ eta_error``: the Frank–Wolfe gap is meaningful at the accuracy of η."""
        return self.gap >= self.eta_error

    @property
    def optimality(self) -> float:
        """``max(gap, eta_error)``: how far ``η(r)`` may be above the optimum, as far as the
        certificate and the accuracy of η can tell."""
        return max(self.gap, self.eta_error)


@dataclass(frozen=True)
class IntegerAllocation:
    """Integer slot counts ``r_i ≥ r_min`` summing to ``r_tot`` that minimise η over integer vectors
    (exactly when the network is decoupled; otherwise a local optimum for single-slot exchanges).

    Attributes:
        counts: integer slot counts.
        eta: ``η(counts)``.
        exchanges: improving single-slot exchanges applied after the greedy phase.
        evaluations: cost evaluations used.
    """

    counts: npt.NDArray[np.int64]
    eta: float
    exchanges: int
    evaluations: int


# ----------------------------------------------------------------------------- small utilities


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


def value_gradient(net: Any, r: F64) -> tuple[float, F64]:
    """``(η(r), ∇η(r))`` with one Riccati solve when the network offers ``value_and_gradient``."""
    fn = getattr(net, "value_and_gradient", None)
    if fn is not None:
        f, g = fn(r)
        return float(f), np.asarray(g, dtype=np.float64)
    return float(net.cost(r)), np.asarray(net.gradient(r), dtype=np.float64)


def value_gradient_hessian(net: Any, r: F64) -> tuple[float, F64, F64]:
    """``(η, ∇η, ∇²η)`` at ``r`` with one Riccati solve when the network offers it."""
    fn = getattr(net, "value_gradient_hessian", None)
    if fn is not None:
        f, g, h = fn(r)
        return float(f), np.asarray(g, dtype=np.float64), np.asarray(h, dtype=np.float64)
    g = np.asarray(net.gradient(r), dtype=np.float64)
    return float(net.cost(r)), g, np.asarray(net.hessian(r), dtype=np.float64)


def _num_sensors(net: CostModel) -> int:
    require_attrs("net", net, "sensors", "r_min")
    return len(net.sensors)


def _validate(net: CostModel, r_tot: float) -> tuple[int, float, float]:
    n_sens = _num_sensors(net)
    r_min = float(net.r_min)
    r_tot = as_real("r_tot", r_tot)
    sigma = float(r_tot) - n_sens * r_min
    if sigma < -1e-12 * max(1.0, abs(float(r_tot))):
        raise InvalidInputError(
            f"infeasible capacity: r_tot = {r_tot} < N·r_min = {n_sens}·{r_min} = {n_sens * r_min}"
        )
    return n_sens, r_min, max(sigma, 0.0)


def _kkt(
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


def _result(
    net: CostModel,
    gamma: F64,
    sigma: float,
    r_tot: float,
    iterations: int,
    method: str,
    active_tol: float,
    *,
    hessian: str | None = None,
    hvp_count: int = 0,
    value_grad: tuple[float, F64] | None = None,
    eta_error: float | None = None,
) -> Allocation:
    r = gamma + float(net.r_min)
    eta, g = value_gradient(net, r) if value_grad is None else value_grad
    if eta_error is None:
        at = getattr(net, "at", None)
        eta_error = float(at(r).value_error) if at is not None else 0.0
    g = np.array(g, dtype=np.float64)
    mu, active, kkt = _kkt(gamma, g, sigma, active_tol)
    for arr in (r, gamma, g):
        arr.setflags(write=False)
    idx = np.flatnonzero(active)
    idx.setflags(write=False)
    return Allocation(
        r=r,
        gamma=gamma,
        sigma=sigma,
        r_tot=float(r_tot),
        eta=eta,
        gradient=g,
        mu=mu,
        active=idx,
        kkt_residual=kkt,
        gap=frank_wolfe_gap(gamma, g),
        iterations=iterations,
        method=method,
        hessian=hessian,
        hvp_count=hvp_count,
        eta_error=eta_error,
    )


# ------------------------------------------------------------------ QP over the simplex (exact)


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


def _simplex_qp(h: F64, c: F64, x0: F64, sigma: float, max_iter: int) -> F64:
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


# ----------------------------------------------------------------------------------- methods


def _armijo(
    net: CostModel,
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


class _Points:
    """Value, gradient and second-order information at rates ``r`` for the Newton variants.

    With ``net.at`` (a :class:`~capalloc_rs.network.CostPoint` per rate vector) one Riccati solve
    serves the value, the gradient and every product or the Hessian at that point, and the last
    point is kept: the line search's first trial (usually accepted) is the next step's point.
    Without it, falls back to ``value_gradient_hessian``. Counts the products it computes."""

    def __init__(self, net: CostModel) -> None:
        self.net = net
        self.at = getattr(net, "at", None)
        self.last: tuple[bytes, CostPointModel] | None = None
        self.hvps = 0

    def point(self, r: F64) -> CostPointModel:
        assert self.at is not None
        key = r.tobytes()
        if self.last is None or self.last[0] != key:
            self.last = (key, self.at(r))
        return self.last[1]

    def value_gradient(self, r: F64) -> tuple[float, F64]:
        if self.at is None:
            return value_gradient(self.net, r)
        p = self.point(r)
        return float(p.value), np.asarray(p.gradient, dtype=np.float64)

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
    if st is None or len(st.a_blocks) != _num_sensors(net):
        return None
    from . import _core

    models = [
        _core.CostModel(a, g, [c])
        for a, g, c in zip(st.a_blocks, st.g_blocks, st.c_blocks, strict=True)
    ]

    def curvature(r: F64) -> F64:
        out = np.empty(len(models))
        for i, m in enumerate(models):
            h = m.evaluate(r[i : i + 1], 2, 1).hessian
            assert h is not None
            out[i] = h[0, 0]
        return out

    return curvature


def _forcing(rel_gap: float) -> float:
    """The CG truncation ``η_k = min(0.1, gap/|η|)``: proportional to the certificate, hence to
    the projected gradient, so inexact Newton keeps quadratic local convergence. The cap 0.1
    (rather than the usual 0.5) saved one Newton step — one Riccati solve, worth ~20 products — at
    N = 20–200 in ``benches/compare_allocation.py`` for the same number of products."""
    return min(0.1, rel_gap)


def _newton_cg_step(
    hvp: Any, g: F64, gamma: F64, free: npt.NDArray[np.intp], dinv: F64, forcing: float, budget: int
) -> tuple[F64, int]:
    """Approximately minimises ``gᵀd + ½ dᵀHd`` over ``{Σd = 0, γ + d ≥ 0, d = 0 off free}`` by
    projected preconditioned CG on the face (``dinv`` = 1/diag of the preconditioner, on all N),
    truncated at ``‖P r‖ ≤ forcing·‖P g_F‖``; bound hits fix the index and restart CG on the
    smaller face. Returns the step and the number of products used (≤ ``budget``).

    The residual ``r = g_F + H d_F`` is kept free of its multiplier part — after each update
    ``r ← r − λ1`` with ``λ = (1ᵀD⁻¹r)/(1ᵀD⁻¹1)`` (Gould–Hribar–Nocedal's residual update) — so the
    preconditioned projection ``z = D⁻¹r`` does not cancel the O(|μ|) constant against the
    O(‖P g‖) rest, which would stall CG near the optimum."""
    n = g.size
    d = np.zeros(n)

    def pres(r: F64) -> float:  # Euclidean norm of the projected residual
        return float(np.linalg.norm(r - r.mean()))

    def deflate(r: F64, w: F64) -> F64:  # r − λ1 with 1ᵀD⁻¹(r − λ1) = 0
        # Twice: the first pass cancels |μ| ≫ ‖P r‖ and leaves an error of ε|μ| in every entry,
        # which would make Σz, hence Σd, wrong at the level that matters near the optimum.
        for _ in range(2):
            r = r - float((w * r).sum()) / float(w.sum())
        return r

    r = g[free].copy()  # gradient of the model at d = 0, restricted to the face
    target = forcing * pres(r)
    used = 0
    restart = True
    w = p = z = r
    rz = 0.0
    while used < budget and free.size >= 2:
        if restart:
            w = dinv[free]
            r = deflate(r, w)
            if pres(r) <= target:
                break
            z = w * r
            p = -z
            rz = float(r @ z)
            restart = False
            if rz <= 0.0:
                break
        p_full = np.zeros(n)
        p_full[free] = p
        hp = hvp(p_full)[free]
        used += 1
        kappa = float(p @ hp)
        cur = gamma[free] + d[free]
        neg = np.flatnonzero(p < 0.0)
        if neg.size:
            ratios = np.maximum(cur[neg], 0.0) / -p[neg]
            k = int(np.argmin(ratios))
            alpha_b, hit = float(ratios[k]), int(neg[k])
        else:
            alpha_b, hit = math.inf, -1
        if kappa <= 0.0:  # no positive curvature (rounding on a convex η): go to the boundary
            if hit >= 0 and not np.any(d):
                d[free] += alpha_b * p
                d[free[hit]] = -gamma[free[hit]]
            break
        alpha = rz / kappa
        if alpha_b < alpha:  # the step leaves the simplex: stop at the face, fix the index
            d[free] += alpha_b * p
            d[free[hit]] = -gamma[free[hit]]
            r = r + alpha_b * hp
            keep = np.arange(free.size) != hit
            free, r = free[keep], r[keep]
            restart = True
            continue
        d[free] += alpha * p
        r = deflate(r + alpha * hp, w)
        if pres(r) <= target:
            break
        z = w * r
        rz_new = float(r @ z)
        if rz_new <= 0.0:
            break
        p = -z + (rz_new / rz) * p
        rz = rz_new
    return d, used


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


def _newton(
    net: CostModel,
    n_sens: int,
    r_min: float,
    sigma: float,
    tol: float,
    max_iter: int,
    g0: F64,
    mode: str,
) -> tuple[F64, int, _Points]:
    pts = _Points(net)
    curvature = _decoupled_curvature(net) if mode == "hvp" else None
    gamma = g0.copy()
    stall = _Stall(3)
    for it in range(max_iter):
        r = gamma + r_min
        f, g = pts.value_gradient(r)
        gap = frank_wolfe_gap(gamma, g)
        if gap <= tol * max(abs(f), 1e-300):
            return gamma, it, pts
        if mode == "hvp":
            mu = float(gamma @ g) / sigma
            free = np.flatnonzero((gamma > 0.0) | (g < mu))
            dinv = np.ones(n_sens)
            if curvature is not None:
                h0 = curvature(r)
                if np.all(np.isfinite(h0)) and float(np.max(h0)) > 0.0:
                    dinv = 1.0 / np.maximum(h0, 1e-6 * float(np.max(h0)))
            forcing = _forcing(gap / max(abs(f), 1e-300))
            d, _ = _newton_cg_step(
                lambda v: pts.hvp(r, v),  # noqa: B023
                g,
                gamma,
                free,
                dinv,
                forcing,
                budget=max(free.size, 1),
            )
        else:
            h = pts.hessian(r)
            h = 0.5 * (h + h.T)
            # Regularise: η is convex but its Hessian may be singular (non-regular triplets).
            h = h + (1e-12 * max(float(np.max(np.abs(np.diag(h)))), 1e-300)) * np.eye(n_sens)
            # QP in the variable x = γ + d: minimise (g − Hγ)ᵀx + ½ xᵀHx over the simplex.
            x = _simplex_qp(h, g - h @ gamma, gamma, sigma, max_iter=20 * n_sens + 100)
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


def _projected_gradient(
    net: CostModel, r_min: float, sigma: float, tol: float, max_iter: int, g0: F64
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


def _double_bracket(
    net: CostModel, n_sens: int, r_min: float, sigma: float, tol: float, max_steps: int, g0: F64
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


@accepts_path
@numerical_errors
def optimal_allocation(
    net: CostModel,
    r_tot: float,
    *,
    method: Method = "newton",
    tol: float = 1e-12,
    max_iter: int | None = None,
    gamma0: Any = None,
    hessian: HessianMode = "auto",
) -> Allocation:
    """The optimal allocation ``argmin η(r_min + γ)`` over the simplex of height
    ``σ = r_tot − N·r_min``, with its KKT certificate (Theorem 1).

    Args:
        net: the network (see :class:`CostModel`).
        r_tot: total capacity (slots per unit time in the fast-sampling limit).
        method: ``"newton"`` (default), ``"projected-gradient"`` or ``"double-bracket"``.
        tol: stop when the Frank–Wolfe gap ≤ ``tol·η`` (for the flow at least 1e-9·η). A method
            that stalls in floating point first returns its point if the gap is ≤ 1e-8·η (the
            result's ``gap`` says exactly how close it is) and raises otherwise.
        max_iter: iteration bound (defaults: 200 Newton steps, 50 000 gradient steps, 200 000 ODE
            steps); exceeding it raises :class:`~capalloc_rs.errors.ConvergenceError`.
        gamma0: optional starting point on the simplex (warm start), default uniform.
        hessian: the Newton variant: ``"exact"`` (SQP with the ``N × N`` Hessian), ``"hvp"``
            (Newton–CG with Hessian-vector products, needs ``net.at``) or ``"auto"`` (``"hvp"``
            from :data:`HVP_MIN_SENSORS` sensors on when ``net.at`` exists, else ``"exact"``).
            Ignored by the other methods. The result's ``hessian`` field says which ran.

    Raises:
        InvalidInputError: infeasible capacity (``r_tot < N·r_min``), bad method or start.
        ConvergenceError: the certificate was not reached within the bound.
    """
    n_sens, r_min, sigma = _validate(net, r_tot)
    r_tot = as_real("r_tot", r_tot)
    tol = as_real("tol", tol, positive=True)
    if max_iter is not None:
        max_iter = as_count("max_iter", max_iter, minimum=1)
    if not isinstance(method, str) or not isinstance(hessian, str):
        raise InvalidInputError(f"method and hessian must be strings, got {method!r}, {hessian!r}")
    if method not in METHODS:
        raise InvalidInputError(f"method must be {one_of(METHODS)}, got {method!r}")
    if hessian not in HESSIAN_MODES:
        raise InvalidInputError(f"hessian must be {one_of(HESSIAN_MODES)}, got {hessian!r}")
    has_points = callable(getattr(net, "at", None))
    mode: str | None = None
    if method == "newton":
        if hessian == "hvp" and not has_points:
            raise InvalidInputError(
                "hessian='hvp' needs a network with an at(r) evaluation point (capalloc_rs.Network)"
            )
        mode = hessian
        if mode == "auto":
            mode = "hvp" if has_points and n_sens >= HVP_MIN_SENSORS else "exact"
    active_tol = 1e-9 * sigma if method == "double-bracket" else 0.0
    if sigma == 0.0 or n_sens == 1:
        gamma = np.full(n_sens, sigma / n_sens) if n_sens == 1 else np.zeros(n_sens)
        return _result(net, gamma, sigma, r_tot, 0, method, active_tol, hessian=mode)
    if gamma0 is None:
        g0 = np.full(n_sens, sigma / n_sens)
    else:
        g0 = as_float_array("gamma0", gamma0, 1)
        if g0.shape != (n_sens,) or not np.all(np.isfinite(g0)) or np.any(g0 < 0):
            raise InvalidInputError(f"gamma0 must be {n_sens} finite non-negative numbers")
        if abs(float(g0.sum()) - sigma) > 1e-9 * max(sigma, 1.0):
            raise InvalidInputError(f"gamma0 must sum to sigma = {sigma}, got {g0.sum()}")
        g0 = _fix_sum(g0.copy(), sigma)
    hvps, value_grad, eta_error = 0, None, None
    if method == "newton":
        assert mode is not None
        gamma, its, pts = _newton(net, n_sens, r_min, sigma, tol, max_iter or 200, g0, mode)
        # The last point is usually cached already: no further Riccati solve for the result.
        hvps, value_grad = pts.hvps, pts.value_gradient(gamma + r_min)
        eta_error = pts.value_error(gamma + r_min)
    elif method == "projected-gradient":
        gamma, its = _projected_gradient(net, r_min, sigma, tol, max_iter or 50_000, g0)
    else:
        gamma, its = _double_bracket(
            net, n_sens, r_min, sigma, max(tol, FLOW_TOL), max_iter or 200_000, g0
        )
    res = _result(
        net,
        gamma,
        sigma,
        r_tot,
        its,
        method,
        active_tol,
        hessian=mode,
        hvp_count=hvps,
        value_grad=value_grad,
        eta_error=eta_error,
    )
    # A gap below the accuracy of η is not a failure to converge: the result says so (certified).
    if res.gap > max(max(tol, STAGNATION_GAP) * max(abs(res.eta), 1e-300), 10.0 * res.eta_error):
        raise ConvergenceError(
            f"{method} stagnated with Frank–Wolfe gap {res.gap:.3e} (η = {res.eta:.6e}); "
            "the cost is too flat or too noisy to certify the optimum"
        )
    return res


# ------------------------------------------------------------------------- integer allocation


@accepts_path
@numerical_errors
def integer_allocation(net: Any, r_tot: int, *, deadline: float | None = None) -> IntegerAllocation:
    """Integer slot counts ``r_i ≥ r_min`` with ``Σ r_i = r_tot`` minimising ``η(r)``.

    ``r_tot`` is an integer (an integral float such as ``8.0`` is accepted, ``8.5`` refused). A
    non-integer ``r_min`` follows the rule of schedules: each count is at least ``⌈r_min⌉`` (the
    least integer with ``r_i ≥ r_min``), and at least 1 since ``η`` needs positive rates.

    Greedy marginal allocation (each remaining slot goes to the sensor whose extra slot lowers η
    most), started from the floor of the continuous optimum when σ is large, followed by
    single-slot exchanges ``r − e_i + e_j`` until none improves. For a decoupled network η is a
    sum of convex functions of one count each, and exchange-optimality is global optimality
    (discrete convexity), so the result is exact; for coupled networks it is exchange-optimal.
    Candidate moves are evaluated in parallel with ``net.cost_many``.

    ``deadline`` (a ``time.monotonic()`` value) cuts both phases short once passed (remaining slots
    are then spread evenly, and no more exchanges are tried): the counts are feasible but maybe
    not exchange-optimal (``best_schedule`` uses it for its ``time_limit``).
    """
    n_sens = _num_sensors(net)
    # The one rule for slot counts (as for schedules): a sensor needs ⌈r_min⌉ slots to satisfy
    # r_i ≥ r_min, and at least one here, since η(r) is defined for positive rates only.
    r_min_f = as_real("net.r_min", net.r_min)
    if r_min_f < 0:
        raise InvalidInputError(f"net.r_min must be >= 0, got {r_min_f:g}")
    r_min = max(1, min_slots(r_min_f))
    total = as_count("r_tot", r_tot, maximum=limits.MAX_INTEGER_ALLOCATION_SLOTS)
    if total < n_sens * r_min:
        raise InvalidInputError(
            f"infeasible capacity: r_tot = {total} < N·r_min = {n_sens * r_min}"
        )
    spare = total - n_sens * r_min
    evaluations = 0

    def costs(rows: npt.NDArray[np.int64]) -> F64:
        nonlocal evaluations
        evaluations += rows.shape[0]
        return np.asarray(net.cost_many(rows.astype(np.float64)), dtype=np.float64)

    counts = np.full(n_sens, r_min, dtype=np.int64)
    if spare > 4 * n_sens:
        cont = optimal_allocation(net, float(total))
        counts = r_min + np.floor(cont.gamma + 1e-9).astype(np.int64)
    eye = np.eye(n_sens, dtype=np.int64)
    while counts.sum() < total:
        if deadline is not None and time.monotonic() >= deadline:
            counts[np.argmin(counts)] += 1  # out of time: fill the rest evenly
            continue
        cand = counts + eye
        counts = cand[int(np.argmin(costs(cand)))]
    best = float(costs(counts[None, :])[0])
    pairs = [(i, j) for i, j in itertools.permutations(range(n_sens), 2)]
    exchanges = 0
    for _ in range(10 * spare + 100):
        if deadline is not None and time.monotonic() >= deadline:
            break
        moves = [(i, j) for i, j in pairs if counts[i] > r_min]
        if not moves:
            break
        cand = np.array([counts - eye[i] + eye[j] for i, j in moves])
        vals = costs(cand)
        k = int(np.argmin(vals))
        if not vals[k] < best - 1e-13 * abs(best):
            break
        counts, best = cand[k], float(vals[k])
        exchanges += 1
    counts.setflags(write=False)
    return IntegerAllocation(counts=counts, eta=best, exchanges=exchanges, evaluations=evaluations)
