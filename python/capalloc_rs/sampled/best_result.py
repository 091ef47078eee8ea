"""The results of :func:`~capalloc_rs.best_schedule`: each starting :class:`Candidate` and the
:class:`BestSchedule` with its certificate (a proven lower bound on ``η̄`` over every schedule,
:mod:`capalloc_rs.sampled.relaxation`, :mod:`capalloc_rs.sampled.grouped` and
:mod:`capalloc_rs.sampled.exact`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from .._json import ints, plain
from .schedule import Schedule

__all__ = ["Candidate", "BestSchedule"]


@dataclass(frozen=True)
class Candidate:
    """A schedule and its exact finite-τ cost (``inf`` if its steady state does not exist)."""

    name: str
    schedule: Schedule
    eta_bar: float

    def to_dict(self) -> dict[str, Any]:
        """``{"name", "schedule" (the slots), "eta_bar"}`` as plain JSON-ready values."""
        out: dict[str, Any] = plain(
            {"name": self.name, "schedule": self.schedule.slots, "eta_bar": self.eta_bar}
        )
        return out

    def __repr__(self) -> str:
        return f"Candidate({self.name!r}, r_tot={self.schedule.r_tot}, eta_bar={self.eta_bar:.6g})"


@dataclass(frozen=True)
class BestSchedule:
    """The result of :func:`best_schedule`.

    Attributes:
        schedule: the best schedule found.
        eta_bar: its exact cost ``η̄(τ, R)`` under ``which``.
        eta_limit: ``η(counts)``, the fast-sampling cost of its counts (``net.cost``; ``nan`` if the
            network has no ``cost`` method) — what the τ → 0 theory predicts for these counts.
        counts: the schedule's counts.
        which: ``"boundary"`` or ``"average"`` (see :mod:`capalloc_rs.sampled`).
        tau: the period.
        start: the name of the candidate the local search started from.
        candidates: every starting candidate by name (``"initial"``, ``"round_robin"``,
            ``"greedy"``) with its exact cost.
        moves: improving moves applied by the local search (a shift of several slots and a
            displacement step of the default screened search count as one each).
        evaluations: schedules whose exact cost was computed: the starting candidates, every
            neighbour costed by the search (no-op and starving moves, and neighbours skipped
            after ``time_limit``, are not counted) and every extra move verified.
        converged: ``True`` if the search stopped at a local minimum (no improving move), ``False``
            if it hit ``max_moves`` or ``time_limit``.
        stopped: why the search stopped: ``"local_minimum"``, ``"max_moves"``,
            ``"time_limit"``, (screened methods without confirmation) ``"screened_minimum"``:
            no move predicted to improve did, and the exhaustive neighbourhood was not costed,
            or (default ``method="screened"`` above ``screened.DISPLACE_NEIGHBOURS``
            neighbours) ``"stalled"``: the last ``screened.STALL_SCREENS`` screens together
            lowered ``η̄`` by less than ``screened.STALL_RTOL`` (relative). Except at
            ``"local_minimum"``, ``schedule`` is the best found so far, at most as costly as
            every starting candidate.
        elapsed: wall-clock seconds spent.
        budget: the channel units per period the search had, ``B`` (``r_tot`` for unit costs).
        budget_used: ``Σ_l b_{R_l}`` of the schedule (``≤ budget``; the rest is idle time).
        lower_bound: a proven lower bound on ``η̄`` (``which``) over *every* schedule with the
            budget and the count limits (:mod:`capalloc_rs.sampled.relaxation` and
            :mod:`capalloc_rs.sampled.grouped`; with ``method="exact"`` also the
            branch-and-bound's, :mod:`capalloc_rs.sampled.exact`,
            :mod:`capalloc_rs.sampled.exact_grid`);
            ``nan`` when none was computed (``certify=False``, or a cost grid too fine).
        gap: ``eta_bar − lower_bound`` (``≥ 0``): no schedule is better than ``eta_bar`` by more.
        proven_optimal: ``True`` when the schedule is proven optimal (the exact search exhausted
            its tree, or the bound meets ``eta_bar``).
        nodes: nodes bounded by the exact search (0 for the local searches).
    """

    schedule: Schedule
    eta_bar: float
    eta_limit: float
    counts: tuple[int, ...]
    which: str
    tau: float
    start: str
    candidates: Mapping[str, Candidate] = field(repr=False)
    moves: int
    evaluations: int
    converged: bool
    stopped: str = "local_minimum"
    elapsed: float = 0.0
    budget: float = math.nan
    budget_used: float = math.nan
    lower_bound: float = math.nan
    gap: float = math.nan
    proven_optimal: bool = False
    nodes: int = 0

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (non-finite numbers as ``None``): the keys of the
        CLI's ``--json`` — ``r_tot``, ``error_vs_limit`` (``eta_bar − eta_limit``),
        ``relative_error_vs_limit`` (divided by ``eta_limit``) and ``baselines`` (each
        candidate's ``eta_bar`` by name) included — plus ``start`` and ``elapsed``.

        Returns:
            ``{"tau", "r_tot", "schedule", "counts", "which", "eta_bar", "eta_limit",
            "error_vs_limit", "relative_error_vs_limit", "converged", "stopped", "moves",
            "evaluations", "baselines", "budget", "budget_used", "start", "elapsed",
            "lower_bound", "gap", "proven_optimal", "nodes"}``.
        """
        error = self.eta_bar - self.eta_limit
        out: dict[str, Any] = plain(
            {
                "tau": self.tau,
                "r_tot": self.schedule.r_tot,
                "schedule": list(self.schedule.slots),
                "counts": ints(self.counts),
                "which": self.which,
                "eta_bar": self.eta_bar,
                "eta_limit": self.eta_limit,
                "error_vs_limit": error,
                "relative_error_vs_limit": error / self.eta_limit if self.eta_limit else math.nan,
                "converged": self.converged,
                "stopped": self.stopped,
                "moves": self.moves,
                "evaluations": self.evaluations,
                "baselines": {k: c.eta_bar for k, c in self.candidates.items()},
                "budget": self.budget,
                "budget_used": self.budget_used,
                "start": self.start,
                "elapsed": self.elapsed,
                "lower_bound": self.lower_bound,
                "gap": self.gap,
                "proven_optimal": self.proven_optimal,
                "nodes": self.nodes,
            }
        )
        return out

    def __repr__(self) -> str:
        return (
            f"BestSchedule(tau={self.tau:g}, r_tot={self.schedule.r_tot}, "
            f"eta_bar={self.eta_bar:.6g}, eta_limit={self.eta_limit:.6g}, start={self.start!r}, "
            f"moves={self.moves}, stopped={self.stopped!r}, gap={self.gap:.3g})"
        )
