"""What the ``capalloc`` commands print: JSON (``--json``) and the text of each result.

The JSON of a result is its ``to_dict()`` (the one serialisation, shared with the sweep's rows),
sometimes with keys the command adds (the demo's ``eta_star_continuous``, a saved ``plot``);
:func:`print_json` passes it through :func:`capalloc_rs._json.plain` (plain Python values; counts,
slots, seeds and sensor indices as integers; non-finite numbers as ``null``).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from .._json import ints, plain
from .._optional import require
from ..allocation import Allocation, Filtration
from ..errors import InvalidInputError
from ..network import Network
from ..sampled import BestSchedule, MonteCarloResult

__all__ = [
    "load",
    "print_allocation",
    "print_filtration",
    "print_json",
    "print_mc",
    "print_schedule",
    "save_plot",
]


def print_json(obj: Any) -> None:
    """``obj`` as indented strict JSON on stdout."""
    print(json.dumps(plain(obj), indent=2, allow_nan=False))


def _vec(x: Any, fmt: str = "{:.6g}") -> str:
    return "[" + ", ".join(fmt.format(float(v)) for v in np.asarray(x).ravel()) + "]"


def load(path: str) -> Network:
    """The network of the model file ``path``."""
    return Network.load(path)


# -- allocations ----------------------------------------------------------------------------


def _method_name(a: Allocation) -> str:
    if a.hessian == "hvp":
        return f"{a.method}, Newton–CG with {a.hvp_count} Hessian-vector products"
    if a.hessian == "exact":
        return f"{a.method}, exact Hessian"
    return str(a.method)


def print_allocation(a: Allocation, limits: bool = False) -> None:
    """The allocation's text; ``limits``: the network has costs or limits (budget B, costs and the
    capped sensors are shown)."""
    if limits and a.costs is not None:
        print(
            f"  budget B = {a.budget:g} channel units   σ = B − Σ b_i r_min,i = {a.sigma:g}   "
            f"({_method_name(a)}, {a.iterations} iterations)"
        )
        print(f"  costs b       = {_vec(a.costs)}")
    else:
        print(
            f"  r_tot = {a.r_tot:g}   σ = r_tot − N·r_min = {a.sigma:g}   ({_method_name(a)}, "
            f"{a.iterations} iterations)"
        )
    print(f"  r*            = {_vec(a.r)}")
    print(f"  η(r*)         = {a.eta:.10g}")
    print(f"  ∇η(r*)        = {_vec(a.gradient)}")
    print(
        f"  active set    = {ints(a.active)}   μ = {a.mu:.6g}   "
        f"shadow price −μ = {a.shadow_price:.6g}"
    )
    if a.at_cap:
        assert a.upper_multipliers is not None
        nu = [float(a.upper_multipliers[i]) for i in a.at_cap]
        print(f"  at their cap  = {list(a.at_cap)}   ν = μ − g_i/b_i = {_vec(nu)}")
    print(
        f"  certificate   : Frank–Wolfe gap {a.gap:.2e} ≥ η(r) − η*,  "
        f"KKT residual {a.kkt_residual:.2e}"
    )


# -- filtrations ----------------------------------------------------------------------------


def print_filtration(f: Filtration) -> None:
    print(
        f"  σ ∈ [0, {f.sigma_max:g}]: entry order {ints(f.entry_order)}; "
        f"nested (filtration): {f.is_filtration}; monotone: {f.is_monotone}; "
        f"[η''_JJ]⁻¹ diagonally dominant: {f.diagonally_dominant}"
    )
    if _has_limits(f):
        _print_box_segments(f)
    else:
        print("     from σ      to σ   μ at start  −μ at start    active set")
        bp = f.breakpoints
        for k, s in enumerate(f.active_sets):
            mu = _mu_at_start(f, k)
            print(f"  {bp[k]:10.6g}  {bp[k + 1]:10.6g}  {mu:11.6g}  {-mu:11.6g}    {ints(s)}")
        print("  (−μ = shadow price: by how much η* falls per extra unit of capacity)")
    others = [e for e in f.events if e.kind not in ("enter", "leave")]
    for e in others:
        where = f"σ = {e.sigma:.6g}" + (f" (B = {e.budget:.6g})" if _has_limits(f) else "")
        print(
            f"  event at {where}: {e.kind} (sensor {e.sensor}), "
            f"shadow price −μ = {e.shadow_price:.6g}"
        )
    if not f.converged:
        print(
            f"  stopped early ({f.stopped}): the path is traced on [0, {f.sigma_max:g}] only "
            "(raise --max-nodes / --time-limit to go further)"
        )


def _has_limits(f: Filtration) -> bool:
    """Whether the network has sample costs or rate limits (not the paper's form)."""
    return not bool(getattr(f.net, "is_paper_form", True))


def _print_box_segments(f: Filtration) -> None:
    """The pieces of a path with costs or limits: σ, the budget B, μ, the free and the capped
    sensors."""
    print("     from σ      to σ    from B  μ at start  −μ at start    free / capped")
    bp = f.breakpoints
    for k, s in enumerate(f.active_sets):
        mu = _mu_at_start(f, k)
        capped = f.capped_sets[k] if f.capped_sets else ()
        print(
            f"  {bp[k]:10.6g}  {bp[k + 1]:10.6g}  {bp[k] + f.budget_min:8.6g}  {mu:10.6g}  "
            f"{-mu:11.6g}    {ints(s)} / {ints(capped)}"
        )
    print(
        "  (B = σ + Σ b_i r_min,i channel units per unit time; −μ = shadow price: by how much "
        "η* falls per extra channel unit of budget)"
    )


def _mu_at_start(f: Filtration, k: int) -> float:
    """μ at the breakpoint σ_k, from the first traced node of segment ``k`` (μ is continuous
    along the path, so either side of the breakpoint gives it)."""
    idx = np.flatnonzero(f.node_segment == k)
    return float(f.node_mu[idx[0]]) if idx.size else float("nan")


def save_plot(
    f: Filtration, path: str, *, rates: bool = False, log: bool = False, budget: bool = False
) -> None:
    """Saves the filtration plot asked for with ``--plot FILE``.

    Raises:
        MissingDependencyError: matplotlib is not installed (exit status 2, with the pip command).
        InvalidInputError: the file cannot be written.
    """
    matplotlib = require("matplotlib", "--plot")
    matplotlib.use("Agg")
    plt = require("matplotlib.pyplot", "--plot")
    ax = f.plot(rates=rates, log=log, budget=budget)
    try:
        ax.figure.savefig(path, dpi=120, bbox_inches="tight")
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"cannot save the plot to {path}: {exc}") from None
    finally:
        plt.close(ax.figure)


# -- schedules and Monte Carlo --------------------------------------------------------------


def print_schedule(b: BestSchedule, eta_star: float | None = None) -> None:
    print(f"  τ = {b.tau:g}, r_tot = {sum(b.counts)} slots per period, figure: {b.which}")
    if b.budget_used != sum(b.counts) or b.budget != b.budget_used:
        print(f"  budget        = {b.budget:g} channel units per period, {b.budget_used:g} used")
    print(f"  schedule      = {ints(b.schedule)}   counts {ints(b.counts)}")
    print(f"  η̄(τ, R)       = {b.eta_bar:.10g}")
    print(f"  η(counts)     = {b.eta_limit:.10g}   (fast-sampling limit τ → 0 of these counts)")
    rel = (b.eta_bar - b.eta_limit) / b.eta_limit
    print(
        f"  error         = {b.eta_bar - b.eta_limit:+.4g}  ({100 * rel:+.3g} %; O(τ) by "
        "Corollary 1)"
    )
    if eta_star is not None:
        print(f"  η* (continuous optimum at this r_tot) = {eta_star:.10g}")
    if math.isfinite(b.lower_bound):
        print(
            f"  lower bound   = {b.lower_bound:.10g}   (proven, over every schedule of the "
            f"budget)   gap = {b.gap:.3g}   proven_optimal: {b.proven_optimal}"
        )
    base = ", ".join(f"{k} {c.eta_bar:.6g}" for k, c in b.candidates.items())
    print(f"  baselines     : {base};  local search: {b.moves} moves, converged: {b.converged}")
    if not b.converged:
        print(
            f"  stopped early ({b.stopped}): the best schedule found so far, not a local minimum "
            "(raise --max-moves / --time-limit to search further)"
        )


def print_mc(m: MonteCarloResult) -> None:
    done = m.periods_completed
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
