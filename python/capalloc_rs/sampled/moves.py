"""The moves of the screened schedule search (:mod:`capalloc_rs.sampled.screened`): one slot
given to another sensor (*reassignment*), two adjacent slots exchanged (*swap*) and one sample
moved to another slot, the samples in between one slot back (*shift*, :mod:`.shifts`), ranked by
their predicted change of ``η̄`` and packed into batches of non-overlapping moves that keep the
count limits and the budget.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .channel import ScheduleLimits
from .shifts import best_shifts

__all__: list[str] = []


@dataclass(frozen=True)
class _Move:
    predicted: float
    kind: str  # "reassign" (slot a to sensor b), "swap" (slots a, a + 1), "shift" (slot a to b)
    a: int
    b: int

    def span(self) -> tuple[int, ...]:
        if self.kind == "shift":
            return tuple(range(min(self.a, self.b), max(self.a, self.b) + 1))
        return (self.a,) if self.kind == "reassign" else (self.a, self.a + 1)


def _ranked(sc: Any, slots: list[int], max_shift: int) -> tuple[list[_Move], list[_Move]]:
    """The reassignments and the swaps (``max_shift > 1``: the shifts of :mod:`.shifts`, the
    best per slot) predicted to lower the cost, each best first (ranked apart: the first-order
    screen of a reassignment, a large change of one slot, is optimistic; that of a swap, a small
    change, close to exact)."""
    reassign = np.asarray(sc.reassign)
    moves = [
        _Move(float(reassign[pos, j]), "reassign", int(pos), int(j))
        for pos, j in zip(*np.nonzero(reassign < 0.0), strict=True)
    ]
    moves.sort(key=lambda mv: (mv.predicted, mv.a, mv.b))
    swap = np.asarray(sc.swap)
    if max_shift > 1:
        shifts = [_Move(p, "shift", a, b) for p, a, b in best_shifts(swap, slots, max_shift)]
        return moves, shifts
    swaps = [_Move(float(swap[at]), "swap", int(at), 0) for at in np.flatnonzero(swap < 0.0)]
    swaps.sort(key=lambda mv: (mv.predicted, mv.a))
    return moves, swaps


def _apply(slots: list[int], mv: _Move) -> None:
    if mv.kind == "reassign":
        slots[mv.a] = mv.b
    elif mv.kind == "shift":
        slots.insert(mv.b, slots.pop(mv.a))
    else:
        slots[mv.a], slots[mv.a + 1] = slots[mv.a + 1], slots[mv.a]


def _pack(
    ranked: list[_Move], slots: list[int], n_sensors: int, lim: ScheduleLimits, limit: int
) -> list[_Move]:
    """Non-overlapping moves in rank order (at most ``limit``) that keep every sensor within its
    count limits, and the schedule within the budget, when applied together."""
    counts = np.bincount(np.asarray(slots), minlength=n_sensors)
    used: set[int] = set()
    out: list[_Move] = []
    for mv in ranked:
        if len(out) >= limit:
            break
        span = mv.span()
        if used.intersection(span):
            continue
        if mv.kind == "reassign":
            i = slots[mv.a]
            if counts[i] - 1 < lim.lo[i]:
                continue
            if not lim.plain:
                counts[i] -= 1
                counts[mv.b] += 1
                if not lim.fits(counts):
                    counts[i] += 1
                    counts[mv.b] -= 1
                    continue
                counts[i] += 1
                counts[mv.b] -= 1
            counts[i] -= 1
            counts[mv.b] += 1
        used.update(span)
        out.append(mv)
    return out


def _with(slots: list[int], moves: list[_Move]) -> list[int]:
    trial = list(slots)
    for mv in moves:
        _apply(trial, mv)
    return trial


def _interleave(a: list[_Move], b: list[_Move]) -> list[_Move]:
    out: list[_Move] = []
    for x, y in zip(a, b, strict=False):
        out += [x, y]
    longer = a if len(a) > len(b) else b
    return out + longer[min(len(a), len(b)) :]
