"""Worker side of :func:`capalloc_rs.sweep`: run one chunk of tasks, one row per task.

Everything here is importable without pyarrow or tqdm (workers only need numpy and the extension),
takes and returns only picklable values (networks, floats, lists, dicts), and never raises for a
failing task: the failure becomes the row's ``error`` (``"ExceptionClass: message"``).

Also the lazy bridge to the finite-τ API (:mod:`capalloc_rs.sampled` of issue 6), so that this
module and the CLI import without it.
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import FeatureUnavailableError, InvalidInputError

__all__ = ["COMPUTES", "TaskSpec", "run_chunk", "run_task", "sampled_api"]

#: What a sweep task can compute.
COMPUTES = ("allocation", "filtration", "schedule")


@dataclass(frozen=True)
class TaskSpec:
    """One task: a network (or the reason it could not be built) and a capacity."""

    task_id: str
    network_index: int
    r_tot: float
    network_digest: str
    network: Any  # capalloc_rs.Network, or None when it could not be loaded
    load_error: str | None = None


def _sampled_attr(modules: Sequence[str], name: str) -> Any:
    for mod in ("", *modules):  # the package's own export first, then its modules
        try:
            m = importlib.import_module(f"capalloc_rs.{mod}" if mod else "capalloc_rs")
        except ImportError:
            continue
        obj = getattr(m, name, None)
        if callable(obj):
            return obj
    raise FeatureUnavailableError(
        f"the finite-τ schedule API ({name}) is not available in this build of capalloc_rs"
    )


def sampled_api() -> dict[str, Any]:
    """The finite-τ functions ``best_schedule``, ``simulate``, ``sampled_cost`` and the class
    ``Schedule``, imported lazily.

    Raises:
        FeatureUnavailableError: this build has no sampled-system layer.
    """
    return {
        "best_schedule": _sampled_attr(("sampled",), "best_schedule"),
        "simulate": _sampled_attr(("sampled",), "simulate"),
        "sampled_cost": _sampled_attr(("sampled",), "sampled_cost"),
        "Schedule": _sampled_attr(("sampled",), "Schedule"),
    }


def _floats(x: Any) -> list[float]:
    return [float(v) for v in np.asarray(x, dtype=np.float64).ravel()]


def _ints(x: Any) -> list[int]:
    return [int(v) for v in np.asarray(x).ravel()]


def _allocation(net: Any, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    from .allocation import optimal_allocation

    a = optimal_allocation(
        net,
        r_tot,
        method=params["method"],
        tol=params["tol"],
        hessian=params.get("hessian", "auto"),
    )
    return {
        "eta": float(a.eta),
        "r": _floats(a.r),
        "gamma": _floats(a.gamma),
        "gradient": _floats(a.gradient),
        "mu": float(a.mu),
        "active": _ints(a.active),
        "gap": float(a.gap),
        "kkt_residual": float(a.kkt_residual),
        "iterations": int(a.iterations),
    }


def _filtration(net: Any, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    from .allocation import filtration

    sigma_max = float(r_tot) - net.num_sensors * float(net.r_min)
    if not sigma_max > 0:
        raise InvalidInputError(
            f"a filtration needs r_tot > N·r_min = {net.num_sensors * float(net.r_min):g}, "
            f"got r_tot = {r_tot:g}"
        )
    f = filtration(net, sigma_max, tol=params["tol"])
    r = np.asarray(f.allocation(sigma_max), dtype=np.float64) + float(net.r_min)
    return {
        "eta": float(net.cost(r)),
        "r": _floats(r),
        "mu": float(f.mu(sigma_max)),
        "sigma_max": sigma_max,
        "breakpoints": _floats(f.breakpoints),
        "active_sets": [list(s) for s in f.active_sets],
        "entry_order": list(f.entry_order),
        "is_monotone": bool(f.is_monotone),
        "is_filtration": bool(f.is_filtration),
    }


def _schedule(net: Any, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    if r_tot != math.floor(r_tot):
        raise InvalidInputError(f"a schedule needs an integer number of slots, got r_tot = {r_tot}")
    best = sampled_api()["best_schedule"](net, params["tau"], int(r_tot), which=params["which"])
    eta_bar, eta_limit = float(best.eta_bar), float(best.eta_limit)
    return {
        "eta": eta_bar,
        "tau": float(params["tau"]),
        "schedule": _ints(best.schedule.as_array()),
        "counts": [int(c) for c in best.counts],
        "eta_bar": eta_bar,
        "eta_limit": eta_limit,
        "relative_error": (eta_bar - eta_limit) / eta_limit if eta_limit else math.nan,
        "converged": bool(best.converged),
    }


_RUNNERS = {"allocation": _allocation, "filtration": _filtration, "schedule": _schedule}


def run_task(compute: str, params: Mapping[str, Any], task: TaskSpec) -> dict[str, Any]:
    """The row of one task; a failure is recorded in ``error`` instead of raised."""
    row: dict[str, Any] = {
        "task_id": task.task_id,
        "network_index": task.network_index,
        # slots are ints (a schedule's r_tot is checked integral), capacities floats
        "r_tot": int(task.r_tot) if compute == "schedule" else task.r_tot,
        "network_digest": task.network_digest,
        "num_sensors": None,
        "error": task.load_error,
    }
    if task.network is None:
        return row
    row["num_sensors"] = int(task.network.num_sensors)
    try:
        row.update(_RUNNERS[compute](task.network, task.r_tot, params))
    except Exception as exc:  # a failing task must not stop the sweep
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def run_chunk(
    compute: str, params: Mapping[str, Any], tasks: Sequence[TaskSpec]
) -> list[dict[str, Any]]:
    """Rows of a chunk of tasks, in the chunk's order (executed on a worker)."""
    return [run_task(compute, params, t) for t in tasks]
