"""The proven optimal schedule for small instances: depth-first branch-and-bound over the slot
assignments, each partial schedule bounded by relaxing its unassigned slots
(:mod:`capalloc_rs.sampled.relaxation`), for sensors of **equal sample costs** (every slot of the
same length ``bτ₀``). With unequal costs the later slots' positions depend on the earlier choices;
:func:`exact_search` then runs the search of :mod:`capalloc_rs.sampled.exact_grid`, which bounds
the free part of the period on the cost grid.

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

**Computing a bound.** The relaxed slot of each allowed set is a sensor of an *augmented*
model (the network's sensors plus one sensor ``ĉ`` with ``τ ĉĉᵀ = J`` per allowed set met, of
the same cost), so a node's bound is the exact cost, in the Rust core, of the schedule
``R_1 … R_d ρ … ρ`` of the augmented model: its doubling converges to the limit of ``Ψᵏ(0)``
(no steady state: ``+∞``, since then no completion has one either).

**Lengths.** The paper's case has ``L = r_tot``. Otherwise ``L`` ranges over ``max(1, Σ⌈r_min⌉)
… L* = min(⌊B/b⌋, Σ⌊r_max⌋)``; for the boundary figure only ``L*`` is searched: a schedule of
``L < L*`` slots has an idle unit after its last slot that a sensor below its cap can take, and
that map is ``⪯`` (an update after the same prediction), so by the theorem its steady state is
``⪯`` — the best boundary schedule has ``L*`` slots.

**Symmetry.** Only for ``which="average"`` without idle time (``L b = B``): the figure is then
invariant under rotation, and every schedule has a rotation starting with its smallest sensor
index, so the tree keeps only ``R_l ≥ R_1``. The boundary figure is not rotation invariant and
no symmetry is used.

**Implementations** (``exact_impl``). ``"rust"`` (the default) runs the tree in the Rust core
(``capalloc::sampled::exact_dfs``) with the relaxed slot of every allowed set given as its factor:
one slot map composed per node, the powers ``ρ^k`` composed once, each node's bound iterated from
its parent's bound state (every iterate is a bound, so most pruned nodes cost one application of
``Ψ``), and for the boundary figure the slots fixed from the *last* one backwards (``Ψ = T ∘
φ_{R_L} ∘ … ∘ φ_{R_{L−d+1}} ∘ ρ^{L−d}``: the slots nearest the boundary are exact first).
``"python"`` is the search above, one Rust cost of the augmented model per node; it is also used
with more than ``MAX_KERNEL_SENSORS`` sensors. Both prove the same optimum.

**Boundary figure and rotation.** Without idle time, let ``Σ_0 = Σ̄, Σ_l = φ_{R_l}(Σ_{l−1})`` be
``R``'s periodic orbit (``Σ_L = Σ_0``). Then ``Σ_k`` is a fixed point of the period map of the
rotation ``R' = R_{k+1} … R_L R_1 … R_k``, and the stabilising one (its closed-loop monodromy is a
cyclic permutation of the same product of factors, with the same non-zero eigenvalues), so
``η̄_boundary(R') = tr(M Σ_k)`` — the boundary figure of a rotation is another posterior of the
orbit, in general a different number (the tests exhibit one). So the boundary figure has no
rotation symmetry, and with idle time a rotation is not even a schedule (the tail moves); no
symmetry is used for it.

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

from .. import _core
from .._arrays import F64
from ..errors import ConvergenceError, InvalidInputError
from .channel import ScheduleLimits
from .exact_grid import grid_exact_search
from .exhaustive import _cost
from .relaxation import BOUND_RTOL, dominating_factor
from .schedule import Schedule
from .system import SampledSystem

__all__ = ["EXACT_IMPLS", "ExactSearch", "equal_costs", "exact_search"]

#: The implementations of the equal-cost tree (``exact_impl``).
EXACT_IMPLS = ("rust", "python")
#: Most sensors of the Rust kernel (one relaxed factor per non-empty set: ``2^N − 1``).
MAX_KERNEL_SENSORS = 10


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
    """The data of one search: the model, the augmented model of relaxed slots (one extra
    sensor per allowed set), the nodes bounded and the incumbent."""

    m: SampledSystem
    tau: float
    which: str
    lim: ScheduleLimits
    cbar: list[F64]
    extra: dict[tuple[int, ...], int] = field(default_factory=dict)
    factors: list[F64] = field(default_factory=list)
    core: _core.SampledModel | None = None
    best: Schedule | None = None
    best_cost: float = math.inf
    nodes: int = 0


def _tree(m: SampledSystem, tau: float, which: str, lim: ScheduleLimits) -> _Tree:
    cbar = [np.sqrt(tau) * c for c in m.sensors]
    return _Tree(m, tau, which, lim, cbar)


def _relaxed_sensor(tr: _Tree, allowed: tuple[int, ...]) -> int:
    """The index of the augmented model's sensor ``ĉ`` with ``τ ĉĉᵀ = J`` for ``allowed``."""
    if allowed not in tr.extra:
        tr.extra[allowed] = tr.m.n_sensors + len(tr.factors)
        tr.factors.append(dominating_factor([tr.cbar[i] for i in allowed], tr.tau, tr.m.n))
        tr.core = None
    return tr.extra[allowed]


def _augmented(tr: _Tree) -> _core.SampledModel:
    if tr.core is None:
        m = tr.m
        sensors = list(m.sensors) + tr.factors
        b = float(m.sample_costs[0])
        costs = None if m.costs is None else [b] * len(sensors)
        tr.core = _core.SampledModel(m.A, m.Q, sensors, costs=costs, weight=m.weight)
    return tr.core


def _bound(tr: _Tree, prefix: tuple[int, ...], allowed: tuple[int, ...], L: int) -> float:
    """The node's lower bound (module docstring), lowered by ``BOUND_RTOL``."""
    tr.nodes += 1
    free = L - len(prefix)
    slots = list(prefix) + [_relaxed_sensor(tr, allowed)] * free if free else list(prefix)
    core = _augmented(tr)
    arr = np.asarray(slots, dtype=np.int64)
    try:
        v = float(core.cost(tr.tau, arr, tr.which, budget=tr.lim.core_budget))
    except ConvergenceError:
        return math.inf  # Ψᵏ(0) unbounded: no completion has a steady state either
    return v * (1 - BOUND_RTOL)


@dataclass(frozen=True)
class _Node:
    prefix: tuple[int, ...]
    counts: tuple[int, ...]
    bound: float


def _allowed(tr: _Tree, counts: tuple[int, ...], first: int) -> tuple[int, ...]:
    hi = tr.lim.hi
    return tuple(
        i for i in range(tr.m.n_sensors) if i >= first and (hi is None or counts[i] < hi[i])
    )


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
        out.append(_Node(prefix, counts, _bound(tr, prefix, allowed, L)))
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
    bound = _bound(tr, (), _allowed(tr, counts, 0), L)
    return _Node((), counts, bound), symmetric


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


def _relaxed_factors(tr: _Tree) -> list[F64]:
    """The relaxed sensor ``ĉ`` of every non-empty set of sensors, by bit mask − 1."""
    n_s = tr.m.n_sensors
    sets = ([tr.cbar[i] for i in range(n_s) if mask >> i & 1] for mask in range(1, 2**n_s))
    return [dominating_factor(cb, tr.tau, tr.m.n) for cb in sets]


def _kernel_length(
    tr: _Tree, L: int, factors: list[F64], node_limit: int, deadline: float
) -> list[float]:
    """Searches the schedules of ``L`` slots in the Rust kernel; the bound of what is left open
    at a limit (empty when the tree was exhausted)."""
    n_s = tr.m.n_sensors
    b = float(tr.m.sample_costs[0])
    symmetric = tr.which == "average" and abs(L * b - tr.lim.budget) <= 1e-12 * tr.lim.budget
    hi = list(tr.lim.hi) if tr.lim.hi is not None else [L] * n_s
    left = deadline - time.monotonic()
    out = _core.sampled_exact_schedule(
        tr.m.core,
        tr.tau,
        L,
        tr.which,
        factors,
        [int(v) for v in tr.lim.lo],
        [int(min(v, L)) for v in hi],
        tr.best_cost,
        symmetric,
        max(0, node_limit - tr.nodes),
        time_limit=left if math.isfinite(left) else None,
        budget=tr.lim.core_budget,
    )
    tr.nodes += out.nodes
    if out.slots is not None:
        tr.best, tr.best_cost = Schedule(list(out.slots), n_s), out.eta_bar
    return [] if out.complete else [out.lower_bound]


def _check_impl(exact_impl: str) -> None:
    if exact_impl not in EXACT_IMPLS:
        raise InvalidInputError(f"exact_impl must be one of {EXACT_IMPLS}, got {exact_impl!r}")


def exact_search(
    m: SampledSystem,
    tau: float,
    which: str,
    lim: ScheduleLimits,
    incumbent: Schedule,
    incumbent_cost: float,
    node_limit: int,
    deadline: float,
    exact_impl: str = "rust",
) -> ExactSearch:
    """The branch-and-bound of the module docstring from an incumbent (its exact cost); with
    unequal sample costs the one of :mod:`capalloc_rs.sampled.exact_grid`.

    ``node_limit`` bounds the nodes whose bound is computed and ``deadline`` (a
    ``time.monotonic()`` time) the wall clock; either stops the search with the incumbent and a
    valid lower bound. Ctrl-C raises ``KeyboardInterrupt`` between nodes.

    Args:
        exact_impl: ``"rust"`` (default: the kernel ``capalloc::sampled::exact_dfs``, for equal
            costs and at most ``MAX_KERNEL_SENSORS`` sensors) or ``"python"`` (the search of
            before, one augmented-model cost per node). Unequal costs always use
            :mod:`capalloc_rs.sampled.exact_grid`.

    Raises:
        InvalidInputError: ``exact_impl`` is not one of ``EXACT_IMPLS``.
    """
    _check_impl(exact_impl)
    if not equal_costs(m):
        found = grid_exact_search(
            m, tau, which, lim, incumbent, incumbent_cost, node_limit, deadline
        )
        if found is None:  # a cost grid too fine: no search, no bound
            return ExactSearch(incumbent, incumbent_cost, math.nan, 0, False)
        return ExactSearch(*found)
    tr = _tree(m, tau, which, lim)
    tr.best, tr.best_cost = incumbent, incumbent_cost
    open_bounds: list[float] = []
    lengths = _lengths(tr)
    kernel = exact_impl == "rust" and m.n_sensors <= MAX_KERNEL_SENSORS
    factors = _relaxed_factors(tr) if kernel else []
    for k, L in enumerate(lengths):
        if tr.nodes >= node_limit or time.monotonic() >= deadline:
            open_bounds.extend(_root(tr, rest)[0].bound for rest in lengths[k:])
            break
        if kernel:
            open_bounds.extend(_kernel_length(tr, L, factors, node_limit, deadline))
        else:
            open_bounds.extend(n.bound for n in _search_length(tr, L, node_limit, deadline))
    complete = not open_bounds
    lower = min([tr.best_cost, *open_bounds])
    assert tr.best is not None
    return ExactSearch(tr.best, tr.best_cost, lower, tr.nodes, complete)
