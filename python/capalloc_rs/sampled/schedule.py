"""Periodic schedules: which sensor sends in each of the ``r_tot`` slots of a period.

A :class:`Schedule` is the paper's allocation strategy ``R``: a periodic sequence
``R_1, …, R_{r_tot}`` of sensor indices (0-based here). Its counts ``r_i = #{l : R_l = i}`` are
the rates of the fast-sampling problem (slots per period); see :mod:`capalloc_rs.sampled.system`
for the scaling that makes this exact.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal, overload

import numpy as np
import numpy.typing as npt

from .. import limits
from .._json import ints
from ..errors import ScheduleError
from ..limits import check_limit, min_slots

__all__ = ["Schedule", "Order", "min_slots"]  # min_slots: from capalloc_rs.limits

Order = Literal["interleaved", "blocked"]

I64 = npt.NDArray[np.int64]


def _as_index(name: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise ScheduleError(f"{name} must be an integer sensor index, got {v!r}")
    return int(v)


def _check_slots(r_tot: int) -> None:
    limits.check_limit("r_tot (slots per period)", r_tot, "MAX_SLOTS_PER_PERIOD")


def _check_sensors(n: int) -> None:
    limits.check_limit("n_sensors", n, "MAX_SENSORS")


@dataclass(frozen=True, init=False)
class Schedule:
    """A periodic schedule: ``slots[l]`` is the sensor that sends in slot ``l`` of every period.

    Attributes:
        slots: the sensor index of each slot, ``0 ≤ slots[l] < n_sensors``.
        n_sensors: the number of sensors ``N`` of the network (sensors may have no slot).

    Schedules are immutable and hashable; two schedules are equal when their slots and ``N`` are.
    """

    slots: tuple[int, ...]
    n_sensors: int

    def __init__(self, slots: Sequence[int] | npt.ArrayLike, n_sensors: int | None = None):
        try:
            raw = np.asarray(slots)
        except (TypeError, ValueError, OverflowError):
            raise ScheduleError(
                "a schedule is a non-empty 1-D sequence of sensor indices, got a ragged or "
                f"non-numeric {type(slots).__name__}"
            ) from None
        if raw.ndim != 1 or raw.size == 0:
            raise ScheduleError(
                f"a schedule is a non-empty 1-D sequence of sensor indices, got shape {raw.shape}"
            )
        check_limit("r_tot (the schedule's length)", int(raw.size), "MAX_SLOTS_PER_PERIOD")
        if raw.dtype.kind not in "iu":
            seq = [_as_index(f"slot {pos}", v) for pos, v in enumerate(raw.tolist())]
        else:
            seq = [int(v) for v in raw.tolist()]
        bad = [(pos, i) for pos, i in enumerate(seq) if i < 0]
        if bad:
            raise ScheduleError(f"slot {bad[0][0]} names sensor {bad[0][1]}: indices must be >= 0")
        n = max(seq) + 1 if n_sensors is None else _as_index("n_sensors", n_sensors)
        if n < 1:
            raise ScheduleError(f"n_sensors must be >= 1, got {n}")
        _check_sensors(n)
        out = [(pos, i) for pos, i in enumerate(seq) if i >= n]
        if out:
            pos, i = out[0]
            raise ScheduleError(
                f"slot {pos} names sensor {i}, but there are only {n} sensors (indices 0..{n - 1})"
            )
        object.__setattr__(self, "slots", tuple(seq))
        object.__setattr__(self, "n_sensors", n)

    # -- construction -------------------------------------------------------------------------

    @classmethod
    def from_counts(
        cls, counts: Sequence[int] | npt.ArrayLike, order: Order = "interleaved"
    ) -> Schedule:
        """The schedule with ``counts[i]`` slots for sensor ``i`` in the given order.

        * ``"interleaved"``: each sensor's slots spread as evenly as possible over the period. The
          ``k``-th slot of sensor ``i`` (``k = 0, …, r_i − 1``) has the ideal position
          ``(k + ½)·r_tot / r_i``; slots are sorted by ideal position (ties: lower sensor index
          first). Consecutive slots of sensor ``i`` are then ``r_tot/r_i`` apart up to ±1, and equal
          counts give round-robin ``0, 1, …, N−1, 0, 1, …``.
        * ``"blocked"``: all slots of sensor 0, then all of sensor 1, and so on.
        """
        try:
            c = np.asarray(counts)
        except (TypeError, ValueError, OverflowError):
            raise ScheduleError(
                f"counts must be a non-empty 1-D sequence of integers, got {type(counts).__name__}"
            ) from None
        if c.ndim != 1 or c.size == 0:
            raise ScheduleError(f"counts must be a non-empty 1-D sequence, got shape {c.shape}")
        cs = [
            _as_index(f"counts[{i}]", v) if c.dtype.kind not in "iu" else int(v)
            for i, v in enumerate(c.tolist())
        ]
        if any(v < 0 for v in cs):
            raise ScheduleError(f"counts must be >= 0, got {cs}")
        r_tot = sum(cs)
        if r_tot == 0:
            raise ScheduleError("counts must sum to at least one slot")
        _check_slots(r_tot)
        if not isinstance(order, str) or order not in ("blocked", "interleaved"):
            raise ScheduleError(f"order must be 'interleaved' or 'blocked', got {order!r}")
        if order == "blocked":
            slots = [i for i, ri in enumerate(cs) for _ in range(ri)]
        elif order == "interleaved":
            keys = [((k + 0.5) * r_tot / ri, i) for i, ri in enumerate(cs) for k in range(ri)]
            keys.sort()
            slots = [i for _, i in keys]
        else:
            raise ScheduleError(f"order must be 'interleaved' or 'blocked', got {order!r}")
        return cls(slots, n_sensors=len(cs))

    @classmethod
    def round_robin(cls, n_sensors: int, r_tot: int) -> Schedule:
        """Round robin: counts as equal as possible (the first ``r_tot mod N`` sensors get one slot
        more), evenly interleaved — ``0, 1, …, N−1, 0, 1, …`` when ``N`` divides ``r_tot``."""
        n = _as_index("n_sensors", n_sensors)
        r = _as_index("r_tot", r_tot)
        if n < 1 or r < 1:
            raise ScheduleError(f"need n_sensors >= 1 and r_tot >= 1, got {n} and {r}")
        _check_slots(r)
        _check_sensors(n)
        counts = [r // n + (1 if i < r % n else 0) for i in range(n)]
        return cls.from_counts(counts, "interleaved")

    # -- views --------------------------------------------------------------------------------

    @property
    def r_tot(self) -> int:
        """Slots per period."""
        return len(self.slots)

    @property
    def counts(self) -> I64:
        """``r_i``: the number of slots of each sensor (length ``n_sensors``; a fresh array)."""
        return np.bincount(np.asarray(self.slots, dtype=np.int64), minlength=self.n_sensors).astype(
            np.int64
        )

    def as_array(self) -> I64:
        """The slots as a fresh int64 array."""
        return np.asarray(self.slots, dtype=np.int64)

    def rotated(self, k: int) -> Schedule:
        """The same cyclic sequence started at slot ``k``: ``R_{k}, …, R_{r_tot−1}, R_0, …``."""
        k = _as_index("k", k) % self.r_tot
        return Schedule(self.slots[k:] + self.slots[:k], self.n_sensors)

    def budget_used(self, costs: Any = None) -> float:
        """``Σ_l b_{R_l}``: the channel units per period the schedule uses when a sample of sensor
        ``i`` costs ``costs[i]`` (``None``: unit costs, the number of slots ``r_tot``).

        Raises:
            ScheduleError: ``costs`` is not one positive finite number per sensor.
        """
        if costs is None:
            return float(self.r_tot)
        b = self._costs(costs)
        return float(sum(b[i] for i in self.slots))

    def _costs(self, costs: Any) -> npt.NDArray[np.float64]:
        try:
            b = np.asarray(costs, dtype=np.float64)
        except (TypeError, ValueError):
            raise ScheduleError(f"costs must be numbers, got {costs!r}") from None
        if b.ndim == 0:
            b = np.full(self.n_sensors, float(b))
        if b.shape != (self.n_sensors,) or not np.all(np.isfinite(b) & (b > 0)):
            raise ScheduleError(
                f"costs must be {self.n_sensors} positive finite numbers (one per sensor), "
                f"got {costs!r}"
            )
        return b

    def validate(
        self,
        n_sensors: int,
        r_min: Any = 0.0,
        *,
        costs: Any = None,
        budget: float | None = None,
        r_max: Any = None,
    ) -> None:
        """Checks the schedule against a network with ``n_sensors`` sensors and rate bound
        ``r_min``: the number of sensors matches and every sensor has at least ``⌈r_min⌉`` slots
        (``r_min`` a number, or one per sensor). Optionally, every sensor has at most
        ``⌊r_max,i⌋`` slots (``r_max``: one number per sensor, ``inf`` for no cap) and the
        schedule uses at most ``budget`` channel units with sample costs ``costs``
        (:meth:`budget_used`; relative tolerance 1e-12).

        Raises:
            ScheduleError: naming the unknown index, the starved or capped sensor, or the
                budget exceeded.
        """
        if self.n_sensors != n_sensors:
            bad = [i for i in self.slots if i >= n_sensors]
            if bad:
                raise ScheduleError(
                    f"the schedule names sensor {bad[0]}, but the network has {n_sensors} sensors "
                    f"(indices 0..{n_sensors - 1})"
                )
            raise ScheduleError(
                f"the schedule is for {self.n_sensors} sensors, the network has {n_sensors}"
            )
        counts = self.counts
        if np.ndim(r_min) == 0:
            self._check_minima(counts, [r_min] * n_sensors)
        else:
            self._check_minima(counts, [float(v) for v in np.asarray(r_min).ravel()])
        if r_max is not None:
            self._check_caps(counts, np.asarray(r_max, dtype=np.float64).ravel())
        if budget is not None:
            used = self.budget_used(costs)
            if used > float(budget) * (1 + 1e-12):
                raise ScheduleError(
                    f"the schedule uses {used:g} channel units per period, more than the budget "
                    f"{float(budget):g}"
                )

    def _check_minima(self, counts: I64, r_min: list[Any]) -> None:
        if len(r_min) != self.n_sensors:
            raise ScheduleError(f"r_min must have one entry per sensor ({self.n_sensors})")
        need = [min_slots(float(v)) for v in r_min]
        starved = [i for i in range(self.n_sensors) if counts[i] < need[i]]
        if starved:
            i = starved[0]
            shown = r_min[i] if len(set(need)) > 1 else r_min[0]
            raise ScheduleError(
                f"sensor {i} is starved: it has {int(counts[i])} slot(s) per period but r_min = "
                f"{shown} requires at least {need[i]} (starved sensors: {starved})"
            )

    def _check_caps(self, counts: I64, r_max: npt.NDArray[np.float64]) -> None:
        if r_max.shape != (self.n_sensors,):
            raise ScheduleError(f"r_max must have one entry per sensor ({self.n_sensors})")
        over = [
            i
            for i in range(self.n_sensors)
            if math.isfinite(r_max[i]) and counts[i] > math.floor(r_max[i] * (1 + 1e-12))
        ]
        if over:
            i = over[0]
            raise ScheduleError(
                f"sensor {i} has {int(counts[i])} slot(s) per period but r_max = {r_max[i]:g} "
                f"allows at most {math.floor(r_max[i] * (1 + 1e-12))} (capped sensors: {over})"
            )

    # -- sequence protocol --------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self.slots)

    def __iter__(self) -> Iterator[int]:
        return iter(self.slots)

    @overload
    def __getitem__(self, k: int) -> int: ...
    @overload
    def __getitem__(self, k: slice) -> tuple[int, ...]: ...
    def __getitem__(self, k: int | slice) -> int | tuple[int, ...]:
        return self.slots[k]

    def to_dict(self) -> dict[str, Any]:
        """The schedule as plain JSON-ready values.

        Returns:
            ``{"slots": [int, …], "n_sensors": int, "r_tot": int, "counts": [int, …]}``.
        """
        return {
            "slots": list(self.slots),
            "n_sensors": self.n_sensors,
            "r_tot": self.r_tot,
            "counts": ints(self.counts),
        }

    def __repr__(self) -> str:
        body = ", ".join(map(str, self.slots[:20])) + (", …" if self.r_tot > 20 else "")
        return f"Schedule([{body}], n_sensors={self.n_sensors}, r_tot={self.r_tot})"
