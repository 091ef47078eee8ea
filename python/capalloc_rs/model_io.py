"""Reading and writing networks: TOML and JSON (small models, human-readable) and ``.npz`` (large).

TOML/JSON schema (version 1). Matrices are lists of rows; a sensor matrix with one column may be
written as a flat list. Indices count from 0. Unknown keys are errors (they are usually typos).

Top level:

* ``format = "capalloc-network"`` (optional; if present it must be this string);
* ``version = 1`` (optional);
* ``r_min`` — the minimum rate, ``> 0`` (optional, default 1.0);

then **either** the block form (the paper's model)

* ``eps`` — coupling strength ``ε`` (optional, default 0.0);
* ``[[subsystems]]`` — one table per subsystem with ``A`` (``n_i × n_i``), ``G`` (``n_i × n_i``,
  nonsingular) and ``c`` (``n_i × p_i``): sensor ``i`` measures ``c_iᵀ x_i``;
* ``[[couplings]]`` (optional) — tables with ``i``, ``j`` (``i ≠ j``) and ``A`` (``n_i × n_j``):
  the block ``A_ij`` of ``A`` is ``ε·A``;

**or** the general form

* ``A``, ``G`` (``n × n``) and ``[[sensors]]`` — tables with ``c`` (``n × p_i``).

Example (the paper's Example 1; ``examples/example1.toml``)::

    format = "capalloc-network"
    version = 1
    r_min = 1.0

    [[subsystems]]
    A = [[-1.0, 0.0], [0.0, -2.0]]
    G = [[2.23606797749979, 0.0], [-1.3416407864998738, 1.4832396974191326]]
    c = [1.0, 1.0]

JSON has the same structure (``{"subsystems": [{"A": …, "G": …, "c": …}], …}``).

``.npz`` files hold the arrays ``format``, ``version``, ``r_min`` and either ``A``, ``G``,
``sensor_0`` … (general form) or ``eps``, ``A_0``, ``G_0``, ``c_0`` …, and ``coupling`` (the
unscaled ``n × n`` coupling matrix, zero diagonal blocks) for block networks.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import limits
from ._arrays import F64
from ._npz import read_npz
from ._textdata import read_data
from .errors import CapallocError, InputError, ModelFormatError, NumericalError

if TYPE_CHECKING:
    from .network import Network

__all__ = ["FORMAT", "VERSION", "to_dict", "from_dict", "dumps_toml", "dumps_json", "save", "load"]

FORMAT = "capalloc-network"
VERSION = 1

_TOP_COMMON = {"format", "version", "r_min"}
_TOP_BLOCK = _TOP_COMMON | {"eps", "subsystems", "couplings"}
_TOP_GENERAL = _TOP_COMMON | {"A", "G", "sensors"}


# -- writing ------------------------------------------------------------------------------------


def _rows(m: F64) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(m)]


def _sensor(c: F64) -> list[float] | list[list[float]]:
    return [float(v) for v in c[:, 0]] if c.shape[1] == 1 else _rows(c)


def to_dict(net: Network) -> dict[str, Any]:
    """The network as plain lists and numbers (the TOML/JSON schema)."""
    d: dict[str, Any] = {"format": FORMAT, "version": VERSION, "r_min": net.r_min}
    st = net.structure
    if st is None:
        d["A"] = _rows(net.a)
        d["G"] = _rows(net.g)
        d["sensors"] = [{"c": _sensor(c)} for c in net.sensors]
        return d
    d["eps"] = st.eps
    d["subsystems"] = [
        {"A": _rows(a), "G": _rows(g), "c": _sensor(c)}
        for a, g, c in zip(st.a_blocks, st.g_blocks, st.c_blocks, strict=True)
    ]
    d["couplings"] = [{"i": i, "j": j, "A": _rows(b)} for (i, j), b in sorted(st.couplings.items())]
    if not d["couplings"]:
        del d["couplings"]
    return d


def _toml_value(v: Any, indent: str = "") -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError("TOML output of non-finite numbers is not supported")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a JSON string is a valid TOML basic string
    if isinstance(v, list):
        if v and isinstance(v[0], list):  # a matrix: one row per line
            inner = "".join(f"{indent}  {_toml_value(x)},\n" for x in v)
            return f"[\n{inner}{indent}]"
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(d: dict[str, Any]) -> str:
    """TOML text for a dict of the schema (scalars and matrices at the top level, then arrays of
    tables)."""
    lines = ["# capalloc-rs network model (schema: capalloc_rs.model_io)"]
    tables = {k: v for k, v in d.items() if isinstance(v, list) and v and isinstance(v[0], dict)}
    for k, v in d.items():
        if k not in tables:
            lines.append(f"{k} = {_toml_value(v)}")
    for k, items in tables.items():
        for item in items:
            lines.append("")
            lines.append(f"[[{k}]]")
            for kk, vv in item.items():
                lines.append(f"{kk} = {_toml_value(vv)}")
    return "\n".join(lines) + "\n"


def dumps_json(d: dict[str, Any]) -> str:
    """JSON text for a dict of the schema, one matrix row per line."""

    def enc(v: Any, ind: str) -> str:
        inner = ind + "  "
        if isinstance(v, dict):
            items = [f"{inner}{json.dumps(k)}: {enc(x, inner)}" for k, x in v.items()]
            return "{\n" + ",\n".join(items) + f"\n{ind}}}"
        if isinstance(v, list) and v and isinstance(v[0], list | dict):
            items = [f"{inner}{enc(x, inner)}" for x in v]
            return "[\n" + ",\n".join(items) + f"\n{ind}]"
        return json.dumps(v)

    return enc(d, "") + "\n"


def _format_of(path: Path, format: str | None) -> str:
    fmt = (format or path.suffix.lstrip(".")).lower()
    if fmt not in ("toml", "json", "npz"):
        raise InputError(
            f"unknown model format {fmt!r} for {path}: use 'toml', 'json' or 'npz' "
            "(or the matching file extension)"
        )
    return fmt


def save(net: Network, path: str | os.PathLike[str], format: str | None = None) -> None:
    """Writes ``net`` as TOML, JSON or ``.npz`` (by ``format`` or the extension of ``path``)."""
    p = Path(path)
    fmt = _format_of(p, format)
    if fmt == "toml":
        p.write_text(dumps_toml(to_dict(net)), encoding="utf-8")
    elif fmt == "json":
        p.write_text(dumps_json(to_dict(net)), encoding="utf-8")
    else:
        arrays: dict[str, Any] = {
            "format": np.array(FORMAT),
            "version": np.array(VERSION),
            "r_min": np.array(net.r_min),
        }
        st = net.structure
        if st is None:
            arrays["A"] = net.a
            arrays["G"] = net.g
            for i, c in enumerate(net.sensors):
                arrays[f"sensor_{i}"] = c
        else:
            arrays["eps"] = np.array(st.eps)
            for i, (a, g, c) in enumerate(zip(st.a_blocks, st.g_blocks, st.c_blocks, strict=True)):
                arrays[f"A_{i}"], arrays[f"G_{i}"], arrays[f"c_{i}"] = a, g, c
            arrays["coupling"] = st.coupling
        with open(p, "wb") as f:
            np.savez(f, **arrays)


# -- reading ------------------------------------------------------------------------------------


class _Fail(Exception):
    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}")


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _number(x: Any, field: str, *, positive: bool = False) -> float:
    if not _is_number(x):
        raise _Fail(field, f"expected a number, got {type(x).__name__} {_short(x)}")
    try:
        v = float(x)
    except OverflowError:
        raise _Fail(field, "a number too large for a float64") from None
    if not math.isfinite(v):
        raise _Fail(field, f"must be finite, got {v}")
    if positive and v <= 0:
        raise _Fail(field, f"must be positive, got {v}")
    return v


def _short(x: Any) -> str:
    r = repr(x) if not isinstance(x, list | dict) else f"of length {len(x)}"
    return r if len(r) <= 60 else r[:57] + "…"


def _integer(x: Any, field: str) -> int:
    if isinstance(x, bool) or not isinstance(x, int):
        raise _Fail(field, f"expected an integer, got {type(x).__name__} {_short(x)}")
    return x


def _dimension(field: str, size: int) -> None:
    if size > limits.MAX_MODEL_STATES:
        raise _Fail(
            field,
            f"{size} entries, more than capalloc_rs.limits.MAX_MODEL_STATES = "
            f"{limits.MAX_MODEL_STATES}",
        )


def _matrix(
    x: Any, field: str, *, rows: int | None = None, cols: int | None = None, vector_ok: bool = False
) -> F64:
    """A real matrix from a list of rows (or, with ``vector_ok``, a flat list = one column)."""
    if not isinstance(x, list) or not x:
        raise _Fail(field, f"expected a non-empty list of rows, got {type(x).__name__}")
    _dimension(field, len(x))
    if not any(isinstance(v, list) for v in x):  # a flat list
        if not vector_ok:
            raise _Fail(field, "expected a matrix (a list of rows), got a flat list")
        for k, v in enumerate(x):
            if not _is_number(v):
                raise _Fail(
                    f"{field}[{k}]", f"expected a number, got {type(v).__name__} {_short(v)}"
                )
        arr = _float_array([[v] for v in x], field)
    else:
        for k, row in enumerate(x):
            if not isinstance(row, list) or not row:
                raise _Fail(f"{field}[{k}]", "expected a non-empty list of numbers")
            _dimension(f"{field}[{k}]", len(row))
            for m, v in enumerate(row):
                if not _is_number(v):
                    raise _Fail(
                        f"{field}[{k}][{m}]",
                        f"expected a number, got {type(v).__name__} {_short(v)}",
                    )
        widths = {len(row) for row in x}
        if len(widths) != 1:
            raise _Fail(field, f"rows have different lengths {sorted(widths)}")
        arr = _float_array(x, field)
    if not np.all(np.isfinite(arr)):
        raise _Fail(field, "contains non-finite numbers")
    if rows is not None and arr.shape[0] != rows:
        raise _Fail(field, f"must have {rows} rows, got {arr.shape[0]}")
    if cols is not None and arr.shape[1] != cols:
        raise _Fail(field, f"must have {cols} columns, got {arr.shape[1]}")
    return arr


def _float_array(x: list[Any], field: str) -> F64:
    try:
        return np.array(x, dtype=np.float64)
    except OverflowError:
        raise _Fail(field, "contains a number too large for a float64") from None


def _square(x: Any, field: str) -> F64:
    m = _matrix(x, field)
    if m.shape[0] != m.shape[1]:
        raise _Fail(field, f"must be square, got {m.shape[0]}×{m.shape[1]}")
    return m


def _table(x: Any, field: str, allowed: set[str], required: set[str]) -> dict[str, Any]:
    if not isinstance(x, dict):
        raise _Fail(field, f"expected a table, got {type(x).__name__}")
    unknown = sorted(set(x) - allowed)
    if unknown:
        shown = ", ".join(_short(k) for k in unknown[:5]) + (" …" if len(unknown) > 5 else "")
        raise _Fail(field, f"unknown key(s) [{shown}] (allowed: {sorted(allowed)})")
    missing = sorted(required - set(x))
    if missing:
        raise _Fail(field, f"missing key(s) {missing}")
    return x


def _list_of_tables(x: Any, field: str) -> list[Any]:
    if not isinstance(x, list) or not x:
        raise _Fail(field, f"expected a non-empty array of tables, got {type(x).__name__}")
    _dimension(field, len(x))
    return x


def _parse(d: Any) -> Network:
    from .network import Network

    if not isinstance(d, dict):
        raise _Fail("<top level>", f"expected a table, got {type(d).__name__}")
    if "format" in d and d["format"] != FORMAT:
        raise _Fail("format", f"must be {FORMAT!r}, got {_short(d['format'])}")
    if "version" in d and _integer(d["version"], "version") != VERSION:
        raise _Fail("version", f"unsupported version {d['version']} (this reader knows {VERSION})")
    r_min = _number(d.get("r_min", 1.0), "r_min", positive=True)
    if "subsystems" in d:
        _table(d, "<top level>", _TOP_BLOCK, {"subsystems"})
        subs = _list_of_tables(d["subsystems"], "subsystems")
        a_b: list[F64] = []
        g_b: list[F64] = []
        c_b: list[F64] = []
        for i, s in enumerate(subs):
            f = f"subsystems[{i}]"
            _table(s, f, {"A", "G", "c"}, {"A", "G", "c"})
            a = _square(s["A"], f"{f}.A")
            n_i = a.shape[0]
            _dimension("subsystems (total state dimension)", sum(b.shape[0] for b in a_b) + n_i)
            a_b.append(a)
            g_b.append(_matrix(s["G"], f"{f}.G", rows=n_i, cols=n_i))
            c_b.append(_matrix(s["c"], f"{f}.c", rows=n_i, vector_ok=True))
        couplings: dict[tuple[int, int], F64] = {}
        for k, cp in enumerate(
            _list_of_tables(d["couplings"], "couplings") if "couplings" in d else []
        ):
            f = f"couplings[{k}]"
            _table(cp, f, {"i", "j", "A"}, {"i", "j", "A"})
            i, j = _integer(cp["i"], f"{f}.i"), _integer(cp["j"], f"{f}.j")
            for name, v in (("i", i), ("j", j)):
                if not 0 <= v < len(subs):
                    raise _Fail(f"{f}.{name}", f"{v} is out of range for {len(subs)} subsystems")
            if i == j:
                raise _Fail(f, f"i = j = {i}: a subsystem cannot be coupled to itself")
            if (i, j) in couplings:
                raise _Fail(f, f"the pair ({i}, {j}) appears twice")
            couplings[(i, j)] = _matrix(
                cp["A"], f"{f}.A", rows=a_b[i].shape[0], cols=a_b[j].shape[0]
            )
        eps = _number(d.get("eps", 0.0), "eps")
        return Network.from_blocks(a_b, g_b, c_b, couplings or None, eps, r_min)
    if "A" not in d:
        raise _Fail("<top level>", "needs either [[subsystems]] (block form) or A, G, [[sensors]]")
    _table(d, "<top level>", _TOP_GENERAL, {"A", "G", "sensors"})
    a = _square(d["A"], "A")
    n = a.shape[0]
    g = _matrix(d["G"], "G", rows=n, cols=n)
    sensors = []
    for i, s in enumerate(_list_of_tables(d["sensors"], "sensors")):
        _table(s, f"sensors[{i}]", {"c"}, {"c"})
        sensors.append(_matrix(s["c"], f"sensors[{i}].c", rows=n, vector_ok=True))
    return Network(a, g, sensors, r_min)


def from_dict(d: Any, source: str = "model") -> Network:
    """A network from the schema's dict. Malformed data raise :class:`ModelFormatError` naming
    ``source`` and the field; invalid models raise the network's own errors."""
    try:
        return _parse(d)
    except _Fail as e:
        raise ModelFormatError(f"{source}: {e}") from None
    except InputError as e:
        raise type(e)(f"{source}: {e}") from None


def _unknown_arrays(unknown: set[str]) -> None:
    if unknown:
        names = sorted(unknown)
        shown = ", ".join(repr(k[:40]) for k in names[:5]) + (" …" if len(names) > 5 else "")
        raise _Fail("<archive>", f"{len(names)} unknown array(s) [{shown}]")


def _npz_parse(z: Mapping[str, np.ndarray[Any, Any]]) -> Network:
    from .network import Network

    keys = set(z)

    def get(key: str) -> F64:
        if key not in keys:
            raise _Fail(key, "missing array")
        arr = z[key]
        if arr.dtype.kind not in "fiu":
            raise _Fail(key, f"expected a real numeric array, got dtype {arr.dtype}")
        return np.asarray(arr, dtype=np.float64)

    def scalar(key: str, default: float) -> float:
        if key not in keys:
            return default
        arr = get(key)
        if arr.shape != ():
            raise _Fail(key, f"expected a scalar, got shape {arr.shape}")
        return float(arr)

    if "format" in keys and str(z["format"]) != FORMAT:
        raise _Fail("format", f"must be {FORMAT!r}, got {_short(str(z['format']))}")
    if "version" in keys and scalar("version", VERSION) != VERSION:
        raise _Fail("version", f"unsupported version (this reader knows {VERSION})")
    r_min = scalar("r_min", 1.0)
    if "A_0" in keys:
        nsub = 0
        while f"A_{nsub}" in keys:
            nsub += 1
        expected = {"format", "version", "r_min", "eps", "coupling"} | {
            f"{x}_{i}" for x in "AGc" for i in range(nsub)
        }
        _unknown_arrays(keys - expected)
        a_b = [get(f"A_{i}") for i in range(nsub)]
        _dimension("A_* (total state dimension)", sum(a.shape[0] if a.ndim else 1 for a in a_b))
        g_b = [get(f"G_{i}") for i in range(nsub)]
        c_b = [get(f"c_{i}") for i in range(nsub)]
        coupling = get("coupling") if "coupling" in keys else None
        return Network.from_blocks(a_b, g_b, c_b, coupling, scalar("eps", 0.0), r_min)
    nsens = 0
    while f"sensor_{nsens}" in keys:
        nsens += 1
    expected = {"format", "version", "r_min", "A", "G"} | {f"sensor_{i}" for i in range(nsens)}
    _unknown_arrays(keys - expected)
    if nsens == 0:
        raise _Fail("sensor_0", "missing array (no sensors)")
    return Network(get("A"), get("G"), [get(f"sensor_{i}") for i in range(nsens)], r_min)


def _fmt_error(source: str) -> Any:
    return lambda msg: ModelFormatError(f"{source}: {msg}")


def load(path: str | os.PathLike[str], format: str | None = None) -> Network:
    """Reads a network from TOML, JSON or ``.npz`` (by ``format`` or the extension).

    Files are checked against :mod:`capalloc_rs.limits` before their data are read (file size,
    nesting depth and number size of TOML/JSON, the zip directory and ``.npy`` headers of an
    ``.npz``: member count, declared shapes, uncompressed sizes); pickled arrays are never loaded.

    Raises:
        ModelFormatError: the file is not a well-formed model (truncated or damaged archive,
            syntax error, missing or unknown field, wrong shape, over a limit); the message names
            the file and the field. Other :class:`~capalloc_rs.errors.InputError` subclasses:
            a well-formed model that is not a valid network (e.g. an unobservable subsystem).
        OSError: the file cannot be opened.
    """
    p = Path(path)
    fmt = _format_of(p, format)
    source = str(p)
    fail = _fmt_error(source)
    try:
        if fmt == "npz":
            arrays = read_npz(p, fail)
            try:
                return _npz_parse(arrays)
            except _Fail as e:
                raise fail(str(e)) from None
        return from_dict(read_data(p, fmt, fail), source)
    except InputError as e:
        if isinstance(e, ModelFormatError) or str(e).startswith(f"{source}: "):
            raise
        raise type(e)(f"{source}: {e}") from None
    except (OSError, CapallocError):
        raise
    except MemoryError:
        raise fail("the model does not fit in memory") from None
    except np.linalg.LinAlgError as e:
        raise NumericalError(f"{source}: {e}") from None
    except Exception as e:
        # a backstop: whatever a malformed file provokes, the caller sees one package error
        raise fail(f"malformed model ({type(e).__name__}: {str(e)[:200]})") from None
