"""The columns of a sweep's table: their names and Arrow types for each compute.

A row is the task's identity and the ``to_dict()`` of its result — the dict the CLI prints with
``--json`` — flattened by :func:`flatten` (nested keys joined with ``"."``), so the CLI's JSON and
the sweep's rows share one set of keys. The same names are the keys of the rows that
:func:`capalloc_rs.sweep.tasks.run_task` returns, so a row converts to Arrow (or to a
:class:`~capalloc_rs.sweep.rowtable.RowTable` without pyarrow) column by column. pyarrow is
optional: :func:`columns` needs none, :func:`schema` needs it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from .._optional import require
from ..errors import InvalidInputError, MissingDependencyError

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["NOT_COLUMNS", "arrow", "columns", "flatten", "have_pyarrow", "rows_to_table", "schema"]


def arrow() -> Any:
    """The pyarrow module (with ``pyarrow.parquet`` loaded).

    Raises:
        MissingDependencyError: pyarrow is not installed (the message has the pip command).
    """
    pyarrow = require("pyarrow", "a sweep's Parquet output")
    require("pyarrow.parquet", "a sweep's Parquet output")
    return pyarrow


def have_pyarrow() -> bool:
    """Whether pyarrow can be imported."""
    try:
        arrow()
    except MissingDependencyError:
        return False
    return True


_F, _I, _S, _B = "float64", "int64", "string", "bool"
_FL, _IL = "list<float64>", "list<int64>"
_EVENTS = (
    "list<struct<sigma: float64, kind: string, sensor: int64, mu: float64, shadow_price: float64, "
    "budget: float64>>"
)

#: The columns every row has: the task's identity, its failure, and the figure ``eta`` with the
#: rates ``r`` and multiplier ``mu`` where the compute has them (``r_tot`` is a slot count for
#: schedules, a capacity otherwise).
_COMMON = [
    ("task_id", _S),
    ("network_index", _I),
    ("r_tot", _F),
    ("network_digest", _S),
    ("num_sensors", _I),
    ("error", _S),
    ("eta", _F),
    ("r", _FL),
    ("mu", _F),
]

#: The columns of each compute after the common ones: the keys of its result's ``to_dict()``
#: (:meth:`Allocation.to_dict`, :meth:`Filtration.to_dict`, :meth:`BestSchedule.to_dict`,
#: :meth:`RobustAllocation.to_dict` with ``nominal_value``; its ``eta`` is the robust ``value``),
#: flattened by :func:`flatten`.
_EXTRA: dict[str, list[tuple[str, str]]] = {
    "allocation": [
        ("sigma", _F),
        ("gamma", _FL),
        ("gradient", _FL),
        ("active", _IL),
        ("certificate.frank_wolfe_gap", _F),
        ("certificate.kkt_residual", _F),
        ("iterations", _I),
        ("method", _S),
        ("hessian", _S),
        ("hessian_vector_products", _I),
        ("eta_error", _F),
        ("certified", _B),
        ("optimality", _F),
        ("shadow_price", _F),
        ("budget", _F),
        ("costs", _FL),
        ("at_minimum", _IL),
        ("at_cap", _IL),
        ("lower_multipliers", _FL),
        ("upper_multipliers", _FL),
    ],
    "filtration": [
        ("sigma_max", _F),
        ("breakpoints", _FL),
        ("active_sets", "list<list<int64>>"),
        ("entry_order", _IL),
        ("events", _EVENTS),
        ("is_monotone", _B),
        ("is_filtration", _B),
        ("diagonally_dominant", _B),
        ("converged", _B),
        ("stopped", _S),
        ("sigma_requested", _F),
        ("capped_sets", "list<list<int64>>"),
        ("budget_min", _F),
        ("shadow_price", _F),
    ],
    "schedule": [
        ("tau", _F),
        ("schedule", _IL),
        ("counts", _IL),
        ("which", _S),
        ("eta_bar", _F),
        ("eta_limit", _F),
        ("error_vs_limit", _F),
        ("relative_error_vs_limit", _F),
        ("converged", _B),
        ("stopped", _S),
        ("moves", _I),
        ("evaluations", _I),
        ("baselines.initial", _F),
        ("baselines.round_robin", _F),
        ("baselines.greedy", _F),
        ("budget", _F),
        ("budget_used", _F),
        ("start", _S),
        ("lower_bound", _F),
        ("gap", _F),
        ("proven_optimal", _B),
        ("nodes", _I),
    ],
    "robust": [
        ("objective", _S),
        ("value", _F),
        ("eta_per_model", _FL),
        ("weights", _FL),
        ("lower_bound", _F),
        ("gap", _F),
        ("shadow_price", _F),
        ("iterations", _I),
        ("evaluations", _I),
        ("eta_error", _F),
        ("certified", _B),
        ("budget", _F),
        ("num_models", _I),
        ("nominal_value", _F),
    ],
}

#: Keys of a result's ``to_dict()`` that are not columns: the search's wall time (a sweep's rows
#: are deterministic, so that a resumed sweep returns the same table as an uninterrupted one).
NOT_COLUMNS: dict[str, frozenset[str]] = {
    "allocation": frozenset(),
    "filtration": frozenset(),
    "schedule": frozenset({"elapsed"}),
    "robust": frozenset(),
}


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """A result's ``to_dict()`` as the columns of one row: a nested dict becomes one column per
    key, named by the path of keys joined with ``"."`` — as :func:`pandas.json_normalize` does —
    so ``{"certificate": {"frank_wolfe_gap": g}}`` gives the column ``certificate.frank_wolfe_gap``.
    Lists (of numbers, of lists, of dicts) stay one list column.

    Args:
        d: a dict of plain JSON-ready values.
        prefix: the path of ``d`` itself (empty at the top).

    Returns:
        A dict with no dict values.
    """
    out: dict[str, Any] = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flatten(v, f"{name}."))
        else:
            out[name] = v
    return out


def columns(compute: str) -> list[tuple[str, str]]:
    """The columns of a sweep's table for ``compute``: ``(name, Arrow type name)`` pairs (also
    the keys of the rows of an in-memory sweep without pyarrow).

    Raises:
        InvalidInputError: ``compute`` is not ``"allocation"``, ``"filtration"``, ``"schedule"``
            or ``"robust"``.
    """
    if compute not in _EXTRA:
        raise InvalidInputError(f"compute must be one of {', '.join(_EXTRA)}, got {compute!r}")
    fields = _COMMON + _EXTRA[compute]
    if compute == "schedule":  # slots; schedules have no rates or multiplier
        fields = [("r_tot", _I) if f[0] == "r_tot" else f for f in fields]
        fields = [f for f in fields if f[0] not in ("r", "mu")]
    return fields


def schema(compute: str) -> pa.Schema:
    """The Arrow schema of a sweep's table for ``compute`` (see :func:`columns`)."""
    pa = arrow()
    f64, i64 = pa.float64(), pa.int64()
    event = pa.struct(
        [
            ("sigma", f64),
            ("kind", pa.string()),
            ("sensor", i64),
            ("mu", f64),
            ("shadow_price", f64),
            ("budget", f64),
        ]
    )
    types = {
        _S: pa.string(),
        _I: i64,
        _F: f64,
        _B: pa.bool_(),
        _FL: pa.list_(f64),
        _IL: pa.list_(i64),
        "list<list<int64>>": pa.list_(pa.list_(i64)),
        _EVENTS: pa.list_(event),
    }
    return pa.schema([(name, types[t]) for name, t in columns(compute)])


def rows_to_table(rows: Sequence[Mapping[str, Any]], sch: pa.Schema) -> pa.Table:
    """The Arrow table of ``rows`` (dicts keyed by column name; a missing key is a null)."""
    pa = arrow()
    cols = {name: [row.get(name) for row in rows] for name in sch.names}
    return pa.Table.from_pydict(cols, schema=sch)
