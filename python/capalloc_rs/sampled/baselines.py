"""The starting schedules of the search and the literature's baselines.

* :func:`round_robin_schedule` — uniform allocation: counts as equal as possible, cyclic order.
* :func:`greedy_schedule` — greedy sensor scheduling: each slot takes the sensor whose measurement
  most reduces the trace of the posterior covariance, run to a periodic steady state.
* :func:`initial_counts` — slot counts from the fast-sampling problem (the optimal integer
  allocation of ``η(r)``), rounded to ``r_tot`` slots; the search evenly interleaves them.
* :func:`rounded_counts` — the optimal real allocation rounded by largest remainders (the cheap
  start of the screened search).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import numpy.typing as npt

from .._arrays import as_count, as_real, numerical_errors
from ..allocation import integer_allocation, optimal_allocation
from ..errors import ConvergenceError, InvalidInputError, NumericalError, ScheduleError
from ..limits import check_limit, min_slots
from ..network import Network, accepts_path
from .channel import ScheduleLimits, schedule_limits
from .schedule import Schedule
from .system import SampledSystem, Which, _check_tau, sampled_covariance, sampled_system

__all__ = [
    "round_robin_schedule",
    "greedy_schedule",
    "initial_counts",
    "rounded_counts",
    "budget_counts",
]


_NO_CAP = 10**10000


def _check_r_tot(m: SampledSystem, r_tot: int | float) -> int | float:
    """``r_tot`` as the budget: a slot count for unit costs (the paper's ``r_tot``), any positive
    number of channel units ``B`` with sample costs; checked against the sensors' minima."""
    if m.costs is not None:
        b = as_real("r_tot (the budget in channel units)", r_tot, positive=True)
        schedule_limits(m, b)
        return b
    if m.rate_min is not None:
        r = as_count("r_tot", r_tot, maximum=_NO_CAP)
        check_limit("r_tot (slots per period)", r, "MAX_SLOTS_PER_PERIOD")
        schedule_limits(m, r)
        return r
    # Integral floats (8.0) too, the rule of every slot count; no cap here, so that check_limit
    # below names the limit (capalloc_rs.limits.MAX_SLOTS_PER_PERIOD) however large r_tot is.
    r = as_count("r_tot", r_tot, maximum=_NO_CAP)
    check_limit("r_tot (slots per period)", r, "MAX_SLOTS_PER_PERIOD")
    need = m.n_sensors * min_slots(m.r_min)
    if r < max(1, need):
        raise ScheduleError(
            f"r_tot = {r} slots cannot give each of the {m.n_sensors} sensors its "
            f"{min_slots(m.r_min)} slot(s) (r_min = {m.r_min}): need r_tot >= {max(1, need)}"
        )
    return r


@accepts_path
def round_robin_schedule(net: Any, r_tot: int | float) -> Schedule:
    """Uniform allocation: every sensor gets ``⌊r_tot/N⌋`` slots (the first ``r_tot mod N`` one
    more), in cyclic order ``0, 1, …, N−1, 0, …`` (:meth:`~capalloc_rs.Schedule.round_robin`).

    With sample costs, rate minima or caps (``r_tot`` is then the budget ``B`` in channel
    units): every sensor starts at its least count, then the sensors take one more sample each
    in turn ``0, 1, …, N−1, 0, …`` while it fits in the budget and under their cap (a sensor
    that no longer fits is skipped); the counts are evenly interleaved."""
    m = sampled_system(net)
    r = _check_r_tot(m, r_tot)
    lim = schedule_limits(m, r)
    if lim.plain:
        return Schedule.round_robin(m.n_sensors, int(r))
    hi = lim.hi or (2**62,) * m.n_sensors
    counts = _fill_in_turn(list(lim.lo), m.sample_costs, hi, lim)
    return Schedule.from_counts(counts, "interleaved")


@accepts_path
@numerical_errors
def greedy_schedule(
    net: Any,
    tau: float,
    r_tot: int | float,
    *,
    which: Which = "boundary",
    max_rounds: int = 50,
    deadline: float = math.inf,
) -> Schedule:
    """The greedy sensor-scheduling heuristic, run to a periodic steady state.

    One *pass* builds a period slot by slot from a posterior covariance ``Σ``: slot ``l`` predicts
    ``P = E Σ Eᵀ + H`` and takes the sensor ``i`` that minimises ``tr φ_i(Σ)``, i.e. maximises the
    trace reduction ``tr(P c̄_i (I + c̄_iᵀ P c̄_i)⁻¹ c̄_iᵀ P)`` (ties: lowest index), except that
    sensors still owed slots under ``r_min`` are forced once the remaining slots are exactly those
    owed. The first pass starts from the boundary covariance of round robin's steady state; each
    next pass starts from the boundary covariance of the previous pass's schedule's periodic steady
    state, until a schedule repeats (a periodic steady state of the heuristic) or ``max_rounds``
    passes, or once ``time.monotonic()`` passes ``deadline`` (after at least one pass). Returns
    the best schedule (exact cost under ``which``) among the passes.

    With sample costs, per-sensor minima or caps, ``r_tot`` is the budget ``B`` in channel units:
    a pass takes samples while one fits in the budget left, choosing the largest (weighted) trace
    reduction *per channel unit* among the sensors below their cap that fit (sensors owed samples
    under their minimum are kept payable), and the rest of the period is idle
    (``capalloc::sampled::search::greedy_pass_limits``).
    """
    m = sampled_system(net)
    t = _check_tau(tau)
    r = _check_r_tot(m, r_tot)
    rounds = as_count("max_rounds", max_rounds, minimum=1)
    return greedy_run(m, t, r, which, rounds, deadline)[0]


def greedy_run(
    m: SampledSystem, t: float, r: int | float, which: Which, max_rounds: int, deadline: float
) -> tuple[Schedule, float, float]:
    """:func:`greedy_schedule` after its checks, with the exact costs it computed on the way:
    ``(schedule, its cost, round robin's cost)`` under ``which`` (``inf``: no periodic steady
    state; the schedule's cost is ``inf`` too when no pass had one)."""
    need = min_slots(m.r_min)
    lim = schedule_limits(m, r)
    kw = lim.core_kwargs()
    budget = kw.pop("budget", None)
    rr = round_robin_schedule(m, r)
    try:
        rr_cov = sampled_covariance(m, t, rr, check=False, budget=budget)
        sigma, rr_cost = rr_cov.boundary, rr_cov.eta(which)
    except ConvergenceError:  # round robin has no steady state: the first pass starts from I
        sigma, rr_cost = np.eye(m.n), math.inf
    seen: set[Schedule] = set()
    best: tuple[float, Schedule] | None = None
    for k in range(max_rounds):
        if k > 0 and time.monotonic() >= deadline:
            break
        greedy = m.core.greedy_pass(t, r, np.asarray(sigma), need, **kw)
        s = Schedule(greedy.slots, m.n_sensors)
        if s in seen:
            break
        seen.add(s)
        try:
            cov = sampled_covariance(m, t, s, check=False, budget=budget)
        except ConvergenceError:  # this pass's schedule has no steady state: no next pass
            break
        cost = cov.eta(which)
        if best is None or cost < best[0]:
            best = (cost, s)
        sigma = cov.boundary
    if best is None:
        return s, math.inf, rr_cost
    return best[1], best[0], rr_cost


def _continuous_floor(net: Any, m: SampledSystem, lim: ScheduleLimits) -> tuple[list[int], str]:
    """The continuous optimum of a :class:`~capalloc_rs.Network` at the budget
    (:func:`~capalloc_rs.optimal_allocation`) rounded down, within the count limits, when that
    fits in the budget; else the least counts."""
    if isinstance(net, Network):
        try:
            x = np.asarray(optimal_allocation(net, float(lim.budget)).r, dtype=np.float64)
        except (InvalidInputError, NumericalError):
            x = None  # no usable optimum: from the least counts
        if x is not None and x.shape == (m.n_sensors,) and np.all(np.isfinite(x)):
            c = np.floor(x * (1 + 1e-12)).astype(np.int64)
            c = np.maximum(c, np.asarray(lim.lo))
            if lim.hi is not None:
                c = np.minimum(c, np.asarray(lim.hi))
            if lim.fits(c):
                return [int(v) for v in c], "allocation.optimal_allocation rounded down, then"
    return list(lim.lo), "from the least counts,"


def budget_counts(
    net: Any, m: SampledSystem, lim: ScheduleLimits, *, deadline: float = math.inf
) -> tuple[list[int], str]:
    """Starting counts with sample costs, rate minima or caps: the continuous optimum at the
    budget rounded down (for a :class:`~capalloc_rs.Network` with a usable optimum; else the
    least counts), then each further sample goes to the sensor whose extra sample lowers
    ``η = net.cost`` most per channel unit, among those that fit in the budget and under their
    cap (``N`` cost evaluations per sample; a zero count is evaluated at the rate 1e-9, ``η``
    needing positive rates). Without ``net.cost``, or when ``η`` cannot be evaluated, or once
    ``deadline`` has passed, the rest of the budget is filled in turn as by
    :func:`round_robin_schedule`.

    Returns:
        ``(counts, rule)``.
    """
    b = m.sample_costs
    hi = lim.hi or (2**62,) * m.n_sensors
    counts, rule = _continuous_floor(net, m, lim)
    cost = getattr(net, "cost", None)
    steps = int(lim.budget / float(np.min(b))) + 1
    for _ in range(steps):
        fit = [
            i
            for i in range(m.n_sensors)
            if counts[i] < hi[i] and lim.used(counts) + b[i] <= lim.budget * (1 + 1e-12)
        ]
        if not fit:
            break
        gains = None if time.monotonic() >= deadline else _unit_gains(cost, counts, fit, b)
        if gains is None:
            return _fill_in_turn(counts, b, hi, lim), f"{rule} filled in turn"
        counts[fit[int(np.argmax(gains))]] += 1
    return counts, f"{rule} marginal greedy per channel unit on net.cost"


def _unit_gains(cost: Any, counts: list[int], fit: list[int], b: Any) -> list[float] | None:
    """The decrease of ``η`` per channel unit of one more sample of each sensor of ``fit``
    (``None`` without ``net.cost`` or when ``η`` cannot be evaluated)."""
    if not callable(cost):
        return None
    try:
        base = np.maximum(np.asarray(counts, dtype=np.float64), 1e-9)
        here = float(cost(base))
        gains = []
        for i in fit:
            c = base.copy()
            c[i] = counts[i] + 1
            gains.append((here - float(cost(c))) / float(b[i]))
    except (InvalidInputError, NumericalError):
        return None
    return gains


def _fill_in_turn(counts: list[int], b: Any, hi: Any, lim: ScheduleLimits) -> list[int]:
    """``counts`` with one more sample per sensor in turn while it fits and is under its cap."""
    out = list(counts)
    left = lim.budget * (1 + 1e-12) - lim.used(out)
    while True:  # each pass adds a sample or stops: at most budget / min(b) + 1 passes
        added = False
        for i in range(len(out)):
            if b[i] <= left and out[i] < hi[i]:
                out[i] += 1
                left -= b[i]
                added = True
        if not added:
            return out


def _largest_remainder(x: npt.NDArray[np.float64], r_tot: int, lo: int) -> list[int]:
    """Rounds nonnegative ``x`` (``Σx = r_tot``) to integers ``≥ lo`` with the same sum."""
    base = np.maximum(np.floor(x).astype(np.int64), lo)
    rest = r_tot - int(base.sum())
    order = np.argsort(-(x - np.floor(x)), kind="stable")
    k = 0
    while rest > 0:
        base[order[k % len(order)]] += 1
        rest -= 1
        k += 1
    while rest < 0:
        for i in np.argsort(x - base, kind="stable"):
            if base[i] > lo:
                base[i] -= 1
                rest += 1
                break
        else:  # every count is at lo: no rounding reaches r_tot (bounded, never spins)
            raise ScheduleError(
                f"cannot round the allocation to r_tot = {r_tot} slots with at least {lo} each"
            )
    return [int(v) for v in base]


@accepts_path
def initial_counts(net: Any, r_tot: int, *, deadline: float = math.inf) -> tuple[list[int], str]:
    """Starting counts for :func:`~capalloc_rs.best_schedule` and the rule that produced them.

    1. for a :class:`~capalloc_rs.Network`, ``capalloc_rs.integer_allocation(net, r_tot)`` (the
       optimal integer allocation of the fast-sampling problem) when it has one: not when
       ``r_tot`` is outside its domain or ``η`` cannot be evaluated accurately at some counts;
    2. otherwise, if the network has ``cost(r)`` (``η``), the marginal-greedy allocation: start
       from ``⌈r_min⌉`` slots each and give each further slot to the sensor whose extra slot lowers
       ``η`` most (``N`` cost evaluations per slot; optimal for separable convex η, a good start
       otherwise — the exact local search that follows does not depend on it for its guarantees);
    3. otherwise round robin.

    ``deadline`` (a ``time.monotonic()`` value) cuts rules 1 and 2 short once passed (their
    counts are then feasible but less refined). With sample costs, per-sensor minima or caps
    (``r_tot`` is then the budget ``B`` in channel units): :func:`budget_counts`.
    """
    m = sampled_system(net)
    r = _slot_count(net, m, r_tot, deadline)
    if not isinstance(r, int):
        return r
    lo = min_slots(m.r_min)
    if isinstance(net, Network):
        counts = _allocation_counts(net, m, r, lo, deadline)
        if counts is not None:
            return counts, "allocation.integer_allocation"
    cost = getattr(net, "cost", None)
    if callable(cost):
        counts = [lo] * m.n_sensors
        for _ in range(r - sum(counts)):
            if time.monotonic() >= deadline:
                counts[int(np.argmin(counts))] += 1  # out of time: fill evenly
                continue
            trial = []
            for i in range(m.n_sensors):
                c = np.asarray(counts, dtype=np.float64)
                c[i] += 1
                trial.append(float(cost(c)))
            i = int(np.argmin(trial))
            counts[i] += 1
        return counts, "marginal greedy on net.cost"
    return [int(v) for v in Schedule.round_robin(m.n_sensors, r).counts], "round robin"


@accepts_path
def rounded_counts(net: Any, r_tot: int, *, deadline: float = math.inf) -> tuple[list[int], str]:
    """Starting counts of the screened :func:`~capalloc_rs.best_schedule`: for a
    :class:`~capalloc_rs.Network`, ``capalloc_rs.optimal_allocation(net, r_tot)`` (the optimal real
    allocation of the fast-sampling problem, one Newton solve) rounded to ``r_tot`` by largest
    remainders, at least ``⌈r_min⌉`` each; otherwise, or when it has no usable optimum,
    :func:`initial_counts`. The schedule search moves slots between sensors, so the rounding need
    not be the optimal integer allocation.

    With sample costs, per-sensor minima or caps (``r_tot`` is then the budget ``B`` in channel
    units): :func:`budget_counts`.

    Returns:
        ``(counts, rule)``: the counts and ``"allocation.optimal_allocation rounded"`` or the rule
        of :func:`initial_counts`.
    """
    m = sampled_system(net)
    r = _slot_count(net, m, r_tot, deadline)
    if not isinstance(r, int):
        return r
    lo = min_slots(m.r_min)
    if isinstance(net, Network) and r >= m.n_sensors * max(lo, 1):
        try:
            alloc = optimal_allocation(net, float(r))
        except (InvalidInputError, NumericalError):
            # No usable optimum (η cannot be evaluated accurately somewhere on the way): the
            # integer rules below.
            alloc = None
        x = None if alloc is None else np.asarray(alloc.r, dtype=np.float64)
        if x is not None and x.shape == (m.n_sensors,) and np.all(np.isfinite(x)):
            x = np.maximum(x, 0.0)
            return _largest_remainder(
                x * (r / x.sum()), r, lo
            ), "allocation.optimal_allocation rounded"
    return initial_counts(net, r, deadline=deadline)


def _slot_count(
    net: Any, m: SampledSystem, r_tot: Any, deadline: float
) -> int | tuple[list[int], str]:
    """``r_tot`` as a slot count in the paper's case; otherwise (sample costs, per-sensor minima
    or caps) the counts of :func:`budget_counts` for the budget ``r_tot``."""
    r = _check_r_tot(m, r_tot)
    lim = schedule_limits(m, r)
    if not lim.plain:
        return budget_counts(net, m, lim, deadline=deadline)
    return int(r)


def _allocation_counts(
    net: Network, m: SampledSystem, r: int, lo: int, deadline: float
) -> list[int] | None:
    """The counts of :func:`~capalloc_rs.integer_allocation`, rounded to ``r`` slots of at least
    ``lo`` each; ``None`` when the fast-sampling problem has no usable integer allocation."""
    try:
        alloc = integer_allocation(net, r, deadline=None if math.isinf(deadline) else deadline)
    except (InvalidInputError, NumericalError):
        # No usable integer allocation. InvalidInputError: r_tot is outside integer_allocation's
        # domain (η needs a slot for every sensor, a schedule does not: r_tot < N·max(1, ⌈r_min⌉);
        # or r_tot > limits.MAX_INTEGER_ALLOCATION_SLOTS) — the inputs themselves were checked
        # above. NumericalError: η(r) could not be evaluated accurately at some counts.
        return None
    counts = np.asarray(alloc.counts, dtype=np.float64)
    if counts.shape != (m.n_sensors,) or not np.all(np.isfinite(counts)) or np.any(counts < lo):
        return None
    return _largest_remainder(counts * (r / counts.sum()), r, lo)
