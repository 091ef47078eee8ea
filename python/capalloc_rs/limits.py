"""Work limits: how large a problem the package accepts before refusing it up front, and the
default budgets of the long searches.

Every limit is a module-level constant read at call time, so it can be raised (or lowered) for a
session::

    import capalloc_rs.limits
    capalloc_rs.limits.MAX_STATE_DIMENSION = 20_000

Refusals raise :class:`capalloc_rs.errors.InvalidInputError` naming the limit and how to raise it.
The Rust core has hard ceilings of its own above these defaults (``MAX_SLOTS_PER_PERIOD`` in
``capalloc::sampled``), which guard it against absurd sizes whatever the Python settings.
"""

from __future__ import annotations

import math

from .errors import InvalidInputError

__all__ = [
    "MAX_STATE_DIMENSION",
    "MAX_SENSORS",
    "MAX_SLOTS_PER_PERIOD",
    "BEST_SCHEDULE_MAX_MOVES",
    "BEST_SCHEDULE_TIME_LIMIT",
    "FILTRATION_MAX_NODES",
    "FILTRATION_TIME_LIMIT",
    "check_limit",
    "check_time_limit",
]

#: Largest state dimension ``n`` of a network. Dense ``n × n`` matrices and ``O(n³)`` solves: at
#: ``n = 5000`` one matrix is 200 MB and one real Schur form takes minutes.
MAX_STATE_DIMENSION = 5000

#: Largest number of sensors ``N`` of a network (the Hessian is ``N × N`` and costs ``N`` Lyapunov
#: solves; the schedule search evaluates ``r_tot·N`` neighbours per move).
MAX_SENSORS = 5000

#: Largest number of slots per period ``r_tot`` of a sampled schedule (a schedule is a list of
#: ``r_tot`` sensor indices; the search composes ``2·r_tot`` triplets per neighbourhood).
MAX_SLOTS_PER_PERIOD = 100_000

#: Default move budget of :func:`capalloc_rs.best_schedule` (its ``max_moves``).
BEST_SCHEDULE_MAX_MOVES = 10_000

#: Default wall-clock budget in seconds of :func:`capalloc_rs.best_schedule` (its ``time_limit``;
#: ``None`` = no limit).
BEST_SCHEDULE_TIME_LIMIT: float | None = None

#: Default node budget of :func:`capalloc_rs.filtration` (its ``max_nodes``).
FILTRATION_MAX_NODES = 20_000

#: Default wall-clock budget in seconds of :func:`capalloc_rs.filtration` (its ``time_limit``;
#: ``None`` = no limit).
FILTRATION_TIME_LIMIT: float | None = None


def check_limit(what: str, value: int, limit_name: str) -> None:
    """Refuses ``value`` above the limit ``limit_name`` of this module (read now, so that a
    changed setting takes effect)."""
    limit = globals()[limit_name]
    if value > limit:
        shown = f"{float(value):.3g}" if value >= 10**15 else str(value)
        raise InvalidInputError(
            f"{what} = {shown} exceeds the limit {limit} (capalloc_rs.limits.{limit_name}); "
            f"raise that constant if you really mean it"
        )


def check_time_limit(time_limit: float | None) -> float | None:
    """``time_limit`` as positive seconds or ``None``; anything else is refused."""
    if time_limit is None:
        return None
    try:
        t = float(time_limit)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"time_limit must be a number of seconds or None, got {time_limit!r}"
        ) from None
    if math.isnan(t) or t <= 0:
        raise InvalidInputError(f"time_limit must be positive seconds or None, got {time_limit!r}")
    return t
