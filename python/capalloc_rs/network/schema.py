"""Checked reading of the model schema: a dict (from TOML or JSON) or the arrays of an ``.npz``
become the constructor arguments of a network, or a :class:`~capalloc_rs.errors.ModelFormatError`
naming the field that is wrong (the schema is described in :mod:`capalloc_rs.model_io`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .. import limits
from .._arrays import F64
from ..errors import InputError, ModelFormatError
from .stochastic import noise_factor, whitened_sensor

__all__ = ["FORMAT", "VERSION", "npz_parse", "parse"]

FORMAT = "capalloc-network"
VERSION = 1

_TOP_COMMON = {"format", "version", "r_min", "weight"}
_TOP_BLOCK = _TOP_COMMON | {"eps", "subsystems", "couplings"}
_TOP_GENERAL = _TOP_COMMON | {"A", "G", "B_w", "W", "sensors"}

#: The keys of a subsystem table: ``A``, the noise as ``G`` or as ``B_w`` (and ``W``), the sensor
#: as ``c`` (``n_i × p_i``, the paper's) or as ``C`` (``p_i × n_i``, outputs ``y = C x``) and ``R``.
_SUBSYSTEM = {"A", "G", "B_w", "W", "c", "C", "R", "cost", "r_min", "r_max"}
#: The keys of a sensor table of the general form (the sensor, its sample cost and rate limits).
_SENSOR = {"c", "C", "R", "cost", "r_min", "r_max"}


class _Fail(Exception):
    def __init__(self, field: str, problem: str) -> None:
        super().__init__(f"{field}: {problem}" if field else problem)


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def _number(
    x: Any, field: str, *, positive: bool = False, nonnegative: bool = False, inf_ok: bool = False
) -> float:
    if not _is_number(x):
        raise _Fail(field, f"expected a number, got {type(x).__name__} {_short(x)}")
    try:
        v = float(x)
    except OverflowError:
        raise _Fail(field, "a number too large for a float64") from None
    if not (math.isfinite(v) or (inf_ok and v == math.inf)):
        raise _Fail(field, f"must be finite, got {v}")
    if positive and v <= 0:
        raise _Fail(field, f"must be positive, got {v}")
    if nonnegative and v < 0:
        raise _Fail(field, f"must be non-negative, got {v}")
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


def _numbers(row: list[Any], field: str) -> None:
    """Every entry of ``row`` is a number (else the field of the first that is not)."""
    for k, v in enumerate(row):
        if not _is_number(v):
            raise _Fail(f"{field}[{k}]", f"expected a number, got {type(v).__name__} {_short(v)}")


def _rows_array(x: list[Any], field: str) -> F64:
    """A matrix from a list of rows of numbers, all of one length."""
    for k, row in enumerate(x):
        if not isinstance(row, list) or not row:
            raise _Fail(f"{field}[{k}]", "expected a non-empty list of numbers")
        _dimension(f"{field}[{k}]", len(row))
        _numbers(row, f"{field}[{k}]")
    widths = {len(row) for row in x}
    if len(widths) != 1:
        raise _Fail(field, f"rows have different lengths {sorted(widths)}")
    return _float_array(x, field)


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
        _numbers(x, field)
        arr = _float_array([[v] for v in x], field)
    else:
        arr = _rows_array(x, field)
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


def _whitened(fn: Any, *args: Any) -> F64:
    """``fn(*args)`` (a whitening of :mod:`.stochastic`) with its input errors as ``_Fail``."""
    try:
        out: F64 = fn(*args)
    except InputError as e:
        raise _Fail("", str(e)) from None
    return out


def _noise(t: dict[str, Any], f: str, n: int) -> F64:
    """``G`` of a table: its ``G`` (``n × m``), or ``B_w W^{1/2}`` from ``B_w`` and ``W``
    (default ``I``)."""
    if ("G" in t) == ("B_w" in t) or ("W" in t and "G" in t):
        raise _Fail(f, "give the process noise either as G or as B_w (and W), not both or neither")
    if "G" in t:
        return _matrix(t["G"], f"{f}.G", rows=n, vector_ok=True)
    b_w = _matrix(t["B_w"], f"{f}.B_w", rows=n, vector_ok=True)
    w = _matrix(t["W"], f"{f}.W") if "W" in t else 1.0
    return _whitened(noise_factor, f"{f}.B_w", f"{f}.W", b_w, w, n)


def _sensor(t: dict[str, Any], f: str, n: int) -> F64:
    """``ĉ`` of a table: its ``c`` (``n × p``), or ``Cᵀ R^{-1/2}`` from ``C`` (``p × n``) and
    ``R`` (default ``I``)."""
    if ("c" in t) == ("C" in t) or ("R" in t and "c" in t):
        raise _Fail(
            f, "give the sensor either as c (n×p) or as C (p×n, and R), not both or neither"
        )
    if "c" in t:
        return _matrix(t["c"], f"{f}.c", rows=n, vector_ok=True)
    cv = t["C"]
    rows = isinstance(cv, list) and any(isinstance(v, list) for v in cv)
    c = _matrix(cv if rows else [cv], f"{f}.C")  # a flat list is one output (one row)
    r = _matrix(t["R"], f"{f}.R") if "R" in t else 1.0
    return _whitened(whitened_sensor, f"{f}.C", f"{f}.R", c, r, n)


def _subsystems(d: dict[str, Any]) -> tuple[list[F64], list[F64], list[F64]]:
    """``(A_i), (G_i), (c_i)`` of the ``[[subsystems]]`` tables."""
    a_b: list[F64] = []
    g_b: list[F64] = []
    c_b: list[F64] = []
    for i, s in enumerate(_list_of_tables(d["subsystems"], "subsystems")):
        f = f"subsystems[{i}]"
        _table(s, f, _SUBSYSTEM, {"A"})
        a = _square(s["A"], f"{f}.A")
        n_i = a.shape[0]
        _dimension("subsystems (total state dimension)", sum(b.shape[0] for b in a_b) + n_i)
        a_b.append(a)
        g_b.append(_noise(s, f, n_i))
        c_b.append(_sensor(s, f, n_i))
    return a_b, g_b, c_b


def _limits(tables: list[Any], prefix: str, r_min: float) -> dict[str, Any]:
    """The per-sensor ``cost``, ``r_min`` and ``r_max`` of the sensor tables as constructor
    arguments (``costs``, ``r_min``, ``r_max`` lists), or nothing when no table has any (the
    paper's case keeps the scalar ``r_min``)."""
    keys = ("cost", "r_min", "r_max")
    if not any(k in t for t in tables for k in keys):
        return {}
    costs, lows, caps = [], [], []
    for i, t in enumerate(tables):
        f = f"{prefix}[{i}]"
        costs.append(_number(t.get("cost", 1.0), f"{f}.cost", positive=True))
        lows.append(_number(t.get("r_min", r_min), f"{f}.r_min", nonnegative=True))
        caps.append(_number(t.get("r_max", math.inf), f"{f}.r_max", positive=True, inf_ok=True))
    return {"costs": costs, "r_min": lows, "r_max": caps}


def _coupling_pair(cp: Any, f: str, count: int) -> tuple[int, int]:
    """The checked ``(i, j)`` of the coupling table ``f``."""
    _table(cp, f, {"i", "j", "A"}, {"i", "j", "A"})
    i, j = _integer(cp["i"], f"{f}.i"), _integer(cp["j"], f"{f}.j")
    for name, v in (("i", i), ("j", j)):
        if not 0 <= v < count:
            raise _Fail(f"{f}.{name}", f"{v} is out of range for {count} subsystems")
    if i == j:
        raise _Fail(f, f"i = j = {i}: a subsystem cannot be coupled to itself")
    return i, j


def _couplings(d: dict[str, Any], a_b: list[F64]) -> dict[tuple[int, int], F64]:
    """The ``[[couplings]]`` tables as ``{(i, j): A_ij}``."""
    couplings: dict[tuple[int, int], F64] = {}
    tables = _list_of_tables(d["couplings"], "couplings") if "couplings" in d else []
    for k, cp in enumerate(tables):
        f = f"couplings[{k}]"
        i, j = _coupling_pair(cp, f, len(a_b))
        if (i, j) in couplings:
            raise _Fail(f, f"the pair ({i}, {j}) appears twice")
        couplings[(i, j)] = _matrix(cp["A"], f"{f}.A", rows=a_b[i].shape[0], cols=a_b[j].shape[0])
    return couplings


def _parse_general(d: dict[str, Any], r_min: float) -> dict[str, Any]:
    """The general form ``A``, ``G``, ``[[sensors]]``."""
    _table(d, "<top level>", _TOP_GENERAL, {"A", "sensors"})
    a = _square(d["A"], "A")
    n = a.shape[0]
    g = _noise(d, "<top level>", n)
    sensors = []
    for i, s in enumerate(_list_of_tables(d["sensors"], "sensors")):
        _table(s, f"sensors[{i}]", _SENSOR, set())
        sensors.append(_sensor(s, f"sensors[{i}]", n))
    spec = {"a": a, "g": g, "sensors": sensors, "r_min": r_min}
    return spec | _limits(d["sensors"], "sensors", r_min)


def _parse(d: Any) -> dict[str, Any]:
    if not isinstance(d, dict):
        raise _Fail("<top level>", f"expected a table, got {type(d).__name__}")
    if "format" in d and d["format"] != FORMAT:
        raise _Fail("format", f"must be {FORMAT!r}, got {_short(d['format'])}")
    if "version" in d and _integer(d["version"], "version") != VERSION:
        raise _Fail("version", f"unsupported version {d['version']} (this reader knows {VERSION})")
    r_min = _number(d.get("r_min", 1.0), "r_min", nonnegative=True)
    if "subsystems" not in d:
        if "A" not in d:
            raise _Fail(
                "<top level>", "needs either [[subsystems]] (block form) or A, G, [[sensors]]"
            )
        return _with_weight(d, _parse_general(d, r_min))
    _table(d, "<top level>", _TOP_BLOCK, {"subsystems"})
    a_b, g_b, c_b = _subsystems(d)
    couplings = _couplings(d, a_b)
    eps = _number(d.get("eps", 0.0), "eps")
    spec = {
        "a_blocks": a_b,
        "g_blocks": g_b,
        "c_blocks": c_b,
        "couplings": couplings or None,
        "eps": eps,
        "r_min": r_min,
    } | _limits(d["subsystems"], "subsystems", r_min)
    return _with_weight(d, spec)


def _with_weight(d: dict[str, Any], spec: dict[str, Any]) -> dict[str, Any]:
    """``spec`` with the top-level ``weight`` (the matrix ``M`` of ``tr(M Σ)``), if given."""
    if "weight" in d:
        spec["weight"] = _square(d["weight"], "weight")
    return spec


def parse(d: Any, source: str = "model") -> dict[str, Any]:
    """The constructor arguments of the network a dict of the schema describes.

    Args:
        d: the dict (as read from TOML or JSON).
        source: where ``d`` came from, for error messages.

    Returns:
        ``{"a_blocks", "g_blocks", "c_blocks", "couplings", "eps", "r_min"}`` (the arguments of
        :meth:`Network.from_blocks <capalloc_rs.Network.from_blocks>`) for the block form,
        ``{"a", "g", "sensors", "r_min"}`` (those of :class:`~capalloc_rs.Network`) for the
        general form.

    Raises:
        ModelFormatError: malformed data; the message names ``source`` and the field.
    """
    try:
        return _parse(d)
    except _Fail as e:
        raise ModelFormatError(f"{source}: {e}") from None


def _unknown_arrays(unknown: set[str]) -> None:
    if unknown:
        names = sorted(unknown)
        shown = ", ".join(repr(k[:40]) for k in names[:5]) + (" …" if len(names) > 5 else "")
        raise _Fail("<archive>", f"{len(names)} unknown array(s) [{shown}]")


class _Archive:
    """Checked access to the arrays of an ``.npz`` model."""

    def __init__(self, z: Mapping[str, np.ndarray[Any, Any]]) -> None:
        self.z = z
        self.keys = set(z)

    def get(self, key: str) -> F64:
        if key not in self.keys:
            raise _Fail(key, "missing array")
        arr = self.z[key]
        if arr.dtype.kind not in "fiu":
            raise _Fail(key, f"expected a real numeric array, got dtype {arr.dtype}")
        return np.asarray(arr, dtype=np.float64)

    def scalar(self, key: str, default: float) -> float:
        if key not in self.keys:
            return default
        arr = self.get(key)
        if arr.shape != ():
            raise _Fail(key, f"expected a scalar, got shape {arr.shape}")
        return float(arr)

    def count(self, prefix: str) -> int:
        """How many of ``prefix0``, ``prefix1``, … there are (consecutively from 0)."""
        k = 0
        while f"{prefix}{k}" in self.keys:
            k += 1
        return k


def _npz_blocks(z: _Archive, r_min: float) -> dict[str, Any]:
    nsub = z.count("A_")
    expected = {"format", "version", "r_min", "eps", "coupling", "weight", *_NPZ_LIMITS} | {
        f"{x}_{i}" for x in "AGc" for i in range(nsub)
    }
    _unknown_arrays(z.keys - expected)
    a_b = [z.get(f"A_{i}") for i in range(nsub)]
    _dimension("A_* (total state dimension)", sum(a.shape[0] if a.ndim else 1 for a in a_b))
    return {
        "a_blocks": a_b,
        "g_blocks": [z.get(f"G_{i}") for i in range(nsub)],
        "c_blocks": [z.get(f"c_{i}") for i in range(nsub)],
        "couplings": z.get("coupling") if "coupling" in z.keys else None,
        "eps": z.scalar("eps", 0.0),
        "r_min": r_min,
    }


_NPZ_LIMITS = {"costs": "costs", "rate_min": "r_min", "rate_max": "r_max"}


def _npz_parse(arrays: Mapping[str, np.ndarray[Any, Any]]) -> dict[str, Any]:
    z = _Archive(arrays)
    spec = _npz_spec(z, arrays)
    if "weight" in z.keys:
        spec["weight"] = z.get("weight")
    for key, arg in _NPZ_LIMITS.items():
        if key in z.keys:
            spec[arg] = z.get(key)
    return spec


def _npz_spec(z: _Archive, arrays: Mapping[str, np.ndarray[Any, Any]]) -> dict[str, Any]:
    if "format" in z.keys and str(arrays["format"]) != FORMAT:
        raise _Fail("format", f"must be {FORMAT!r}, got {_short(str(arrays['format']))}")
    if "version" in z.keys and z.scalar("version", VERSION) != VERSION:
        raise _Fail("version", f"unsupported version (this reader knows {VERSION})")
    r_min = z.scalar("r_min", 1.0)
    if "A_0" in z.keys:
        return _npz_blocks(z, r_min)
    nsens = z.count("sensor_")
    expected = {"format", "version", "r_min", "A", "G", "weight", *_NPZ_LIMITS} | {
        f"sensor_{i}" for i in range(nsens)
    }
    _unknown_arrays(z.keys - expected)
    if nsens == 0:
        raise _Fail("sensor_0", "missing array (no sensors)")
    sensors = [z.get(f"sensor_{i}") for i in range(nsens)]
    return {"a": z.get("A"), "g": z.get("G"), "sensors": sensors, "r_min": r_min}


def npz_parse(arrays: Mapping[str, np.ndarray[Any, Any]], source: str) -> dict[str, Any]:
    """The constructor arguments (as :func:`parse`) of the arrays of an ``.npz`` model.

    Raises:
        ModelFormatError: a missing, unknown or malformed array; the message names ``source``.
    """
    try:
        return _npz_parse(arrays)
    except _Fail as e:
        raise ModelFormatError(f"{source}: {e}") from None
