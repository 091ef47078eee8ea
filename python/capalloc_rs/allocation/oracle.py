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
    "WARM_START_MIN_ORDER",
    "CountingOracle",
    "CostOracle",
    "CostPointOracle",
    "PointCache",
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


#: From this order n of the state on, each new evaluation point is reached from the previous one
#: (:meth:`capalloc_rs.network.CostPoint.warm`) instead of solved cold: the warm start costs Schur
#: forms of ``n × n`` closed loops instead of the ``2n × 2n`` Hamiltonian, 1.7× less at n = 100
#: and 400, nothing gained at n = 20 (``benches/warm_cost.rs``).
WARM_START_MIN_ORDER = 64


class PointCache:
    """Value, gradient and Hessian at rates ``r`` through evaluation points (``net.at``), the
    last one kept and each new one warm-started from it when the model is large enough
    (order at least ``min_order``, default :data:`WARM_START_MIN_ORDER`). Without ``net.at``
    (other oracles), the one-call functions."""

    def __init__(
        self,
        net: Any,
        min_order: int | None = None,
        chord_steps: int = 0,
        compensated: bool = True,
    ) -> None:
        self.net = net
        self.at = getattr(net, "at", None)
        self.last: tuple[bytes, CostPointOracle] | None = None
        threshold = WARM_START_MIN_ORDER if min_order is None else min_order
        self.warm = int(getattr(net, "n", 0)) >= threshold
        #: Chord corrections of each warm start (:meth:`CostPoint.warm`); 0: none.
        self.chord_steps = chord_steps
        #: ``False``: warm starts without the compensated refinement (:meth:`CostPoint.warm`).
        self.compensated = compensated

    def point(self, r: F64) -> CostPointOracle:
        """The evaluation point at ``r`` (the last one again when ``r`` is unchanged)."""
        assert self.at is not None
        key = r.tobytes()
        if self.last is None or self.last[0] != key:
            prev = None if self.last is None else self.last[1]
            warm = getattr(prev, "warm", None) if self.warm else None
            if warm is None:
                self.last = (key, self.at(r))
            elif not self.compensated:
                self.last = (key, warm(r, chord_steps=self.chord_steps, compensated=False))
            elif self.chord_steps:
                self.last = (key, warm(r, chord_steps=self.chord_steps))
            else:
                self.last = (key, warm(r))
        return self.last[1]

    def value_gradient(self, r: F64) -> tuple[float, F64]:
        """``(η(r), ∇η(r))``."""
        if self.at is None:
            return value_gradient(self.net, r)
        p = self.point(r)
        return float(p.value), np.asarray(p.gradient, dtype=np.float64)

    def value_gradient_hessian(self, r: F64) -> tuple[float, F64, F64]:
        """``(η(r), ∇η(r), ∇²η(r))``."""
        if self.at is None:
            return value_gradient_hessian(self.net, r)
        p = self.point(r)
        h = np.asarray(p.hessian(), dtype=np.float64)
        return float(p.value), np.asarray(p.gradient, dtype=np.float64), h


class CountingOracle:
    """A network that counts the work asked of it — evaluation points (``at`` and warm starts),
    Hessians, their principal blocks and Hessian-vector products — in :attr:`counts`; everything
    else is the network's. For measuring what a method costs (benchmarks, tests), independent of
    the machine's speed."""

    def __init__(self, net: Any) -> None:
        self._net = net
        self.counts = {"points": 0, "hessians": 0, "hessian_blocks": 0, "hvps": 0}

    def __getattr__(self, name: str) -> Any:
        return getattr(self._net, name)

    def at(self, r: Any) -> Any:
        """The network's point at ``r``, counted."""
        self.counts["points"] += 1
        return _CountingPoint(self._net.at(r), self.counts)


class _CountingPoint:
    """An evaluation point whose Hessians, products and warm starts are counted."""

    def __init__(self, point: Any, counts: dict[str, int]) -> None:
        self._point, self._counts = point, counts

    def __getattr__(self, name: str) -> Any:
        return getattr(self._point, name)

    def hessian(self) -> Any:
        self._counts["hessians"] += 1
        return self._point.hessian()

    def hessian_block(self, idx: Any) -> Any:
        self._counts["hessian_blocks"] += 1
        return self._point.hessian_block(idx)

    def hvp(self, v: Any) -> Any:
        self._counts["hvps"] += 1 if np.ndim(v) == 1 else int(np.shape(v)[1])
        return self._point.hvp(v)

    def warm(self, r: Any, **kw: Any) -> Any:
        self._counts["points"] += 1
        return _CountingPoint(self._point.warm(r, **kw), self._counts)
