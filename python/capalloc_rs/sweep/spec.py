"""Sweep spec files: a sweep described in TOML or JSON (schema in ``examples/sweep.toml``).

A spec names what each task computes (``compute`` and its parameters), the capacities (a list,
or ``{start, stop, num}`` for ``numpy.linspace``), and the networks: model files (relative to the
spec's directory) and/or a ``[networks.random]`` table of :func:`random_networks` arguments.
:func:`load_spec` checks every field and the sweep's size against :mod:`capalloc_rs.limits`, and
refuses a malformed spec with a :class:`~capalloc_rs.errors.SweepError` naming the field.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import limits
from .._textdata import finite_float, read_data
from ..allocation import HESSIAN_MODES, one_of
from ..errors import InvalidInputError, SweepError
from ..network import Network
from .networks import Chain, random_networks
from .options import task_params
from .rowtable import RowTable
from .run import sweep
from .tasks import COMPUTES

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["SPEC_FORMAT", "SweepSpec", "load_spec"]

SPEC_FORMAT = "capalloc-sweep"

_SPEC_KEYS = {
    "format",
    "version",
    "compute",
    "capacities",
    "networks",
    "tau",
    "which",
    "method",
    "tol",
    "hessian",
    "chunk_size",
    "robust",
}
_RANDOM_KEYS = {"count", "N", "n", "p", "eps", "seed", "r_min", "costs", "r_max"}
#: The defaults of the optional keys of ``[networks.random]`` (those of :func:`random_networks`).
_RANDOM_DEFAULTS: dict[str, Any] = {"n": 2, "p": 1, "eps": 0.1, "seed": 0, "r_min": 1.0}
_RANDOM_INTEGERS = ("count", "N", "n", "p", "seed")


@dataclass(frozen=True)
class SweepSpec:
    """A parsed sweep spec file (see :func:`load_spec`).

    Attributes:
        files: model files (resolved against the spec's directory).
        random: keyword arguments of :func:`random_networks`, or ``None``.
        capacities: the ``r_tot`` values.
        compute: what each task computes, as in :func:`~capalloc_rs.sweep.sweep`.
        tau: the period of ``compute = "schedule"``.
        which: the figure of ``compute = "schedule"``.
        method: the allocation method.
        tol: the tolerance, or ``None`` for the function's own.
        chunk_size: tasks per chunk.
        hessian: the Newton variant of the allocation.
        robust: the ``[robust]`` table of ``compute = "robust"`` (``objective``,
            ``num_models``, ``eps = [low, high]``, ``seed``; see
            :func:`~capalloc_rs.sweep.sweep`), or ``None``.
    """

    files: tuple[Path, ...]
    random: Mapping[str, Any] | None
    capacities: tuple[float, ...]
    compute: str
    tau: float | None
    which: str
    method: str
    tol: float | None
    chunk_size: int
    hessian: str = "auto"
    robust: Mapping[str, Any] | None = None

    def networks(self) -> Sequence[Network | Path]:
        """The spec's networks as a lazy sequence: the model files (as paths, loaded by
        :func:`~capalloc_rs.sweep.sweep`, so a bad file gives error rows), then the random
        networks."""
        rnd: Sequence[Network] = []
        if self.random is not None:
            r = dict(self.random)
            rnd = random_networks(
                r["count"],
                r["N"],
                r["n"],
                r["p"],
                r["eps"],
                r["seed"],
                r["r_min"],
                costs=r.get("costs"),
                r_max=r.get("r_max"),
            )
        return Chain(list(self.files), rnd)

    @property
    def num_networks(self) -> int:
        """How many networks the spec describes."""
        return len(self.files) + (0 if self.random is None else int(self.random["count"]))

    def run(self, **kwargs: Any) -> pa.Table | RowTable:
        """:func:`~capalloc_rs.sweep.sweep` over this spec (keyword arguments: ``executor``,
        ``out``, …)."""
        kwargs.setdefault("chunk_size", self.chunk_size)
        return sweep(
            self.networks(),
            self.capacities,
            compute=self.compute,
            tau=self.tau,
            which=self.which,
            method=self.method,
            tol=self.tol,
            hessian=self.hessian,
            robust=self.robust if self.compute == "robust" else None,
            **kwargs,
        )


def _spec_number(name: str, v: Any, *, integer: bool = False) -> Any:
    f = finite_float(v)
    ok = f is not None
    if ok and integer:
        ok = isinstance(v, int) or float(v).is_integer()
    if not ok:
        kind = "an integer" if integer else "a number"
        raise SweepError(f"spec: {name} must be {kind}, got {v!r}")
    return int(v) if integer else float(v)


def _read(p: Path) -> dict[str, Any]:
    """The spec's top-level table, after the checks of its keys, format and version."""
    fmt = "json" if p.suffix.lower() == ".json" else "toml"
    d = read_data(p, fmt, lambda msg: SweepError(f"{p}: {msg}"))
    if not isinstance(d, dict):
        raise SweepError(f"{p}: the spec must be a table/object at the top level")
    unknown = sorted(set(d) - _SPEC_KEYS)
    if unknown:
        raise SweepError(f"{p}: unknown key(s) {', '.join(unknown)}")
    if d.get("format", SPEC_FORMAT) != SPEC_FORMAT:
        raise SweepError(f"{p}: format must be {SPEC_FORMAT!r}, got {d['format']!r}")
    if d.get("version", 1) != 1:
        raise SweepError(f"{p}: unsupported version {d['version']!r} (this build reads 1)")
    return d


def _capacity_range(p: Path, raw: Mapping[str, Any]) -> tuple[float, ...]:
    """``capacities = {start, stop, num}``: ``num`` values of ``numpy.linspace``."""
    extra = sorted(set(raw) - {"start", "stop", "num"})
    if extra or not {"start", "stop", "num"} <= set(raw):
        raise SweepError(f"{p}: capacities as a table needs exactly start, stop, num")
    num = _spec_number("capacities.num", raw["num"], integer=True)
    if num < 1:
        raise SweepError(f"{p}: capacities.num must be at least 1")
    if num > limits.MAX_SWEEP_TASKS:
        raise SweepError(
            f"{p}: capacities.num = {num} is more than capalloc_rs.limits.MAX_SWEEP_TASKS = "
            f"{limits.MAX_SWEEP_TASKS}"
        )
    start = _spec_number("capacities.start", raw["start"])
    stop = _spec_number("capacities.stop", raw["stop"])
    return tuple(float(x) for x in np.linspace(start, stop, num))


def _capacities(p: Path, raw: Any) -> tuple[float, ...]:
    if raw is None:
        raise SweepError(f"{p}: capacities is missing")
    if isinstance(raw, dict):
        return _capacity_range(p, raw)
    if isinstance(raw, list) and raw:
        return tuple(_spec_number(f"capacities[{k}]", v) for k, v in enumerate(raw))
    raise SweepError(f"{p}: capacities must be a non-empty list or {{start, stop, num}}")


def _check_random(p: Path, rnd: Mapping[str, Any]) -> None:
    """The random networks' sizes: positive, and within ``limits.MAX_MODEL_STATES``."""
    for k in ("count", "N", "n", "p"):
        if rnd[k] < (0 if k == "count" else 1):
            raise SweepError(f"{p}: networks.random.{k} must be positive, got {rnd[k]}")
    states = rnd["N"] * rnd["n"]
    if states > limits.MAX_MODEL_STATES or rnd["p"] > limits.MAX_MODEL_STATES:
        raise SweepError(
            f"{p}: networks.random needs N·n ≤ capalloc_rs.limits.MAX_MODEL_STATES = "
            f"{limits.MAX_MODEL_STATES} (and p as well), got N = {rnd['N']}, n = {rnd['n']}, "
            f"p = {rnd['p']}"
        )
    if rnd["seed"] < 0:
        raise SweepError(f"{p}: networks.random.seed must be non-negative, got {rnd['seed']}")


def _random(p: Path, r: Any) -> dict[str, Any]:
    """The ``[networks.random]`` table as :func:`random_networks` arguments."""
    if not isinstance(r, dict):
        raise SweepError(f"{p}: networks.random must be a table")
    bad = sorted(set(r) - _RANDOM_KEYS)
    if bad:
        raise SweepError(f"{p}: unknown key(s) in networks.random: {', '.join(bad)}")
    for req in ("count", "N"):
        if req not in r:
            raise SweepError(f"{p}: networks.random.{req} is missing")
    rnd = {
        k: _spec_number(
            f"networks.random.{k}", r.get(k, _RANDOM_DEFAULTS.get(k)), integer=k in _RANDOM_INTEGERS
        )
        for k in ("count", "N", "n", "p", "eps", "seed", "r_min")
    }
    for k in ("costs", "r_max"):  # scalars or one per sensor, checked by the networks
        if k in r:
            rnd[k] = _limit_value(f"networks.random.{k}", r[k], inf_ok=k == "r_max")
    _check_random(p, rnd)
    return rnd


def _limit_value(name: str, v: Any, *, inf_ok: bool) -> Any:
    """A per-sensor property of the random networks: a number or a list of numbers (``inf`` is
    no cap)."""
    if isinstance(v, list):
        return [_limit_value(f"{name}[{k}]", x, inf_ok=inf_ok) for k, x in enumerate(v)]
    if inf_ok and isinstance(v, float) and v == float("inf"):
        return v
    return _spec_number(name, v)


def _networks(p: Path, nets: Any) -> tuple[tuple[Path, ...], dict[str, Any] | None]:
    """The ``[networks]`` table: the model files and the random networks' arguments."""
    if not isinstance(nets, dict) or not nets:
        raise SweepError(f"{p}: [networks] with files = [...] and/or [networks.random] is missing")
    unknown = sorted(set(nets) - {"files", "random"})
    if unknown:
        raise SweepError(f"{p}: unknown key(s) in networks: {', '.join(unknown)}")
    files_raw = nets.get("files", [])
    if not isinstance(files_raw, list) or not all(isinstance(f, str) for f in files_raw):
        raise SweepError(f"{p}: networks.files must be a list of paths")
    files = tuple(p.parent / f for f in files_raw)
    rnd = _random(p, nets["random"]) if "random" in nets else None
    if not files and rnd is None:
        raise SweepError(f"{p}: networks has no files and no random table")
    return files, rnd


def _check_size(p: Path, num_networks: int, num_capacities: int) -> None:
    tasks = num_networks * num_capacities
    if tasks > limits.MAX_SWEEP_TASKS:
        raise SweepError(
            f"{p}: {tasks} tasks (networks × capacities), more than "
            f"capalloc_rs.limits.MAX_SWEEP_TASKS = {limits.MAX_SWEEP_TASKS}; split the sweep"
        )


def _choices(p: Path, d: Mapping[str, Any]) -> tuple[str, str, str]:
    """``which``, ``method`` and ``hessian`` (strings; the Newton variant checked here, the rest
    by :func:`~capalloc_rs.sweep.sweep`)."""
    which = d.get("which", "boundary")
    method = d.get("method", "newton")
    hessian = d.get("hessian", "auto")
    if not all(isinstance(v, str) for v in (which, method, hessian)):
        raise SweepError(f"{p}: which, method and hessian must be strings")
    if hessian not in HESSIAN_MODES:
        raise SweepError(f"{p}: hessian must be {one_of(HESSIAN_MODES)}, got {hessian!r}")
    return which, method, hessian


def _optional_number(d: Mapping[str, Any], key: str) -> float | None:
    v = d.get(key)
    return None if v is None else float(_spec_number(key, v))


def _robust(p: Path, d: Mapping[str, Any], compute: str) -> dict[str, Any] | None:
    """The ``[robust]`` table (only with ``compute = "robust"``; keys checked, values checked by
    :func:`~capalloc_rs.sweep.sweep`'s options, here as SweepError)."""
    raw = d.get("robust")
    if raw is None:
        return {} if compute == "robust" else None
    if compute != "robust":
        raise SweepError(f"{p}: [robust] applies to compute = 'robust'")
    if not isinstance(raw, dict):
        raise SweepError(f"{p}: robust must be a table")
    try:
        task_params("robust", None, "boundary", "newton", None, "auto", raw)
    except InvalidInputError as exc:
        raise SweepError(f"{p}: {exc}") from None
    return dict(raw)


def load_spec(path: str | os.PathLike[str]) -> SweepSpec:
    """Reads a sweep spec (TOML or JSON, by extension; schema in ``examples/sweep.toml``).

    Args:
        path: the spec file (``.json`` is read as JSON, anything else as TOML).

    Returns:
        The parsed spec.

    Raises:
        SweepError: a malformed spec (the message names the field).
        OSError: an unreadable file.
    """
    p = Path(path)
    d = _read(p)
    compute = d.get("compute", "allocation")
    if compute not in COMPUTES:
        raise SweepError(f"{p}: compute must be one of {', '.join(COMPUTES)}, got {compute!r}")
    caps = _capacities(p, d.get("capacities"))
    files, rnd = _networks(p, d.get("networks"))
    _check_size(p, len(files) + (rnd["count"] if rnd else 0), len(caps))
    if compute == "schedule" and d.get("tau") is None:
        raise SweepError(f"{p}: compute = 'schedule' needs tau")
    which, method, hessian = _choices(p, d)
    return SweepSpec(
        robust=_robust(p, d, compute),
        files=files,
        random=rnd,
        capacities=caps,
        compute=compute,
        tau=_optional_number(d, "tau"),
        which=which,
        method=method,
        tol=_optional_number(d, "tol"),
        chunk_size=_spec_number("chunk_size", d.get("chunk_size", 16), integer=True),
        hessian=hessian,
    )
