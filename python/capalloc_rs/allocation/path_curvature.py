"""Second derivatives of the optimal allocation map and of its event functions carried across a
breakpoint: the quadratic term of the continuation's predictors (:mod:`.continuation`) at the
start of a segment, where no second node of the segment is known yet.

On the segment ``[σ_a, σ_b]`` ending at a breakpoint ``σ_b`` the cubic Hermite interpolant of the
nodes ``a`` and ``b`` (values ``y`` and derivatives ``y'`` with respect to σ) has, at ``σ_b``, the
second derivative

    y''(σ_b) ≈ (6(y_a − y_b) + 2h(y'_a + 2y'_b))/h²,   h = σ_b − σ_a,

exact for cubics (error ``O(h)·y'''`` otherwise). After the breakpoint the tangent changes
(Proposition 5 on the new face) but the map stays smooth in each share that keeps its role: the
shares free on both sides and the enter functions ``(g_j − μ)/|μ|`` of the sensors still at
their minimum. Their second derivatives are carried over (rescaled to the new segment's ``|μ|``),
the others set to 0 (the entering share, which starts at 0 with a new slope; capped shares; the
second block of cap functions). The predictor from the segment's first node ``s`` is then

    f(σ) ≈ f_s + (σ − σ_s) f'_s + ½(σ − σ_s)² f''_carried,

a second-order Taylor model in every carried component instead of the tangent alone, and the
event functions are extrapolated the same way: the breakpoints ahead are predicted more closely
and the Newton solve that locates them starts closer (fewer evaluations of η). The carried
second derivatives only shape the starting points: every node is still corrected to the KKT
conditions by Newton's method, so the path and its breakpoints do not depend on them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["carried_events", "carried_path", "hermite_second_derivative"]

F64 = npt.NDArray[np.float64]


def hermite_second_derivative(h: float, ya: Any, da: Any, yb: Any, db: Any) -> Any:
    """The second derivative at the right end of the cubic Hermite interpolant of
    ``(ya, da)`` and ``(yb, db)`` a distance ``h > 0`` apart (arrays or floats)."""
    return (6.0 * (ya - yb) + 2.0 * h * (da + 2.0 * db)) / (h * h)


def carried_path(
    ends: tuple[Any, Any], start: Any, active: list[int]
) -> tuple[Any, F64, float] | None:
    """``(start, f'', μ'')``: the second derivatives of the shares and of μ at the breakpoint
    ``ends[1]`` on the segment ending there (nodes ``ends``), kept for the shares free before and
    after it (0 for the others); ``None`` if the segment has no length or they are not finite."""
    pa, pb = ends[0].point, ends[1].point
    hh = pb.sigma - pa.sigma
    if not hh > 0.0:
        return None
    c = hermite_second_derivative(hh, pa.gamma, pa.dgamma, pb.gamma, pb.dgamma)
    cmu = float(hermite_second_derivative(hh, pa.mu, pa.dmu, pb.mu, pb.dmu))
    keep = np.zeros(c.size, dtype=bool)
    keep[active] = True
    keep &= pa.dgamma != 0.0
    out = np.asarray(np.where(keep, c, 0.0), dtype=np.float64)
    if not (np.all(np.isfinite(out)) and np.isfinite(cmu)):
        return None
    return start, out, cmu


def carried_events(
    before: Any, after: Any, ends: tuple[Any, Any], start: Any
) -> tuple[Any, F64] | None:
    """``(start, e'')``: the second derivatives of the event functions ``before`` (a
    continuation ``_Events``) at the breakpoint ``ends[1]`` on the segment ending there (nodes
    ``ends``), in the scale of the functions ``after``, kept for the enter functions of the
    sensors at their minimum on both sides (0 for the others); ``None`` if the segment has no
    length or they are not finite."""
    a, b = ends
    hh = b.sigma - a.sigma
    if not hh > 0.0:
        return None
    va, da = before.at(a)
    vb, db = before.at(b)
    c2 = hermite_second_derivative(hh, va, da, vb, db) * (before.scale / after.scale)
    same = ~before.mask & ~before.capped & ~after.mask & ~after.capped
    out = np.zeros(va.size)
    out[: before.n] = np.where(same, c2[: before.n], 0.0)
    if not np.all(np.isfinite(out)):
        return None
    return start, out
