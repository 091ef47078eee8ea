"""The optimal allocation of a network with sample costs, per-sensor minima or caps (not in the
paper's form): the problem on the weighted box-simplex, solved in channel units.

A sample of sensor ``i`` costs ``b_i`` channel units; rates ``r`` spend ``Σ b_i r_i`` channel
units per unit time. The problem

    minimise η(r)   subject to   r_min,i ≤ r_i ≤ r_max,i,   Σ b_i r_i = B

is, in the variable ``s = b ∘ r`` of the network in channel units
(``Network.in_channel_units()``, whose cost at ``s`` is the original cost at ``r = s/b``),
``minimise η(s)`` over ``{lo ≤ s ≤ hi, Σs = B}`` with ``lo = b ∘ r_min``, ``hi = b ∘ r_max``:
with ``γ = s − lo`` the box-simplex ``{0 ≤ γ ≤ c, Σγ = σ}`` of :mod:`.box_simplex`
(``c = hi − lo``, ``σ = B − Σ lo``). It is feasible iff ``Σ lo ≤ B ≤ Σ hi``
(``Network.budget_range``); at either end the only feasible point is every sensor at its minimum
(or at its cap).

KKT (η convex; ``g`` the gradient in channel units, ``∂η/∂r_i = b_i g_i``): ``g_i = μ`` on the
free set, ``g_i ≥ μ`` at a minimum, ``g_i ≤ μ`` at a cap; μ < 0 is the price per channel unit
(``dη*/dB = μ``), the bound multipliers ``λ_i = g_i − μ`` and ``ν_i = μ − g_i`` are the
sensitivities ``dη*/dr_min,i = b_i λ_i`` and ``dη*/dr_max,i = −b_i ν_i``. The certificate is the
Frank–Wolfe gap on the box-simplex (a fractional knapsack), a proven bound on ``η(r) − η*``.

Start. The decoupled optimum (:mod:`.decoupled`, solved in the Rust core for one common minimum
and no caps) is the start (``start="decoupled"``, and ``"auto"`` for Newton) when the network in
channel units still has one common minimum (to 1e-12 relative) and no caps and is a block network
with one subsystem per sensor (e.g. costs alone with ``b_i r_min,i`` equal): it is then the same
problem as the paper's. Otherwise ``start="decoupled"`` is refused (InvalidInputError naming
``start``), and ``"auto"`` starts Newton on a block network from the decoupled optimum with the
smallest minimum ``m = min_i b_i r_min,i`` for all, no caps and the same budget, projected
(Euclidean) onto the box-simplex: 4–5 Newton steps instead of 7 at N = 50–100 with 20–40 % of the
sensors at a bound (``Network.random(N, 2, eps=0.05)``). Projected gradient, ``start="uniform"``
and networks without blocks start from the Euclidean projection of the uniform point ``γ = σ/N``
onto the box-simplex.

The Rust core's Newton loop and the double-bracket flow know only Theorem 1's simplex: for these
networks ``engine="core"`` and ``method="double-bracket"`` raise
:class:`~capalloc_rs.errors.FeatureUnavailableError`, and ``engine="auto"`` runs the Python loop.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .._arrays import as_float_array, as_real
from ..errors import FeatureUnavailableError, InvalidInputError
from .box_newton import box_newton, box_projected_gradient
from .box_simplex import fix_sum_box, project_box_simplex
from .decoupled import SEPARABLE_START_TOL, decoupled_start, has_decoupled_start
from .result import Allocation, BoxProblem, make_box_allocation

__all__ = ["box_problem", "budgeted_allocation", "check_budgeted_options", "is_paper_form"]

F64 = npt.NDArray[np.float64]


def is_paper_form(net: Any) -> bool:
    """Whether ``net`` is in the paper's form (unit costs, one common minimum, no caps); duck-typed
    oracles without ``is_paper_form`` are."""
    return bool(getattr(net, "is_paper_form", True))


def box_problem(net: Any, budget: Any, name: str = "r_tot") -> BoxProblem:
    """The box-simplex of ``net`` at the budget ``B`` (checked against ``net.budget_range``,
    InvalidInputError naming ``name``; within 1e-12 relative of an end it is that end)."""
    b_val = as_real(name, budget)
    low, high = (float(v) for v in net.budget_range)
    slack = 1e-12 * max(1.0, abs(b_val))  # as for r_tot < N·r_min: rounding is not infeasible
    if not low - slack <= b_val <= high + slack:
        raise InvalidInputError(
            f"infeasible budget: {name} = {b_val:g} (the budget B = Σ b_i r_i in channel units) "
            f"must lie in the network's budget range [{low:g}, {high:g}] "
            "(Σ b_i r_min,i ≤ B ≤ Σ b_i r_max,i)"
        )
    cu = net.in_channel_units()
    costs = np.asarray(net.costs, dtype=np.float64)
    lo = np.asarray(cu.rate_min, dtype=np.float64)
    cap = np.asarray(cu.rate_max, dtype=np.float64) - lo
    sigma = max(b_val - float(np.sum(lo)), 0.0)
    sigma = min(sigma, float(np.sum(cap)))
    return BoxProblem(net=cu, lo=lo, cap=cap, sigma=sigma, costs=costs, budget=b_val)


#: Minima in channel units within this relative spread count as one common minimum for the
#: decoupled start (``b_i·(ρ/b_i)`` is ρ only up to rounding).
COMMON_MIN_RTOL = 1e-12


def _has_decoupled(prob: BoxProblem) -> bool:
    """The decoupled start applies: one common minimum (to :data:`COMMON_MIN_RTOL`) and no caps
    in channel units, and a block network with one subsystem per sensor."""
    spread = float(np.max(prob.lo) - np.min(prob.lo))
    return (
        spread <= COMMON_MIN_RTOL * float(np.max(prob.lo))
        and not np.any(np.isfinite(prob.cap))
        and has_decoupled_start(prob.net)
    )


def _checked_gamma0(prob: BoxProblem, gamma0: Any) -> F64:
    n = prob.lo.size
    g0 = as_float_array("gamma0", gamma0, 1)
    if g0.shape != (n,) or not np.all(np.isfinite(g0)) or np.any(g0 < 0):
        raise InvalidInputError(f"gamma0 must be {n} finite non-negative numbers")
    if np.any(g0 > prob.cap):
        raise InvalidInputError("gamma0 must lie below the caps b_i (r_max,i − r_min,i)")
    if abs(float(g0.sum()) - prob.sigma) > 1e-9 * max(prob.sigma, 1.0):
        raise InvalidInputError(f"gamma0 must sum to sigma = {prob.sigma}, got {g0.sum()}")
    return fix_sum_box(g0.copy(), prob.cap, prob.sigma)


def _start(prob: BoxProblem, gamma0: Any, start: str, method: str, tol: float) -> F64:
    """The starting point on the box-simplex (see the module docstring)."""
    if gamma0 is not None:
        return _checked_gamma0(prob, gamma0)
    n = prob.lo.size
    if start == "decoupled" or (start == "auto" and method == "newton" and _has_decoupled(prob)):
        common = float(np.mean(prob.lo))
        dec = decoupled_start(prob.net, prob.sigma, tol, r_min=common)
        if dec is not None:
            return fix_sum_box(dec + common - prob.lo, prob.cap, prob.sigma)
    if start == "auto" and method == "newton" and has_decoupled_start(prob.net):
        projected = _projected_decoupled(prob)
        if projected is not None:
            return projected
    return project_box_simplex(np.full(n, prob.sigma / n), prob.cap, prob.sigma)


def _projected_decoupled(prob: BoxProblem) -> F64 | None:
    """The decoupled optimum with the common minimum ``m = min lo`` and no caps at the same
    budget (``σ' = B − N·m``), projected onto the box-simplex: a start near the optimum when the
    minima differ or caps exist (``None`` when the decoupled problem is not defined)."""
    common = float(np.min(prob.lo))
    height = prob.budget - prob.lo.size * common
    dec = decoupled_start(prob.net, height, SEPARABLE_START_TOL, r_min=common)
    if dec is None:
        return None
    return project_box_simplex(dec + common - prob.lo, prob.cap, prob.sigma)


def check_budgeted_options(prob: BoxProblem, method: str, engine: str, start: str) -> None:
    """Refuses what only exists for Theorem 1's simplex."""
    if method == "double-bracket":
        raise FeatureUnavailableError(
            "method='double-bracket' (the paper's flow on the simplex) does not handle sample "
            "costs, per-sensor minima or caps: use method='newton' or 'projected-gradient'"
        )
    if engine == "core":
        raise FeatureUnavailableError(
            "engine='core' (the Rust Newton loop) takes one common r_min and no caps: use "
            "engine='python' or 'auto' for a network with costs or limits"
        )
    if start == "decoupled" and not _has_decoupled(prob):
        raise InvalidInputError(
            "start='decoupled' needs, in channel units, one common minimum b_i·r_min,i, no caps "
            "and a block network with one subsystem per sensor; use start='uniform' or 'auto'"
        )


def budgeted_allocation(
    net: Any,
    budget: Any,
    *,
    method: str,
    tol: float,
    max_iter: int | None,
    gamma0: Any,
    mode: str | None,
    start: str,
    warm_order: int | None,
    engine: str,
) -> Allocation:
    """:func:`~.optimal.optimal_allocation` for a network not in the paper's form (arguments
    validated by the caller, ``mode`` the Newton variant or ``None``)."""
    prob = box_problem(net, budget)
    check_budgeted_options(prob, method, engine, start)
    n = prob.lo.size
    if prob.sigma == 0.0 or prob.sigma >= float(np.sum(prob.cap)) or n == 1:
        gamma = np.zeros(n) if prob.sigma == 0.0 else np.minimum(prob.cap, prob.sigma)
        gamma = fix_sum_box(gamma, prob.cap, prob.sigma)
        return make_box_allocation(prob, gamma, 0, method, 0.0, hessian=mode)
    g0 = _start(prob, gamma0, start, method, tol)
    if mode is not None:
        gamma, its, pts = box_newton(
            prob.net, prob.lo, prob.cap, prob.sigma, tol, max_iter or 200, g0, mode, warm_order
        )
        s = gamma + prob.lo
        return make_box_allocation(
            prob,
            gamma,
            its,
            method,
            0.0,
            hessian=mode,
            hvp_count=pts.hvps,
            value_grad=pts.value_gradient(s),
            eta_error=pts.value_error(s),
        )
    gamma, its = box_projected_gradient(
        prob.net, prob.lo, prob.cap, prob.sigma, tol, max_iter or 50_000, g0
    )
    return make_box_allocation(prob, gamma, its, method, 0.0)
