"""The JSON the CLI printed before every result had ``to_dict()``: the dict builders of the old
``capalloc_rs.cli`` (``_allocation_dict``, ``_filtration_dict``, ``_schedule_dict``,
``_mc_dict``), kept here verbatim as the independent route against which ``to_dict()`` and the
CLI's ``--json`` (now ``to_dict()``) are checked: every key printed then is printed now, with the
same value."""

from __future__ import annotations

from typing import Any

from capalloc_rs._json import ints as _ints


def allocation_dict(a: Any) -> dict[str, Any]:
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


def filtration_dict(f: Any) -> dict[str, Any]:
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


def schedule_dict(b: Any, eta_star: float | None = None) -> dict[str, Any]:
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
        "budget": b.budget,
        "budget_used": b.budget_used,
        "lower_bound": b.lower_bound,
        "gap": b.gap,
        "proven_optimal": b.proven_optimal,
        "nodes": b.nodes,
    }
    if eta_star is not None:
        d["eta_star_continuous"] = eta_star
    return d


def mc_dict(m: Any) -> dict[str, Any]:
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
