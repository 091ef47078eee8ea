"""The options of one :func:`~capalloc_rs.sweep.sweep` call, checked once.

:class:`SweepOptions` is built from the keyword arguments of the call by
:meth:`SweepOptions.build`, which refuses bad arguments with an
:class:`~capalloc_rs.errors.InvalidInputError` naming the argument; afterwards the sweep trusts
it. The task parameters (``params``) are the values that enter every task id: for allocations the
method, tolerance and (if not ``"auto"``) the Newton variant; for filtrations the tolerance; for
schedules the period ``tau`` and the figure ``which``; for robust allocations the objective, the
number of models, the coupling range, the seed and the tolerance.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import limits
from .._arrays import as_count, as_real
from ..allocation import HESSIAN_MODES, METHODS, OBJECTIVES, one_of
from ..errors import InvalidInputError
from .columns import arrow, have_pyarrow
from .tasks import COMPUTES

__all__ = ["SweepOptions", "check_task_count"]


def check_task_count(count: int) -> None:
    """Refuses a sweep of more than ``limits.MAX_SWEEP_TASKS`` tasks."""
    if count > limits.MAX_SWEEP_TASKS:
        raise InvalidInputError(
            f"the sweep has {count} tasks (networks × capacities), more than "
            f"capalloc_rs.limits.MAX_SWEEP_TASKS = {limits.MAX_SWEEP_TASKS}; split it"
        )


def _allocation_params(method: str, tol: float | None, hessian: str) -> dict[str, Any]:
    if method not in METHODS:
        raise InvalidInputError(f"method must be {one_of(METHODS)}, got {method!r}")
    if hessian not in HESSIAN_MODES:
        raise InvalidInputError(f"hessian must be {one_of(HESSIAN_MODES)}, got {hessian!r}")
    params: dict[str, Any] = {
        "method": method,
        "tol": 1e-12 if tol is None else as_real("tol", tol, positive=True),
    }
    if hessian != "auto":  # absent for "auto": task ids of earlier sweeps stay valid
        params["hessian"] = hessian
    return params


def _schedule_params(tau: float | None, which: str) -> dict[str, Any]:
    if tau is None or as_real("tau", tau) <= 0:
        raise InvalidInputError(f"compute='schedule' needs a period tau > 0, got {tau!r}")
    if which not in ("boundary", "average"):
        raise InvalidInputError(f"which must be 'boundary' or 'average', got {which!r}")
    return {"tau": float(tau), "which": which}


#: The keys of ``robust=`` and their defaults (``objective``, models, coupling range, seed).
ROBUST_DEFAULTS: dict[str, Any] = {
    "objective": "mean",
    "num_models": 8,
    "eps": (0.0, 0.3),
    "seed": 0,
}


def _robust_params(robust: Mapping[str, Any] | None, tol: float | None) -> dict[str, Any]:
    """``robust=`` checked: ``objective``, ``num_models``, ``eps = (low, high)``, ``seed``."""
    raw = dict(ROBUST_DEFAULTS)
    if robust is not None:
        if not isinstance(robust, Mapping):
            raise InvalidInputError(f"robust must be a mapping, got {type(robust).__name__}")
        unknown = sorted(set(robust) - set(ROBUST_DEFAULTS))
        if unknown:
            raise InvalidInputError(f"robust: unknown key(s) {', '.join(map(str, unknown))}")
        raw.update(robust)
    if raw["objective"] not in OBJECTIVES:
        raise InvalidInputError(
            f"robust objective must be {one_of(OBJECTIVES)}, got {raw['objective']!r}"
        )
    eps = raw["eps"]
    if isinstance(eps, str | bytes) or not isinstance(eps, Sequence) or len(eps) != 2:
        raise InvalidInputError(f"robust eps must be [low, high], got {eps!r}")
    low, high = as_real("robust eps[0]", eps[0]), as_real("robust eps[1]", eps[1])
    if high < low:
        raise InvalidInputError(f"robust eps must be [low, high] with low ≤ high, got {eps!r}")
    return {
        "objective": raw["objective"],
        "num_models": as_count("robust num_models", raw["num_models"], minimum=1, maximum=10_000),
        "eps_low": low,
        "eps_high": high,
        "seed": as_count("robust seed", raw["seed"]),
        "tol": 1e-12 if tol is None else as_real("tol", tol, positive=True),
    }


def task_params(
    compute: str,
    tau: float | None,
    which: str,
    method: str,
    tol: float | None,
    hessian: str = "auto",
    robust: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The parameters of every task of a ``compute`` sweep (see the module docstring)."""
    if compute not in COMPUTES:
        raise InvalidInputError(f"compute must be one of {', '.join(COMPUTES)}, got {compute!r}")
    if robust is not None and compute != "robust":
        raise InvalidInputError("robust= applies to compute='robust'")
    if compute == "robust":
        return _robust_params(robust, tol)
    if compute == "allocation":
        return _allocation_params(method, tol, hessian)
    if compute == "filtration":
        return {"tol": 1e-10 if tol is None else as_real("tol", tol, positive=True)}
    return _schedule_params(tau, which)


def _capacity(c: Any, compute: str) -> float:
    if isinstance(c, bool):
        raise InvalidInputError(f"capacities must be numbers, got {c!r}")
    try:
        v = float(c)
    except (TypeError, ValueError):
        raise InvalidInputError(f"capacities must be numbers, got {c!r}") from None
    if not math.isfinite(v):
        raise InvalidInputError(f"capacities must be finite, got {c!r}")
    if compute == "schedule" and v != math.floor(v):
        raise InvalidInputError(f"schedule capacities must be integers (slots), got {c!r}")
    return v


def checked_capacities(capacities: Iterable[float], compute: str) -> tuple[float, ...]:
    """The capacities as floats, duplicates dropped, in their order."""
    if isinstance(capacities, str | bytes) or not isinstance(capacities, Iterable):
        raise InvalidInputError(f"capacities must be a list of numbers, got {capacities!r}")
    out = tuple(dict.fromkeys(_capacity(c, compute) for c in capacities))
    if not out:
        raise InvalidInputError("capacities is empty")
    return out


def _optional_count(name: str, v: int | None, maximum: int | None = None) -> int | None:
    if v is None:
        return None
    if maximum is None:
        return as_count(name, v, minimum=1)
    return as_count(name, v, minimum=1, maximum=maximum)


def _checked_executor(executor: Executor | None) -> Executor | None:
    if executor is not None and not hasattr(executor, "submit"):
        raise InvalidInputError(f"executor must be a concurrent.futures.Executor, got {executor!r}")
    return executor


@dataclass(frozen=True)
class SweepOptions:
    """The checked options of one sweep (see :func:`~capalloc_rs.sweep.sweep` for each).

    Attributes:
        compute: what each task computes.
        params: the task parameters (they enter every task id).
        capacities: the ``r_tot`` values, without duplicates.
        executor: the caller's executor, or ``None`` for the sweep's own.
        workers: processes of the sweep's own executor.
        max_pending: chunks in flight at once, or ``None`` for twice the executor's width.
        chunk_size: tasks per chunk.
        out_dir: the Parquet directory, or ``None`` (in memory).
        resume: skip tasks already saved in ``out_dir``.
        progress: show a progress bar.
        arrow: return a pyarrow table (else, in memory without pyarrow, a RowTable).
    """

    compute: str
    params: Mapping[str, Any]
    capacities: tuple[float, ...]
    executor: Executor | None
    workers: int
    max_pending: int | None
    chunk_size: int
    out_dir: Path | None
    resume: bool
    progress: bool
    arrow: bool

    @classmethod
    def build(
        cls,
        capacities: Iterable[float],
        *,
        compute: str,
        tau: float | None,
        which: str,
        method: str,
        tol: float | None,
        hessian: str,
        executor: Executor | None,
        workers: int | None,
        out: str | os.PathLike[str] | None,
        resume: bool,
        progress: bool,
        chunk_size: int,
        max_pending: int | None,
        robust: Mapping[str, Any] | None = None,
    ) -> SweepOptions:
        """The options of a :func:`~capalloc_rs.sweep.sweep` call, in the order it checks them.

        Raises:
            InvalidInputError: a bad argument (the message names it).
            MissingDependencyError: ``out`` is given and pyarrow is not installed.
        """
        if out is not None:
            arrow()  # fail now if pyarrow is missing: Parquet output needs it
        params = task_params(compute, tau, which, method, tol, hessian, robust)
        caps = checked_capacities(capacities, compute)
        size = as_count("chunk_size", chunk_size, minimum=1)
        n_workers = _optional_count("workers", workers, limits.MAX_SWEEP_WORKERS)
        return cls(
            compute=compute,
            params=params,
            capacities=caps,
            max_pending=_optional_count("max_pending", max_pending),
            executor=_checked_executor(executor),
            workers=n_workers if n_workers is not None else (os.cpu_count() or 1),
            chunk_size=size,
            out_dir=None if out is None else Path(out),
            resume=bool(resume),
            progress=bool(progress),
            arrow=out is not None or have_pyarrow(),
        )

    def window(self, width: int) -> int:
        """Chunks in flight at once, for an executor running ``width`` calls at once."""
        if self.max_pending is not None:
            return self.max_pending
        return 2 * max(width, 1)
