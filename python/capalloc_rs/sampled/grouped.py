"""A tighter provable lower bound on ``η̄`` for the paper's case (unit costs, ``r_tot = L`` slots,
one common minimum): the error split into groups, each relaxed around one *key* sensor whose
slot positions are enumerated, and the counts chosen by a knapsack.

**Split.** ``M = Σ_g M_g`` with ``M_g = R e_g e_gᵀ R ⪰ 0``, ``R = M^{1/2}`` (``M = I``: the state
coordinates), so ``η̄(R) = Σ_g tr(M_g Σ̄_R)`` (boundary; the same for each slot's posterior, so
also for the average). Group ``g``'s key sensor ``κ(g) = i`` maximises ``‖ĉ_iᵀ R e_g‖``; the
groups of one key are merged, ``M_i = Σ_{κ(g) = i} M_g`` (the same positions ``P`` serve them
all, so one minimum over ``P`` of their sum is at least the sum of their minima).

**Group relaxation.** For a position set ``P ⊆ {1 … L}`` let ``Ψ_{g,P}`` be the period whose
slot ``l`` predicts over ``τ₀`` and updates with ``J₊ = J₋ + c̄_i c̄_iᵀ`` (``i`` the key of ``g``)
if ``l ∈ P`` and with ``J₋`` otherwise, ``J₋ ⪰ c̄_j c̄_jᵀ`` for every ``j ≠ i``
(:func:`~capalloc_rs.sampled.relaxation.dominating_information`). For a schedule ``R`` with
``P = {l : R_l = i}``, every slot of ``Ψ_{g,P}`` is ``⪯`` the same slot of ``Φ_R`` (more
information, same prediction), so by the relaxation theorem
(:mod:`capalloc_rs.sampled.relaxation`) ``tr(M_g Σ̄_R) ≥ f_g(P)``, the cost of
``Ψ_{g,P}``'s fixed point with weight ``M_g`` (for the average: the mean over its posteriors).
*Superset:* since ``J₊ ⪰ J₋``, ``P ⊆ P'`` ⇒ ``Ψ_{g,P'} ⪯ Ψ_{g,P}`` ⇒ ``f_g(P') ≤ f_g(P)``
(and the same for every posterior of the trajectories). Hence with
``k = |P|``: ``tr(M_g Σ̄_R) ≥ F_g(k) = min_{|P| = k} f_g(P)``.

**Phases.** Without idle time (the paper's case) the slot maps of ``Ψ_{g,P}`` and of its
rotation ``P + r`` are the same cycle started at another slot: if ``Ψ = A ∘ B`` (``B`` the first
``r`` slots) the rotation is ``Ψ' = B ∘ A`` and ``Ψ'ᵏ⁺¹(0) = B(Ψᵏ(A(0))) ⪰ B(Ψᵏ(0))`` (``A(0) ⪰ 0``,
monotonicity), so the least fixed point of ``Ψ'`` is ``⪰`` the posterior after slot ``r`` of
``Ψ``'s periodic trajectory from its least fixed point. Hence one trajectory of ``Ψ_{g,P}``
bounds all ``L`` rotations: for the boundary figure ``f_g(P + r) ≥`` the least ``tr(M_g ·)``
over its posteriors; the average figure is the mean over the posteriors, the same for every
rotation. Every set has a rotation containing the first slot, so ``F_g(k)`` is the least of
these over the ``C(L − 1, k − 1)`` sets containing slot 1 — enumerated while there are at most
``max_sets`` of them (``MAX_SETS`` for ``certify="grouped"``, ``CHEAP_SETS`` for the default).

**Longest gap (beyond the enumeration).** ``k ≥ 1`` positions on the cycle of ``L`` slots leave
``L − k`` others in ``k`` cyclic gaps, so one gap has ``m ≥ ⌈(L − k)/k⌉`` slots; rotated to start
at slot 1, the set lies in ``{m + 1 … L}`` and (superset, below) ``F_g(k) ≥ f_g({m + 1 … L})``
over its phases — one trajectory per distinct ``m``. *Blocks:* with the slots cut into blocks of
``s`` consecutive slots, a set of ``k`` positions rotated to contain the first slot meets at most
``k`` blocks, the first among them, so it lies in a union of ``k`` blocks containing the first
(add blocks if it meets fewer) — ``F_g(k) ≥`` the least ``f_g`` over those unions, for the least
``s`` with at most ``max_sets`` of them. Every entry is at least the all-positions bound
``f_g({1 … L})``.

**Lazy tables.** ``F_g`` is non-increasing in ``k`` (every ``k``-set lies in a ``(k+1)``-set), so
a bound on ``F_g(k)`` bounds every ``F_g(j)``, ``j ≤ k``. The tables start at the all-positions
bound (``k = 0``: exact); the knapsack below is solved, the entries its minimiser uses are
refined (the larger of the enumeration or blocks and the longest gap, then raised below), and
again until its minimiser uses only refined entries, a deadline passes or a budget of
trajectories is spent — every entry is a valid bound at every round, so the last value is.

**Theorem.** For every schedule with counts ``k``: ``η̄(R) ≥ Σ_g F_g(k_{κ(g)})``; so
``η̄ ≥ min { Σ_i G_i(k_i) : Σ_i k_i = L, ⌈r_min⌉ ≤ k_i ≤ ⌊r_max,i⌋ }`` with
``G_i(k) = Σ_{κ(g) = i} F_g(k)`` — a separable knapsack solved exactly by dynamic programming.
The trajectories are computed in the Rust core (an augmented model with the two sensors ``J₋``,
``J₊``; its steady state and posteriors) and the result is lowered by ``BOUND_RTOL``.
"""

from __future__ import annotations

import itertools
import math
import time

import numpy as np

from .. import _core
from .._arrays import F64
from ..errors import ConvergenceError
from .channel import ScheduleLimits
from .relaxation import BOUND_RTOL, dominating_information
from .system import SampledSystem

__all__ = ["CHEAP_SETS", "CHEAP_WORK", "MAX_SETS", "grouped_lower_bound"]

#: Most position sets enumerated per key sensor and count by ``certify="grouped"`` (beyond: the
#: longest-gap bound).
MAX_SETS = 1000
#: The same for the default certificate (``certify=True``): the cheap grouped bound.
CHEAP_SETS = 32
#: The default certificate computes at most ``CHEAP_WORK / (L n³)`` trajectories (each costs
#: about ``L n³`` operations, ≈ 2 ms at L = n = 20) and is skipped (only the relaxed bound
#: counts) when one round of refinements may need more: it runs in full up to N = 10
#: subsystems of ``n = 2`` with ``L = 20`` slots (≈ 0.5–1 s), not at ``L = 30`` or N = 20.
CHEAP_WORK = 6e7


def _factor(j: F64, tau: float) -> F64:
    """``ĉ`` with ``τ ĉĉᵀ ⪰ J`` (eigenvalues rounded up by a relative 1e-12)."""
    w, v = np.linalg.eigh(0.5 * (j + j.T))
    keep = w > 0
    c = v[:, keep] * np.sqrt(w[keep] * (1 + 1e-12) / tau)
    return c if c.shape[1] else np.zeros((j.shape[0], 1))


def _sqrt_psd(m: F64) -> F64:
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    return np.asarray((v * np.sqrt(np.clip(w, 0.0, None))) @ v.T)


def _f(
    core: _core.SampledModel, weight: F64, tau: float, L: int, pos: tuple[int, ...], which: str
) -> float:
    """``f_g(P)`` for ``P = pos`` and every rotation of it (module docstring, *phases*): the
    least posterior of ``Ψ_{g,P}``'s periodic trajectory for the boundary figure, their mean for
    the average."""
    slots = np.zeros(L, dtype=np.int64)
    slots[list(pos)] = 1
    try:
        post = np.asarray(core.steady_state(tau, slots).posteriors)
    except ConvergenceError:
        return math.inf  # Ψ unbounded: no schedule with these positions has a steady state
    traces = np.einsum("ij,lij->l", weight, post)
    return float(traces.min() if which == "boundary" else traces.mean())


def _gap_run(L: int, k: int) -> tuple[int, ...]:
    """The positions outside the first ``⌈(L − k)/k⌉`` slots: some rotation of every set of
    ``k ≥ 1`` positions lies in them (its longest cyclic gap has at least that many slots)."""
    return tuple(range(-(-(L - k) // k), L))


def _block_sets(L: int, k: int, max_sets: int) -> list[tuple[int, ...]]:
    """Supersets covering every set of ``k ≥ 1`` positions up to rotation (module docstring,
    *blocks*): the unions of ``k`` blocks of ``s`` consecutive slots containing the first block,
    for the least ``s ≥ 2`` with at most ``max_sets`` of them."""
    for s in range(2, L + 1):
        nb = -(-L // s)
        if k >= nb:
            return [tuple(range(L))]
        if math.comb(nb - 1, k - 1) <= max_sets:
            return [
                tuple(p for b in (0, *rest) for p in range(b * s, min(L, (b + 1) * s)))
                for rest in itertools.combinations(range(1, nb), k - 1)
            ]
    return [tuple(range(L))]


class _KeyTable:
    """``G_i(k)`` of one key sensor, refined on demand: every entry starts at the all-positions
    bound (``k = 0``: its exact value); entry ``k`` refined is the larger of the longest-gap
    bound and the least over the enumerated sets, else the blocks (module docstring); and since
    ``G_i`` is non-increasing in ``k``, each entry is raised to the entries above it."""

    def __init__(
        self, core: _core.SampledModel, weight: F64, tau: float, L: int, which: str, max_sets: int
    ) -> None:
        self.core, self.weight, self.tau, self.L, self.which = core, weight, tau, L, which
        self.max_sets = max_sets
        self.known: dict[tuple[int, ...], float] = {}
        floor = self.f(tuple(range(L)))
        self.values = [floor] * (L + 1)
        self.values[0] = max(floor, self.f(()))
        self.refined = {0}

    def f(self, pos: tuple[int, ...]) -> float:
        """``f_g(pos)`` over its phases (remembered)."""
        if pos not in self.known:
            self.known[pos] = _f(self.core, self.weight, self.tau, self.L, pos, self.which)
        return self.known[pos]

    def refine(self, k: int) -> None:
        """Entry ``k ≥ 1`` refined (never below the bound already there), then the envelope."""
        self.refined.add(k)
        L = self.L
        if math.comb(L - 1, k - 1) <= self.max_sets:
            sets: list[tuple[int, ...]] = [
                (0, *rest) for rest in itertools.combinations(range(1, L), k - 1)
            ]
        else:
            sets = _block_sets(L, k, self.max_sets)
        value = max(self.f(_gap_run(L, k)), min(self.f(p) for p in sets))
        for j in range(k, -1, -1):  # G_i(j) ≥ G_i(k) for j ≤ k
            if self.values[j] >= value:
                break
            self.values[j] = value


def _knapsack(
    tables: list[list[float]], lo: tuple[int, ...], hi: list[int], L: int
) -> tuple[float, list[int]]:
    """``min Σ_i G_i(k_i)`` over ``Σ k_i = L``, ``lo_i ≤ k_i ≤ hi_i``, and a minimiser."""
    best = [0.0] + [math.inf] * L
    choice: list[list[int]] = []
    for g, a, b in zip(tables, lo, hi, strict=True):
        nxt = [math.inf] * (L + 1)
        pick = [-1] * (L + 1)
        for used in range(L + 1):
            if math.isinf(best[used]):
                continue
            for k in range(a, min(b, L - used) + 1):
                if best[used] + g[k] < nxt[used + k]:
                    nxt[used + k], pick[used + k] = best[used] + g[k], k
        best = nxt
        choice.append(pick)
    counts = [0] * len(tables)
    left = L
    for i in range(len(tables) - 1, -1, -1):
        counts[i] = max(choice[i][left], 0)
        left -= counts[i]
    return best[L], counts


def grouped_lower_bound(
    m: SampledSystem,
    tau: float,
    lim: ScheduleLimits,
    which: str,
    deadline: float = math.inf,
    cheap: bool = False,
) -> float:
    """The bound of the module docstring (``nan`` outside the paper's case or with one
    sensor): at most ``MAX_SETS`` position sets per key sensor and count, or with ``cheap``
    (the default certificate of ``best_schedule``) ``CHEAP_SETS`` and at most
    ``CHEAP_WORK / (L n³)`` trajectories (``nan`` if one round of refinements may need more)."""
    if not lim.plain or m.n_sensors < 2:
        return math.nan
    L = int(round(lim.budget))
    n, N = m.n, m.n_sensors
    root = np.eye(n) if m.weight is None else _sqrt_psd(np.asarray(m.weight))
    keys = [int(np.argmax([np.linalg.norm(c.T @ root[:, g]) for c in m.sensors])) for g in range(n)]
    max_sets, most = MAX_SETS, math.inf
    if cheap:
        max_sets, most = CHEAP_SETS, CHEAP_WORK / (L * n**3)
        if len(set(keys)) * (CHEAP_SETS + 3) > most:  # not even one round of refinements
            return math.nan
    cbar = [np.sqrt(tau) * c for c in m.sensors]
    tables: dict[int, _KeyTable] = {}
    for i in sorted(set(keys)):
        r_i = root[:, [g for g in range(n) if keys[g] == i]]
        m_i = r_i @ r_i.T  # M_i = Σ_{κ(g) = i} M_g
        j_minus = dominating_information([cbar[j] for j in range(N) if j != i])[0]
        j_plus = j_minus + cbar[i] @ cbar[i].T
        core = _core.SampledModel(m.A, m.Q, [_factor(j_minus, tau), _factor(j_plus, tau)])
        tables[i] = _KeyTable(core, m_i, tau, L, which, max_sets)
    return _refined_knapsack(tables, N, lim.lo, L, deadline, most)


def _refined_knapsack(
    tables: dict[int, _KeyTable],
    N: int,
    lo: tuple[int, ...],
    L: int,
    deadline: float,
    most: float,
) -> float:
    """The knapsack over the tables, refining the entries its minimiser uses until they are all
    refined, the deadline passes or ``most`` trajectories were computed (at most ``N·(L + 1)``
    rounds: each refines an entry); every entry is a valid bound at every round, so the last
    value is."""
    zero = [0.0] * (L + 1)
    for _ in range(N * (L + 1) + 1):
        value, counts = _knapsack(
            [tables[i].values if i in tables else zero for i in range(N)], lo, [L] * N, L
        )
        todo = [i for i in tables if counts[i] not in tables[i].refined]
        if not todo or not math.isfinite(value):
            break
        for i in todo:
            if time.monotonic() >= deadline or sum(len(t.known) for t in tables.values()) >= most:
                return value * (1 - BOUND_RTOL)
            tables[i].refine(counts[i])
    return value * (1 - BOUND_RTOL) if math.isfinite(value) else math.nan
