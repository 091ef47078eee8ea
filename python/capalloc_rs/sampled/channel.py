"""The network seen by a sampled channel: its matrices, the sample costs and count limits of its
sensors and the error weight — and the feasibility of a schedule's counts against a budget.

**Sample costs.** A sample of sensor ``i`` costs ``b_i > 0`` channel units (``net.costs``,
default 1). A period ``τ`` carries a budget of ``B`` channel units; a schedule ``R_1 … R_L``
uses ``Σ_l b_{R_l} ≤ B`` of them (the rest of the period is idle). Its counts ``k_i`` satisfy
``⌈r_min,i⌉ ≤ k_i ≤ ⌊r_max,i⌋`` (``net.rate_min``, ``net.rate_max``; the rounding rule of
:func:`capalloc_rs.limits.min_slots`) and ``Σ_i b_i k_i ≤ B``. With unit costs and ``B = r_tot``
this is the paper's channel of ``r_tot`` slots per period.

**Weight.** With an error weight ``M`` (``net.error_weight``) every figure of the sampled system
is ``tr(M Σ)`` instead of ``tr Σ``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _core
from .._arrays import F64, as_matrix
from ..errors import InvalidInputError, ScheduleError, ShapeError
from ..limits import min_slots

__all__ = ["SampledSystem", "ScheduleLimits", "sampled_system", "schedule_limits"]

#: Relative tolerance of the budget (``capalloc::sampled::discretisation::BUDGET_RTOL``).
BUDGET_RTOL = 1e-12


def _readonly(a: F64) -> F64:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class SampledSystem:
    """A network's raw matrices for the sampled system: ``A``, ``Q = G Gᵀ``, the sensors ``ĉ_i``
    and ``r_min``, validated once (build it with :func:`sampled_system`); and, beyond the
    paper's case, the sample costs ``b_i`` (``costs``, ``None``: all 1), the per-sensor rate
    limits (``rate_min``, ``rate_max``; ``None``: ``r_min`` for all, no cap) and the error
    weight ``M`` (``weight``, ``None``: the plain trace).

    It carries the same validated system in Rust (:attr:`core`, a ``_core.SampledModel``, which
    does not pickle); this wrapper adds the rate limits and pickling."""

    A: F64
    Q: F64
    sensors: tuple[F64, ...]
    r_min: float
    costs: F64 | None = None
    rate_min: F64 | None = None
    rate_max: F64 | None = None
    weight: F64 | None = field(default=None, repr=False)

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])

    @property
    def n_sensors(self) -> int:
        """Number of sensors ``N``."""
        return len(self.sensors)

    @property
    def is_paper_form(self) -> bool:
        """Unit costs, one common ``r_min``, no cap, no weight: the paper's case."""
        return (
            self.costs is None
            and self.rate_min is None
            and self.rate_max is None
            and self.weight is None
        )

    @property
    def sample_costs(self) -> F64:
        """``b_i`` for every sensor (ones for unit costs; a fresh array)."""
        return np.ones(self.n_sensors) if self.costs is None else np.array(self.costs)

    @property
    def min_counts(self) -> tuple[int, ...]:
        """``⌈r_min,i⌉``: the least samples of each sensor per period."""
        if self.rate_min is None:
            return (min_slots(self.r_min),) * self.n_sensors
        return tuple(min_slots(float(v)) for v in self.rate_min)

    @property
    def max_counts(self) -> tuple[int, ...] | None:
        """``⌊r_max,i⌋`` (with the tolerance of :func:`~capalloc_rs.limits.min_slots`; a very
        large number for no cap), or ``None`` when no sensor has a cap."""
        if self.rate_max is None:
            return None
        return tuple(
            2**62 if not math.isfinite(v) else max(0, math.floor(float(v) * (1 + 1e-12)))
            for v in self.rate_max
        )

    @property
    def core(self) -> _core.SampledModel:
        """The system validated once in Rust (built on first use, then kept with this object):
        the sampled functions and the schedule search evaluate through it, so a search converts
        and checks ``(A, Q, sensors)`` once rather than for every candidate schedule."""
        core = self.__dict__.get("_core_model")
        if core is None:
            if self.costs is None and self.weight is None:
                core = _core.SampledModel(self.A, self.Q, list(self.sensors))
            else:
                costs = None if self.costs is None else [float(b) for b in self.costs]
                core = _core.SampledModel(
                    self.A, self.Q, list(self.sensors), costs=costs, weight=self.weight
                )
            object.__setattr__(self, "_core_model", core)
        return core

    def trace(self, s: F64) -> float:
        """``tr(M S)`` (``tr S`` without a weight)."""
        if self.weight is None:
            return float(np.trace(s))
        return float(np.sum(self.weight * s))

    def __getstate__(self) -> dict[str, Any]:
        # The Rust model is rebuilt on first use after unpickling (it does not pickle).
        return {k: v for k, v in self.__dict__.items() if k != "_core_model"}

    def __repr__(self) -> str:
        extra = "" if self.costs is None else f", costs={[float(b) for b in self.costs]}"
        extra += "" if self.weight is None else ", weighted"
        return f"SampledSystem(n={self.n}, n_sensors={self.n_sensors}, r_min={self.r_min:g}{extra})"


def _attr(net: Any, *names: str) -> Any:
    """The first of ``names`` that ``net`` has (``None`` if none)."""
    for name in names:
        v = getattr(net, name, None)
        if v is not None:
            return v
    return None


def _per_sensor(name: str, v: Any, count: int) -> F64 | None:
    """A per-sensor property as a read-only float array (``None`` stays ``None``)."""
    if v is None:
        return None
    a = np.asarray(v, dtype=np.float64)
    if a.ndim == 0:
        a = np.full(count, float(a))
    if a.shape != (count,):
        raise ShapeError(f"{name} must have one entry per sensor ({count}), got shape {a.shape}")
    return _readonly(np.array(a))


def _extras(net: Any, count: int) -> tuple[float, F64 | None, F64 | None, F64 | None]:
    """``(r_min, costs, rate_min, rate_max)``; the arrays ``None`` where they are the paper's."""
    costs = _per_sensor("net.costs", getattr(net, "costs", None), count)
    if costs is not None:
        if not np.all(np.isfinite(costs) & (costs > 0)):
            raise InvalidInputError(f"net.costs must be positive and finite, got {costs}")
        if np.all(costs == 1.0):
            costs = None
    rmin = _per_sensor("net.rate_min", getattr(net, "rate_min", None), count)
    r_raw = getattr(net, "r_min", 0.0)
    r_min = float(np.min(r_raw)) if np.ndim(r_raw) else float(r_raw)
    if rmin is not None and np.all(rmin == rmin[0]):
        r_min, rmin = float(rmin[0]), None
    rmax = _per_sensor("net.rate_max", getattr(net, "rate_max", None), count)
    if rmax is not None and not np.any(np.isfinite(rmax)):
        rmax = None
    return r_min, costs, rmin, rmax


def sampled_system(net: Any) -> SampledSystem:
    """The :class:`SampledSystem` of a network object (a :class:`SampledSystem` passes through).

    Duck-typed: ``A`` or ``a``; ``Q``/``q`` or else ``G``/``g`` (``Q = G Gᵀ``); ``sensors``;
    ``r_min`` (default 0); optionally ``costs``, ``rate_min``, ``rate_max`` (per sensor) and
    ``error_weight`` (``M``) — :class:`capalloc_rs.Network` has all of them.

    Raises:
        InvalidInputError: ``net`` lacks ``A`` or ``sensors``, or both ``Q`` and ``G``; a cost
            is not positive and finite.
        ShapeError: the matrices do not fit together, or there is no sensor.
    """
    if isinstance(net, SampledSystem):
        return net
    a_raw = _attr(net, "A", "a")
    sensors_raw = _attr(net, "sensors")
    if a_raw is None or sensors_raw is None:
        raise InvalidInputError(
            f"the network must have attributes A (or a) and sensors, got {type(net).__name__}"
        )
    a = as_matrix("net.A", a_raw)
    q_raw = _attr(net, "Q", "q")
    if q_raw is None:
        g_raw = _attr(net, "G", "g")
        if g_raw is None:
            raise InvalidInputError("the network must have an attribute Q (= G Gᵀ) or G")
        g = as_matrix("net.G", g_raw)
        q = g @ g.T
    else:
        q = as_matrix("net.Q", q_raw)
    n = a.shape[0]
    if a.shape != (n, n) or q.shape != (n, n):
        raise ShapeError(f"A and Q must be n×n with the same n, got {a.shape} and {q.shape}")
    sensors = []
    for i, c in enumerate(list(sensors_raw)):
        ci = np.asarray(c, dtype=np.float64)
        if ci.ndim == 1:
            ci = ci.reshape(-1, 1)
        ci = as_matrix(f"sensor {i}", ci)
        if ci.shape[0] != n or ci.shape[1] == 0:
            raise ShapeError(f"sensor {i} must be n×p with n = {n}, p >= 1, got {ci.shape}")
        sensors.append(_readonly(np.array(ci)))
    if not sensors:
        raise ShapeError("the network has no sensors")
    r_min, costs, rmin, rmax = _extras(net, len(sensors))
    w_raw = getattr(net, "error_weight", None)
    weight = None if w_raw is None else _readonly(np.array(as_matrix("net.error_weight", w_raw)))
    if weight is not None and weight.shape != (n, n):
        raise ShapeError(f"the error weight must be {n}×{n}, got {weight.shape}")
    a_ro, q_ro = _readonly(np.array(a)), _readonly(np.array(q))
    return SampledSystem(a_ro, q_ro, tuple(sensors), r_min, costs, rmin, rmax, weight)


@dataclass(frozen=True)
class ScheduleLimits:
    """What a schedule of a search may be: counts ``lo[i] ≤ k_i ≤ hi[i]`` and ``Σ b_i k_i ≤
    budget`` (``costs`` ``None``: unit costs; ``hi`` ``None``: no caps).

    ``core_kwargs()`` are the keywords of the Rust kernels for these limits: none in the paper's
    case (one common minimum ``lo[0]``, passed as ``min_count``; unit costs; schedules of exactly
    ``budget`` slots), so that its calls are exactly those of the paper's search."""

    budget: float
    lo: tuple[int, ...]
    hi: tuple[int, ...] | None
    costs: F64 | None

    @property
    def min_count(self) -> int:
        """The common minimum passed as the kernels' ``min_count``."""
        return min(self.lo)

    @property
    def plain(self) -> bool:
        """Unit costs, one common minimum, no caps."""
        return self.costs is None and self.hi is None and len(set(self.lo)) == 1

    def core_kwargs(self) -> dict[str, Any]:
        """The Rust kernels' keywords (``budget``, ``min_counts``, ``max_counts``)."""
        if self.plain:
            return {}
        kw: dict[str, Any] = {"budget": float(self.budget), "min_counts": list(self.lo)}
        if self.hi is not None:
            kw["max_counts"] = list(self.hi)
        return kw

    @property
    def core_budget(self) -> float | None:
        """The ``budget`` keyword of the kernels (``None`` in the paper's case)."""
        return None if self.plain else float(self.budget)

    def used(self, counts: Any) -> float:
        """``Σ b_i k_i``."""
        c = np.asarray(counts, dtype=np.float64)
        return float(c.sum() if self.costs is None else c @ self.costs)

    def fits(self, counts: Any) -> bool:
        """Whether ``counts`` are within the limits and the budget."""
        c = np.asarray(counts)
        if np.any(c < np.asarray(self.lo)):
            return False
        if self.hi is not None and np.any(c > np.asarray(self.hi)):
            return False
        return self.used(c) <= self.budget * (1 + BUDGET_RTOL)


def schedule_limits(m: SampledSystem, budget: float) -> ScheduleLimits:
    """The :class:`ScheduleLimits` of the network for a budget ``B``.

    Raises:
        ScheduleError: the minima need more than ``B`` channel units, or a cap is below its
            minimum.
    """
    lo = m.min_counts
    hi = m.max_counts
    costs = m.costs
    b = m.sample_costs
    need = float(np.asarray(lo, dtype=np.float64) @ b)
    if need > budget * (1 + BUDGET_RTOL):
        raise ScheduleError(
            f"a budget of {budget:g} channel units per period cannot pay for the least counts "
            f"{list(lo)} of the sensors (they need {need:g})"
        )
    if hi is not None:
        bad = [i for i in range(m.n_sensors) if hi[i] < lo[i]]
        if bad:
            raise ScheduleError(
                f"sensor {bad[0]}: its cap r_max allows {hi[bad[0]]} samples per period, fewer "
                f"than its least count {lo[bad[0]]}"
            )
    return ScheduleLimits(float(budget), lo, hi, costs)
