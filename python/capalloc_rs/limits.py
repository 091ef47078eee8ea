"""Work limits: how large a problem the package accepts before refusing it up front, and the
default budgets of the long searches.

Every limit is a module-level constant read at call time, so it can be raised (or lowered) for a
session::

    import capalloc_rs.limits
    capalloc_rs.limits.MAX_STATE_DIMENSION = 20_000

Refusals raise :class:`capalloc_rs.errors.InvalidInputError` naming the limit and how to raise it.
The Rust core has hard ceilings of its own above these defaults (``MAX_SLOTS_PER_PERIOD`` in
``capalloc::sampled``), which guard it against absurd sizes whatever the Python settings.

The Python side (model files, sweep specs, Monte Carlo, sweeps) checks its limits before reading
or allocating anything: a typo or a hostile file gives an error message at once instead of an
hour of work, a MemoryError or a hang. Model files raise
:class:`~capalloc_rs.errors.ModelFormatError`, sweep specs :class:`~capalloc_rs.errors.SweepError`.
"""

from __future__ import annotations

import math

from .errors import InvalidInputError, ScheduleError

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
    "min_slots",
    "MAX_MODEL_FILE_BYTES",
    "MAX_MODEL_STATES",
    "MAX_MODEL_ARRAY_ELEMENTS",
    "MAX_MODEL_ELEMENTS",
    "MAX_NPZ_MEMBERS",
    "MAX_NESTING",
    "MAX_ARRAYS",
    "MAX_NUMBER_CHARS",
    "MAX_INTEGER",
    "MAX_MONTE_CARLO_STEPS",
    "MAX_MONTE_CARLO_ELEMENTS",
    "MAX_INTEGER_ALLOCATION_SLOTS",
    "MAX_SWEEP_TASKS",
    "MAX_SWEEP_WORKERS",
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
        digits = str(value)
        # Scientific notation from the digits: float() overflows for integers beyond 1e308.
        shown = f"{digits[0]}.{digits[1:3]}e{len(digits) - 1}" if value >= 10**15 else digits
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
    except OverflowError:  # an int beyond float range: more seconds than a float holds
        raise InvalidInputError(
            f"time_limit is too large for a float number of seconds, got {time_limit!r:.40}"
        ) from None
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"time_limit must be a number of seconds or None, got {time_limit!r}"
        ) from None
    if math.isnan(t) or t <= 0:
        raise InvalidInputError(f"time_limit must be positive seconds or None, got {time_limit!r}")
    return t


# -- Python side: model files, sweep specs, Monte Carlo, sweeps ---------------------------------

#: Largest TOML/JSON model or sweep-spec file read (bytes).
MAX_MODEL_FILE_BYTES = 256 * 2**20

#: Largest state dimension ``n`` (and any other array dimension) of a model file, and of
#: ``N·n`` for the random networks of a sweep spec. Checked on the declared shapes (the ``.npy``
#: headers of an ``.npz``) before any data are read.
MAX_MODEL_STATES = 2000

#: Most elements of one array of a model file (declared shape, before reading).
MAX_MODEL_ARRAY_ELEMENTS = MAX_MODEL_STATES * MAX_MODEL_STATES

#: Most elements of all arrays of a model file together (declared shapes, before reading); also
#: bounds the uncompressed size of an ``.npz`` (8 bytes per element plus headers), read from the
#: zip directory before anything is decompressed.
MAX_MODEL_ELEMENTS = 4 * MAX_MODEL_STATES * MAX_MODEL_STATES

#: Most members of an ``.npz`` model archive.
MAX_NPZ_MEMBERS = 10_000

#: Deepest nesting of arrays/tables in a TOML or JSON file (the schemas need at most 5).
MAX_NESTING = 64

#: Most arrays and tables (``[`` and ``{``, counted in the text) of a TOML or JSON file; a model
#: has a few per matrix row.
MAX_ARRAYS = 10**6

#: Longest number literal in a TOML or JSON file (characters).
MAX_NUMBER_CHARS = 100

#: Largest magnitude of an integer in a TOML or JSON file (a float64 holds integers exactly up to
#: 2⁵³; this bound only keeps numbers convertible).
MAX_INTEGER = 2**63

#: Most simulated steps ``runs × periods × slots per period`` of one Monte Carlo call.
MAX_MONTE_CARLO_STEPS = 10**9

#: Most state values held at once by one Monte Carlo call, ``runs × (n + slots per period)``
#: (each is 8 bytes, and a few arrays of this size are alive at a time).
MAX_MONTE_CARLO_ELEMENTS = 5 * 10**7

#: Largest ``r_tot`` of :func:`~capalloc_rs.integer_allocation` (slots).
MAX_INTEGER_ALLOCATION_SLOTS = 10**9

#: Most tasks (networks × capacities) of one sweep.
MAX_SWEEP_TASKS = 10**8

#: Most local worker processes of one sweep.
MAX_SWEEP_WORKERS = 1024


def min_slots(r_min: float) -> int:
    """The least integer number of slots per period that satisfies a rate bound ``r ≥ r_min``:
    ``⌈r_min⌉`` (with a relative tolerance of 1e-12, so that ``r_min = 1.0000000000001`` still
    means 1). The one rule for slot counts, shared by schedules and integer allocations.

    Raises:
        ScheduleError: ``r_min`` is not a finite number ``≥ 0``.
    """
    if not isinstance(r_min, int | float) or not math.isfinite(r_min) or r_min < 0:
        raise ScheduleError(f"r_min must be finite and >= 0, got {r_min}")
    return max(0, math.ceil(r_min * (1 - 1e-12)))
