"""The columns of a sweep's table: their names and Arrow types for each compute.

The same names are the keys of the rows that :func:`capalloc_rs.sweep.tasks.run_task` returns, so
a row converts to Arrow (or to a :class:`~capalloc_rs.sweep.rowtable.RowTable` without pyarrow)
column by column. pyarrow is optional: :func:`columns` needs none, :func:`schema` needs it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from .._optional import require
from ..errors import InvalidInputError, MissingDependencyError
from .tasks import COMPUTES

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = ["arrow", "columns", "have_pyarrow", "rows_to_table", "schema"]


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


_FL, _IL = "list<float64>", "list<int64>"

#: Columns every row has (``r_tot`` is a slot count for schedules, a capacity otherwise).
_COMMON = [
    ("task_id", "string"),
    ("network_index", "int64"),
    ("r_tot", "float64"),
    ("network_digest", "string"),
    ("num_sensors", "int64"),
    ("error", "string"),
    ("eta", "float64"),
    ("r", _FL),
    ("mu", "float64"),
]

#: The columns of each compute after the common ones.
_EXTRA: dict[str, list[tuple[str, str]]] = {
    "allocation": [
        ("gamma", _FL),
        ("gradient", _FL),
        ("active", _IL),
        ("gap", "float64"),
        ("kkt_residual", "float64"),
        ("iterations", "int64"),
    ],
    "filtration": [
        ("sigma_max", "float64"),
        ("breakpoints", _FL),
        ("active_sets", "list<list<int64>>"),
        ("entry_order", _IL),
        ("is_monotone", "bool"),
        ("is_filtration", "bool"),
    ],
    "schedule": [
        ("tau", "float64"),
        ("schedule", _IL),
        ("counts", _IL),
        ("eta_bar", "float64"),
        ("eta_limit", "float64"),
        ("relative_error", "float64"),
        ("converged", "bool"),
    ],
}


def columns(compute: str) -> list[tuple[str, str]]:
    """The columns of a sweep's table for ``compute``: ``(name, Arrow type name)`` pairs (also
    the keys of the rows of an in-memory sweep without pyarrow).

    Raises:
        InvalidInputError: ``compute`` is not one of :data:`~capalloc_rs.sweep.tasks.COMPUTES`.
    """
    if compute not in _EXTRA:
        raise InvalidInputError(f"compute must be one of {', '.join(COMPUTES)}, got {compute!r}")
    fields = _COMMON + _EXTRA[compute]
    if compute == "schedule":  # slots; schedules have no rates or multiplier
        fields = [("r_tot", "int64") if f[0] == "r_tot" else f for f in fields]
        fields = [f for f in fields if f[0] not in ("r", "mu")]
    return fields


def schema(compute: str) -> pa.Schema:
    """The Arrow schema of a sweep's table for ``compute`` (see :func:`columns`)."""
    pa = arrow()
    f64, i64 = pa.float64(), pa.int64()
    types = {
        "string": pa.string(),
        "int64": i64,
        "float64": f64,
        "bool": pa.bool_(),
        "list<float64>": pa.list_(f64),
        "list<int64>": pa.list_(i64),
        "list<list<int64>>": pa.list_(pa.list_(i64)),
    }
    return pa.schema([(name, types[t]) for name, t in columns(compute)])


def rows_to_table(rows: Sequence[Mapping[str, Any]], sch: pa.Schema) -> pa.Table:
    """The Arrow table of ``rows`` (dicts keyed by column name; a missing key is a null)."""
    pa = arrow()
    cols = {name: [row.get(name) for row in rows] for name in sch.names}
    return pa.Table.from_pydict(cols, schema=sch)
