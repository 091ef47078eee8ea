"""``capalloc schedule`` and ``simulate``: the best periodic schedule at a finite period τ, and a
Monte Carlo check of a schedule's error against the predicted ``η̄(τ, R)``.

With sample costs in the model file (per-sensor ``cost``, ``r_min``, ``r_max``), ``--budget B``
is the channel units per period (``--r-tot`` is the paper's case, unit costs). ``simulate
--time-limit`` bounds the whole command: the schedule search of ``--r-tot`` gets what is
left of the budget, then the Monte Carlo what is left after it.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from typing import Any

from ..errors import InvalidInputError
from ..network import Network
from ..sampled import MonteCarloResult, Schedule, best_schedule, sampled_cost, simulate
from .output import load, print_json, print_mc, print_schedule
from .values import int_arg, parse_slots

__all__ = ["run_schedule", "run_simulate"]

#: The shortest budget handed to an API call when the command's time is (nearly) used up: the
#: call then stops at its first check (``best_schedule`` after its starting candidates).
_SPENT = 1e-9


def _progress(args: argparse.Namespace) -> bool | None:
    return False if args.no_progress else None


def _search_budget(args: argparse.Namespace, net: Network) -> int | float:
    """The budget of the search: ``--r-tot`` slots, or ``--budget`` channel units (a whole number
    of slots when every sample costs one unit, as ``--r-tot``)."""
    if args.budget is None:
        return int_arg("--r-tot", args.r_tot)
    if all(float(b) == 1.0 for b in net.costs):
        return int_arg("--budget (with unit sample costs, slots per period)", args.budget)
    return float(args.budget)


def run_schedule(args: argparse.Namespace) -> int:
    """``capalloc schedule MODEL --tau T (--r-tot R | --budget B)``."""
    net = load(args.model)
    best = best_schedule(
        net,
        args.tau,
        _search_budget(args, net),
        which=args.which,
        check=not args.no_check,
        max_moves=args.max_moves,
        time_limit=args.time_limit,
        progress=_progress(args),
    )
    if args.json:
        print_json(best.to_dict())
    else:
        print(f"best schedule for {args.model}")
        print_schedule(best)
    return 0


def _stop_note(search_stopped: bool, mc: MonteCarloResult | None) -> str | None:
    """The one ``stopped early (time_limit)`` line of ``simulate``, or ``None`` if it completed."""
    if mc is None:
        return (
            "stopped early (time_limit) in the schedule search: the best schedule found so far, "
            "no Monte Carlo run (raise --time-limit)"
        )
    if mc.stopped != "completed":
        return (
            f"stopped early (time_limit): Monte Carlo over {mc.periods_completed} of "
            f"{mc.periods} periods (raise --time-limit to simulate them all)"
        )
    if search_stopped:
        return (
            "stopped early (time_limit) in the schedule search: the Monte Carlo is of the best "
            "schedule found so far, not a local minimum (raise --time-limit)"
        )
    return None


def _schedule_to_simulate(
    args: argparse.Namespace, net: Network, remaining: Callable[[], float | None]
) -> tuple[Schedule, str, bool, float | None]:
    """``(schedule, "given" or "best", whether the search stopped on the time limit, the channel
    budget of the period or None for what the schedule uses)``."""
    if args.schedule is not None:
        budget = None if args.budget is None else float(args.budget)
        return Schedule(parse_slots(args.schedule), net.num_sensors), "given", False, budget
    if args.r_tot is None and args.budget is None:
        raise InvalidInputError("give --r-tot, --budget or --schedule")
    if args.r_tot is not None and args.budget is not None:
        raise InvalidInputError("give --r-tot or --budget for the schedule search, not both")
    search = _search_budget(args, net)
    best = best_schedule(
        net,
        args.tau,
        search,
        which=args.which,
        check=not args.no_check,
        time_limit=remaining(),
        progress=_progress(args),
    )
    budget = None if isinstance(search, int) else float(search)
    return best.schedule, "best", best.stopped == "time_limit", budget


def _json_result(
    args: argparse.Namespace,
    sched: Schedule,
    source: str,
    cost: float,
    mc: MonteCarloResult | None,
    note: str | None,
) -> dict[str, Any]:
    d: dict[str, Any] = (
        mc.to_dict()
        if mc is not None
        else {"mse": None, "ci": [None, None], "predicted_in_ci": False, "runs": args.runs,
              "periods": args.periods, "periods_completed": 0, "seed": args.seed}
    )  # fmt: skip
    d.update(
        {
            "tau": args.tau,
            "schedule": list(int(i) for i in sched),
            "source": source,
            "which": args.which,
            "eta_bar": cost,
            "converged": note is None,
            "stopped": "completed" if note is None else "time_limit",
        }
    )
    return d


def _print_result(
    args: argparse.Namespace,
    sched: Schedule,
    source: str,
    cost: float,
    mc: MonteCarloResult | None,
    note: str | None,
) -> None:
    print(
        f"Monte Carlo check for {args.model}: τ = {args.tau:g}, {source} schedule "
        f"{list(int(i) for i in sched)}"
    )
    print(f"  η̄(τ, R) ({args.which}) = {cost:.10g}")
    if mc is not None:
        print_mc(mc)
    print(f"  converged: {note is None}")
    if note is not None:
        print(f"  {note}")


def run_simulate(args: argparse.Namespace) -> int:
    """``capalloc simulate MODEL --tau T (--r-tot R | --schedule …)``."""
    started = time.monotonic()
    deadline = math.inf if args.time_limit is None else started + args.time_limit

    def remaining() -> float | None:
        if args.time_limit is None:
            return None
        return max(deadline - time.monotonic(), _SPENT)

    net = load(args.model)
    sched, source, search_stopped, budget = _schedule_to_simulate(args, net, remaining)
    cost = sampled_cost(net, args.tau, sched, args.which, check=not args.no_check, budget=budget)
    mc = None
    if not (search_stopped and time.monotonic() >= deadline):
        mc = simulate(
            net,
            args.tau,
            sched,
            args.periods,
            args.seed,
            runs=args.runs,
            which=args.which,
            check=not args.no_check,
            time_limit=remaining(),
            progress=_progress(args),
            budget=budget,
        )
    note = _stop_note(search_stopped, mc)
    if args.json:
        print_json(_json_result(args, sched, source, cost, mc, note))
    else:
        _print_result(args, sched, source, cost, mc, note)
    return 0
