"""The record of a traced path (Theorem 2): its nodes with their segments, the events, the
breakpoints and active sets, and the checks of the theorem accumulated along the way — shared by
the path followers of :mod:`.filtration` and :mod:`.continuation`.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from .channel_box import ChannelBox
from .corrector import _Point
from .filtration_result import EventKind, Filtration, FiltrationEvent

__all__: list[str] = []

F64 = npt.NDArray[np.float64]


class _Path:
    """What the tracer records along the path: the nodes (with their segment), the events, the
    breakpoints and active sets, and the checks of Theorem 2 (monotone shares, diagonal
    dominance of ``[η''_JJ]⁻¹``)."""

    def __init__(self, active: list[int], p: _Point, budget_min: float = math.nan) -> None:
        self.budget_min = budget_min
        self.events: list[FiltrationEvent] = [self._event(p, "enter", i) for i in active]
        self.entry_order: list[int] = list(active)
        self.breakpoints = [0.0]
        self.sets: list[tuple[int, ...]] = [tuple(active)]
        self.capped_sets: list[tuple[int, ...]] = [()]
        self.seg = 0
        self.nodes: list[tuple[_Point, int]] = [(p, 0)]
        self.is_monotone = True
        self.dd_all = True

    def _event(self, p: _Point, kind: EventKind, sensor: int) -> FiltrationEvent:
        """The event ``kind`` of ``sensor`` at ``p``, with the budget there."""
        return FiltrationEvent(p.sigma, kind, sensor, p.mu, p.sigma + self.budget_min)

    def node(self, q: _Point) -> None:
        """A node of the current segment."""
        self.nodes.append((q, self.seg))
        self.dd_all &= q.dd

    def monotonicity(self, loc: _Point, sensor: int, lost: bool) -> None:
        """A share's derivative changed sign at ``loc`` (no active-set change)."""
        kind: EventKind = "monotonicity-lost" if lost else "monotonicity-regained"
        self.events.append(self._event(loc, kind, sensor))
        self.is_monotone &= not lost

    def change(
        self, loc: _Point, kind: str, sensor: int, active: list[int], capped: list[int]
    ) -> tuple[list[int], list[int], F64]:
        """``sensor`` enters, leaves, reaches its cap (``"cap"``) or leaves it (``"uncap"``)
        at ``loc``: the new free and capped sets and the start of the new segment's corrector
        (a leaving share set to zero)."""
        gam = loc.gamma.copy()
        if kind == "leave":
            active = [i for i in active if i != sensor]
            self.events.append(self._event(loc, "leave", sensor))
            self.is_monotone = False
            gam[sensor] = 0.0
        elif kind == "cap":
            active = [i for i in active if i != sensor]
            capped = sorted([*capped, sensor])
            self.events.append(self._event(loc, "capped", sensor))
        elif kind == "uncap":  # a capped share starts to fall
            active = sorted([*active, sensor])
            capped = [i for i in capped if i != sensor]
            self.events.append(self._event(loc, "uncapped", sensor))
            self.is_monotone = False
        else:
            active = sorted([*active, sensor])
            self.events.append(self._event(loc, "enter", sensor))
            if sensor not in self.entry_order:
                self.entry_order.append(sensor)
        self.seg += 1
        self.breakpoints.append(loc.sigma)
        self.sets.append(tuple(active))
        self.capped_sets.append(tuple(capped))
        return active, capped, gam

    def segment_start(self, p: _Point, active: list[int]) -> None:
        """The first node of a new segment; a share may start decreasing right at the breakpoint
        (no crossing to detect)."""
        self.nodes.append((p, self.seg))
        for i in active:
            if p.dgamma[i] < 0:
                self.events.append(self._event(p, "monotonicity-lost", i))
                self.is_monotone = False

    def result(
        self, box: ChannelBox, sigma_max: float, tol: float, stopped: str, end: float
    ) -> Filtration:
        """The :class:`Filtration` of the path, traced to ``end`` (``sigma_max`` if completed)."""
        breakpoints, sets = list(self.breakpoints), list(self.sets)
        capped = list(self.capped_sets)
        breakpoints.append(end)
        if len(breakpoints) > 2 and breakpoints[-2] >= end:  # an event exactly at σ_max
            breakpoints.pop(-2)
            sets.pop()
            capped.pop()
        nodes = self.nodes
        arrays = [
            np.array([pt.sigma for pt, _ in nodes]),
            np.array([pt.gamma for pt, _ in nodes]),
            np.array([pt.mu for pt, _ in nodes]),
            np.array([pt.dgamma for pt, _ in nodes]),
        ]
        segs = np.array([k for _, k in nodes], dtype=np.intp)
        bp = np.array(breakpoints)
        for arr in (*arrays, segs, bp):
            arr.setflags(write=False)
        leaves = any(ev.kind == "leave" for ev in self.events)
        return Filtration(
            net=box.source,
            sigma_max=float(end),
            tol=tol,
            breakpoints=bp,
            active_sets=tuple(sets),
            entry_order=tuple(self.entry_order),
            events=tuple(self.events),
            is_monotone=self.is_monotone and not leaves,
            is_filtration=not leaves,
            diagonally_dominant=self.dd_all,
            node_sigma=arrays[0],
            node_gamma=arrays[1],
            node_mu=arrays[2],
            node_dgamma=arrays[3],
            node_segment=segs,
            converged=stopped == "completed",
            stopped=stopped,
            sigma_requested=sigma_max,
            capped_sets=tuple(capped),
            budget_min=box.budget_min,
        )
