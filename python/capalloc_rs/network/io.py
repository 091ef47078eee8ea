"""The model-file formats: TOML and JSON (small models, human-readable) and ``.npz`` (large).

This module turns files into constructor arguments of a network (a plain dict of arrays, see
:func:`capalloc_rs.network.schema.parse`) and networks into files; it does not build networks
itself (that is :meth:`capalloc_rs.Network.load` and :mod:`capalloc_rs.model_io`).

The schema is described in :mod:`capalloc_rs.model_io` (:mod:`capalloc_rs.network.files`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .._arrays import F64
from .._npz import read_npz
from .._textdata import read_data
from ..errors import CapallocError, InputError, ModelFormatError, NumericalError
from .cost import BlockStructure
from .schema import FORMAT, VERSION, npz_parse, parse

__all__ = [
    "FORMAT",
    "VERSION",
    "NetworkData",
    "to_dict",
    "parse",
    "dumps_toml",
    "dumps_json",
    "save",
    "read",
    "model_errors",
]


# -- writing ------------------------------------------------------------------------------------


def _rows(m: F64) -> list[list[float]]:
    return [[float(v) for v in row] for row in np.asarray(m)]


def _sensor(c: F64) -> list[float] | list[list[float]]:
    return [float(v) for v in c[:, 0]] if c.shape[1] == 1 else _rows(c)


class NetworkData(Protocol):
    """What writing a network needs (a :class:`capalloc_rs.Network` has it)."""

    @property
    def r_min(self) -> Any: ...

    @property
    def costs(self) -> F64: ...

    @property
    def rate_min(self) -> F64: ...

    @property
    def rate_max(self) -> F64: ...

    @property
    def is_paper_form(self) -> bool: ...

    @property
    def a(self) -> F64: ...

    @property
    def g(self) -> F64: ...

    @property
    def sensors(self) -> tuple[F64, ...]: ...

    @property
    def structure(self) -> BlockStructure | None: ...

    @property
    def error_weight(self) -> F64 | None: ...


def _limits(net: NetworkData) -> tuple[float, list[dict[str, float]]]:
    """The top-level ``r_min`` and each sensor table's ``cost``, ``r_min``, ``r_max`` entries
    (only those that differ from the defaults: 1, the top-level ``r_min``, none)."""
    lo = float(np.min(net.rate_min))
    common = bool(np.all(net.rate_min == lo))
    r_min = lo if common else 1.0
    out = []
    for b, r0, r1 in zip(net.costs, net.rate_min, net.rate_max, strict=True):
        t = {} if b == 1.0 else {"cost": float(b)}
        t |= {} if r0 == r_min else {"r_min": float(r0)}
        out.append(t | ({} if math.isinf(r1) else {"r_max": float(r1)}))
    return r_min, out


def to_dict(net: NetworkData) -> dict[str, Any]:
    """The network as plain lists and numbers (the TOML/JSON schema)."""
    r_min, limits = _limits(net)
    d: dict[str, Any] = {"format": FORMAT, "version": VERSION, "r_min": r_min}
    if net.error_weight is not None:
        d["weight"] = _rows(net.error_weight)
    st = net.structure
    if st is None:
        d["A"] = _rows(net.a)
        d["G"] = _rows(net.g)
        d["sensors"] = [{"c": _sensor(c)} | t for c, t in zip(net.sensors, limits, strict=True)]
        return d
    d["eps"] = st.eps
    d["subsystems"] = [
        {"A": _rows(a), "G": _rows(g), "c": _sensor(c)} | t
        for a, g, c, t in zip(st.a_blocks, st.g_blocks, st.c_blocks, limits, strict=True)
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


def save(net: NetworkData, path: str | os.PathLike[str], format: str | None = None) -> None:
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
            "r_min": np.array(_limits(net)[0]),
        }
        if not net.is_paper_form:
            arrays |= {"costs": net.costs, "rate_min": net.rate_min, "rate_max": net.rate_max}
        if net.error_weight is not None:
            arrays["weight"] = net.error_weight
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


def _fmt_error(source: str) -> Any:
    return lambda msg: ModelFormatError(f"{source}: {msg}")


@contextmanager
def model_errors(source: str) -> Iterator[None]:
    """Whatever reading a model file or building its network raises inside the block comes out
    as one package error naming ``source``: an :class:`~capalloc_rs.errors.InputError` gets the
    prefix ``source:`` (once), ``MemoryError`` becomes a ModelFormatError, a
    ``numpy.linalg.LinAlgError`` a NumericalError; ``OSError`` and package errors pass."""
    fail = _fmt_error(source)
    try:
        yield
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
        # a backstop: whatever a malformed file provokes, the caller sees one package error (the
        # original exception stays attached as its cause, for whoever debugs the reader)
        raise fail(f"malformed model ({type(e).__name__}: {str(e)[:200]})") from e


def read(path: str | os.PathLike[str], format: str | None = None) -> tuple[dict[str, Any], str]:
    """Reads a model file from TOML, JSON or ``.npz`` (by ``format`` or the extension).

    Files are checked against :mod:`capalloc_rs.limits` before their data are read (file size,
    nesting depth and number size of TOML/JSON, the zip directory and ``.npy`` headers of an
    ``.npz``: member count, declared shapes, uncompressed sizes); pickled arrays are never loaded.

    Args:
        path: the file.
        format: ``"toml"``, ``"json"`` or ``"npz"``; default: the extension of ``path``.

    Returns:
        The constructor arguments (as :func:`parse`) and the source name for error messages.

    Raises:
        ModelFormatError: the file is not a well-formed model (truncated or damaged archive,
            syntax error, missing or unknown field, wrong shape, over a limit); the message names
            the file and the field.
        OSError: the file cannot be opened.
    """
    p = Path(path)
    fmt = _format_of(p, format)
    source = str(p)
    with model_errors(source):
        if fmt == "npz":
            spec = npz_parse(read_npz(p, _fmt_error(source)), source)
        else:
            spec = parse(read_data(p, fmt, _fmt_error(source)), source)
    return spec, source
