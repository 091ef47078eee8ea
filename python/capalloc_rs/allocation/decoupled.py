"""The decoupled start of Newton's method: the optimum of a block network at ε = 0.

For a block network whose sensor ``i`` measures only subsystem ``i`` (``Network.structure`` with
one block per sensor; ``A = blockdiag(A_i) + ε·coupling``, ``G = blockdiag(G_i)``), setting
``ε = 0`` makes ``Σ`` block diagonal and the cost separable, ``η(r) = Σ_i η_i(r_i)`` with
``η_i(r_i) = tr Σ_i(r_i)`` the cost of subsystem ``i`` alone (``tr(M_ii Σ_i)`` with an error
weight ``M``, whose off-diagonal blocks do not matter at ε = 0). The separable problem

    minimise Σ_i η_i(r_min + γ_i)   subject to   γ ≥ 0,  Σ γ_i = σ

is solved in the Rust core (``_core.separable_allocation``: Newton with the diagonal Hessian
``η_i''``, whose quadratic model over the simplex is minimised exactly by a search on the
multiplier over sorted breakpoints; ``N`` small Riccati solves per step). For weakly coupled
networks its optimum is ``O(ε)`` from the coupled one, so Newton's method on the full problem
starts close to quadratic convergence; at ``ε = 0`` it *is* the optimum.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .. import _core
from ..errors import NumericalError
from .oracle import num_sensors
from .simplex import _fix_sum

__all__ = [
    "SEPARABLE_MAX_ITER",
    "SEPARABLE_START_TOL",
    "decoupled_covariance",
    "decoupled_start",
    "has_decoupled_start",
]

F64 = npt.NDArray[np.float64]

#: Newton steps of the separable problem at most (it converges quadratically: 4–8 from uniform).
SEPARABLE_MAX_ITER = 50

#: For a coupled network (ε ≠ 0) the separable problem is solved to a Frank–Wolfe gap of this
#: times its cost only: its optimum is itself ``O(ε)`` (~1e-3 relative in γ at ε = 0.05) from the
#: coupled one, so a looser start costs no coupled Newton step: the same steps and products at
#: N = 5–200 for 1e-3 as for 1e-5 (``Network.random(N, 2, eps=0.05)`` and 200
#: ``random_networks`` each at N = 5, 10, 20), two separable steps fewer than to 1e-12 (of 4–7).
#: At ε = 0 the start is solved to the caller's tolerance: it is then the optimum.
SEPARABLE_START_TOL = 1e-3


def has_decoupled_start(net: Any) -> bool:
    """Whether ``net`` is a block network with one subsystem per sensor (``structure``)."""
    st = getattr(net, "structure", None)
    return st is not None and len(st.a_blocks) == num_sensors(net)


def decoupled_start(net: Any, sigma: float, tol: float, r_min: float | None = None) -> F64 | None:
    """``γ`` of the decoupled (ε = 0) optimum on the simplex of height ``sigma``, solved until its
    Frank–Wolfe gap is at most ``tol`` times its cost when the network is decoupled (ε = 0 or no
    coupling), at most ``max(tol, SEPARABLE_START_TOL)`` times it otherwise (or
    :data:`SEPARABLE_MAX_ITER` steps).

    ``r_min`` replaces ``net.r_min`` (the common minimum of the separable problem).

    ``None`` when ``net`` has no such block structure, or when a subsystem alone has no
    stabilising Riccati solution (an unstable mode it cannot see itself, observed through the
    coupling only): then the decoupled problem is not defined and the caller starts elsewhere.

    Raises:
        InvalidInputError: as the cost at these rates would (e.g. rates too large to resolve).
    """
    common = float(net.r_min) if r_min is None else float(r_min)
    if not has_decoupled_start(net) or not common > 0.0:
        return None  # at a zero minimum a subsystem alone may have no steady state
    st = net.structure
    decoupled = st.eps == 0.0 or not np.any(st.coupling)
    sep_tol = tol if decoupled else max(tol, SEPARABLE_START_TOL)
    weights = _weight_blocks(net)
    if weights is not None and not all(np.any(b) for b in weights):
        return None  # a subsystem whose error does not count: no separable start
    try:
        sol = _core.separable_allocation(
            list(st.a_blocks),
            list(st.g_blocks),
            list(st.c_blocks),
            common,
            float(sigma),
            float(sep_tol),
            SEPARABLE_MAX_ITER,
            weight_blocks=weights,
        )
    except NumericalError:
        # Only the solver's failures on a subsystem (no stabilising solution, singular
        # problem): the decoupled start does not exist. Input errors propagate.
        return None
    gamma = np.array(sol.gamma, dtype=np.float64)
    if gamma.shape != (num_sensors(net),) or not np.all(np.isfinite(gamma)):
        return None
    return _fix_sum(gamma, sigma)


def _weight_blocks(net: Any) -> list[F64] | None:
    """The diagonal blocks ``M_ii`` of the network's error weight (at ε = 0, ``Σ`` is block
    diagonal and ``tr(M Σ) = Σ_i tr(M_ii Σ_i)``); ``None`` without a weight."""
    m = getattr(net, "error_weight", None)
    if m is None:
        return None
    off = net.structure.offsets
    return [m[off[i] : off[i + 1], off[i] : off[i + 1]] for i in range(len(off) - 1)]


def decoupled_covariance(net: Any, r: F64) -> F64:
    """``blockdiag(Σ_i(r_i))``: the covariance of the decoupled network (ε = 0) at rates ``r``,
    one small Riccati solve per subsystem — a start for the coupled ``Σ(r)`` (``O(ε)`` away) by
    Newton–Kleinman (``Network.at(r, start=...)``). ``net`` must have a decoupled start
    (:func:`has_decoupled_start`)."""
    st = net.structure
    off = st.offsets
    out = np.zeros((off[-1], off[-1]))
    for i, (a, g, c) in enumerate(zip(st.a_blocks, st.g_blocks, st.c_blocks, strict=True)):
        sig = _core.CostModel(a, g, [c]).evaluate(r[i : i + 1], 0).sigma
        out[off[i] : off[i + 1], off[i] : off[i + 1]] = sig
    return out
