"""The ``capalloc`` command line.

Subcommands (``capalloc`` alone prints them, with status 0; ``capalloc COMMAND --help`` every
option, each with its help)::

    capalloc demo [--plot FILE] [--tau T]                    the main job on a built-in network
    capalloc check MODEL                                     the network's assumptions
    capalloc solve MODEL --r-tot R [--method M] [--hessian H] [--integer]  optimum + certificate
    capalloc trace MODEL --sigma-max S [--plot FILE [--rates] [--log]]  filtration, breakpoints
    capalloc schedule MODEL --tau T --r-tot R [--no-check]   best schedule at a finite period
    capalloc simulate MODEL --tau T (--r-tot R | --schedule 0,1,0,2) [--periods P] [--no-check]
    capalloc sweep SPEC --out DIR [--resume | --overwrite] [--workers K | --scheduler ADDRESS]

``--plot FILE`` needs matplotlib: without it the command fails (status 2) with the pip command; no
command writes a file that was not asked for. ``--no-check`` skips the check of Proposition 1 (as
``check=False`` does in the API) and says so in one line ``capalloc: warning: …`` on stderr. Slot
counts (``--r-tot`` of ``schedule``, ``simulate`` and ``solve --integer``) are integers (``8.0`` is
accepted); JSON output has integers for counts, slots, seeds and sensor indices.

MODEL is a network file (TOML, JSON or ``.npz``; see :mod:`capalloc_rs.model_io`), SPEC a sweep
spec (see :func:`capalloc_rs.sweep.load_spec`). Every subcommand takes ``--json`` for
machine-readable output on stdout. User mistakes (bad files, bad arguments, infeasible or
unsolvable problems) end with one line ``capalloc: error: …`` on stderr and exit status 2, never a
traceback (set ``CAPALLOC_TRACEBACK=1`` to see one); under ``--json`` the error is also printed on
stdout as ``{"error": {"type": …, "message": …}}``. An interrupted command (Ctrl-C) exits with
status 130 and one line; a closed stdout pipe (``capalloc demo | head -2``) ends quietly with
status 0. ``trace``, ``schedule`` and ``simulate`` take ``--time-limit SECONDS`` (for ``simulate``
the whole command: the schedule search of ``--r-tot`` and the Monte Carlo), ``trace`` and
``schedule`` also ``--max-nodes N`` / ``--max-moves N``; a budget that ends the work early is not an
error (exit status 0): the output says ``converged: False``, which budget ``stopped`` it, and one
``stopped early (…)`` line with what the result then is. They show progress on stderr when it is
a terminal (``--no-progress``: none).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn, cast

import numpy as np

from ._json import ints as _ints
from ._json import plain
from ._optional import require
from ._unchecked import UNCHECKED_MESSAGE
from .errors import CapallocError, InvalidInputError, SweepError, UncheckedExistenceWarning

__all__ = ["main", "build_parser", "demo_network"]

#: Exit status for user mistakes and numerical failures.
EXIT_ERROR = 2
#: Exit status after Ctrl-C (128 + SIGINT, as shells report it).
EXIT_INTERRUPTED = 130


# -- the built-in example -------------------------------------------------------------------


def demo_network() -> Any:
    """The demo's network: ``examples/three_subsystems.toml`` (three weakly coupled subsystems of
    sizes 2, 3, 1, ε = 0.1; subsystem 1's sensor has two outputs), embedded so that ``capalloc
    demo`` needs no file."""
    from .network import Network

    return Network.from_blocks(
        a_blocks=[
            [[0.0, 1.0], [-4.0, -0.4]],
            [[0.2, 1.0, 0.0], [0.0, -0.5, 1.0], [0.0, 0.0, -1.0]],
            [[-0.3]],
        ],
        g_blocks=[
            [[0.5, 0.0], [0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.3, 1.0, 0.0], [0.0, 0.3, 1.0]],
            [[2.0]],
        ],
        c_blocks=[[1.0, 0.0], [[1.0, 0.0], [0.0, 0.0], [0.0, 1.0]], [0.5]],
        couplings={
            (0, 1): [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
            (1, 2): [[0.0], [0.0], [1.0]],
            (2, 0): [[1.0, -1.0]],
        },
        eps=0.1,
        r_min=1.0,
    )


# -- output helpers -------------------------------------------------------------------------


def _print_json(obj: Any) -> None:
    print(json.dumps(plain(obj), indent=2, allow_nan=False))


def _vec(x: Any, fmt: str = "{:.6g}") -> str:
    return "[" + ", ".join(fmt.format(float(v)) for v in np.asarray(x).ravel()) + "]"


def _load(path: str) -> Any:
    from .network import Network

    return Network.load(path)


# -- pieces shared by the subcommands and the demo --------------------------------------------


def _allocation_dict(a: Any) -> dict[str, Any]:
    return {
        "r_tot": a.r_tot,
        "sigma": a.sigma,
        "r": a.r,
        "gamma": a.gamma,
        "eta": a.eta,
        "gradient": a.gradient,
        "mu": a.mu,
        "active": _ints(a.active),
        "certificate": {"frank_wolfe_gap": a.gap, "kkt_residual": a.kkt_residual},
        "iterations": a.iterations,
        "method": a.method,
        "hessian": a.hessian,
        "hessian_vector_products": a.hvp_count,
    }


def _method_name(a: Any) -> str:
    if a.hessian == "hvp":
        return f"{a.method}, Newton–CG with {a.hvp_count} Hessian-vector products"
    if a.hessian == "exact":
        return f"{a.method}, exact Hessian"
    return str(a.method)


def _print_allocation(a: Any) -> None:
    print(
        f"  r_tot = {a.r_tot:g}   σ = r_tot − N·r_min = {a.sigma:g}   ({_method_name(a)}, "
        f"{a.iterations} iterations)"
    )
    print(f"  r*            = {_vec(a.r)}")
    print(f"  η(r*)         = {a.eta:.10g}")
    print(f"  ∇η(r*)        = {_vec(a.gradient)}")
    print(f"  active set    = {_ints(a.active)}   μ = {a.mu:.6g}")
    print(
        f"  certificate   : Frank–Wolfe gap {a.gap:.2e} ≥ η(r) − η*,  "
        f"KKT residual {a.kkt_residual:.2e}"
    )


def _filtration_dict(f: Any) -> dict[str, Any]:
    return {
        "sigma_max": f.sigma_max,
        "breakpoints": f.breakpoints,
        "active_sets": [_ints(s) for s in f.active_sets],
        "entry_order": _ints(f.entry_order),
        "events": [{"sigma": e.sigma, "kind": e.kind, "sensor": e.sensor} for e in f.events],
        "is_monotone": f.is_monotone,
        "is_filtration": f.is_filtration,
        "diagonally_dominant": f.diagonally_dominant,
        "converged": f.converged,
        "stopped": f.stopped,
    }


def _print_filtration(f: Any) -> None:
    print(
        f"  σ ∈ [0, {f.sigma_max:g}]: entry order {_ints(f.entry_order)}; "
        f"nested (filtration): {f.is_filtration}; monotone: {f.is_monotone}; "
        f"[η''_JJ]⁻¹ diagonally dominant: {f.diagonally_dominant}"
    )
    print("     from σ      to σ        active set")
    bp = f.breakpoints
    for k, s in enumerate(f.active_sets):
        print(f"  {bp[k]:10.6g}  {bp[k + 1]:10.6g}    {_ints(s)}")
    others = [e for e in f.events if e.kind not in ("enter", "leave")]
    for e in others:
        print(f"  event at σ = {e.sigma:.6g}: {e.kind} (sensor {e.sensor})")
    if not f.converged:
        print(
            f"  stopped early ({f.stopped}): the path is traced on [0, {f.sigma_max:g}] only "
            "(raise --max-nodes / --time-limit to go further)"
        )


def _save_plot(f: Any, path: str, *, rates: bool = False, log: bool = False) -> None:
    """Saves the filtration plot asked for with ``--plot FILE``.

    Raises:
        MissingDependencyError: matplotlib is not installed (exit status 2, with the pip command).
        InvalidInputError: the file cannot be written.
    """
    matplotlib = require("matplotlib", "--plot")
    matplotlib.use("Agg")
    plt = require("matplotlib.pyplot", "--plot")
    ax = f.plot(rates=rates, log=log)
    try:
        ax.figure.savefig(path, dpi=120, bbox_inches="tight")
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"cannot save the plot to {path}: {exc}") from None
    finally:
        plt.close(ax.figure)


def _schedule_dict(b: Any, eta_star: float | None = None) -> dict[str, Any]:
    d = {
        "tau": b.tau,
        "r_tot": int(sum(b.counts)),
        "schedule": list(int(i) for i in b.schedule),
        "counts": _ints(b.counts),
        "which": b.which,
        "eta_bar": b.eta_bar,
        "eta_limit": b.eta_limit,
        "error_vs_limit": b.eta_bar - b.eta_limit,
        "relative_error_vs_limit": (b.eta_bar - b.eta_limit) / b.eta_limit,
        "converged": b.converged,
        "stopped": b.stopped,
        "moves": b.moves,
        "evaluations": b.evaluations,
        "baselines": {k: c.eta_bar for k, c in b.candidates.items()},
    }
    if eta_star is not None:
        d["eta_star_continuous"] = eta_star
    return d


def _print_schedule(b: Any, eta_star: float | None = None) -> None:
    print(f"  τ = {b.tau:g}, r_tot = {sum(b.counts)} slots per period, figure: {b.which}")
    print(f"  schedule      = {_ints(b.schedule)}   counts {_ints(b.counts)}")
    print(f"  η̄(τ, R)       = {b.eta_bar:.10g}")
    print(f"  η(counts)     = {b.eta_limit:.10g}   (fast-sampling limit τ → 0 of these counts)")
    rel = (b.eta_bar - b.eta_limit) / b.eta_limit
    print(
        f"  error         = {b.eta_bar - b.eta_limit:+.4g}  ({100 * rel:+.3g} %; O(τ) by "
        "Corollary 1)"
    )
    if eta_star is not None:
        print(f"  η* (continuous optimum at this r_tot) = {eta_star:.10g}")
    base = ", ".join(f"{k} {c.eta_bar:.6g}" for k, c in b.candidates.items())
    print(f"  baselines     : {base};  local search: {b.moves} moves, converged: {b.converged}")
    if not b.converged:
        print(
            f"  stopped early ({b.stopped}): the best schedule found so far, not a local minimum "
            "(raise --max-moves / --time-limit to search further)"
        )


def _mc_dict(m: Any) -> dict[str, Any]:
    return {
        "mse": m.mse,
        "ci": [m.ci_low, m.ci_high],
        "level": m.level,
        "predicted": m.predicted,
        "predicted_in_ci": bool(m.contains(m.predicted)),
        "runs": m.runs,
        "periods": m.periods,
        "periods_completed": getattr(m, "periods_completed", m.periods),
        "seed": m.seed,
    }


def _print_mc(m: Any) -> None:
    done = getattr(m, "periods_completed", m.periods)
    if done == 0:
        print(f"  Monte Carlo   : no period simulated ({m.runs} runs, seed {m.seed})")
        print(f"  predicted η̄   = {m.predicted:.6g}")
        return
    ok = "inside" if m.contains(m.predicted) else "OUTSIDE"
    of = f"{done} of {m.periods}" if done != m.periods else f"{m.periods}"
    print(
        f"  Monte Carlo   : MSE = {m.mse:.6g}, {100 * m.level:g} % CI [{m.ci_low:.6g}, "
        f"{m.ci_high:.6g}] ({m.runs} runs × {of} periods, seed {m.seed})"
    )
    print(f"  predicted η̄   = {m.predicted:.6g}: {ok} the interval")


# -- subcommands ----------------------------------------------------------------------------


def _demo(args: argparse.Namespace) -> int:
    from ._tasks import sampled_api
    from .allocation import filtration, optimal_allocation
    from .errors import FeatureUnavailableError

    net = demo_network()
    r_tot = float(args.r_tot)
    out: dict[str, Any] = {
        "network": {
            "n": net.n,
            "N": net.num_sensors,
            "eps": net.eps,
            "r_min": net.r_min,
            "outputs": list(net.outputs),
        }
    }
    text = not args.json
    if text:
        print(
            "capalloc demo: three weakly coupled subsystems (n = 2, 3, 1; ε = 0.1; "
            "examples/three_subsystems.toml)"
        )
        rep = net.check()
        print(
            f"  detectable: {rep.detectable}; every subsystem observable: "
            f"{all(s.observable for s in rep.subsystems)}; regular triplets: {rep.regular}"
        )
        print("\n1. Optimal allocation (fast-sampling limit) with its KKT certificate")
    alloc = optimal_allocation(net, r_tot)
    out["allocation"] = _allocation_dict(alloc)
    if text:
        _print_allocation(alloc)
        print("\n2. Filtration: the optimal allocation as the capacity grows")
    filt = filtration(net, float(args.sigma_max))
    out["filtration"] = _filtration_dict(filt)
    if text:
        _print_filtration(filt)
    if args.plot:  # only when asked: the demo writes no file by default
        _save_plot(filt, args.plot)
        out["filtration"]["plot"] = args.plot
        if text:
            print(f"  plot saved to {args.plot}")
    if text:
        print(f"\n3. Best schedule at finite period τ = {args.tau:g} vs the fast-sampling limit")
    try:
        api = sampled_api()
    except FeatureUnavailableError as exc:
        out["schedule"] = None
        if text:
            print(f"  skipped: {exc}")
        else:
            _print_json(out)
        return 0
    slots = int(round(r_tot))
    best = api["best_schedule"](net, float(args.tau), slots)
    eta_star = alloc.eta if float(slots) == r_tot else None
    out["schedule"] = _schedule_dict(best, eta_star)
    mc = api["simulate"](
        net, float(args.tau), best.schedule, int(args.periods), int(args.seed), runs=int(args.runs)
    )
    out["schedule"]["monte_carlo"] = _mc_dict(mc)
    if text:
        _print_schedule(best, eta_star)
        _print_mc(mc)
    else:
        _print_json(out)
    return 0


def _check(args: argparse.Namespace) -> int:
    net = _load(args.model)
    rep = net.check()
    if args.json:
        _print_json(
            {
                "n": rep.n,
                "num_sensors": rep.num_sensors,
                "eps": rep.eps,
                "open_loop_abscissa": rep.open_loop_abscissa,
                "g_rcond": rep.g_rcond,
                "detectable": rep.detectable,
                "detectability_margin": rep.detectability_margin,
                "observable": rep.observable,
                "observability_margin": rep.observability_margin,
                "regular": rep.regular,
                "ok": rep.ok,
                "subsystems": [
                    {
                        "index": s.index,
                        "n": s.n,
                        "p": s.p,
                        "observable": s.observable,
                        "observability_margin": s.observability_margin,
                        "regular": s.regular,
                        "regularity_margin": s.regularity_margin,
                    }
                    for s in rep.subsystems
                ],
            }
        )
    else:
        print(rep)
    return 0


def _solve(args: argparse.Namespace) -> int:
    from .allocation import integer_allocation, optimal_allocation

    net = _load(args.model)
    if args.integer:
        slots = _int_arg("--r-tot", args.r_tot)
        ia = integer_allocation(net, slots)
        if args.json:
            _print_json(
                {
                    "r_tot": slots,
                    "counts": ia.counts,
                    "eta": ia.eta,
                    "exchanges": ia.exchanges,
                    "evaluations": ia.evaluations,
                }
            )
        else:
            print(
                f"integer allocation for r_tot = {slots}: counts {_ints(ia.counts)}, "
                f"η = {ia.eta:.10g} ({ia.exchanges} exchanges, {ia.evaluations} evaluations)"
            )
        return 0
    a = optimal_allocation(net, args.r_tot, method=args.method, tol=args.tol, hessian=args.hessian)
    if args.json:
        _print_json(_allocation_dict(a))
    else:
        print(f"optimal allocation for {args.model}")
        _print_allocation(a)
    return 0


def _trace(args: argparse.Namespace) -> int:
    from .allocation import filtration

    net = _load(args.model)
    f = filtration(
        net,
        args.sigma_max,
        tol=args.tol,
        max_nodes=args.max_nodes,
        time_limit=args.time_limit,
        progress=False if args.no_progress else None,
    )
    d = _filtration_dict(f)
    if args.plot:
        _save_plot(f, args.plot, rates=args.rates, log=args.log)
        d["plot"] = args.plot
    if args.json:
        _print_json(d)
    else:
        print(f"filtration of {args.model}")
        _print_filtration(f)
        if args.plot:
            print(f"  plot saved to {args.plot}")
    return 0


def _int_arg(name: str, v: float) -> int:
    if v != math.floor(v):
        raise InvalidInputError(f"{name} must be an integer number of slots, got {v:g}")
    return int(v)


def _schedule(args: argparse.Namespace) -> int:
    from ._tasks import sampled_api

    net = _load(args.model)
    api = sampled_api()
    best = api["best_schedule"](
        net,
        args.tau,
        _int_arg("--r-tot", args.r_tot),
        which=args.which,
        check=not args.no_check,
        max_moves=args.max_moves,
        time_limit=args.time_limit,
        progress=False if args.no_progress else None,
    )
    if args.json:
        _print_json(_schedule_dict(best))
    else:
        print(f"best schedule for {args.model}")
        _print_schedule(best)
    return 0


def _parse_slots(s: str) -> list[int]:
    try:
        slots = [int(x) for x in s.replace(" ", "").split(",") if x != ""]
    except ValueError:
        raise InvalidInputError(
            f"--schedule must be comma-separated sensor indices like 0,1,0,2; got {s!r}"
        ) from None
    if not slots:
        raise InvalidInputError("--schedule is empty")
    return slots


#: The shortest budget handed to an API call when the command's time is (nearly) used up: the
#: call then stops at its first check (``best_schedule`` after its starting candidates).
_SPENT = 1e-9


def _simulate_stop_note(search_stopped: bool, mc: Any) -> str | None:
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


def _simulate(args: argparse.Namespace) -> int:
    import time

    from ._tasks import sampled_api

    started = time.monotonic()
    deadline = math.inf if args.time_limit is None else started + args.time_limit
    progress = False if args.no_progress else None

    def remaining() -> float | None:
        if args.time_limit is None:
            return None
        return max(deadline - time.monotonic(), _SPENT)

    net = _load(args.model)
    api = sampled_api()
    search_stopped = False
    if args.schedule is not None:
        sched: Any = api["Schedule"](_parse_slots(args.schedule), net.num_sensors)
        source = "given"
    else:
        best = api["best_schedule"](
            net,
            args.tau,
            _int_arg("--r-tot", args.r_tot),
            which=args.which,
            check=not args.no_check,
            time_limit=remaining(),
            progress=progress,
        )
        sched, source = best.schedule, "best"
        search_stopped = best.stopped == "time_limit"
    cost = api["sampled_cost"](net, args.tau, sched, args.which, check=not args.no_check)
    mc = None
    if not (search_stopped and time.monotonic() >= deadline):
        mc = api["simulate"](
            net,
            args.tau,
            sched,
            args.periods,
            args.seed,
            runs=args.runs,
            which=args.which,
            check=not args.no_check,
            time_limit=remaining(),
            progress=progress,
        )
    note = _simulate_stop_note(search_stopped, mc)
    stopped = "completed" if note is None else "time_limit"
    if args.json:
        d: dict[str, Any] = (
            _mc_dict(mc)
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
                "stopped": stopped,
            }
        )
        _print_json(d)
    else:
        print(
            f"Monte Carlo check for {args.model}: τ = {args.tau:g}, {source} schedule "
            f"{list(int(i) for i in sched)}"
        )
        print(f"  η̄(τ, R) ({args.which}) = {cost:.10g}")
        if mc is not None:
            _print_mc(mc)
        print(f"  converged: {note is None}")
        if note is not None:
            print(f"  {note}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from .sweep import _PART_GLOB, SweepStats, load_spec

    spec = load_spec(args.spec)
    out = Path(args.out)
    has_parts = out.is_dir() and any(out.glob(_PART_GLOB))
    if has_parts and not (args.resume or args.overwrite):
        raise SweepError(
            f"{out} already holds sweep results; pass --resume to continue them or --overwrite "
            "to start afresh"
        )
    executor: Any = None
    client: Any = None
    if args.scheduler:
        Client = require("distributed", "--scheduler").Client
        try:
            client = cast(Any, Client)(args.scheduler, timeout=args.connect_timeout)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SweepError(
                f"cannot connect to the dask scheduler {args.scheduler}: {exc}"
            ) from None
        executor = client.get_executor()
    stats = SweepStats()
    try:
        table = spec.run(
            out=out,
            resume=not args.overwrite,
            executor=executor,
            workers=args.workers,
            progress=not args.no_progress,
            stats=stats,
            **({"chunk_size": args.chunk_size} if args.chunk_size else {}),
        )
    except KeyboardInterrupt:
        print(
            f"capalloc: interrupted after {stats.computed} new tasks; finished chunks are saved "
            f"in {out} (continue with --resume)",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    finally:
        if client is not None:
            client.close()
    summary = {
        "spec": args.spec,
        "out": str(out),
        "compute": spec.compute,
        "networks": spec.num_networks,
        "capacities": list(spec.capacities),
        "tasks": stats.tasks,
        "computed": stats.computed,
        "skipped": stats.skipped,
        "failed": stats.failed,
        "part_files_written": stats.chunks,
        "seconds": round(stats.seconds, 3),
        "rows": table.num_rows,
    }
    if args.json:
        _print_json(summary)
    else:
        rate = stats.computed / stats.seconds if stats.seconds > 0 else math.nan
        print(
            f"sweep {args.spec}: {stats.tasks} tasks ({spec.num_networks} networks × "
            f"{len(spec.capacities)} capacities, compute = {spec.compute})"
        )
        print(
            f"  computed {stats.computed}, skipped (already done) {stats.skipped}, "
            f"failed {stats.failed}; {stats.seconds:.2f} s ({rate:.1f} tasks/s)"
        )
        print(f"  results: {out}/ (Parquet dataset; pandas.read_parquet({str(out)!r}))")
        if stats.failed:
            errs = [e for e in table.column("error").to_pylist() if e is not None]
            print(f"  first error: {errs[0]}")
    return 0


# -- parser ---------------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """Argument errors as one line (``capalloc: error: …``) and exit status 2."""

    #: The last usage error (for the ``--json`` error object); shared by the subparsers.
    last_error: str | None = None

    def error(self, message: str) -> NoReturn:
        sub = self.prog.removeprefix("capalloc").strip()
        where = f"{sub}: " if sub else ""
        text = " ".join(f"{where}{message} (see {self.prog} --help)".split())
        _Parser.last_error = text
        with contextlib.suppress(OSError, ValueError):
            print(f"capalloc: error: {text}", file=sys.stderr)
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


def _positive(kind: type, zero: bool = False) -> Any:
    """An argparse type: a finite number ``> 0`` (``>= 0`` with ``zero``) of type ``kind``."""

    def parse(s: str) -> Any:
        try:
            v = kind(s)
        except ValueError:
            v = _integral(s) if kind is int else None  # "400.0" is a count, as in the API
        if v is None:
            what = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {what}, got {_shown(s)}") from None
        try:
            ok = math.isfinite(float(v)) and (v >= 0 if zero else v > 0)
        except OverflowError:  # an int too large for a float
            ok = False
        if not ok:
            sign = "non-negative" if zero else "positive"
            raise argparse.ArgumentTypeError(f"must be {sign} and finite, got {_shown(s)}")
        return v

    parse.__name__ = kind.__name__
    return parse


def build_parser() -> argparse.ArgumentParser:
    """The ``capalloc`` argument parser."""
    from . import __version__
    from .allocation import HESSIAN_MODES, METHODS

    parser = _Parser(
        prog="capalloc",
        description="Optimal capacity allocation for sampled networked systems.",
    )
    parser.add_argument("--version", action="version", version=f"capalloc {__version__}")
    sub = parser.add_subparsers(
        dest="command",
        required=True,
        parser_class=_Parser,
        metavar="COMMAND",
        help="run 'capalloc COMMAND --help' for its options",
    )
    pos = _positive(float)
    posint = _positive(int)

    def add(name: str, help: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help, description=help)
        p.add_argument("--json", action="store_true", help="machine-readable output on stdout")
        return p

    def budget_args(p: argparse.ArgumentParser, what: str) -> None:
        p.add_argument(
            "--time-limit",
            type=pos,
            metavar="SECONDS",
            help=f"stop {what} after SECONDS of wall time and report the best found so far "
            "(stopped: time_limit); default: no limit",
        )
        p.add_argument(
            "--no-progress",
            action="store_true",
            help="no progress bar (shown on stderr by default when it is a terminal)",
        )

    def which_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--which",
            default="boundary",
            choices=["boundary", "average"],
            help="the figure η̄: error covariance at the period boundary (default) or its average "
            "over the slots",
        )

    def no_check_arg(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "--no-check",
            action="store_true",
            help="skip the check of Proposition 1 (used sensors observe A, τ does not alias two "
            "eigenvalues), like check=False in the API, with its warning",
        )

    p = add("demo", "the main job on a built-in network: allocation, filtration, schedule")
    p.add_argument("--r-tot", type=pos, default=8.0, help="capacity (default 8)")
    p.add_argument("--sigma-max", type=pos, default=12.0, help="end of the filtration (12)")
    p.add_argument("--tau", type=pos, default=0.5, help="period of the schedule (0.5)")
    p.add_argument("--periods", type=posint, default=400, help="Monte Carlo periods (400)")
    p.add_argument("--runs", type=posint, default=64, help="Monte Carlo runs (64)")
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
    p.set_defaults(func=_demo)

    p = add("check", "check a network's assumptions (observability, detectability, regularity)")
    p.add_argument("model", help="network file (.toml, .json, .npz)")
    p.set_defaults(func=_check)

    p = add("solve", "optimal allocation at a capacity, with its KKT certificate")
    p.add_argument("model", help="network file (.toml, .json, .npz)")
    p.add_argument("--r-tot", type=pos, required=True, help="total capacity r_tot")
    p.add_argument(
        "--method",
        default="newton",
        choices=METHODS,
        help="optimisation method (default newton: projected Newton with its KKT certificate)",
    )
    p.add_argument(
        "--hessian",
        default="auto",
        choices=HESSIAN_MODES,
        help="Newton variant: exact Hessian, Newton–CG with Hessian-vector products, or by size",
    )
    p.add_argument("--tol", type=pos, default=1e-12, help="relative certificate tolerance")
    p.add_argument("--integer", action="store_true", help="integer slot counts instead")
    p.set_defaults(func=_solve)

    p = add("trace", "the filtration: optimal allocation for σ in [0, σ_max] and breakpoints")
    p.add_argument("model", help="network file (.toml, .json, .npz)")
    p.add_argument("--sigma-max", type=pos, required=True, help="σ_max = r_tot,max − N·r_min")
    p.add_argument("--tol", type=pos, default=1e-10, help="breakpoint tolerance (relative)")
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
        "--max-nodes",
        type=posint,
        metavar="N",
        help="stop after N path nodes (default capalloc_rs.limits.FILTRATION_MAX_NODES); "
        "the output then says stopped: max_nodes",
    )
    budget_args(p, "the path following")
    p.set_defaults(func=_trace)

    p = add("schedule", "best periodic schedule at a finite period τ")
    p.add_argument("model", help="network file (.toml, .json, .npz)")
    p.add_argument("--tau", type=pos, required=True, help="period τ")
    p.add_argument("--r-tot", type=pos, required=True, help="slots per period")
    which_arg(p)
    p.add_argument(
        "--max-moves",
        type=_positive(int, zero=True),
        metavar="N",
        help="stop the local search after N improving moves (default "
        "capalloc_rs.limits.BEST_SCHEDULE_MAX_MOVES); the output then says stopped: max_moves",
    )
    no_check_arg(p)
    budget_args(p, "the search")
    p.set_defaults(func=_schedule)

    p = add("simulate", "Monte Carlo check of a schedule's error against the prediction")
    p.add_argument("model", help="network file (.toml, .json, .npz)")
    p.add_argument("--tau", type=pos, required=True, help="period τ")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--r-tot", type=pos, help="simulate the best schedule with this many slots")
    g.add_argument("--schedule", help="simulate this schedule: sensor indices, e.g. 0,1,0,2")
    p.add_argument("--periods", type=posint, default=400, help="periods per run (400)")
    p.add_argument("--runs", type=posint, default=64, help="independent runs (64)")
    p.add_argument("--seed", type=int, default=0, help="random seed (0)")
    which_arg(p)
    no_check_arg(p)
    budget_args(p, "the command (the schedule search of --r-tot, then the Monte Carlo)")
    p.set_defaults(func=_simulate)

    p = add("sweep", "run a sweep spec in parallel into a resumable Parquet dataset")
    p.add_argument("spec", help="sweep spec (.toml or .json; see examples/sweep.toml)")
    p.add_argument("--out", required=True, help="output directory (Parquet part-files)")
    m = p.add_mutually_exclusive_group()
    m.add_argument("--resume", action="store_true", help="continue the results in --out")
    m.add_argument("--overwrite", action="store_true", help="discard the results in --out")
    w = p.add_mutually_exclusive_group()
    w.add_argument("--workers", type=posint, help="local worker processes (default: all cores)")
    w.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="dask.distributed scheduler, e.g. tcp://10.0.0.1:8786",
    )
    p.add_argument(
        "--connect-timeout",
        type=pos,
        default=10.0,
        metavar="SECONDS",
        help="how long to wait for the --scheduler (10)",
    )
    p.add_argument("--chunk-size", type=posint, help="tasks per chunk/part-file")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_sweep)
    return parser


def _one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (OSError: ``file: reason``)."""
    if isinstance(exc, OSError) and exc.filename:
        msg = f"{exc.filename}: {exc.strerror or exc}"
    else:
        msg = str(exc) or type(exc).__name__
    return " ".join(msg.split())


def _report(message: str, kind: str, as_json: bool) -> None:
    """``capalloc: error: …`` on stderr; under ``--json`` also the error as JSON on stdout."""
    if as_json:
        with contextlib.suppress(OSError, ValueError):
            print(json.dumps({"error": {"type": kind, "message": message}}), flush=True)
    with contextlib.suppress(OSError, ValueError):
        print(f"capalloc: error: {message}", file=sys.stderr, flush=True)


def _silence_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so that the flush at interpreter exit does
    not fail again (the recipe of Python's documentation on SIGPIPE)."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def _report_warnings(caught: Sequence[warnings.WarningMessage]) -> None:
    """Each distinct warning once, on one line ``capalloc: warning: …`` on stderr (``--no-check``
    says the API's check=False warning in the CLI's words)."""
    seen: set[str] = set()
    for w in caught:
        msg = str(w.message)
        if isinstance(w.message, UncheckedExistenceWarning):
            msg = msg.replace("check=False", "--no-check", 1) if msg == UNCHECKED_MESSAGE else msg
        if msg not in seen:
            seen.add(msg)
            with contextlib.suppress(OSError, ValueError):
                print(f"capalloc: warning: {' '.join(msg.split())}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``capalloc`` console script; returns the exit status.

    Never raises (except with ``CAPALLOC_TRACEBACK=1``): user mistakes and failures end with one
    line ``capalloc: error: …`` on stderr and status 2 (under ``--json`` also
    ``{"error": {"type": …, "message": …}}`` on stdout), Ctrl-C with one line and status 130, and
    a closed stdout pipe (``capalloc demo | head``) quietly with status 0.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    _Parser.last_error = None
    as_json = "--json" in argv
    traceback = bool(os.environ.get("CAPALLOC_TRACEBACK"))
    try:
        parser = build_parser()
        if not argv:  # like git: the help, and success
            parser.print_help()
            return 0
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help, --version, argument errors (already reported)
            code = int(exc.code) if isinstance(exc.code, int) else EXIT_ERROR
            if code and as_json:
                msg = getattr(parser, "last_error", None) or "invalid arguments"
                with contextlib.suppress(OSError, ValueError):
                    print(json.dumps({"error": {"type": "UsageError", "message": msg}}))
            sys.stdout.flush()
            return code
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UncheckedExistenceWarning)
            code = int(args.func(args))
        _report_warnings(caught)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except KeyboardInterrupt:
        with contextlib.suppress(OSError, ValueError):
            print("capalloc: interrupted", file=sys.stderr, flush=True)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _silence_stdout()
        return 0
    except (CapallocError, ValueError, OSError) as exc:
        # ValueError: what a library reports as a bad value; OSError: unreadable/unwritable files.
        if traceback:
            raise
        # The API's advice in the CLI's words (the aliasing check: check=False → --no-check).
        msg = _one_line(exc).replace("pass check=False", "pass --no-check")
        _report(msg, type(exc).__name__, as_json)
        return EXIT_ERROR
    except MemoryError:
        if traceback:
            raise
        _report("out of memory (try a smaller problem)", "MemoryError", as_json)
        return EXIT_ERROR
    except Exception as exc:  # a bug: still one line, with the way to see the traceback
        if traceback:
            raise
        _report(
            f"internal error ({type(exc).__name__}: {_one_line(exc)}); please report it, with "
            "the traceback shown by CAPALLOC_TRACEBACK=1",
            type(exc).__name__,
            as_json,
        )
        return EXIT_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
