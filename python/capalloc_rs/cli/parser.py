"""The ``capalloc`` argument parser: its subcommands, their options, and the option types.

Argument errors end as every other error does: one line ``capalloc: error: …`` (naming the
subcommand and pointing at its ``--help``) and exit status 2. Numbers are checked by their type
(positive and finite; slot counts may be written ``8.0``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any, NoReturn

from .._core import __version__
from ..allocation import HESSIAN_MODES, METHODS, OBJECTIVES
from ..allocation.integer import INTEGER_METHODS
from .allocation import run_check, run_solve, run_trace
from .demo import run_demo
from .errors import EXIT_ERROR, say
from .sampled import run_schedule, run_simulate
from .sweep import run_sweep

__all__ = ["Parser", "build_parser"]

_MODEL_HELP = "network file (.toml, .json, .npz)"


class Parser(argparse.ArgumentParser):
    """Argument errors as one line (``capalloc: error: …``) and exit status 2."""

    #: The last usage error (for the ``--json`` error object); shared by the subparsers.
    last_error: str | None = None

    def error(self, message: str) -> NoReturn:
        sub = self.prog.removeprefix("capalloc").strip()
        where = f"{sub}: " if sub else ""
        text = " ".join(f"{where}{message} (see {self.prog} --help)".split())
        Parser.last_error = text
        say(f"capalloc: error: {text}")
        raise SystemExit(EXIT_ERROR)


def _shown(s: str) -> str:
    r = repr(s)
    return r if len(r) <= 40 else f"{r[:30]}…' ({len(s)} characters)"


def _integral(s: str) -> int | None:
    """``int`` of a float literal with an integer value (``"400.0"``), else ``None``."""
    try:
        f = float(s)
    except ValueError:
        return None
    return int(f) if math.isfinite(f) and f.is_integer() else None


def _in_range(v: Any, zero: bool) -> bool:
    try:
        return math.isfinite(float(v)) and (v >= 0 if zero else v > 0)
    except OverflowError:  # an int too large for a float
        return False


def _positive(kind: type, zero: bool = False) -> Callable[[str], Any]:
    """An argparse type: a finite number ``> 0`` (``>= 0`` with ``zero``) of type ``kind``."""

    def parse(s: str) -> Any:
        try:
            v = kind(s)
        except ValueError:
            v = _integral(s) if kind is int else None  # "400.0" is a count, as in the API
        if v is None:
            what = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {what}, got {_shown(s)}") from None
        if not _in_range(v, zero):
            sign = "non-negative" if zero else "positive"
            raise argparse.ArgumentTypeError(f"must be {sign} and finite, got {_shown(s)}")
        return v

    parse.__name__ = kind.__name__
    return parse


_POS = _positive(float)
_POSINT = _positive(int)


def _budget_args(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--time-limit",
        type=_POS,
        metavar="SECONDS",
        help=f"stop {what} after SECONDS of wall time and report the best found so far "
        "(stopped: time_limit); default: no limit",
    )
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (shown on stderr by default when it is a terminal)",
    )


def _which_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--which",
        default="boundary",
        choices=["boundary", "average"],
        help="the figure η̄: error covariance at the period boundary (default) or its average "
        "over the slots",
    )


def _no_check_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--no-check",
        action="store_true",
        help="skip the check of Proposition 1 (used sensors observe A, τ does not alias two "
        "eigenvalues), like check=False in the API, with its warning",
    )


_Add = Callable[[str, str], argparse.ArgumentParser]


def _add_demo(add: _Add) -> None:
    p = add("demo", "the main job on a built-in network: allocation, filtration, schedule")
    p.add_argument("--r-tot", type=_POS, default=8.0, help="capacity (default 8)")
    p.add_argument("--sigma-max", type=_POS, default=12.0, help="end of the filtration (12)")
    p.add_argument("--tau", type=_POS, default=0.5, help="period of the schedule (0.5)")
    p.add_argument("--periods", type=_POSINT, default=400, help="Monte Carlo periods (400)")
    p.add_argument("--runs", type=_POSINT, default=64, help="Monte Carlo runs (64)")
    p.add_argument("--seed", type=int, default=0, help="Monte Carlo seed (0)")
    p.add_argument(
        "--plot",
        metavar="FILE",
        help="save the filtration plot to FILE (needs matplotlib); default: no plot, no file",
    )
    p.add_argument(
        "--no-plot",
        action="store_true",
        help="no plot (the default; kept for old scripts)",
    )
    p.set_defaults(func=run_demo)


def _add_check_and_solve(add: _Add) -> None:
    p = add("check", "check a network's assumptions (observability, detectability, regularity)")
    p.add_argument("model", help=_MODEL_HELP)
    p.set_defaults(func=run_check)

    p = add("solve", "optimal allocation at a capacity, with its KKT certificate")
    p.add_argument(
        "model",
        nargs="+",
        help=_MODEL_HELP + "; several with --robust (models of the same sensors)",
    )
    p.add_argument(
        "--r-tot",
        type=_POS,
        required=True,
        help="total capacity r_tot; for a model with sample costs or rate limits the budget "
        "B = Σ b_i r_i in channel units",
    )
    p.add_argument(
        "--method",
        choices=METHODS + INTEGER_METHODS,
        help="optimisation method (default newton: projected Newton with its KKT certificate); "
        "with --integer greedy (default: greedy plus exchanges) or branch-and-bound (proven "
        "optimal counts)",
    )
    p.add_argument(
        "--hessian",
        default="auto",
        choices=HESSIAN_MODES,
        help="Newton variant: exact Hessian, Newton–CG with Hessian-vector products, or by size",
    )
    p.add_argument("--tol", type=_POS, default=1e-12, help="relative certificate tolerance")
    p.add_argument("--integer", action="store_true", help="integer slot counts instead")
    p.add_argument(
        "--time-limit",
        type=_POS,
        metavar="SECONDS",
        help="with --integer: stop after SECONDS of wall time with the best counts found and "
        "their proven gap (stopped: time_limit); default: no limit",
    )
    p.add_argument(
        "--max-nodes",
        type=_POSINT,
        metavar="N",
        help="with --integer --method branch-and-bound: stop after N relaxations (default "
        "100000) with the best counts found and their proven gap (stopped: max_nodes)",
    )
    p.add_argument(
        "--robust",
        choices=OBJECTIVES,
        help="one allocation for all the models: minimise the mean or the worst-case error",
    )
    p.add_argument(
        "--weights",
        metavar="W1,W2,…",
        help="with --robust mean: one non-negative weight per model (default equal)",
    )
    p.set_defaults(func=run_solve)


def _add_trace(add: _Add) -> None:
    p = add("trace", "the filtration: optimal allocation for σ in [0, σ_max] and breakpoints")
    p.add_argument("model", help=_MODEL_HELP)
    p.add_argument(
        "--sigma-max",
        type=_POS,
        required=True,
        help="σ_max = r_tot,max − N·r_min (with sample costs or rate limits: "
        "B_max − Σ b_i r_min,i, at most Σ b_i (r_max,i − r_min,i))",
    )
    p.add_argument("--tol", type=_POS, default=1e-10, help="breakpoint tolerance (relative)")
    p.add_argument("--plot", metavar="FILE", help="save the filtration plot (needs matplotlib)")
    p.add_argument(
        "--rates", action="store_true", help="plot the rates r_i instead of γ_i = r_i − r_min"
    )
    p.add_argument(
        "--log",
        action="store_true",
        help="plot on a symmetric-log scale (one large share does not flatten the rest)",
    )
    p.add_argument(
        "--budget",
        action="store_true",
        help="plot against the budget r_tot = σ + N·r_min (B = σ + Σ b_i r_min,i with sample "
        "costs or rate limits) instead of σ (needs --plot)",
    )
    p.add_argument(
        "--max-nodes",
        type=_POSINT,
        metavar="N",
        help="stop after N path nodes (default capalloc_rs.limits.FILTRATION_MAX_NODES); "
        "the output then says stopped: max_nodes",
    )
    _budget_args(p, "the path following")
    p.set_defaults(func=run_trace)


def _add_schedule(add: _Add) -> None:
    p = add("schedule", "best periodic schedule at a finite period τ")
    p.add_argument("model", help=_MODEL_HELP)
    p.add_argument("--tau", type=_POS, required=True, help="period τ")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--r-tot", type=_POS, help="slots per period (unit sample costs)")
    g.add_argument(
        "--budget",
        type=_POS,
        metavar="B",
        help="channel units per period: a sample of sensor i costs its cost b_i from the model "
        "file (with unit costs the same as --r-tot)",
    )
    _which_arg(p)
    p.add_argument(
        "--max-moves",
        type=_positive(int, zero=True),
        metavar="N",
        help="stop the local search after N improving moves (default "
        "capalloc_rs.limits.BEST_SCHEDULE_MAX_MOVES); the output then says stopped: max_moves",
    )
    _no_check_arg(p)
    _budget_args(p, "the search")
    p.set_defaults(func=run_schedule)


def _add_simulate(add: _Add) -> None:
    p = add("simulate", "Monte Carlo check of a schedule's error against the prediction")
    p.add_argument("model", help=_MODEL_HELP)
    p.add_argument("--tau", type=_POS, required=True, help="period τ")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--r-tot", type=_POS, help="simulate the best schedule with this many slots")
    g.add_argument("--schedule", help="simulate this schedule: sensor indices, e.g. 0,1,0,2")
    p.add_argument(
        "--budget",
        type=_POS,
        metavar="B",
        help="channel units per period (sample costs from the model file): the best schedule "
        "of this budget (instead of --r-tot), or the budget of --schedule (default: what it uses; "
        "the rest of the period is idle)",
    )
    p.add_argument("--periods", type=_POSINT, default=400, help="periods per run (400)")
    p.add_argument("--runs", type=_POSINT, default=64, help="independent runs (64)")
    p.add_argument("--seed", type=int, default=0, help="random seed (0)")
    _which_arg(p)
    _no_check_arg(p)
    _budget_args(p, "the command (the schedule search of --r-tot, then the Monte Carlo)")
    p.set_defaults(func=run_simulate)


def _add_sweep(add: _Add) -> None:
    p = add("sweep", "run a sweep spec in parallel into a resumable Parquet dataset")
    p.add_argument("spec", help="sweep spec (.toml or .json; see examples/sweep.toml)")
    p.add_argument("--out", required=True, help="output directory (Parquet part-files)")
    m = p.add_mutually_exclusive_group()
    m.add_argument("--resume", action="store_true", help="continue the results in --out")
    m.add_argument("--overwrite", action="store_true", help="discard the results in --out")
    w = p.add_mutually_exclusive_group()
    w.add_argument("--workers", type=_POSINT, help="local worker processes (default: all cores)")
    w.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="dask.distributed scheduler, e.g. tcp://10.0.0.1:8786",
    )
    p.add_argument(
        "--connect-timeout",
        type=_POS,
        default=10.0,
        metavar="SECONDS",
        help="how long to wait for the --scheduler (10)",
    )
    p.add_argument("--chunk-size", type=_POSINT, help="tasks per chunk/part-file")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_sweep)


def build_parser() -> argparse.ArgumentParser:
    """The ``capalloc`` argument parser."""
    parser = Parser(
        prog="capalloc",
        description="Optimal capacity allocation for sampled networked systems.",
    )
    parser.add_argument("--version", action="version", version=f"capalloc {__version__}")
    sub = parser.add_subparsers(
        dest="command",
        required=True,
        parser_class=Parser,
        metavar="COMMAND",
        help="run 'capalloc COMMAND --help' for its options",
    )

    def add(name: str, help: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help)
        p.add_argument("--json", action="store_true", help="machine-readable output on stdout")
        return p

    for adder in (_add_demo, _add_check_and_solve, _add_trace, _add_schedule, _add_simulate):
        adder(add)
    _add_sweep(add)
    return parser
