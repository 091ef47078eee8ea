"""The allocation robust to model uncertainty: one allocation for K models of the same sensors,
minimising the mean error ``Σ_k w_k η_k(r)`` or the worst case ``max_k η_k(r)``, with a proven
certificate.

Both problems are posed on the constraint set of :func:`~.optimal.optimal_allocation`,
``{r_min,i ≤ r_i ≤ r_max,i, Σ b_i r_i = B}``, in channel units (the weighted box-simplex of
:mod:`.box_simplex`), and both are convex: η_k is convex for every model, so is a non-negative sum
and a pointwise maximum. The solvers are in :mod:`.robust_solvers` (Newton on the mean with the
exact summed Hessian; SQP on the epigraph of the worst case, its QP in :mod:`.minimax_qp`), the
models and their concurrent evaluation in :mod:`.model_set`. Certificates:

* mean: the Frank–Wolfe gap of ``F = Σ w_k η_k``, ``F(r̂) − F* ≤ gap``;
* worst: for λ in the simplex, ``min_r max_k η_k ≥ Σ λ_k η_k(r̂) − FW_λ(r̂)`` (weak duality and
  convexity of the λ-mixture), with λ the SQP's multipliers: ``lower_bound`` and
  ``gap = max_k η_k(r̂) − lower_bound``.

With one model both objectives are :func:`~.optimal.optimal_allocation` itself (the same call,
so the same rates bit for bit).
"""

from __future__ import annotations

from typing import Any, Literal, get_args

import numpy as np
import numpy.typing as npt

from .._arrays import as_count, as_real, numerical_errors
from ..errors import ConvergenceError, InvalidInputError
from ..network import Network
from .box_simplex import box_kkt, fix_sum_box, project_box_simplex
from .budgeted import box_problem
from .model_set import ModelSet, model_list, model_weights
from .optimal import one_of, optimal_allocation
from .result import BoxProblem
from .robust_result import RobustAllocation
from .robust_solvers import SolverState, lower_bound, mean_newton, worst_sqp
from .simplex import STAGNATION_GAP

__all__ = ["OBJECTIVES", "Objective", "robust_allocation", "robust_problem"]

F64 = npt.NDArray[np.float64]

Objective = Literal["mean", "worst"]
#: The values of ``objective``.
OBJECTIVES: tuple[str, ...] = get_args(Objective)


def check_objective(objective: Any, weights: Any) -> Objective:
    """``objective`` is ``"mean"`` or ``"worst"``; ``weights`` only with ``"mean"``."""
    if not isinstance(objective, str) or objective not in OBJECTIVES:
        raise InvalidInputError(f"objective must be {one_of(OBJECTIVES)}, got {objective!r}")
    if objective == "worst" and weights is not None:
        raise InvalidInputError(
            "weights apply to objective='mean' (the worst case weighs no model)"
        )
    return "mean" if objective == "mean" else "worst"


def robust_problem(
    models: Any, budget: Any, objective: Any, weights: Any, num_models: Any, seed: Any
) -> tuple[list[Network], F64, Objective, BoxProblem]:
    """The checked models, weights, objective and the box-simplex at ``budget``."""
    objective = check_objective(objective, weights)
    nets = model_list(models, num_models, seed)
    w = model_weights(weights, len(nets))
    return nets, w, objective, box_problem(nets[0], budget, "budget")


def _single(
    net: Network, budget: float, objective: str, tol: float, max_iter: Any
) -> RobustAllocation:
    a = optimal_allocation(net, budget, tol=tol, max_iter=max_iter)
    return RobustAllocation(
        r=a.r,
        objective=objective,
        value=a.eta,
        eta_per_model=(a.eta,),
        weights=(1.0,),
        lower_bound=a.eta - a.gap,
        gap=a.gap,
        mu=a.mu,
        iterations=a.iterations,
        evaluations=a.iterations + 1,
        eta_error=a.eta_error,
        budget=float(budget),
    )


def _start(ms: ModelSet, w: F64, prob: BoxProblem) -> F64:
    """Newton's start: the optimum of the model of largest weight (its own decoupled start and
    solver, one model's cost), else the projection of the uniform point."""
    n, cap, sigma = prob.lo.size, prob.cap, prob.sigma
    try:
        a = optimal_allocation(ms.nets[int(np.argmax(w))], prob.budget, tol=1e-8)
    except ConvergenceError:
        return project_box_simplex(np.full(n, sigma / n), cap, sigma)
    return fix_sum_box(np.array(a.gamma, dtype=np.float64), cap, sigma)


def _solve(
    ms: ModelSet, w: F64, objective: str, prob: BoxProblem, tol: float, max_iter: int
) -> SolverState:
    """The solver's final state (the point fixed when the box-simplex is a single point)."""
    n, lo, cap, sigma = prob.lo.size, prob.lo, prob.cap, prob.sigma
    if sigma == 0.0 or sigma >= float(np.sum(cap)) or n == 1:
        gamma = np.zeros(n) if sigma == 0.0 else np.minimum(cap, sigma)
        gamma = fix_sum_box(gamma, cap, sigma)
        f, grads = ms.values_gradients(gamma + lo)
        lam = w if objective == "mean" else (f == np.max(f)) / np.sum(f == np.max(f))
        return SolverState(gamma, 0, f, grads, lam, float(lam @ f))
    g0 = _start(ms, w, prob)
    if objective == "mean":
        return mean_newton(ms, w, lo, cap, sigma, tol, max_iter, g0)
    start = mean_newton(ms, w, lo, cap, sigma, max(tol, 1e-8), max_iter, g0)
    return worst_sqp(ms, lo, cap, sigma, tol, max_iter, start.gamma, w)


def _result(
    ms: ModelSet, st: SolverState, objective: str, prob: BoxProblem, w: F64
) -> RobustAllocation:
    s = st.gamma + prob.lo
    errors = ms.value_errors(s)
    if objective == "mean":
        value, eta_error = float(w @ st.values), float(w @ errors)
        bound = lower_bound(w, st.values, st.gradients, st.gamma, prob.cap, prob.sigma)
    else:
        value, eta_error = float(np.max(st.values)), float(np.max(errors))
        bound = st.bound
    mu = box_kkt(st.gamma, st.weights @ st.gradients, prob.cap, 0.0)[0]
    r = s / prob.costs
    r.setflags(write=False)
    return RobustAllocation(
        r=r,
        objective=objective,
        value=value,
        eta_per_model=tuple(float(v) for v in st.values),
        weights=tuple(float(v) for v in st.weights),
        lower_bound=bound,
        gap=max(value - bound, 0.0),
        mu=float(mu),
        iterations=st.iterations,
        evaluations=ms.evaluations,
        eta_error=eta_error,
        budget=prob.budget,
    )


@numerical_errors
def robust_allocation(
    models: Any,
    budget: float,
    *,
    objective: Objective = "mean",
    weights: Any = None,
    num_models: int | None = None,
    seed: int | None = None,
    tol: float = 1e-12,
    max_iter: int | None = None,
) -> RobustAllocation:
    """The allocation minimising the mean or the worst-case error over K models of one sensor
    network, with a proven lower bound on the optimum (see :mod:`capalloc_rs.allocation.robust`).

    Args:
        models: a non-empty list of :class:`~capalloc_rs.Network` (or model files) with the same
            sensors — the same ``N``, sample costs, minima and caps; the dynamics and state
            dimensions may differ — or a sampler ``models(rng) -> Network`` called
            ``num_models`` times with ``rng = numpy.random.default_rng(seed)`` (so a seed makes
            the model set, and the result, reproducible).
        budget: the budget ``B = Σ b_i r_i`` in channel units (``r_tot`` for unit costs), in
            ``models[0].budget_range``.
        objective: ``"mean"`` (minimise ``Σ w_k η_k(r)``) or ``"worst"`` (minimise
            ``max_k η_k(r)``).
        weights: for ``"mean"``, K non-negative weights (normalised to sum 1; default equal).
        num_models: the number of draws of a sampler (only with a sampler).
        seed: the sampler's seed (only with a sampler; ``None``: fresh entropy).
        tol: stop when the certified gap ≤ ``tol·|value|``; a solver that can make no further
            progress returns its point if the gap is ≤ ``1e-8·|value|`` and raises otherwise.
        max_iter: bound on Newton/SQP steps (default 200).

    Returns:
        A :class:`RobustAllocation` with the rates, the objective value, the per-model η, the
        weights (for ``"worst"``: the certificate's λ), ``lower_bound`` and ``gap``.

    Raises:
        InvalidInputError: bad ``models`` (empty, not networks, different sensors), ``weights``
            (wrong length, negative, all zero, or given with ``"worst"``), ``objective``,
            ``num_models``, ``seed``, ``tol``, ``max_iter``, or an infeasible ``budget``.
        ConvergenceError: the certificate was not reached.
    """
    nets, w, goal, prob = robust_problem(models, budget, objective, weights, num_models, seed)
    tol = as_real("tol", tol, positive=True)
    steps = 200 if max_iter is None else as_count("max_iter", max_iter, minimum=1)
    if len(nets) == 1:
        return _single(nets[0], budget, goal, tol, max_iter)
    with ModelSet(nets) as ms:
        res = _result(ms, _solve(ms, w, goal, prob, tol, steps), goal, prob, w)
    limit = max(max(tol, STAGNATION_GAP) * max(abs(res.value), 1e-300), 10.0 * res.eta_error)
    if res.gap > limit:
        raise ConvergenceError(
            f"robust {goal}: stagnated with certified gap {res.gap:.3e} (value {res.value:.6e})"
        )
    return res
