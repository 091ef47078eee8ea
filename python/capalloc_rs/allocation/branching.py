"""Pseudo-cost branching for the integer branch-and-bound: which coordinate of a node's relaxed
optimum ``r̂`` to split on.

Splitting coordinate ``i`` at ``t = ⌊r̂_i⌋`` moves the relaxed optimum of the down child
(``k_i ≤ t``) by at least ``f_i = r̂_i − t`` in that coordinate and of the up child by
``1 − f_i``; near a smooth optimum the bound rises by about ``½ c_i·distance²`` (``c_i`` the
curvature of the relaxation's value in ``r_i``). The pseudo-costs are the observed rises per
squared distance, ``ψ = (child bound − parent bound) / distance²``, averaged per coordinate and
direction (a coordinate not yet branched on takes the average over all coordinates, 1 before
any observation). A node splits the coordinate of largest predicted product
``max(ψ↓ f², ε)·max(ψ↑ (1 − f)², ε)`` (both children rise: best-first closes them sooner);
with every fraction zero it falls back to any coordinate not fixed. The choice affects only how
fast the search closes, never the validity of a bound.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = ["PseudoCosts"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Fractions below this are integral for branching.
INTEGRAL = 1e-9


class PseudoCosts:
    """Per-coordinate observed bound rises per squared distance, down and up."""

    def __init__(self, n: int) -> None:
        self.sum = np.zeros((2, n))
        self.count = np.zeros((2, n))

    def record(self, i: int, up: bool, distance: float, rise: float) -> None:
        """One child's observation: its bound rose by ``rise`` after its coordinate ``i`` moved
        ``distance`` (> 0) up or down."""
        if distance > INTEGRAL and np.isfinite(rise):
            self.sum[int(up), i] += max(rise, 0.0) / distance**2
            self.count[int(up), i] += 1.0

    def _estimates(self) -> F64:
        total = float(np.sum(self.count))
        mean = float(np.sum(self.sum)) / total if total > 0 else 1.0
        with np.errstate(invalid="ignore", divide="ignore"):
            est = np.where(self.count > 0, self.sum / self.count, mean)
        return np.asarray(est, dtype=np.float64)

    def choose(self, r: F64, lo: I64, hi: I64) -> int | None:
        """The coordinate to split (``None``: every coordinate fixed)."""
        free = lo < hi
        if not np.any(free):
            return None
        t = np.minimum(np.maximum(np.floor(r), lo), np.maximum(hi - 1, lo))
        f = np.clip(r - t, 0.0, 1.0)
        frac = free & (f > INTEGRAL) & (f < 1.0 - INTEGRAL)
        if not np.any(frac):
            return int(np.flatnonzero(free)[0])
        est = self._estimates()
        down, up = est[0] * f**2, est[1] * (1.0 - f) ** 2
        eps = 1e-6 * max(float(np.max(np.where(frac, np.maximum(down, up), 0.0))), 1e-300)
        score = np.where(frac, np.maximum(down, eps) * np.maximum(up, eps), -1.0)
        return int(np.argmax(score))
