"""The sampled system at a finite period τ: schedules, their exact periodic steady state, the
search for the best schedule and its Monte Carlo validation.

Modules (lowest first):

* :mod:`~capalloc_rs.sampled.schedule` — :class:`Schedule`, the periodic sequence of sensors.
* :mod:`~capalloc_rs.sampled.channel` — the network seen by the channel (:class:`SampledSystem`):
  sample costs, count limits, error weight, and the feasibility of counts against a budget.
* :mod:`~capalloc_rs.sampled.system` — the discretised system (:class:`SampledSystem`, over the
  Rust ``_core.SampledModel``), Proposition 1's existence check, the periodic steady state
  ``Σ(∞; τ, R)`` and its cost ``η̄(τ, R)``.
* :mod:`~capalloc_rs.sampled.baselines` — round robin, greedy sensor scheduling and the initial
  counts from the fast-sampling allocation.
* :mod:`~capalloc_rs.sampled.exhaustive` — the exhaustive best-improvement local search (the
  reference ``method="exhaustive"``).
* :mod:`~capalloc_rs.sampled.screened` — the screened local search (moves ranked by the
  first-order sensitivity of ``η̄``; the default).
* :mod:`~capalloc_rs.sampled.relaxation` — proven lower bounds on ``η̄`` over every schedule
  (slot maps relaxed to maps ``⪯`` them; monotonicity of the Riccati maps).
* :mod:`~capalloc_rs.sampled.grouped` — the tighter grouped bound (key sensors, a knapsack).
* :mod:`~capalloc_rs.sampled.exact` — the branch-and-bound that proves a schedule optimal;
  :mod:`~capalloc_rs.sampled.exact_grid` — the same for unequal sample costs (cost grid).
* :mod:`~capalloc_rs.sampled.best_result` — :class:`BestSchedule` and :class:`Candidate`.
* :mod:`~capalloc_rs.sampled.search` — :func:`best_schedule`, exact local search (and the
  ``"exact"`` method and the certificate).
* :mod:`~capalloc_rs.sampled.montecarlo` — :func:`simulate`, the periodic Kalman filter's MSE.
"""

from __future__ import annotations

from .baselines import (
    budget_counts,
    greedy_schedule,
    initial_counts,
    round_robin_schedule,
    rounded_counts,
)
from .channel import ScheduleLimits, schedule_limits
from .montecarlo import MonteCarloResult, simulate
from .schedule import Schedule
from .search import BestSchedule, Candidate, best_schedule
from .system import (
    Discretisation,
    SampledCovariance,
    SampledSystem,
    Which,
    check_existence,
    discretise,
    fixed_point_iteration,
    period_triplet,
    propagate,
    sampled_cost,
    sampled_covariance,
    sampled_system,
)

__all__ = [
    "Schedule",
    "SampledSystem",
    "sampled_system",
    "Which",
    "Discretisation",
    "SampledCovariance",
    "check_existence",
    "discretise",
    "period_triplet",
    "sampled_cost",
    "sampled_covariance",
    "propagate",
    "fixed_point_iteration",
    "round_robin_schedule",
    "greedy_schedule",
    "initial_counts",
    "rounded_counts",
    "budget_counts",
    "ScheduleLimits",
    "schedule_limits",
    "Candidate",
    "BestSchedule",
    "best_schedule",
    "MonteCarloResult",
    "simulate",
]
