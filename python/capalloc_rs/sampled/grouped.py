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
Since ``J₊ ⪰ J₋``, ``P ⊆ P'`` ⇒ ``Ψ_{g,P'} ⪯ Ψ_{g,P}`` ⇒ ``f_g(P') ≤ f_g(P)``. Hence with
``k = |P|``: ``tr(M_g Σ̄_R) ≥ F_g(k) = min_{|P| = k} f_g(P)``, computed by enumeration while
there are at most ``MAX_SETS`` sets of size ``k`` (for the average, rotation invariant without
idle time, only sets containing the first slot), and ``F_g(k) ≥ f_g({1 … L})`` beyond.

**Theorem.** For every schedule with counts ``k``: ``η̄(R) ≥ Σ_g F_g(k_{κ(g)})``; so
``η̄ ≥ min { Σ_i G_i(k_i) : Σ_i k_i = L, ⌈r_min⌉ ≤ k_i ≤ ⌊r_max,i⌋ }`` with
``G_i(k) = Σ_{κ(g) = i} F_g(k)`` — a separable knapsack solved exactly by dynamic programming.
The costs ``f_g`` are computed in the Rust core (an augmented model with the two sensors ``J₋``,
``J₊`` and weight ``M_g``) and the result is lowered by ``BOUND_RTOL``.
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

__all__ = ["MAX_SETS", "grouped_lower_bound"]

#: Most position sets enumerated per key sensor and count (beyond: the all-positions bound).
MAX_SETS = 1000


def _factor(j: F64, tau: float) -> F64:
    """``ĉ`` with ``τ ĉĉᵀ ⪰ J`` (eigenvalues rounded up by a relative 1e-12)."""
    w, v = np.linalg.eigh(0.5 * (j + j.T))
    keep = w > 0
    c = v[:, keep] * np.sqrt(w[keep] * (1 + 1e-12) / tau)
    return c if c.shape[1] else np.zeros((j.shape[0], 1))


def _sqrt_psd(m: F64) -> F64:
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    return np.asarray((v * np.sqrt(np.clip(w, 0.0, None))) @ v.T)


def _f(core: _core.SampledModel, tau: float, L: int, pos: tuple[int, ...], which: str) -> float:
    slots = np.zeros(L, dtype=np.int64)
    slots[list(pos)] = 1
    try:
        return float(core.cost(tau, slots, which))
    except ConvergenceError:
        return math.inf  # Ψ unbounded: no schedule with these positions has a steady state


def _group_table(
    core: _core.SampledModel, tau: float, L: int, which: str, deadline: float
) -> list[float]:
    """``F_g(k)`` for ``k = 0 … L`` (enumerated while small enough and before the deadline,
    else the all-positions bound)."""
    floor = _f(core, tau, L, tuple(range(L)), which)
    table = [floor] * (L + 1)
    for k in range(L + 1):
        if time.monotonic() >= deadline:
            break
        if which == "average" and k > 0:
            n_sets = math.comb(L - 1, k - 1)
            sets = ((0, *rest) for rest in itertools.combinations(range(1, L), k - 1))
        else:
            n_sets = math.comb(L, k)
            sets = (p for p in itertools.combinations(range(L), k))
        if n_sets > MAX_SETS:
            break
        table[k] = max(floor, min(_f(core, tau, L, p, which) for p in sets))
    return table


def _knapsack(tables: list[list[float]], lo: tuple[int, ...], hi: list[int], L: int) -> float:
    """``min Σ_i G_i(k_i)`` over ``Σ k_i = L``, ``lo_i ≤ k_i ≤ hi_i``."""
    best = [0.0] + [math.inf] * L
    for g, a, b in zip(tables, lo, hi, strict=True):
        nxt = [math.inf] * (L + 1)
        for used in range(L + 1):
            if math.isinf(best[used]):
                continue
            for k in range(a, min(b, L - used) + 1):
                nxt[used + k] = min(nxt[used + k], best[used] + g[k])
        best = nxt
    return best[L]


def grouped_lower_bound(
    m: SampledSystem, tau: float, lim: ScheduleLimits, which: str, deadline: float = math.inf
) -> float:
    """The bound of the module docstring (``nan`` outside the paper's case or with one
    sensor)."""
    if not lim.plain or m.n_sensors < 2:
        return math.nan
    L = int(round(lim.budget))
    n, N = m.n, m.n_sensors
    cbar = [np.sqrt(tau) * c for c in m.sensors]
    root = np.eye(n) if m.weight is None else _sqrt_psd(np.asarray(m.weight))
    keys = [int(np.argmax([np.linalg.norm(c.T @ root[:, g]) for c in m.sensors])) for g in range(n)]
    tables = [[0.0] * (L + 1) for _ in range(N)]
    for i in sorted(set(keys)):
        r_i = root[:, [g for g in range(n) if keys[g] == i]]
        m_i = r_i @ r_i.T  # M_i = Σ_{κ(g) = i} M_g
        j_minus = dominating_information([cbar[j] for j in range(N) if j != i])[0]
        j_plus = j_minus + cbar[i] @ cbar[i].T
        core = _core.SampledModel(
            m.A, m.Q, [_factor(j_minus, tau), _factor(j_plus, tau)], weight=m_i
        )
        tables[i] = _group_table(core, tau, L, which, deadline)
    hi = [L if lim.hi is None else min(L, h) for h in lim.hi or [L] * N]
    value = _knapsack(tables, lim.lo, hi, L)
    return value * (1 - BOUND_RTOL) if math.isfinite(value) else math.nan
