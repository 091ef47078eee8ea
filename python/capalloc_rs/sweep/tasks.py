"""Worker side of :func:`capalloc_rs.sweep`: run one chunk of tasks, one row per task.

A task is one (network, capacity) pair; what it computes is one of :data:`COMPUTES`: the
continuous optimum at ``r_tot`` (:func:`~capalloc_rs.allocation.optimal_allocation`), the
filtration up to ``σ_max = r_tot − N·r_min`` (:func:`~capalloc_rs.allocation.filtration`), or the
best periodic schedule with ``r_tot`` slots at period ``τ``
(:func:`~capalloc_rs.sampled.best_schedule`), or the robust allocation over the task's
network with an uncertain coupling strength (``"robust"``: the models are the network with ε
replaced by ``num_models`` values drawn uniformly in ``[eps_low, eps_high]`` by
``numpy.random.default_rng(seed)`` — the same values for every task —
:func:`~capalloc_rs.allocation.robust_allocation` with ``objective``; the row also has
``nominal_value``, the objective at the network's own optimum, for comparison).

Everything here is importable without pyarrow or tqdm (workers only need numpy and the extension),
takes and returns only picklable values (networks, floats, lists, dicts), and never raises for a
failing task: the failure becomes the row's ``error`` (``"ExceptionClass: message"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._json import plain
from ..allocation import coupling_models, filtration, optimal_allocation, robust_allocation
from ..errors import CapallocError, InvalidInputError
from ..network import Network
from ..sampled import best_schedule
from .columns import flatten

__all__ = ["COMPUTES", "TASK_ERRORS", "TaskSpec", "run_chunk", "run_task"]

#: What a sweep task can compute.
COMPUTES = ("allocation", "filtration", "schedule", "robust")

#: The failures of one task (or of loading its model file) that become the row's ``error``
#: instead of stopping the sweep: the package's own errors, bad values, numerical trouble, bad or
#: unreadable files, and memory. Anything else (a ``TypeError``, say) is a bug and is raised.
TASK_ERRORS = (CapallocError, ValueError, ArithmeticError, LookupError, OSError, MemoryError)


@dataclass(frozen=True)
class TaskSpec:
    """One task: a network (or the reason it could not be built) and a capacity."""

    task_id: str
    network_index: int
    r_tot: float
    network_digest: str
    network: Network | None  # None when it could not be loaded
    load_error: str | None = None


def _allocation(net: Network, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    a = optimal_allocation(
        net,
        r_tot,
        method=params["method"],
        tol=params["tol"],
        hessian=params.get("hessian", "auto"),
    )
    return a.to_dict()


def _filtration(net: Network, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    """The filtration's ``to_dict()``, and the optimum at its end: ``eta``, ``r``, ``mu`` and the
    shadow price ``−μ``."""
    if not net.is_paper_form:  # traced over the budget B = r_tot in channel units
        return _budget_filtration(net, r_tot, params)
    sigma_max = float(r_tot) - net.num_sensors * float(net.r_min)
    if not sigma_max > 0:
        raise InvalidInputError(
            f"a filtration needs r_tot > N·r_min = {net.num_sensors * float(net.r_min):g}, "
            f"got r_tot = {r_tot:g}"
        )
    f = filtration(net, sigma_max, tol=params["tol"])
    r = np.asarray(f.allocation(sigma_max), dtype=np.float64) + float(net.r_min)
    mu = float(f.mu(sigma_max))
    at_end = {"eta": net.cost(r), "r": r, "mu": mu, "shadow_price": -mu}
    return {**f.to_dict(), **plain(at_end)}


def _budget_filtration(net: Network, budget: float, params: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`_filtration` of a network with sample costs or rate limits: up to
    ``σ_max = B − Σ b_i r_min,i``, the rates at the end ``f.rates(σ_max)`` and μ per channel
    unit."""
    lowest = net.budget_range[0]
    sigma_max = float(budget) - lowest
    if not sigma_max > 0:
        raise InvalidInputError(
            f"a filtration needs a budget r_tot > Σ b_i r_min,i = {lowest:g}, got r_tot = "
            f"{budget:g}"
        )
    f = filtration(net, sigma_max, tol=params["tol"])
    r = np.asarray(f.rates(sigma_max), dtype=np.float64)
    mu = float(f.mu(sigma_max))
    at_end = {"eta": net.cost(r), "r": r, "mu": mu, "shadow_price": -mu}
    return {**f.to_dict(), **plain(at_end)}


def _schedule(net: Network, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    """The best schedule's ``to_dict()``; ``eta`` is its ``eta_bar``. With sample costs (a network
    not in the paper's form) ``r_tot`` is the budget in channel units, any positive number."""
    costs = getattr(net, "costs", None)
    if costs is not None and any(float(b) != 1.0 for b in costs):
        d = best_schedule(net, params["tau"], float(r_tot), which=params["which"]).to_dict()
        return {**d, "eta": d["eta_bar"]}
    if r_tot != math.floor(r_tot):
        raise InvalidInputError(f"a schedule needs an integer number of slots, got r_tot = {r_tot}")
    d = best_schedule(net, params["tau"], int(r_tot), which=params["which"]).to_dict()
    return {**d, "eta": d["eta_bar"]}


def robust_eps(params: Mapping[str, Any]) -> np.ndarray[Any, np.dtype[np.float64]]:
    """The coupling strengths of the models of a ``"robust"`` task (see the module docstring)."""
    rng = np.random.default_rng(params["seed"])
    low, high = float(params["eps_low"]), float(params["eps_high"])
    eps: np.ndarray[Any, np.dtype[np.float64]] = rng.uniform(low, high, size=params["num_models"])
    return eps


def _robust(net: Network, r_tot: float, params: Mapping[str, Any]) -> dict[str, Any]:
    """The robust allocation's ``to_dict()`` over the perturbed couplings of ``net``, and
    ``nominal_value``: the objective at ``net``'s own optimum."""
    models = coupling_models(net, robust_eps(params))
    res = robust_allocation(models, r_tot, objective=params["objective"], tol=params["tol"])
    nominal = optimal_allocation(net, r_tot, tol=params["tol"]).r
    etas = np.array([m.cost(nominal) for m in models])
    value = float(np.mean(etas)) if params["objective"] == "mean" else float(np.max(etas))
    return {**res.to_dict(), "eta": res.value, "nominal_value": value}


_RUNNERS = {
    "allocation": _allocation,
    "filtration": _filtration,
    "schedule": _schedule,
    "robust": _robust,
}


def run_task(compute: str, params: Mapping[str, Any], task: TaskSpec) -> dict[str, Any]:
    """The row of one task: its identity, and its result's ``to_dict()`` flattened into columns
    (:func:`~capalloc_rs.sweep.columns.flatten`); a failure is recorded in ``error`` instead of
    raised."""
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
        result = _RUNNERS[compute](task.network, task.r_tot, params)
    except TASK_ERRORS as exc:  # a failing task must not stop the sweep
        row["error"] = f"{type(exc).__name__}: {exc}"
        return row
    return {**flatten(result), **row}  # the task's identity wins (r_tot as the task has it)


def run_chunk(
    compute: str, params: Mapping[str, Any], tasks: Sequence[TaskSpec]
) -> list[dict[str, Any]]:
    """Rows of a chunk of tasks, in the chunk's order (executed on a worker)."""
    return [run_task(compute, params, t) for t in tasks]
