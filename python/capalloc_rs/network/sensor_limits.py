"""Per-sensor sample costs, rate minima and rate caps — the constraint set of the allocation.

Sensor ``i``'s samples cost ``b_i > 0`` channel units each (different packet sizes); its rate is
bounded by ``r_min,i ≤ r_i ≤ r_max,i`` (``0 ≤ r_min,i < r_max,i ≤ ∞``: a least rate and a hardware
sampling limit; ``r_min,i = 0`` lets a sensor be switched off, provided the sensors with a
positive minimum detect the state, so that ``η`` is finite on the whole feasible set), and a budget
``B`` of channel units per unit time is shared:

    Σ_i b_i r_i = B,    r_min,i ≤ r_i ≤ r_max,i.

The feasible budgets are ``Σ b_i r_min,i ≤ B ≤ Σ b_i r_max,i``. The paper's case is ``b_i = 1``, one
common ``r_min`` and no caps; then ``B`` is the total capacity ``r_tot``.

**Channel units.** With ``s_i = b_i r_i`` (channel units per unit time spent on sensor ``i``) the
information rate is ``W = Σ_i r_i ĉ_i ĉ_iᵀ = Σ_i s_i (ĉ_i/√b_i)(ĉ_i/√b_i)ᵀ``: a network with
costs is, in the variable ``s``, the network with unit costs and sensors ``ĉ_i/√b_i`` on the
box-simplex ``{b∘r_min ≤ s ≤ b∘r_max, Σ s_i = B}``. Gradients map as ``∂η/∂r_i = b_i ∂η/∂s_i``
and Hessians as ``∇²_r η = diag(b) ∇²_s η diag(b)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._arrays import F64, as_float_array, as_real
from ..errors import FeatureUnavailableError, InvalidInputError, ShapeError
from .cost import BlockStructure
from .diagnostics import PBH_RTOL, fmt_mode, pbh_margin

__all__ = [
    "SensorLimits",
    "SensorLimitsView",
    "channel_sensors",
    "check_zero_minima",
    "require_paper_form",
]


def _per_sensor(
    name: str,
    x: Any,
    count: int,
    default: float,
    *,
    finite: bool = True,
    positive: bool = True,
    nonnegative: bool = False,
) -> F64:
    """A per-sensor property given as ``None`` (``default``), a scalar or one value per sensor,
    as a read-only array of ``count`` floats; errors name ``name`` (and the entry)."""
    if x is None:
        vals = [default] * count
    elif (
        isinstance(x, str | bytes)
        or not isinstance(x, Sequence | np.ndarray)
        or (isinstance(x, np.ndarray) and x.ndim == 0)
    ):
        vals = [as_real(name, x, finite=finite, positive=positive, nonnegative=nonnegative)] * count
    elif len(x) != count:
        raise ShapeError(
            f"{name} must be a scalar or have one entry per sensor ({count}), got {x!r:.80}"
        )
    else:
        vals = [
            as_real(f"{name}[{k}]", v, finite=finite, positive=positive, nonnegative=nonnegative)
            for k, v in enumerate(x)
        ]
    out = np.array(vals, dtype=np.float64)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class SensorLimits:
    """The sample costs ``b`` and rate bounds ``[r_min, r_max]`` of ``N`` sensors (read-only
    arrays of length ``N``; ``r_max`` is ``inf`` where a sensor has no cap)."""

    costs: F64
    rate_min: F64
    rate_max: F64

    @classmethod
    def of(cls, count: int, costs: Any = None, r_min: Any = 1.0, r_max: Any = None) -> SensorLimits:
        """Validated limits of ``count`` sensors from scalars or per-sensor sequences.

        Raises:
            ShapeError: a sequence of the wrong length.
            NonFiniteError, InvalidInputError: a cost that is not a finite positive number, a
                minimum that is negative or not finite, a cap not above its sensor's minimum (the
                message names the argument and the sensor).
        """
        b = _per_sensor("costs", costs, count, 1.0)
        lo = _per_sensor(
            "r_min", 1.0 if r_min is None else r_min, count, 1.0, positive=False, nonnegative=True
        )
        hi = _per_sensor("r_max", r_max, count, math.inf, finite=False)
        for i in range(count):
            if not hi[i] > lo[i]:
                raise InvalidInputError(
                    f"r_max[{i}] = {hi[i]:g} must exceed the sensor's minimum r_min[{i}] = "
                    f"{lo[i]:g}"
                )
        return cls(b, lo, hi)

    @property
    def is_paper_form(self) -> bool:
        """Every cost 1, one common positive minimum, no finite cap (the paper's problem)."""
        return bool(
            np.all(self.costs == 1.0)
            and self.rate_min[0] > 0.0
            and np.all(self.rate_min == self.rate_min[0])
            and np.all(np.isinf(self.rate_max))
        )

    @property
    def common_min(self) -> float | None:
        """The minimum shared by every sensor, ``None`` if they differ."""
        r0 = float(self.rate_min[0])
        return r0 if np.all(self.rate_min == r0) else None

    @property
    def report_rate(self) -> float:
        """The rate at which :meth:`Network.check <capalloc_rs.Network.check>` solves each
        subsystem's own Riccati equation (its answers do not depend on it): the smallest positive
        minimum, 1 if every minimum is 0."""
        pos = self.rate_min[self.rate_min > 0.0]
        return float(pos.min()) if pos.size else 1.0

    def budget_of(self, rates: F64) -> float:
        """``Σ_i b_i r_i``: the channel units per unit time that ``rates`` use."""
        return float(self.costs @ rates)

    @property
    def budget_range(self) -> tuple[float, float]:
        """``(Σ b_i r_min,i, Σ b_i r_max,i)``: the feasible budgets (the upper may be ``inf``)."""
        return float(self.costs @ self.rate_min), float(self.costs @ self.rate_max)

    def in_channel_units(self) -> SensorLimits:
        """The limits of ``s = b ∘ r``: unit costs, bounds ``b ∘ r_min`` and ``b ∘ r_max``."""
        return SensorLimits.of(
            self.costs.size, None, self.costs * self.rate_min, self.costs * self.rate_max
        )

    def report_fields(self, a: F64, sensors: Sequence[F64]) -> dict[str, Any]:
        """The fields of :class:`~capalloc_rs.network.NetworkReport` about the limits: the
        feasible budgets (not in the paper's problem) and the detectability margin without the
        sensors whose minimum is 0 (with such sensors)."""
        off = _off_margin(a, sensors, self)
        return {
            "budget_range": None if self.is_paper_form else self.budget_range,
            "detectability_without_off_sensors": None if off is None else off[0],
        }

    def key(self) -> bytes:
        """Bytes identifying the limits (for hashing a network)."""
        arrays = (self.costs, self.rate_min, self.rate_max)
        return b"".join(np.ascontiguousarray(x).tobytes() for x in arrays)

    def equal(self, other: SensorLimits) -> bool:
        """Whether the two limits have the same data."""
        return all(
            np.array_equal(x, y)
            for x, y in zip(
                (self.costs, self.rate_min, self.rate_max),
                (other.costs, other.rate_min, other.rate_max),
                strict=True,
            )
        )

    def describe(self) -> str:
        """A short description for reprs: ``r_min=1`` in the paper's case, else the vectors."""
        if self.is_paper_form:
            return f"r_min={self.rate_min[0]:g}"
        parts = []
        if not np.all(self.costs == 1.0):
            parts.append(f"costs={_short(self.costs)}")
        common = self.common_min
        lows = f"{common:g}" if common is not None else _short(self.rate_min)
        parts.append(f"r_min={lows}")
        if not np.all(np.isinf(self.rate_max)):
            parts.append(f"r_max={_short(self.rate_max)}")
        return ", ".join(parts)


def _short(x: F64) -> str:
    body = ", ".join(f"{v:g}" for v in x[:4])
    return f"[{body}{', …' if x.size > 4 else ''}]"


class SensorLimitsView:
    """The sensor properties of a network (a mixin of :class:`capalloc_rs.Network`, which holds
    them as ``_limits``)."""

    __slots__ = ()
    _limits: SensorLimits

    @property
    def costs(self) -> F64:
        """The sample costs ``b_i > 0`` in channel units (read-only, length ``N``; all 1 in the
        paper's problem): the budget is ``B = Σ b_i r_i``."""
        return self._limits.costs

    @property
    def rate_min(self) -> F64:
        """The minimum rates ``r_min,i ≥ 0`` (read-only, length ``N``)."""
        return self._limits.rate_min

    @property
    def rate_max(self) -> F64:
        """The rate caps ``r_max,i`` (read-only, length ``N``; ``inf`` where there is none)."""
        return self._limits.rate_max

    @property
    def r_min(self) -> Any:
        """The minimum rate: a float when every sensor has the same (the paper's ``r_min``, rates
        ``r = γ + r_min``), else the array :attr:`rate_min`."""
        common = self._limits.common_min
        return self._limits.rate_min if common is None else common

    @property
    def is_paper_form(self) -> bool:
        """Whether the constraints are the paper's: every cost 1, one common positive minimum, no
        cap."""
        return self._limits.is_paper_form

    @property
    def budget_range(self) -> tuple[float, float]:
        """The feasible budgets ``(Σ b_i r_min,i, Σ b_i r_max,i)`` (the upper may be ``inf``)."""
        return self._limits.budget_range

    def budget_of(self, rates: Any) -> float:
        """``Σ_i b_i r_i``: the channel units per unit time the rates use.

        Raises:
            ShapeError: ``rates`` is not a vector of length ``N``.
        """
        r = as_float_array("rates", rates, 1)
        if r.size != self._limits.costs.size:
            raise ShapeError(f"rates must have length {self._limits.costs.size}, got {r.size}")
        return self._limits.budget_of(r)

    def rates_from_gamma(self, gamma: Any) -> F64:
        """The rates ``r = γ + r_min`` (the paper's parametrisation)."""
        g = as_float_array("gamma", gamma, 1)
        common = self._limits.common_min
        if common is not None:
            out: F64 = g + common
            return out
        if g.size != self._limits.rate_min.size:
            raise ShapeError(f"gamma must have length {self._limits.rate_min.size}, got {g.size}")
        out = g + self._limits.rate_min
        return out


def channel_sensors(
    sensors: Sequence[F64], structure: BlockStructure | None, costs: F64
) -> tuple[list[F64], BlockStructure | None]:
    """The sensors ``ĉ_i/√b_i`` of the channel-units network (and its block structure's ``c_i``)."""
    root = np.sqrt(costs)
    scaled = [c / ri for c, ri in zip(sensors, root, strict=True)]
    if structure is None:
        return scaled, None
    blocks = tuple(c / ri for c, ri in zip(structure.c_blocks, root, strict=True))
    st = BlockStructure(
        structure.a_blocks, structure.g_blocks, blocks, structure.coupling, structure.eps
    )
    return scaled, st


def require_paper_form(net: Any, what: str) -> None:
    """Refuses (:class:`~capalloc_rs.errors.FeatureUnavailableError`) a network with sample costs,
    per-sensor minima or caps for a method ``what`` that solves only the paper's problem — never
    silently ignoring the constraints."""
    if not getattr(net, "is_paper_form", True):
        raise FeatureUnavailableError(
            f"{what} does not support sample costs, per-sensor minima or rate caps yet "
            "(the network has them)"
        )


def _off_margin(a: F64, sensors: Sequence[F64], limits: SensorLimits) -> tuple[float, Any] | None:
    """The PBH detectability margin (and weakest mode) of the sensors with a positive minimum,
    ``None`` when no minimum is zero."""
    keep = [c for c, lo in zip(sensors, limits.rate_min, strict=True) if lo > 0.0]
    if len(keep) == len(sensors):
        return None
    c = np.hstack(keep) if keep else np.zeros((a.shape[0], 1))
    return pbh_margin(a, c, unstable_only=True)


def check_zero_minima(a: F64, sensors: Sequence[F64], limits: SensorLimits) -> None:
    """With some minima ``r_min,i = 0``, the sensors with a positive minimum must detect the state
    on their own: then ``Σ(r)`` exists at every feasible ``r`` (more rate never hurts), including
    where the others are switched off.

    Raises:
        InvalidInputError: naming ``r_min`` and the mode those sensors cannot see.
    """
    found = _off_margin(a, sensors, limits)
    if found is None:
        return
    if not np.any(limits.rate_min > 0.0):
        raise InvalidInputError(
            "r_min: every minimum is 0; at least one sensor needs a positive minimum (with every "
            "sensor off there is no measurement at all)"
        )
    margin, lam = found
    if margin <= PBH_RTOL:
        raise InvalidInputError(
            f"r_min: with the zero minima, the sensors with a positive minimum must detect the "
            f"state on their own (else the error is infinite when the others are off), but the "
            f"mode λ = {fmt_mode(lam)} (Re λ ≥ 0) is seen by none of them; give some of the "
            "sensors that see it a positive minimum"
        )
