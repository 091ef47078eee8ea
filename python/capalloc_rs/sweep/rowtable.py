"""The table of an in-memory sweep when pyarrow is not installed.

:class:`RowTable` holds the same rows, columns and order as the :class:`pyarrow.Table` that
:func:`capalloc_rs.sweep` returns when pyarrow is there, and the read-only part of its API that
a user of the results needs: ``num_rows``, ``column_names``, ``column(name).to_pylist()``,
``to_pylist()``, ``to_pydict()`` and ``to_pandas()`` (needs pandas: ``pip install
'capalloc-rs[sweep]'``). Values are plain Python objects (ints, floats, lists, ``None``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from .._optional import require

__all__ = ["Column", "RowTable"]


class Column(list[Any]):
    """One column: a list of values, with the pyarrow calls that read it."""

    def to_pylist(self) -> list[Any]:
        return list(self)

    @property
    def null_count(self) -> int:
        return sum(v is None for v in self)


class RowTable:
    """Rows of a sweep (see the module docstring); ``metadata`` is the pyarrow table's schema
    metadata (``{b"capalloc.sweep": …}``)."""

    def __init__(
        self,
        rows: Sequence[Mapping[str, Any]],
        names: Sequence[str],
        metadata: Mapping[bytes, bytes] | None = None,
    ) -> None:
        self._names = list(names)
        self._rows = [{k: row.get(k) for k in self._names} for row in rows]
        self.metadata = dict(metadata or {})

    @property
    def num_rows(self) -> int:
        return len(self._rows)

    def __len__(self) -> int:
        return len(self._rows)

    @property
    def column_names(self) -> list[str]:
        return list(self._names)

    def column(self, name: str) -> Column:
        if name not in self._names:
            raise KeyError(f"no column {name!r}; the columns are {', '.join(self._names)}")
        return Column(row[name] for row in self._rows)

    def to_pylist(self) -> list[dict[str, Any]]:
        return [dict(row) for row in self._rows]

    def to_pydict(self) -> dict[str, list[Any]]:
        return {k: self.column(k).to_pylist() for k in self._names}

    def to_pandas(self) -> Any:
        pd = require("pandas", "RowTable.to_pandas")
        return pd.DataFrame(self.to_pydict(), columns=self._names)

    def __repr__(self) -> str:
        """One line: the size and the first column names."""
        shown = ", ".join(self._names[:4]) + (", …" if len(self._names) > 4 else "")
        return f"RowTable({self.num_rows} rows × {len(self._names)} columns: {shown})"
