"""``capalloc solve --robust {mean,worst} MODEL1 MODEL2 …``: one allocation for a set of models
of the same sensors (:func:`~capalloc_rs.allocation.robust_allocation`), continuous with its proven
lower bound, or integer counts (``--integer``)."""

from __future__ import annotations

import argparse

import numpy as np

from .._json import ints
from ..allocation import robust_allocation, robust_integer_allocation
from ..errors import InvalidInputError
from .output import print_json

__all__ = ["run_robust"]


def _vec(x: object) -> str:
    return "[" + ", ".join(f"{float(v):.6g}" for v in np.asarray(x).ravel()) + "]"


def _weights(text: str | None) -> list[float] | None:
    """``--weights 1,2,3`` as numbers (checked further by the API)."""
    if text is None:
        return None
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InvalidInputError(
            f"--weights must be comma-separated numbers, one per model, got {text!r}"
        ) from None


def _check(args: argparse.Namespace) -> None:
    if args.method is not None or args.hessian != "auto":
        raise InvalidInputError(
            "--method and --hessian choose the single-model solver: they do not apply to --robust"
        )
    for flag, value in (("--time-limit", args.time_limit), ("--max-nodes", args.max_nodes)):
        if value is not None:
            raise InvalidInputError(f"{flag} applies to single-model --integer: not to --robust")
    if args.weights is not None and args.robust != "mean":
        raise InvalidInputError("--weights applies to --robust mean")


def run_robust(args: argparse.Namespace) -> int:
    """``capalloc solve --robust OBJECTIVE MODEL… --r-tot B [--weights W…] [--integer]``."""
    _check(args)
    weights = _weights(args.weights)
    if args.integer:
        ia = robust_integer_allocation(
            args.model, args.r_tot, objective=args.robust, weights=weights
        )
        if args.json:
            print_json({"r_tot": args.r_tot, **ia.to_dict()})
        else:
            print(
                f"robust ({args.robust}) integer allocation over {len(args.model)} models for "
                f"the budget {args.r_tot:g}: counts {ints(ia.counts)}, value {ia.value:.10g}, "
                f"proven lower bound {ia.lower_bound:.10g} (greedy and exchanges: not claimed "
                "optimal)"
            )
        return 0
    a = robust_allocation(
        args.model, args.r_tot, objective=args.robust, weights=weights, tol=args.tol
    )
    if args.json:
        print_json(a.to_dict())
        return 0
    what = "mean Σ w_k η_k" if a.objective == "mean" else "worst case max_k η_k"
    print(f"robust allocation ({what}) over {a.num_models} models, budget {a.budget:g}")
    print(f"  r*            = {_vec(a.r)}")
    print(f"  value         = {a.value:.10g}")
    print(f"  η per model   = {_vec(a.eta_per_model)}")
    print(f"  weights       = {_vec(a.weights)}")
    print(f"  lower bound   = {a.lower_bound:.10g}   gap = {a.gap:.3g} (proven)")
    print(f"  μ = {a.mu:.6g}   shadow price −μ = {a.shadow_price:.6g}   ({a.iterations} steps)")
    return 0
