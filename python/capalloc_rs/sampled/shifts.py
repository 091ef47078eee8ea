"""Shift moves of the screened schedule search: one sample moved ``k`` slots along the period (the
samples in between each move one slot back), predicted from the screen's adjacent-swap
sensitivities.

A shift of the sample at slot ``a`` to slot ``b > a`` is the chain of the ``k = b − a`` adjacent
swaps that carry it past the samples at ``a + 1, …, b``. Model the first-order change of the cost
when the sample at slot ``l`` moves one slot later as ``d_l`` (when it moves one slot earlier,
``−d_l``), each sample on its own. The screen's swap prediction ``w_l`` (slots ``l, l + 1``
exchanged: the sample at ``l`` one later, the one at ``l + 1`` one earlier) is then
``w_l = d_l − d_{l+1}``, which fixes ``d`` up to a constant, and the shift is predicted as

``P(a → b) = Σ_{j=1..k} (d_a − d_{a+j}) = Σ_{j=1..k} Σ_{m=a..a+j−1} w_m``

(the moved sample ``k`` slots later, the ``k`` others one slot earlier each), and symmetrically
``P(a → a − k) = Σ_{j=1..k} Σ_{m=a−j..a−1} w_m``. With ``c_x = Σ_{m<x} w_m`` (``c_0 = 0``) and
``C_x = Σ_{j<x} c_j``: ``P(a → b) = C_{b+1} − C_{a+1} − k c_a`` and
``P(a → a − k) = k c_a − (C_a − C_{a−k})``. For ``k = 1`` it is the swap's own prediction.
The model is linear in the moved sample's displacement and additive over the samples: a
prediction, which the search checks by an exact costing before taking a move (at N = 100,
r_tot = 300 the top predictions of the first screen were within 5 % of the exact changes).

**Displacement step.** The same model gives every sample's displacement at once: with
``d = −c`` (up to a constant, which no permutation sees), moving the sample of slot ``l`` to the
real position ``l + α c_l`` — later where a later sample lowers the cost — and sorting the samples
by these positions gives a permutation ``π`` of the slots (counts unchanged) predicted to change
the cost by ``Σ_l d_l (π(l) − l)``; ``α`` is set so that the largest displacement of a position
is ``K`` slots (``K`` chosen by the search from exact costings). At N = 100, r_tot = 300 the
predictions of such steps with ``K`` from 32 to 256 slots were within 1–5 % of the exact
changes.

Targets that duplicate a shorter shift (a sample of the moved sample's own sensor) and pairs of
the same sensor (``w_l = +∞`` in the screen: no change) are handled as no change (``w_l = 0``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Displacement", "best_shifts", "displaced"]


def best_shifts(
    swap: Sequence[float] | np.ndarray, slots: Sequence[int], max_shift: int
) -> list[tuple[float, int, int]]:
    """For every slot ``a``, the shift ``a → b`` (``1 ≤ |b − a| ≤ max_shift``) with the lowest
    prediction, if it is negative: ``(prediction, a, b)`` sorted best first (ties by ``a``).

    A target holding a sample of the moved sample's sensor is skipped (the same schedule as the
    shift one slot shorter); a shift by one slot is reported once, from its earlier slot.

    Args:
        swap: The screen's swap predictions ``w_l`` (``r − 1`` values, ``+∞`` where the two slots
            hold the same sensor).
        slots: The current schedule (``r`` sensor indices).
        max_shift: The longest shift considered (``≥ 1``).

    Returns:
        The predicted improving shifts, best first.
    """
    s = np.asarray(slots, dtype=np.int64)
    r = len(s)
    c = _shift_potential(swap, r)  # c[x] = Σ_{m<x} w_m, x = 0..r−1
    big_c = np.concatenate([[0.0], np.cumsum(c)])  # big_c[x] = Σ_{j<x} c_j, x = 0..r
    a = np.arange(r)
    best = np.zeros(r)
    target = np.full(r, -1, dtype=np.int64)
    for k in range(1, min(max_shift, r - 1) + 1):
        for sign in (1, -1):
            b = a + sign * k
            ok = (b >= 0) & (b < r)
            src, dst = a[ok], b[ok]
            if sign > 0:
                pred = big_c[dst + 1] - big_c[src + 1] - k * c[src]
            else:
                if k == 1:
                    continue  # the same swap as the shift by one from the earlier slot
                pred = k * c[src] - (big_c[src] - big_c[dst])
            pred = np.where(s[dst] == s[src], np.inf, pred)
            better = pred < best[src]
            best[src[better]] = pred[better]
            target[src[better]] = dst[better]
    out = [(float(best[i]), int(i), int(target[i])) for i in np.flatnonzero(target >= 0)]
    out.sort()
    return out


def _shift_potential(swap: Sequence[float] | np.ndarray, r: int) -> np.ndarray:
    """``c_x = Σ_{m<x} w_m`` (``x = 0..r−1``; ``+∞`` swaps, same sensor, as ``0``)."""
    w = np.asarray(swap, dtype=np.float64)[: max(r - 1, 0)]
    w = np.where(np.isfinite(w), w, 0.0)
    return np.concatenate([[0.0], np.cumsum(w)])


def displaced(
    swap: Sequence[float] | np.ndarray, slots: Sequence[int], k: int
) -> tuple[list[int], float] | None:
    """The displacement step of largest displacement ``k`` slots and its prediction.

    Args:
        swap: The screen's swap predictions ``w_l`` (as :func:`best_shifts`).
        slots: The current schedule.
        k: The largest displacement of a sample's real position, in slots (``≥ 1``).

    Returns:
        ``(schedule, predicted change)``, or ``None`` when the step leaves the schedule as it is
        or is not predicted to lower the cost.
    """
    s = np.asarray(slots, dtype=np.int64)
    r = len(s)
    c = _shift_potential(swap, r)
    spread = float(np.max(np.abs(c - np.median(c)))) if r else 0.0
    if not spread > 0.0 or not math.isfinite(spread):
        return None
    key = np.arange(r) + (k / spread) * (c - np.median(c))
    perm = np.argsort(key, kind="stable")
    new = s[perm]
    if np.array_equal(new, s):
        return None
    pos = np.empty(r, dtype=np.int64)
    pos[perm] = np.arange(r)
    predicted = float(np.sum(c * (np.arange(r) - pos)))  # Σ d_l (π(l) − l), d = −c
    if not predicted < 0.0:
        return None
    return [int(v) for v in new], predicted


@dataclass
class Displacement:
    """The step-size control of the displacement steps of one search: steps of largest
    displacement ``k/2`` and ``k`` are costed together (``k`` alone while the steps of the
    largest ``k``, ``cap``, are being taken); ``k`` doubles (at most ``cap``) after the step of
    ``k`` is taken, becomes ``k/2`` after that one, ``k/4`` when neither improves; below 2 the
    steps stop (:attr:`active`)."""

    k: int
    cap: int
    at_cap: bool = False

    @property
    def active(self) -> bool:
        """Whether the steps go on (``k ≥ 2``)."""
        return self.k >= 2

    def candidates(
        self, swap: Sequence[float] | np.ndarray, slots: Sequence[int]
    ) -> tuple[list[int], list[list[int]]]:
        """The largest displacements tried and their steps (those predicted to improve)."""
        tried = (self.k,) if self.at_cap else (self.k // 2, self.k)
        steps = [(kk, displaced(swap, slots, kk)) for kk in tried]
        return [kk for kk, st in steps if st is not None], [st[0] for _, st in steps if st]

    def update(self, ks: list[int], taken: int | None) -> None:
        """After the step ``ks[taken]`` was taken (``None``: none improved)."""
        k = self.k
        self.at_cap = taken is not None and ks[taken] == k == self.cap
        if taken is None:
            self.k = k // 4
        else:
            self.k = min(2 * k, self.cap) if ks[taken] == k else ks[taken]
