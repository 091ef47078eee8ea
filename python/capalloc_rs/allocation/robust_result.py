"""The results of the robust allocation over a set of models (:mod:`.robust`):
:class:`RobustAllocation` (the continuous optimum of the mean or worst-case error with its proven
lower bound) and :class:`RobustIntegerAllocation` (integer counts, no optimality claimed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._json import ints, plain

__all__ = ["RobustAllocation", "RobustIntegerAllocation"]

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RobustAllocation:
    """An allocation minimising the mean ``Σ_k w_k η_k(r)`` or the worst case ``max_k η_k(r)``
    over K models, with a proven lower bound on the optimum.

    Attributes:
        r: the rates (``r_min,i ≤ r_i ≤ r_max,i``, ``Σ b_i r_i = B``), read-only.
        objective: ``"mean"`` or ``"worst"``.
        value: the objective at ``r``: ``Σ w_k η_k(r)`` or ``max_k η_k(r)``.
        eta_per_model: ``(η_1(r), …, η_K(r))``.
        weights: for ``"mean"`` the normalised weights ``w``; for ``"worst"`` the weights
            ``λ`` (in the simplex) of the certificate: the mixture of the models that are worst
            at the optimum (the QP multipliers).
        lower_bound: a proven lower bound on the optimum of the objective: for ``"mean"``
            ``value − gap`` (the Frank–Wolfe gap of the mean, a sum of convex functions); for
            ``"worst"`` ``Σ λ_k η_k(r̂) − FW_λ(r̂)`` at the best ``λ`` and iterate ``r̂`` seen,
            a lower bound on ``min_r Σ λ_k η_k(r) ≤ min_r max_k η_k(r)`` (weak duality).
        gap: ``value − lower_bound ≥ 0``: how far ``value`` may be above the optimum.
        mu: the KKT multiplier per channel unit of the mean (for ``"worst"``: of the λ-mixture)
            at ``r``; ``−μ`` is the shadow price of a channel unit (``−d value*/dB``).
        iterations: outer iterations (Newton or SQP steps).
        evaluations: model evaluations (one per model per point).
        eta_error: the Riccati solvers' bound on the error of ``value``.
        budget: the budget ``B`` in channel units (``r_tot`` for unit costs).
    """

    r: F64
    objective: str
    value: float
    eta_per_model: tuple[float, ...]
    weights: tuple[float, ...]
    lower_bound: float
    gap: float
    mu: float
    iterations: int
    evaluations: int
    eta_error: float
    budget: float

    @property
    def num_models(self) -> int:
        """K."""
        return len(self.eta_per_model)

    @property
    def shadow_price(self) -> float:
        """``−μ``."""
        return -self.mu

    @property
    def certified(self) -> bool:
        """``gap ≥ eta_error``: the gap is meaningful at the accuracy of the values."""
        return self.gap >= self.eta_error

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values."""
        return {
            "objective": self.objective,
            "r": plain(self.r),
            "value": plain(self.value),
            "eta_per_model": plain(list(self.eta_per_model)),
            "weights": plain(list(self.weights)),
            "lower_bound": plain(self.lower_bound),
            "gap": plain(self.gap),
            "mu": plain(self.mu),
            "shadow_price": plain(self.shadow_price),
            "iterations": int(self.iterations),
            "evaluations": int(self.evaluations),
            "eta_error": plain(self.eta_error),
            "certified": bool(self.certified),
            "budget": plain(self.budget),
            "num_models": self.num_models,
        }

    def __repr__(self) -> str:
        return (
            f"RobustAllocation(objective={self.objective!r}, K={self.num_models}, "
            f"N={self.r.size}, value={self.value:.12g}, gap={self.gap:.3g}, "
            f"iterations={self.iterations})"
        )


@dataclass(frozen=True)
class RobustIntegerAllocation:
    """Integer counts ``max(1, ⌈r_min,i⌉) ≤ k_i ≤ ⌊r_max,i⌋`` with ``Σ b_i k_i ≤ B`` for the
    mean or worst-case objective: greedy plus exchanges, a local optimum (no optimality is
    claimed); ``lower_bound`` (the continuous robust optimum's proven lower bound) bounds the
    integer optimum from below, so ``value − lower_bound`` is a proven bound on the loss.

    Attributes:
        counts: the integer counts (read-only).
        objective: ``"mean"`` or ``"worst"``.
        value: the objective at ``counts``.
        eta_per_model: ``(η_1(counts), …, η_K(counts))``.
        weights: the mean's normalised weights (for ``"worst"``: equal weights, unused).
        lower_bound: a proven lower bound on the integer optimum.
        exchanges: improving exchanges after the greedy phase.
        evaluations: model evaluations (one per model per count vector).
        budget: ``B``.
        spent: ``Σ b_i k_i ≤ B``.
    """

    counts: npt.NDArray[np.int64]
    objective: str
    value: float
    eta_per_model: tuple[float, ...]
    weights: tuple[float, ...]
    lower_bound: float
    exchanges: int
    evaluations: int
    budget: float
    spent: float

    @property
    def gap(self) -> float:
        """``value − lower_bound``: a proven bound on how far ``value`` is above the optimum."""
        return self.value - self.lower_bound

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (``proven_optimal`` is always False)."""
        return {
            "objective": self.objective,
            "counts": ints(self.counts),
            "value": plain(self.value),
            "eta_per_model": plain(list(self.eta_per_model)),
            "weights": plain(list(self.weights)),
            "lower_bound": plain(self.lower_bound),
            "gap": plain(self.gap),
            "exchanges": int(self.exchanges),
            "evaluations": int(self.evaluations),
            "budget": plain(self.budget),
            "spent": plain(self.spent),
            "proven_optimal": False,
        }

    def __repr__(self) -> str:
        shown = ints(self.counts[:10])
        more = ", …" if self.counts.size > 10 else ""
        return (
            f"RobustIntegerAllocation(objective={self.objective!r}, "
            f"counts=[{', '.join(map(str, shown))}{more}], value={self.value:.12g}, "
            f"gap={self.gap:.3g})"
        )
