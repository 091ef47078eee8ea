"""Root bracketing by false position with the Illinois modification, as the filtration uses it to
locate where a monotonicity slope or an event function changes sign between two path points.

``f(lo) > 0 ≥ f(hi)``: each step takes the secant point of the bracket (its midpoint when the
secant leaves it), keeps the sign change, and halves the value kept at the end that did not move
twice in a row (Illinois), which makes the convergence superlinear instead of one-sided.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

__all__ = ["illinois"]

P = TypeVar("P")

#: Bracketing steps at most (each a corrected path point); the bracket shrinks superlinearly.
MAX_STEPS = 200


def illinois(
    at: Callable[[float], tuple[P, float]],
    lo: float,
    flo: float,
    hi: float,
    fhi: float,
    best: P,
    tol: float,
) -> P:
    """The point at the non-positive end of the bracket once ``hi − lo ≤ tol`` (or after
    :data:`MAX_STEPS` steps): ``at(s)`` gives the point at ``s`` and the function's value there,
    ``flo > 0 ≥ fhi`` the values at the ends and ``best`` the point at ``hi``."""
    side = 0
    for _ in range(MAX_STEPS):
        if hi - lo <= tol:
            break
        s = hi - fhi * (hi - lo) / (fhi - flo) if fhi != flo else 0.5 * (lo + hi)
        if not (lo < s < hi):
            s = 0.5 * (lo + hi)
        q, fs = at(s)
        if fs > 0:
            lo, flo = s, fs
            fhi, side = (0.5 * fhi if side == -1 else fhi), -1
        else:
            hi, fhi, best = s, fs, q
            flo, side = (0.5 * flo if side == 1 else flo), 1
    return best
