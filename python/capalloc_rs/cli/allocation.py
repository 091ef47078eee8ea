"""``capalloc check``, ``solve`` and ``trace``: a network's assumptions, the optimal allocation at a
capacity (continuous with its KKT certificate, or integer slot counts) and the filtration."""

from __future__ import annotations

import argparse
from typing import Any

from .._json import ints
from ..allocation import IntegerAllocation, filtration, integer_allocation, optimal_allocation
from ..allocation.integer import INTEGER_METHODS
from ..errors import InvalidInputError
from .output import load, print_allocation, print_filtration, print_json, save_plot
from .robust import run_robust
from .values import int_arg

__all__ = ["run_check", "run_solve", "run_trace"]


def run_check(args: argparse.Namespace) -> int:
    """``capalloc check MODEL``."""
    rep = load(args.model).check()
    if args.json:
        print_json(rep.to_dict())
    else:
        print(rep)
    return 0


def _integer_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keywords of ``integer_allocation`` from ``--method``, ``--time-limit`` and
    ``--max-nodes`` (with ``--integer``)."""
    method = "greedy" if args.method is None else args.method
    if method not in INTEGER_METHODS:
        raise InvalidInputError(
            f"--method {method} is a continuous method: with --integer give --method greedy or "
            "--method branch-and-bound"
        )
    if args.max_nodes is not None and method != "branch-and-bound":
        raise InvalidInputError("--max-nodes applies to --integer --method branch-and-bound")
    return {"method": method, "time_limit": args.time_limit, "max_nodes": args.max_nodes}


def _proof(ia: IntegerAllocation) -> str:
    """The certificate part of the text output: the proven lower bound and gap, and why the
    search stopped early (if it did)."""
    text = (
        f"lower bound {ia.lower_bound:.10g}, gap {ia.gap:.3g}"
        f"{' (proven optimal)' if ia.proven_optimal else ''}"
    )
    if ia.stopped is not None:
        text += f"; stopped early ({ia.stopped}): the best counts found, with their proven gap"
    return text


def _solve_integer(args: argparse.Namespace) -> int:
    net = load(args.model)
    opts = _integer_options(args)
    if not net.is_paper_form:  # a budget B in channel units: any real number
        ia = integer_allocation(net, args.r_tot, **opts)
        if args.json:
            print_json({"r_tot": args.r_tot, **ia.to_dict()})
        else:
            print(
                f"integer allocation for the budget B = {args.r_tot:g}: counts "
                f"{ints(ia.counts)} spending {ia.spent:g}, η = {ia.eta:.10g} "
                f"({ia.method}, {ia.evaluations} evaluations)"
            )
            print(f"  {_proof(ia)}")
        return 0
    slots = int_arg("--r-tot", args.r_tot)
    ia = integer_allocation(net, slots, **opts)
    if args.json:
        print_json({"r_tot": slots, **ia.to_dict()})
    else:
        print(
            f"integer allocation for r_tot = {slots}: counts {ints(ia.counts)}, "
            f"η = {ia.eta:.10g} ({ia.method}, {ia.exchanges} exchanges, "
            f"{ia.evaluations} evaluations)"
        )
        print(f"  {_proof(ia)}")
    return 0


def _continuous_only(args: argparse.Namespace) -> Any:
    """The continuous ``--method`` (default newton); integer-only options refused."""
    if args.method in INTEGER_METHODS:
        raise InvalidInputError(f"--method {args.method} applies to --integer")
    for flag, value in (("--time-limit", args.time_limit), ("--max-nodes", args.max_nodes)):
        if value is not None:
            raise InvalidInputError(f"{flag} applies to --integer")
    return "newton" if args.method is None else args.method


def run_solve(args: argparse.Namespace) -> int:
    """``capalloc solve MODEL --r-tot R [--method M] [--integer [--time-limit S] [--max-nodes
    N]]``, or with ``--robust`` a set of models."""
    if args.robust is not None:
        return run_robust(args)
    if args.weights is not None:
        raise InvalidInputError("--weights applies to --robust mean")
    if len(args.model) > 1:
        raise InvalidInputError(
            f"{len(args.model)} model files: solving over a set of models needs "
            "--robust mean or --robust worst"
        )
    args.model = args.model[0]
    if args.integer:
        return _solve_integer(args)
    method = _continuous_only(args)
    net = load(args.model)
    a = optimal_allocation(net, args.r_tot, method=method, tol=args.tol, hessian=args.hessian)
    if args.json:
        print_json(a.to_dict())
    else:
        print(f"optimal allocation for {args.model}")
        print_allocation(a, limits=not net.is_paper_form)
    return 0


def run_trace(args: argparse.Namespace) -> int:
    """``capalloc trace MODEL --sigma-max S``."""
    if args.budget and not args.plot:
        raise InvalidInputError("--budget sets the plot's x-axis: it needs --plot FILE")
    net = load(args.model)
    f = filtration(
        net,
        args.sigma_max,
        tol=args.tol,
        max_nodes=args.max_nodes,
        time_limit=args.time_limit,
        progress=False if args.no_progress else None,
    )
    d = f.to_dict()
    if args.plot:
        save_plot(f, args.plot, rates=args.rates, log=args.log, budget=args.budget)
        d["plot"] = args.plot
    if args.json:
        print_json(d)
    else:
        print(f"filtration of {args.model}")
        print_filtration(f)
        if args.plot:
            print(f"  plot saved to {args.plot}")
    return 0
