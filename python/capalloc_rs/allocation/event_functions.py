"""The event functions of one segment of the filtration's path (:mod:`.continuation`) and their
cubic Hermite models between two nodes.

On a segment with active set ``J`` the path meets its next breakpoint where one of these
functions of σ reaches 0: ``e_j = (g_j − μ)/|μ|`` for a sensor ``j ∉ J`` at its minimum (it
*enters*), ``e_i = γ_i`` for ``i ∈ J`` (it *leaves*); with finite caps also ``(μ − g_j)/|μ|``
for a capped sensor (*uncapped*) and ``c_i − γ_i`` for ``i ∈ J`` (*capped*). At a node their
values and slopes are known exactly (the slopes from the tangent: ``(η''·df/dσ − dμ/dσ)_j/|μ|``
and ``df_i/dσ``), so between two nodes each is modelled by the cubic Hermite interpolant of its
values and slopes, and ahead of a node by its quadratic Taylor model (the second derivative from
the slopes at the last two nodes, or carried across the last breakpoint:
:mod:`.path_curvature`). The first root of these models on a grid, refined by Newton's method on
the KKT system (:mod:`.kkt_newton`), is where the path's next event is.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .kkt_newton import Node

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
#: Grid of the cubic event models on a step (first sign change, then refined by Newton).
_GRID = np.linspace(0.0, 1.0, 65)
#: Event function values within this of 0 at a node count by the sign of their slope.
_TINY = 1e-12


def _hermite(s0: float, s1: float, y0: F64, d0: F64, y1: F64, d1: F64, s: F64) -> F64:
    """The cubic Hermite interpolant of (values, slopes) at ``s0`` and ``s1``, evaluated at the
    points ``s`` (also outside [s0, s1]): shape ``(len(s), len(y0))``."""
    hh = s1 - s0
    t = ((np.asarray(s, dtype=np.float64) - s0) / hh)[:, None]
    t2, t3 = t * t, t * t * t
    return np.asarray(
        (2 * t3 - 3 * t2 + 1) * y0
        + (t3 - 2 * t2 + t) * hh * d0
        + (-2 * t3 + 3 * t2) * y1
        + (t3 - t2) * hh * d1,
        dtype=np.float64,
    )


def _hermite_slope(s0: float, s1: float, y0: F64, d0: F64, y1: F64, d1: F64, s: float) -> F64:
    """The derivative of :func:`_hermite`'s interpolant at the point ``s``."""
    hh = s1 - s0
    t = (s - s0) / hh
    return np.asarray(
        (6 * t * t - 6 * t) / hh * (y0 - y1)
        + (3 * t * t - 4 * t + 1) * d0
        + (3 * t * t - 2 * t) * d1,
        dtype=np.float64,
    )


class _Events:
    """The event functions of a segment (enter for ``j ∉ J``, leave for ``i ∈ J``; with finite
    caps, uncap for the capped ``j`` and a second block, cap for ``i ∈ J``), scaled by ``|μ|``
    at the segment's start so that both ends of a step use the same scale."""

    def __init__(
        self, active: list[int], n: int, mu: float, capped: Any = (), cap: F64 | None = None
    ) -> None:
        self.n = n
        self.mask = np.zeros(n, dtype=bool)
        self.mask[active] = True
        self.capped = np.zeros(n, dtype=bool)
        self.capped[list(capped)] = True
        self.scale = max(abs(mu), 1e-300)
        self.cap = cap if cap is not None and bool(np.any(np.isfinite(cap))) else None
        #: The second derivatives carried over from the segment before, at its first node.
        self.carried: tuple[Node, F64] | None = None

    def at(self, node: Node) -> tuple[F64, F64]:
        """(values, slopes) of every event function at ``node``."""
        p = node.point
        val = np.where(self.mask, p.gamma, (node.g - p.mu) / self.scale)
        der = np.where(self.mask, p.dgamma, node.slopes() / self.scale)
        if self.cap is None:
            return val, der
        val = np.where(self.capped, (p.mu - node.g) / self.scale, val)
        der = np.where(self.capped, -node.slopes() / self.scale, der)
        room = self.mask & np.isfinite(self.cap)
        cval = np.where(room, self.cap - p.gamma, 1.0)
        cder = np.where(room, -p.dgamma, 0.0)
        return np.concatenate([val, cval]), np.concatenate([der, cder])

    def kind(self, k: int) -> tuple[str, int]:
        """What event function ``k`` reaching 0 means: ``("enter" | "leave" | "uncap" |
        "cap", sensor)``."""
        if k >= self.n:
            return "cap", k - self.n
        if self.mask[k]:
            return "leave", k
        return ("uncap" if self.capped[k] else "enter"), k

    @staticmethod
    def positive(val: F64, der: F64) -> npt.NDArray[np.bool_]:
        """Which functions are on the positive side (nothing happened yet) at a node: value > 0,
        or within ``_TINY`` of 0 and rising."""
        return np.asarray((val > _TINY) | ((val > -_TINY) & (der > 0.0)), dtype=np.bool_)

    def first_crossing(self, a: Node, b: Node, skip: Any) -> tuple[float, int] | None:
        """The first σ in (a, b] where a function positive at ``a`` reaches 0 on its cubic
        Hermite model between the nodes, and which one (``skip`` excluded: an index, a list
        of indices and ``None``, or ``None``); ``None`` if none."""
        if not b.sigma > a.sigma:
            return None  # an event at the node itself (a tie): nothing in between
        va, da = self.at(a)
        vb, db = self.at(b)
        live = self.positive(va, da)
        if isinstance(skip, list):
            live[[k for k in skip if k is not None]] = False
        elif skip is not None:
            live[skip] = False
        if not np.any(live):
            return None
        s = a.sigma + _GRID * (b.sigma - a.sigma)
        vals = _hermite(a.sigma, b.sigma, va, da, vb, db, s)[:, live]
        vals[-1] = np.minimum(vals[-1], vb[live])  # the end value itself decides at b
        return _first_root(s, vals, np.flatnonzero(live))

    def predicted(self, a: Node, prev: Node | None, step: float) -> tuple[float, int] | None:
        """The first σ in (a, a + step] where a function is predicted to reach 0 from its
        value, slope and (with ``prev``) second derivative at ``a``."""
        va, da = self.at(a)
        c2 = np.zeros_like(va)
        if prev is not None and prev.sigma < a.sigma:
            c2 = (da - self.at(prev)[1]) / (a.sigma - prev.sigma)
        elif self.carried is not None and self.carried[0] is a:
            c2 = self.carried[1]
        now = np.flatnonzero((va <= _TINY) & (da < 0.0))
        if now.size:  # already on its event (a tie at a breakpoint): it happens here
            return a.sigma, int(now[0])
        live = self.positive(va, da)
        if not np.any(live):
            return None
        ds = _GRID * step
        vals = va[live] + ds[:, None] * da[live] + 0.5 * ds[:, None] ** 2 * c2[live]
        return _first_root(a.sigma + ds, vals, np.flatnonzero(live))


def _first_root(s: F64, vals: F64, which: npt.NDArray[np.intp]) -> tuple[float, int] | None:
    """The first grid crossing (value ≤ 0) among the columns of ``vals`` (rows: the points
    ``s``), linearly interpolated, with the index of its function (from ``which``)."""
    hit = vals <= 0.0
    hit[0] = False
    rows = np.where(hit.any(axis=0), hit.argmax(axis=0), s.size)
    col = int(np.argmin(rows))
    k = int(rows[col])
    if k >= s.size:
        return None
    v0, v1 = float(vals[k - 1, col]), float(vals[k, col])
    frac = v0 / (v0 - v1) if v0 > v1 else 1.0
    return float(s[k - 1] + frac * (s[k] - s[k - 1])), int(which[col])
