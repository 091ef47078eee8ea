"""The interface the allocation methods need from a network (duck-typed): the cost oracle
``r ↦ η(r), ∇η(r), ∇²η(r)`` of Theorem 1's problem and, for Newton–CG, evaluation points with
Hessian-vector products. A :class:`capalloc_rs.Network` is both.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from .._arrays import require_attrs

__all__ = [
    "CostOracle",
    "CostPointOracle",
    "num_sensors",
    "value_gradient",
    "value_gradient_hessian",
]

F64 = npt.NDArray[np.float64]


class CostOracle(Protocol):
    """The cost oracle the optimisers need: η(r), ∇η(r), ∇²η(r) for rates r (length N), with the
    network's ``r_min`` and ``sensors``."""

    @property
    def r_min(self) -> float: ...

    @property
    def sensors(self) -> Any: ...

    def cost(self, r: Any) -> float: ...

    def gradient(self, r: Any) -> F64: ...

    def hessian(self, r: Any) -> F64: ...


class CostPointOracle(Protocol):
    """An evaluation point (``Network.at(r)``): the value, gradient and Hessian-vector products
    Newton–CG needs at one rate vector."""

    @property
    def value(self) -> float: ...

    @property
    def gradient(self) -> Any: ...

    def hvp(self, v: Any) -> Any: ...

    def hessian(self) -> Any: ...


def value_gradient(net: Any, r: F64) -> tuple[float, F64]:
    """``(η(r), ∇η(r))`` with one Riccati solve when the network offers ``value_and_gradient``."""
    fn = getattr(net, "value_and_gradient", None)
    if fn is not None:
        f, g = fn(r)
        return float(f), np.asarray(g, dtype=np.float64)
    return float(net.cost(r)), np.asarray(net.gradient(r), dtype=np.float64)


def value_gradient_hessian(net: Any, r: F64) -> tuple[float, F64, F64]:
    """``(η, ∇η, ∇²η)`` at ``r`` with one Riccati solve when the network offers it."""
    fn = getattr(net, "value_gradient_hessian", None)
    if fn is not None:
        f, g, h = fn(r)
        return float(f), np.asarray(g, dtype=np.float64), np.asarray(h, dtype=np.float64)
    g = np.asarray(net.gradient(r), dtype=np.float64)
    return float(net.cost(r)), g, np.asarray(net.hessian(r), dtype=np.float64)


def num_sensors(net: CostOracle) -> int:
    """``N``, after checking that ``net`` has ``sensors`` and ``r_min`` (InvalidInputError)."""
    require_attrs("net", net, "sensors", "r_min")
    return len(net.sensors)
