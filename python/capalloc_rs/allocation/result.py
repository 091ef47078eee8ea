"""The results of the allocation problems: :class:`Allocation` (the continuous optimum of
Theorem 1 with its KKT multiplier and Frank–Wolfe certificate) and :class:`IntegerAllocation`
(integer slot counts).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._json import ints, plain
from .oracle import CostOracle, value_gradient
from .simplex import frank_wolfe_gap, kkt

__all__ = ["Allocation", "IntegerAllocation", "make_allocation"]

F64 = npt.NDArray[np.float64]


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
    def shadow_price(self) -> float:
        """``−μ ≥ 0``: by how much η falls per extra unit of capacity at the optimum (the
        sensitivity ``−dη*/dr_tot``), the engineer's price of a channel unit."""
        return -self.mu

    @property
    def optimality(self) -> float:
        """``max(gap, eta_error)``: how far ``η(r)`` may be above the optimum, as far as the
        certificate and the accuracy of η can tell."""
        return max(self.gap, self.eta_error)

    def to_dict(self) -> dict[str, Any]:
        """The allocation as plain JSON-ready values: the keys of ``capalloc solve --json``
        (the certificate as ``{"frank_wolfe_gap", "kkt_residual"}``, ``hvp_count`` as
        ``hessian_vector_products``) and ``eta_error``, ``certified`` and ``optimality``."""
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
        }

    def __repr__(self) -> str:
        return (
            f"Allocation(N={self.r.size}, r_tot={self.r_tot:g}, eta={self.eta:.12g}, "
            f"active={self.active.size}, gap={self.gap:.3g}, method={self.method!r}, "
            f"iterations={self.iterations})"
        )


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

    def to_dict(self) -> dict[str, Any]:
        """The counts and their cost as plain JSON-ready values."""
        return {
            "counts": ints(self.counts),
            "eta": plain(self.eta),
            "exchanges": int(self.exchanges),
            "evaluations": int(self.evaluations),
        }

    def __repr__(self) -> str:
        shown = ints(self.counts[:10])
        more = ", …" if self.counts.size > 10 else ""
        return (
            f"IntegerAllocation(counts=[{', '.join(map(str, shown))}{more}], "
            f"eta={self.eta:.12g}, exchanges={self.exchanges})"
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
        kkt_residual=residual,
        gap=frank_wolfe_gap(gamma, g),
        iterations=iterations,
        method=method,
        hessian=hessian,
        hvp_count=hvp_count,
        eta_error=eta_error,
    )
