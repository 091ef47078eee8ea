"""Exact integer counts for a decoupled network with sample costs: the separable knapsack

    minimise Σ_i η_i(k_i)   subject to   k_lo,i ≤ k_i ≤ k_hi,i,   Σ b_i k_i ≤ B,

solved by dynamic programming over the sensors on the Pareto frontier of (channel units spent,
cost): after sensor ``i`` the frontier holds, for every reachable spending, the least partial
cost, with dominated states (spending more for no less cost) dropped. For a decoupled network
(one subsystem per sensor, no coupling) ``η(k) = Σ_i η_i(k_i)`` exactly, and
``η_i(k) − η_i(k_lo,i) = η(k_lo + (k − k_lo,i) e_i) − η(k_lo)`` — one evaluation of the network
per sensor and count. With unit costs the spendings are integers and the frontier has at most
``B − Σ k_lo + 1`` states; with unequal costs it can grow, so the program gives up (``None``)
beyond :data:`MAX_KNAPSACK_STATES` states per stage, or :data:`MAX_KNAPSACK_EVALUATIONS`
evaluations for the tables.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["MAX_KNAPSACK_EVALUATIONS", "MAX_KNAPSACK_STATES", "is_decoupled", "separable_knapsack"]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: The Pareto dynamic program gives up when a stage would combine more states and options than
#: this (the greedy and exchanges then stand alone).
MAX_KNAPSACK_STATES = 2_000_000

#: ... or when the tables ``η_i(k)`` would take more evaluations of the network than this.
MAX_KNAPSACK_EVALUATIONS = 20_000


def is_decoupled(net: Any, n_sens: int) -> bool:
    """Whether ``η`` is separable: a block network with one subsystem per sensor and no coupling
    (``ε = 0`` or zero couplings); an error weight's off-diagonal blocks do not matter then."""
    st = getattr(net, "structure", None)
    if st is None or len(st.a_blocks) != n_sens:
        return False
    return bool(st.eps == 0.0 or not np.any(st.coupling))


def _tables(eta: Any, k_lo: I64, k_top: I64) -> list[F64]:
    """``η_i(k) − η_i(k_lo,i)`` for ``k = k_lo,i … k_top,i``, one batch of evaluations."""
    rows = [k_lo.copy()]
    for i in range(k_lo.size):
        for k in range(int(k_lo[i]) + 1, int(k_top[i]) + 1):
            row = k_lo.copy()
            row[i] = k
            rows.append(row)
    vals = eta(np.array(rows, dtype=np.int64))
    base, pos, out = float(vals[0]), 1, []
    for i in range(k_lo.size):
        m = int(k_top[i] - k_lo[i])
        out.append(np.concatenate([[0.0], vals[pos : pos + m] - base]))
        pos += m
    return out


def separable_knapsack(eta: Any, costs: F64, budget: float, k_lo: I64, k_hi: I64) -> I64 | None:
    """The counts minimising ``Σ η_i(k_i)`` (see the module docstring); ``eta`` maps rows of
    counts to costs. ``None`` when the frontier grows beyond :data:`MAX_KNAPSACK_STATES`."""
    spare = budget - float(costs @ k_lo)
    tol = 1e-12 * max(budget, 1.0)
    extra = np.floor((spare + tol) / costs).astype(np.int64)
    k_top = np.minimum(k_hi, k_lo + extra)
    if float(np.sum((k_top - k_lo).astype(np.float64))) + 1 > MAX_KNAPSACK_EVALUATIONS:
        return None
    tables = _tables(eta, k_lo, k_top)
    spent, value = np.zeros(1), np.zeros(1)
    choices: list[tuple[I64, I64]] = []  # per stage: (parent state, extra count) of each state
    for i, tab in enumerate(tables):
        m = tab.size
        if spent.size * m > MAX_KNAPSACK_STATES:
            return None
        s_new = (spent[:, None] + costs[i] * np.arange(m)[None, :]).ravel()
        v_new = (value[:, None] + tab[None, :]).ravel()
        parent = np.repeat(np.arange(spent.size), m)
        extra_k = np.tile(np.arange(m), spent.size)
        ok = s_new <= spare + tol
        s_new, v_new, parent, extra_k = s_new[ok], v_new[ok], parent[ok], extra_k[ok]
        order = np.lexsort((v_new, s_new))
        s_new, v_new, parent, extra_k = (x[order] for x in (s_new, v_new, parent, extra_k))
        keep = v_new < np.concatenate([[np.inf], np.minimum.accumulate(v_new)[:-1]])
        spent, value = s_new[keep], v_new[keep]
        choices.append((parent[keep], extra_k[keep]))
    state = int(np.argmin(value))
    counts = k_lo.copy()
    for i in range(len(tables) - 1, -1, -1):
        parent, extra_k = choices[i]
        counts[i] += int(extra_k[state])
        state = int(parent[state])
    return counts
