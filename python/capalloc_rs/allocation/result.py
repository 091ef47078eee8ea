"""The results of the allocation problems: :class:`Allocation` (the continuous optimum of
Theorem 1 with its KKT multipliers and Frank–Wolfe certificate, on the simplex or, with sample
costs, minima and caps, on the weighted box-simplex of :mod:`.box_simplex`) and
:class:`IntegerAllocation` (integer counts).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._json import ints, plain
from .box_simplex import box_frank_wolfe_gap, box_kkt
from .oracle import CostOracle, value_gradient
from .simplex import frank_wolfe_gap, kkt

__all__ = [
    "Allocation",
    "BoxProblem",
    "IntegerAllocation",
    "make_allocation",
    "make_box_allocation",
]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Allocation:
    """An optimal allocation with its certificate.

    For a network in the paper's form (unit costs, one common ``r_min``, no caps) the problem is
    Theorem 1's simplex; otherwise it is the weighted box-simplex ``{r_min,i ≤ r_i ≤ r_max,i,
    Σ b_i r_i = B}``, solved in channel units ``s = b ∘ r`` (:mod:`.box_simplex`): then ``gamma``,
    ``sigma``, ``mu``, the multipliers and the certificate are per channel unit, and the KKT
    conditions in rates read ``∂η/∂r_i = μ b_i`` on the free set. With unit costs both readings
    coincide.

    Attributes:
        r: rates ``r_min + γ`` (each ≥ r_min, summing to r_tot); with costs and limits
            ``r_min,i ≤ r_i ≤ r_max,i`` with ``Σ b_i r_i = B``.
        gamma: ``γ = r − r_min`` on the simplex of height ``sigma``; with costs
            ``γ = b ∘ (r − r_min)``, the channel units above the minima (``0 ≤ γ_i ≤ b_i (r_max,i
            − r_min,i)``).
        sigma: ``σ = r_tot − N·r_min``; with costs ``σ = B − Σ b_i r_min,i``.
        r_tot: total capacity as passed (the budget ``B`` for a network with costs or limits).
        eta: ``η(r) = tr Σ(r)`` (``tr(M Σ)`` with a weight).
        gradient: ``∂η/∂γ_i = ∂η/∂r_i`` at the solution (always in rates: ``b_i`` times the
            gradient per channel unit).
        mu: the KKT multiplier of Theorem 1, per channel unit (mean gradient per channel unit
            over the free set; without one, ``min g_i/b_i`` over the sensors at their minimum, or
            ``max`` over the capped ones when all are capped).
        active: indices with ``γ_i > 0`` (above their minimum; capped ones included).
        kkt_residual: ``max(max_{free} |g_i/b_i − μ|, max_{at minimum} (μ − g_j/b_j)₊,
            max_{at cap} (g_k/b_k − μ)₊) / |μ|``.
        gap: Frank–Wolfe duality gap (on the simplex, or the weighted box-simplex in channel
            units: a fractional knapsack), an upper bound on ``η(r) − η*`` computed from the
            computed gradient.
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
        budget: the budget ``B = Σ b_i r_i`` in channel units (``r_tot`` for unit costs);
            ``None`` only for an Allocation built by hand the old way.
        costs: the sample costs ``b_i`` (ones in the paper's case).
        at_minimum: indices at their minimum ``r_min,i`` (``γ_i = 0``).
        at_cap: indices at their cap ``r_max,i`` (empty without caps).
        lower_multipliers: per channel unit, ``λ_i = g_i/b_i − μ`` (≥ 0 at the optimum) for the
            sensors at their minimum, 0 elsewhere: ``dη*/dr_min,i = b_i λ_i``.
        upper_multipliers: per channel unit, ``ν_i = μ − g_i/b_i`` (≥ 0 at the optimum) for the
            capped sensors, 0 elsewhere: ``dη*/dr_max,i = −b_i ν_i``.
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
    budget: float | None = None
    costs: F64 | None = None
    at_minimum: tuple[int, ...] = ()
    at_cap: tuple[int, ...] = ()
    lower_multipliers: F64 | None = None
    upper_multipliers: F64 | None = None

    @property
    def certified(self) -> bool:
        """``gap ≥ eta_error``: the Frank–Wolfe gap is meaningful at the accuracy of η."""
        return self.gap >= self.eta_error

    @property
    def shadow_price(self) -> float:
        """``−μ ≥ 0``: by how much η falls per extra unit of capacity at the optimum (the
        sensitivity ``−dη*/dr_tot``, with costs ``−dη*/dB``), the engineer's price of a channel
        unit."""
        return -self.mu

    @property
    def optimality(self) -> float:
        """``max(gap, eta_error)``: how far ``η(r)`` may be above the optimum, as far as the
        certificate and the accuracy of η can tell."""
        return max(self.gap, self.eta_error)

    def to_dict(self) -> dict[str, Any]:
        """The allocation as plain JSON-ready values: the keys of ``capalloc solve --json``
        (the certificate as ``{"frank_wolfe_gap", "kkt_residual"}``, ``hvp_count`` as
        ``hessian_vector_products``) and ``eta_error``, ``certified`` and ``optimality``; the
        budget, the costs, the sensors at their minimum and at their cap and the bound
        multipliers per channel unit (``lower_multipliers``, ``upper_multipliers``)."""
        n = self.r.size
        return {
            "r_tot": plain(self.r_tot),
            "sigma": plain(self.sigma),
            "r": plain(self.r),
            "gamma": plain(self.gamma),
            "eta": plain(self.eta),
            "gradient": plain(self.gradient),
            "mu": plain(self.mu),
            "shadow_price": plain(self.shadow_price),
            "active": ints(self.active),
            "certificate": {
                "frank_wolfe_gap": plain(self.gap),
                "kkt_residual": plain(self.kkt_residual),
            },
            "iterations": int(self.iterations),
            "method": self.method,
            "hessian": self.hessian,
            "hessian_vector_products": int(self.hvp_count),
            "eta_error": plain(self.eta_error),
            "certified": bool(self.certified),
            "optimality": plain(self.optimality),
            "budget": plain(self.r_tot if self.budget is None else self.budget),
            "costs": plain(np.ones(n) if self.costs is None else self.costs),
            "at_minimum": ints(self.at_minimum),
            "at_cap": ints(self.at_cap),
            "lower_multipliers": plain(
                np.zeros(n) if self.lower_multipliers is None else self.lower_multipliers
            ),
            "upper_multipliers": plain(
                np.zeros(n) if self.upper_multipliers is None else self.upper_multipliers
            ),
        }

    def __repr__(self) -> str:
        limits = ""
        if self.costs is not None and (self.at_cap or np.any(self.costs != 1.0)):
            limits = f"budget={self.budget:g}, at_minimum={len(self.at_minimum)}, "
            limits += f"at_cap={len(self.at_cap)}, "
        return (
            f"Allocation(N={self.r.size}, r_tot={self.r_tot:g}, eta={self.eta:.12g}, "
            f"active={self.active.size}, {limits}gap={self.gap:.3g}, method={self.method!r}, "
            f"iterations={self.iterations})"
        )


@dataclass(frozen=True)
class IntegerAllocation:
    """Integer slot counts ``r_i ≥ r_min`` summing to ``r_tot`` that minimise η over integer
    vectors; with sample costs or limits, counts ``max(1, ⌈r_min,i⌉) ≤ k_i ≤ ⌊r_max,i⌋`` with
    ``Σ b_i k_i ≤ B``. With a proven lower bound on the least η over all feasible counts.

    Attributes:
        counts: integer slot counts.
        eta: ``η(counts)``.
        exchanges: improving exchanges applied after the greedy phase.
        evaluations: cost evaluations of integer counts used.
        budget: with costs or limits, the budget ``B`` in channel units; ``None`` in the paper's
            case (the counts then sum to ``r_tot``).
        spent: with costs or limits, ``Σ b_i k_i ≤ B``; ``None`` in the paper's case.
        proven_optimal: whether the counts are proven optimal: ``gap ≤ tolerance``, or the
            exact knapsack program of a decoupled network with costs or limits. (``None`` only
            for a result built by hand the old way in the paper's case.)
        lower_bound: a proven lower bound on the least η over all feasible integer counts (the
            relaxations' certified bounds, :mod:`.integer_relaxation`; ``-inf`` when none was
            computed).
        method: ``"branch-and-bound"`` or ``"greedy"``.
        nodes: relaxations solved (1 for the greedy's root bound).
        tolerance: the proof's tolerance: the counts are proven optimal when
            ``gap ≤ tolerance`` (``tol·|η|`` plus twice the largest certified error of η met).
        stopped: ``None`` when the search finished, ``"max_nodes"`` or ``"time_limit"`` when a
            limit cut it short (the counts are then the best found, ``gap`` still proven).
    """

    counts: npt.NDArray[np.int64]
    eta: float
    exchanges: int
    evaluations: int
    budget: float | None = None
    spent: float | None = None
    proven_optimal: bool | None = None
    lower_bound: float = float("-inf")
    method: str = "greedy"
    nodes: int = 0
    tolerance: float = 0.0
    stopped: str | None = None

    @property
    def gap(self) -> float:
        """``eta − lower_bound ≥ 0``: how far η may be above the integer optimum (proven)."""
        return self.eta - self.lower_bound

    def to_dict(self) -> dict[str, Any]:
        """The counts and their cost as plain JSON-ready values, the lower bound, gap,
        ``proven_optimal``, tolerance, method, nodes and ``stopped``; with costs or limits also
        ``budget`` and ``spent``."""
        d = {
            "counts": ints(self.counts),
            "eta": plain(self.eta),
            "exchanges": int(self.exchanges),
            "evaluations": int(self.evaluations),
            "lower_bound": plain(self.lower_bound),
            "gap": plain(self.gap),
            "proven_optimal": self.proven_optimal,
            "tolerance": plain(self.tolerance),
            "method": self.method,
            "nodes": int(self.nodes),
            "stopped": self.stopped,
        }
        if self.budget is not None:
            d.update(budget=plain(self.budget), spent=plain(self.spent))
        return d

    def __repr__(self) -> str:
        shown = ints(self.counts[:10])
        more = ", …" if self.counts.size > 10 else ""
        spent = ""
        if self.budget is not None and self.spent is not None:
            spent = f", spent={self.spent:g} of {self.budget:g}"
        return (
            f"IntegerAllocation(counts=[{', '.join(map(str, shown))}{more}], "
            f"eta={self.eta:.12g}, gap={self.gap:.3g}, proven_optimal={self.proven_optimal}"
            f"{spent})"
        )


def make_allocation(
    net: CostOracle,
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
    """The :class:`Allocation` at ``γ``: rates, KKT multiplier and residual, Frank–Wolfe gap and
    the accuracy of η (from ``net.at`` when the caller has not measured it), arrays read-only.
    ``value_grad`` is ``(η, ∇η)`` at ``r_min + γ`` if already known (saves a Riccati solve)."""
    r = gamma + float(net.r_min)
    eta, g = value_gradient(net, r) if value_grad is None else value_grad
    if eta_error is None:
        at = getattr(net, "at", None)
        eta_error = float(at(r).value_error) if at is not None else 0.0
    g = np.array(g, dtype=np.float64)
    mu, active, residual = kkt(gamma, g, sigma, active_tol)
    lower = np.where(active, 0.0, g - mu)
    costs, upper = np.ones(g.size), np.zeros(g.size)
    for arr in (r, gamma, g, lower, upper, costs):
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
        kkt_residual=residual,
        gap=frank_wolfe_gap(gamma, g),
        iterations=iterations,
        method=method,
        hessian=hessian,
        hvp_count=hvp_count,
        eta_error=eta_error,
        budget=float(r_tot),
        costs=costs,
        at_minimum=tuple(int(i) for i in np.flatnonzero(~active)),
        at_cap=(),
        lower_multipliers=lower,
        upper_multipliers=upper,
    )


@dataclass(frozen=True)
class BoxProblem:
    """The weighted box-simplex of a network with costs or limits, in channel units: the network
    ``net`` in channel units (rates ``s = b ∘ r``), lower bounds ``lo = b ∘ r_min``, room above
    them ``cap = b ∘ (r_max − r_min)`` (``inf``: no cap), ``σ = B − Σ lo``, the costs ``b`` and
    the budget ``B``."""

    net: Any
    lo: F64
    cap: F64
    sigma: float
    costs: F64
    budget: float


def make_box_allocation(
    prob: BoxProblem,
    gamma: F64,
    iterations: int,
    method: str,
    active_tol: float,
    *,
    hessian: str | None = None,
    hvp_count: int = 0,
    value_grad: tuple[float, F64] | None = None,
    eta_error: float | None = None,
) -> Allocation:
    """The :class:`Allocation` at ``γ`` (channel units above the minima) of a box problem: rates
    ``r = (lo + γ)/b``, the gradient in rates, μ, the bound multipliers and the box-simplex
    Frank–Wolfe gap per channel unit; ``value_grad`` is ``(η, ∇_s η)`` in channel units if known."""
    cu, b = prob.net, prob.costs
    s = gamma + prob.lo
    eta, g_s = value_gradient(cu, s) if value_grad is None else value_grad
    if eta_error is None:
        at = getattr(cu, "at", None)
        eta_error = float(at(s).value_error) if at is not None else 0.0
    g_s = np.array(g_s, dtype=np.float64)
    mu, at_min, at_cap, residual = box_kkt(gamma, g_s, prob.cap, active_tol)
    lower = np.where(at_min, g_s - mu, 0.0)
    upper = np.where(at_cap, mu - g_s, 0.0)
    r, g_r, costs = s / b, g_s * b, b.copy()
    gamma = gamma.copy()
    for arr in (r, gamma, g_r, lower, upper, costs):
        arr.setflags(write=False)
    idx = np.flatnonzero(~at_min)
    idx.setflags(write=False)
    return Allocation(
        r=r,
        gamma=gamma,
        sigma=prob.sigma,
        r_tot=prob.budget,
        eta=float(eta),
        gradient=g_r,
        mu=mu,
        active=idx,
        kkt_residual=residual,
        gap=box_frank_wolfe_gap(gamma, g_s, prob.cap, prob.sigma),
        iterations=iterations,
        method=method,
        hessian=hessian,
        hvp_count=hvp_count,
        eta_error=eta_error,
        budget=prob.budget,
        costs=costs,
        at_minimum=tuple(int(i) for i in np.flatnonzero(at_min)),
        at_cap=tuple(int(i) for i in np.flatnonzero(at_cap)),
        lower_multipliers=lower,
        upper_multipliers=upper,
    )
