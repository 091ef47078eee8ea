"""The proven optimal schedule for small instances: depth-first branch-and-bound over the slot
assignments, each partial schedule bounded by relaxing its unassigned slots
(:mod:`capalloc_rs.sampled.relaxation`), for sensors of **equal sample costs** (every slot of the
same length ``bτ₀``; with unequal costs the later slots' positions depend on the earlier choices
and the method refuses them).

**The tree.** A node fixes the first ``d`` of ``L`` slots, ``R_1 … R_d``, with counts
``k_i ≤ ⌊r_max,i⌋`` and ``Σ_i max(0, ⌈r_min,i⌉ − k_i) ≤ L − d`` (the rest can still meet the
minima). Its children append one sensor.

**The bound of a node.** A free slot will hold a sensor ``i`` with ``k_i < ⌊r_max,i⌋`` (the
*allowed* set ``𝒜``); the relaxed slot ``ρ = U_J ∘ P_{bτ₀}`` with ``J ⪰ c̄_i c̄_iᵀ`` for all
``i ∈ 𝒜`` (:func:`~capalloc_rs.sampled.relaxation.dominating_information`, the scaled sum) is
``⪯ φ_i`` pointwise (same prediction, more information), so the node's map
``Ψ = T ∘ ρ^{L−d} ∘ φ_{R_d} ∘ … ∘ φ_{R_1}`` is ``⪯ Φ_R`` for every completion ``R``, and by the
relaxation theorem ``tr(M Ψᵏ(0)) ≤ η̄_boundary(R)``; for the average figure each posterior of
``R`` is ``⪰`` the matching posterior of ``Ψ`` started from ``Ψᵏ(0)``, and the mean of the latter
bounds ``η̄_average(R)`` (same ``L``). A node whose bound (lowered by ``BOUND_RTOL``) is at least
the incumbent's exact cost is pruned: no completion is better.

**Lengths.** The paper's case has ``L = r_tot``. Otherwise ``L`` ranges over ``max(1, Σ⌈r_min⌉)
… L* = min(⌊B/b⌋, Σ⌊r_max⌋)``; for the boundary figure only ``L*`` is searched: a schedule of
``L < L*`` slots has an idle unit after its last slot that a sensor below its cap can take, and
that map is ``⪯`` (an update after the same prediction), so by the theorem its steady state is
``⪯`` — the best boundary schedule has ``L*`` slots.

**Symmetry.** Only for ``which="average"`` without idle time (``L b = B``): the figure is then
invariant under rotation, and every schedule has a rotation starting with its smallest sensor
index, so the tree keeps only ``R_l ≥ R_1``. The boundary figure is not rotation invariant and
no symmetry is used.

**Certificate.** If the tree is exhausted the incumbent is optimal (``complete``); a node or time
limit stops the search with the incumbent and the lower bound ``min(incumbent, bounds of the open
nodes, root bounds of the lengths not yet searched)`` — every schedule not costed lies below one
of them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .._arrays import F64
from .channel import ScheduleLimits
from .exhaustive import _cost
from .relaxation import BOUND_RTOL, Triplet, dominating_information, power_from_zero
from .schedule import Schedule
from .system import SampledSystem, discretise

__all__ = ["ExactSearch", "exact_search", "equal_costs"]


def equal_costs(m: SampledSystem) -> bool:
    """Whether every sensor's sample cost is the same."""
    b = m.sample_costs
    return bool(np.all(b == b[0]))


@dataclass(frozen=True)
class ExactSearch:
    """The branch-and-bound's outcome: the best schedule (``None``: the incumbent given was
    never beaten), its exact cost, the proven lower bound, nodes bounded and whether the tree
    was exhausted (then the schedule is optimal)."""

    schedule: Schedule
    eta_bar: float
    lower_bound: float
    nodes: int
    complete: bool


@dataclass
class _Tree:
    """The data of one search: slot maps, relaxed slots by allowed set, tails by length."""

    m: SampledSystem
    tau: float
    which: str
    lim: ScheduleLimits
    slots: list[Triplet]
    pred: Triplet
    cbar: list[F64]
    tails: dict[int, Triplet] = field(default_factory=dict)
    suffix: dict[tuple[tuple[int, ...], int, int], Triplet] = field(default_factory=dict)
    relax: dict[tuple[int, ...], Triplet] = field(default_factory=dict)
    best: Schedule | None = None
    best_cost: float = math.inf
    nodes: int = 0


def _tree(m: SampledSystem, tau: float, which: str, lim: ScheduleLimits) -> _Tree:
    b = float(m.sample_costs[0])
    d = discretise(m, tau, lim.budget / b)
    pred = Triplet.prediction(d.E, d.H)
    cbar = [np.sqrt(tau) * c for c in m.sensors]
    slots = [pred.then(Triplet.update(c @ c.T)) for c in cbar]
    return _Tree(m, tau, which, lim, slots, pred, cbar)


def _tail(tr: _Tree, length: int) -> Triplet:
    """The idle tail of a schedule of ``length`` slots."""
    if length not in tr.tails:
        b = float(tr.m.sample_costs[0])
        rem = tr.tau * (1 - length * b / tr.lim.budget)
        t = Triplet.identity(tr.m.n)
        if rem > 1e-12 * tr.tau:
            dt = discretise(tr.m, rem, 1)
            t = Triplet.prediction(dt.E, dt.H)
        tr.tails[length] = t
    return tr.tails[length]


def _relaxed(tr: _Tree, allowed: tuple[int, ...]) -> Triplet:
    if allowed not in tr.relax:
        j = dominating_information([tr.cbar[i] for i in allowed])[0]
        tr.relax[allowed] = tr.pred.then(Triplet.update(j))
    return tr.relax[allowed]


def _suffix(tr: _Tree, allowed: tuple[int, ...], free: int, length: int) -> Triplet:
    """``T ∘ ρ^free``: ``free`` relaxed slots, then the tail."""
    key = (allowed, free, length)
    if key not in tr.suffix:
        if free == 0:
            tr.suffix[key] = _tail(tr, length)
        else:
            tr.suffix[key] = _relaxed(tr, allowed).then(_suffix(tr, allowed, free - 1, length))
    return tr.suffix[key]


@dataclass(frozen=True)
class _Node:
    prefix: tuple[int, ...]
    triplet: Triplet
    counts: tuple[int, ...]
    bound: float


def _allowed(tr: _Tree, counts: tuple[int, ...], first: int) -> tuple[int, ...]:
    hi = tr.lim.hi
    return tuple(
        i for i in range(tr.m.n_sensors) if i >= first and (hi is None or counts[i] < hi[i])
    )


def _bound(tr: _Tree, node_t: Triplet, prefix: tuple[int, ...], rest: Triplet, L: int) -> float:
    """The node's lower bound (module docstring), lowered by ``BOUND_RTOL``."""
    tr.nodes += 1
    x = power_from_zero(node_t)
    if tr.which == "boundary":
        return tr.m.trace(x) * (1 - BOUND_RTOL)
    total = 0.0
    s = x
    for i in prefix:
        s = tr.slots[i].apply(s)
        total += tr.m.trace(s)
    for _ in range(L - len(prefix)):
        s = rest.apply(s)
        total += tr.m.trace(s)
    return total / L * (1 - BOUND_RTOL)


def _children(tr: _Tree, node: _Node, L: int, symmetric: bool) -> list[_Node]:
    d = len(node.prefix)
    lo = tr.lim.lo
    out = []
    first = node.prefix[0] if symmetric and d > 0 else 0
    for i in _allowed(tr, node.counts, first):
        counts = node.counts[:i] + (node.counts[i] + 1,) + node.counts[i + 1 :]
        free = L - d - 1
        if sum(max(0, lo[j] - counts[j]) for j in range(len(counts))) > free:
            continue
        prefix = (*node.prefix, i)
        start = i if symmetric and d == 0 else first
        allowed = _allowed(tr, counts, start)
        if free > 0 and not allowed:
            continue
        t = node.triplet.then(tr.slots[i])
        rest = _relaxed(tr, allowed) if free > 0 else t
        b = _bound(tr, t.then(_suffix(tr, allowed, free, L)), prefix, rest, L)
        out.append(_Node(prefix, t, counts, b))
    out.sort(key=lambda n: -n.bound)
    return out


def _lengths(tr: _Tree) -> list[int]:
    lim = tr.lim
    if lim.plain:
        return [int(round(lim.budget))]
    b = float(tr.m.sample_costs[0])
    top = math.floor(lim.budget / b * (1 + 1e-12))
    if lim.hi is not None:
        top = min(top, sum(lim.hi))
    if tr.which == "boundary":
        return [top]
    return list(range(max(1, sum(lim.lo)), top + 1))


def _root(tr: _Tree, L: int) -> tuple[_Node, bool]:
    n = tr.m.n_sensors
    b = float(tr.m.sample_costs[0])
    symmetric = tr.which == "average" and abs(L * b - tr.lim.budget) <= 1e-12 * tr.lim.budget
    counts = (0,) * n
    allowed = _allowed(tr, counts, 0)
    ident = Triplet.identity(tr.m.n)
    bound = _bound(tr, _suffix(tr, allowed, L, L), (), _relaxed(tr, allowed), L)
    return _Node((), ident, counts, bound), symmetric


def _search_length(tr: _Tree, L: int, node_limit: int, deadline: float) -> list[_Node]:
    """Depth-first search of the schedules of ``L`` slots; the open nodes left at a limit."""
    root, symmetric = _root(tr, L)
    stack = [root]
    while stack:
        if tr.nodes >= node_limit or time.monotonic() >= deadline:
            return stack
        node = stack.pop()
        if node.bound >= tr.best_cost:
            continue
        if len(node.prefix) == L:
            s = Schedule(list(node.prefix), tr.m.n_sensors)
            cost = _cost(tr.m, tr.tau, s, tr.which, tr.lim)
            if cost < tr.best_cost:
                tr.best, tr.best_cost = s, cost
            continue
        stack.extend(c for c in _children(tr, node, L, symmetric) if c.bound < tr.best_cost)
    return []


def exact_search(
    m: SampledSystem,
    tau: float,
    which: str,
    lim: ScheduleLimits,
    incumbent: Schedule,
    incumbent_cost: float,
    node_limit: int,
    deadline: float,
) -> ExactSearch:
    """The branch-and-bound of the module docstring from an incumbent (its exact cost).

    ``node_limit`` bounds the nodes whose bound is computed and ``deadline`` (a
    ``time.monotonic()`` time) the wall clock; either stops the search with the incumbent and a
    valid lower bound. Ctrl-C raises ``KeyboardInterrupt`` between nodes.
    """
    tr = _tree(m, tau, which, lim)
    tr.best, tr.best_cost = incumbent, incumbent_cost
    open_bounds: list[float] = []
    lengths = _lengths(tr)
    for k, L in enumerate(lengths):
        if tr.nodes >= node_limit or time.monotonic() >= deadline:
            open_bounds.extend(_root(tr, rest)[0].bound for rest in lengths[k:])
            break
        open_bounds.extend(n.bound for n in _search_length(tr, L, node_limit, deadline))
    complete = not open_bounds
    lower = min([tr.best_cost, *open_bounds])
    assert tr.best is not None
    return ExactSearch(tr.best, tr.best_cost, lower, tr.nodes, complete)
