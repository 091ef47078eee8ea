"""The proven optimal schedule for sensors of **unequal** sample costs: depth-first
branch-and-bound over the slot sequences, each partial schedule bounded by relaxing the rest of
its period on the cost grid (:mod:`capalloc_rs.sampled.relaxation`).

**Grid.** Let ``g`` be the largest number of which every usable cost ``b_i`` is an integer
multiple (``s_i = b_i/g`` grid units) and ``K = ⌊B/g⌋``. A schedule's slots end at grid times:
slot ``l`` ends at ``Σ_{m ≤ l} s_{R_m}``.

**The tree.** A node fixes a prefix ``R_1 … R_d`` using ``u = Σ s_{R_l} ≤ K`` units, with counts
``k_i ≤ ⌊r_max,i⌋`` and ``Σ_i max(0, ⌈r_min,i⌉ − k_i) s_i ≤ K − u`` (the minima can still be
paid for). Its children append one sensor of the *allowed* set ``𝒜`` (``k_i < ⌊r_max,i⌋`` and
``s_i ≤ K − u``). Every node meeting the minima is itself a schedule (the rest of its period
idle) and a completion of it is any sequence of allowed sensors within the budget.

**The bound of a node.** A completion's slots end at ``u + o`` with ``o`` in the set 𝒪 of sums
``Σ_i n_i s_i ≤ K − u`` of allowed steps (a knapsack), whatever lengths it uses. The relaxed map
``Ψ`` is the prefix's slot maps, then ``K − u`` grid units each predicting over ``gτ₀`` and
updating with ``J ⪰ c̄_i c̄_iᵀ`` for every ``i ∈ 𝒜``
(:func:`~capalloc_rs.sampled.relaxation.dominating_information`, the scaled sum) at the offsets
in 𝒪 and not updating elsewhere, then the idle remainder ``(B − Kg)τ₀``. Written unit by unit
(``P_s ∘ P_t = P_{s+t}``), a completion ``R`` updates with ``c̄_i c̄_iᵀ ⪯ J`` at some offsets of 𝒪
and does not update at the others (``U_J ⪯ I``), so each unit of ``Ψ`` is ``⪯`` the same unit of
``Φ_R``; by monotonicity ``Ψ ⪯ Φ_R`` pointwise and by the relaxation theorem
``tr(M Ψᵏ(0)) ≤ η̄_boundary(R)`` for every completion (the node itself included).

For the average figure the posteriors of ``R``'s slots are ``⪰`` the states ``X_t`` of ``Ψ``
started from its fixed point at the same grid times (the same induction): the prefix's ``d``
posteriors at their ends, and the ``e`` slots of the completion at ``e`` *distinct* offsets of 𝒪.
So ``η̄_average(R) ≥ (Σ_{l ≤ d} tr M X_{t_l} + (sum of the e smallest tr M X_{u+o}, o ∈ 𝒪)) /
(d + e)``, and the node's bound is the least of these over the feasible ``e`` (from the minima
still owed to ``min(Σ_{i∈𝒜} (⌊r_max,i⌋ − k_i), ⌊(K − u)/min s_i⌋)``).

The maps are evaluated in the Rust core as schedules of an *augmented* model: the network's
sensors, one sensor ``ĉ`` with ``τ ĉĉᵀ ⪰ J`` per allowed set met and one sensor without
information, both of cost ``g``; its steady state is the limit of ``Ψᵏ(0)`` (no limit: ``+∞``,
since then no completion has a steady state either).

**Leaves.** The exact cost of a node meeting the minima is computed (for the boundary figure
only if no allowed sensor fits: appending sensor ``i`` at the start of the idle tail replaces a
prediction by a prediction then an update, ``⪯``, so the best boundary schedule leaves no room
for another slot). Pruning, limits and the certificate are those of
:mod:`capalloc_rs.sampled.exact`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from .. import _core
from .._arrays import F64
from ..errors import ConvergenceError
from .channel import ScheduleLimits
from .exhaustive import _cost
from .relaxation import BOUND_RTOL, _grid, _rational, dominating_factor
from .schedule import Schedule
from .system import SampledSystem

__all__ = ["grid_exact_search"]


@dataclass
class _GridTree:
    """One search: the model, its grid, the augmented model and the incumbent."""

    m: SampledSystem
    tau: float
    which: str
    lim: ScheduleLimits
    g: Fraction
    units: int
    steps: tuple[int, ...]
    hi: tuple[int, ...]
    extra: dict[tuple[int, ...], int] = field(default_factory=dict)
    factors: list[F64] = field(default_factory=list)
    reach: dict[tuple[tuple[int, ...], int], list[int]] = field(default_factory=dict)
    core: _core.SampledModel | None = None
    best: Schedule | None = None
    best_cost: float = math.inf
    nodes: int = 0


@dataclass(frozen=True)
class _GNode:
    prefix: tuple[int, ...]
    counts: tuple[int, ...]
    used: int
    bound: float


def _tree(m: SampledSystem, tau: float, which: str, lim: ScheduleLimits) -> _GridTree | None:
    n = m.n_sensors
    hi = tuple(lim.hi) if lim.hi is not None else (2**62,) * n
    usable = [i for i in range(n) if hi[i] >= 1]
    costs = m.sample_costs
    grid = _grid(costs[usable], lim.budget)
    if grid is None:
        return None
    g, units = grid
    steps = tuple(
        round(_rational(float(costs[i])) / g) if i in usable else units + 1 for i in range(n)
    )
    return _GridTree(m, tau, which, lim, g, units, steps, hi)


def _null(tr: _GridTree) -> int:
    """The augmented model's index of the sensor without information (cost ``g``)."""
    return tr.m.n_sensors


def _relaxed(tr: _GridTree, allowed: tuple[int, ...]) -> int:
    """The augmented model's index of the sensor ``ĉ`` with ``τ ĉĉᵀ ⪰ J`` for ``allowed``."""
    if allowed not in tr.extra:
        cbar = [np.sqrt(tr.tau) * tr.m.sensors[i] for i in allowed]
        tr.extra[allowed] = tr.m.n_sensors + 1 + len(tr.factors)
        tr.factors.append(dominating_factor(cbar, tr.tau, tr.m.n))
        tr.core = None
    return tr.extra[allowed]


def _augmented(tr: _GridTree) -> _core.SampledModel:
    if tr.core is None:
        m = tr.m
        sensors = [*m.sensors, np.zeros((m.n, 1)), *tr.factors]
        g = float(tr.g)
        costs = [float(b) for b in m.sample_costs] + [g] * (1 + len(tr.factors))
        tr.core = _core.SampledModel(m.A, m.Q, sensors, costs=costs)
    return tr.core


def _offsets(tr: _GridTree, allowed: tuple[int, ...], free: int) -> list[int]:
    """The offsets ``o ∈ 1..free`` that are sums of the allowed steps (a knapsack)."""
    key = (allowed, free)
    if key not in tr.reach:
        ok = [True] + [False] * free
        steps = sorted({tr.steps[i] for i in allowed})
        for k in range(1, free + 1):
            ok[k] = any(s <= k and ok[k - s] for s in steps)
        tr.reach[key] = [k for k in range(1, free + 1) if ok[k]]
    return tr.reach[key]


def _allowed(tr: _GridTree, counts: tuple[int, ...], used: int) -> tuple[int, ...]:
    free = tr.units - used
    return tuple(i for i in range(tr.m.n_sensors) if counts[i] < tr.hi[i] and tr.steps[i] <= free)


def _owed(tr: _GridTree, counts: tuple[int, ...]) -> tuple[int, int]:
    """(slots still owed to the minima, their grid units)."""
    lo = tr.lim.lo
    short = [max(0, lo[i] - counts[i]) for i in range(len(counts))]
    return sum(short), sum(s * tr.steps[i] for i, s in enumerate(short))


def _average_bound(
    tr: _GridTree, node: tuple[tuple[int, ...], tuple[int, ...], int], traces: list[float]
) -> float:
    """The least mean over the feasible numbers of further slots (module docstring)."""
    prefix, counts, used = node
    d = len(prefix)
    allowed = _allowed(tr, counts, used)
    head = sum(traces[:d])
    free = sorted(traces[d + o - 1] for o in _offsets(tr, allowed, tr.units - used))
    e_min = _owed(tr, counts)[0]
    e_max = 0
    if allowed:
        room = (tr.units - used) // min(tr.steps[i] for i in allowed)
        e_max = min(len(free), room, sum(tr.hi[i] - counts[i] for i in allowed))
    best = math.inf
    acc = head + sum(free[:e_min])
    for e in range(e_min, e_max + 1):
        if e > e_min:
            acc += free[e - 1]
        if d + e >= 1:
            best = min(best, acc / (d + e))
    return best


def _bound(tr: _GridTree, prefix: tuple[int, ...], counts: tuple[int, ...], used: int) -> float:
    """The node's lower bound (module docstring), lowered by ``BOUND_RTOL``."""
    tr.nodes += 1
    allowed = _allowed(tr, counts, used)
    free = tr.units - used
    slots = list(prefix)
    if allowed:
        reach = set(_offsets(tr, allowed, free))
        rho, null = _relaxed(tr, allowed), _null(tr)
        slots += [rho if o in reach else null for o in range(1, free + 1)]
    if not slots:
        return math.inf  # nothing fits and nothing is fixed: no schedule below this node
    try:
        ss = _augmented(tr).steady_state(
            tr.tau, np.asarray(slots, dtype=np.int64), budget=float(tr.lim.budget)
        )
    except ConvergenceError:
        return math.inf  # Ψᵏ(0) unbounded: no completion has a steady state either
    if tr.which == "boundary":
        v = tr.m.trace(np.asarray(ss.boundary))
    else:
        post = np.asarray(ss.posteriors)
        v = _average_bound(tr, (prefix, counts, used), [tr.m.trace(p) for p in post])
    return v * (1 - BOUND_RTOL)


def _children(tr: _GridTree, node: _GNode) -> list[_GNode]:
    out = []
    for i in _allowed(tr, node.counts, node.used):
        counts = node.counts[:i] + (node.counts[i] + 1,) + node.counts[i + 1 :]
        used = node.used + tr.steps[i]
        if _owed(tr, counts)[1] > tr.units - used:
            continue
        prefix = (*node.prefix, i)
        out.append(_GNode(prefix, counts, used, _bound(tr, prefix, counts, used)))
    out.sort(key=lambda n: -n.bound)
    return out


def _visit(tr: _GridTree, node: _GNode) -> None:
    """Cost the node's schedule if it is a leaf (module docstring)."""
    if _owed(tr, node.counts)[0] > 0 or not node.prefix:
        return
    if tr.which == "boundary" and _allowed(tr, node.counts, node.used):
        return
    s = Schedule(list(node.prefix), tr.m.n_sensors)
    cost = _cost(tr.m, tr.tau, s, tr.which, tr.lim)
    if cost < tr.best_cost:
        tr.best, tr.best_cost = s, cost


def grid_exact_search(
    m: SampledSystem,
    tau: float,
    which: str,
    lim: ScheduleLimits,
    incumbent: Schedule,
    incumbent_cost: float,
    node_limit: int,
    deadline: float,
) -> tuple[Schedule, float, float, int, bool] | None:
    """The branch-and-bound of the module docstring from an incumbent (its exact cost).

    Returns:
        ``(schedule, eta_bar, lower_bound, nodes, complete)``; ``None`` when the cost grid has
        more than ``relaxation.MAX_GRID_UNITS`` units (no search).
    """
    tr = _tree(m, tau, which, lim)
    if tr is None:
        return None
    tr.best, tr.best_cost = incumbent, incumbent_cost
    zero = (0,) * m.n_sensors
    stack = [_GNode((), zero, 0, _bound(tr, (), zero, 0))]
    while stack:
        if tr.nodes >= node_limit or time.monotonic() >= deadline:
            break
        node = stack.pop()
        if node.bound >= tr.best_cost:
            continue
        _visit(tr, node)
        stack.extend(c for c in _children(tr, node) if c.bound < tr.best_cost)
    open_bounds = [n.bound for n in stack]
    lower = min([tr.best_cost, *open_bounds])
    assert tr.best is not None
    return tr.best, tr.best_cost, lower, tr.nodes, not open_bounds
