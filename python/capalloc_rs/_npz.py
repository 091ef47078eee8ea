"""Reading the arrays of an ``.npz`` model archive safely: everything is checked against
:mod:`capalloc_rs.limits` before it is read — the member count and uncompressed sizes from the zip
directory, each member's dtype and shape from its ``.npy`` header — so that a small archive cannot
make the reader decompress gigabytes or allocate an array its data do not back. Object (pickled)
arrays are refused; every archive or format problem becomes one exception of the caller's class.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from collections.abc import Callable
from typing import IO, Any

import numpy as np

from . import limits

__all__ = ["read_npz"]

Fail = Callable[[str], Exception]

#: Largest ``.npy`` header read (numpy's own default bound).
_MAX_HEADER = 10_000
#: The string members a model archive may hold (anything else must be numeric).
_STRING_MEMBERS = {"format"}


class _Problem(Exception):
    pass


def _over(what: str, value: int, name: str) -> _Problem:
    return _Problem(f"{what} {value} exceeds capalloc_rs.limits.{name} = {getattr(limits, name)}")


def _header(f: IO[bytes], key: str) -> tuple[tuple[int, ...], bool, np.dtype[Any]]:
    fmt = np.lib.format
    try:
        version = fmt.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(f, max_header_size=_MAX_HEADER)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(f, max_header_size=_MAX_HEADER)
        else:
            raise _Problem(f"{key}: unsupported .npy format version {version}")
    except (_Problem, zipfile.BadZipFile, zlib.error, EOFError, OSError):
        raise
    except Exception as exc:  # numpy parses the header dict with ast/tokenize: anything goes
        raise _Problem(f"{key}: not a valid .npy header ({type(exc).__name__}: {exc})") from None
    return tuple(int(d) for d in shape), bool(fortran), dtype


def _check_dtype(key: str, dtype: np.dtype[Any]) -> None:
    if dtype.hasobject:
        raise _Problem(f"{key}: an object (pickled) array; model archives hold numbers only")
    if dtype.fields is not None or dtype.subdtype is not None:
        raise _Problem(f"{key}: a structured array (dtype {dtype}); expected real numbers")
    if dtype.kind == "U" and key in _STRING_MEMBERS:
        return
    if dtype.kind not in "fiu":
        raise _Problem(f"{key}: expected a real numeric array, got dtype {dtype}")


def _check_shape(key: str, shape: tuple[int, ...]) -> int:
    if len(shape) > 2:
        raise _Problem(f"{key}: expected at most 2 dimensions, got shape {shape}")
    for d in shape:
        if d > limits.MAX_MODEL_STATES:
            raise _over(f"{key}: declared dimension", d, "MAX_MODEL_STATES")
    count = int(np.prod(shape, dtype=np.int64)) if shape else 1
    if count > limits.MAX_MODEL_ARRAY_ELEMENTS:
        raise _over(f"{key}: declared element count", count, "MAX_MODEL_ARRAY_ELEMENTS")
    return count


def _member(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, key: str
) -> tuple[np.ndarray[Any, Any], int]:
    with zf.open(info) as f:
        shape, fortran, dtype = _header(f, key)
        _check_dtype(key, dtype)
        count = _check_shape(key, shape)
        nbytes = count * dtype.itemsize
        held = info.file_size - f.tell()
        if nbytes != held:
            raise _Problem(
                f"{key}: the header declares shape {shape} of {dtype} ({nbytes} bytes) but the "
                f"member holds {held} bytes of data"
            )
        buf = f.read(nbytes)
    if len(buf) != nbytes:
        raise _Problem(f"{key}: truncated data ({len(buf)} of {nbytes} bytes)")
    arr = np.frombuffer(buf, dtype=dtype).reshape(shape, order="F" if fortran else "C")
    return arr.copy(), count


def _read(fh: IO[bytes]) -> dict[str, np.ndarray[Any, Any]]:
    with zipfile.ZipFile(fh) as zf:
        infos = zf.infolist()
        if not infos:
            raise _Problem("an empty archive (no arrays)")
        if len(infos) > limits.MAX_NPZ_MEMBERS:
            raise _over("member count", len(infos), "MAX_NPZ_MEMBERS")
        total_bytes = sum(i.file_size for i in infos)
        byte_limit = 8 * limits.MAX_MODEL_ELEMENTS + len(infos) * (_MAX_HEADER + 16)
        if total_bytes > byte_limit:
            raise _Problem(
                f"the archive expands to {total_bytes} bytes, more than 8 bytes per element of "
                f"capalloc_rs.limits.MAX_MODEL_ELEMENTS = {limits.MAX_MODEL_ELEMENTS}"
            )
        keys = {}
        for info in infos:
            if info.is_dir() or not info.filename.endswith(".npy"):
                raise _Problem(f"member {info.filename[:80]!r} is not a .npy array")
            if info.flag_bits & 0x1:
                raise _Problem(f"member {info.filename[:80]!r} is encrypted")
            key = info.filename[: -len(".npy")]
            if key in keys:
                raise _Problem(f"member {info.filename[:80]!r} appears twice")
            keys[key] = info
        out: dict[str, np.ndarray[Any, Any]] = {}
        elements = 0
        for key, info in keys.items():
            arr, count = _member(zf, info, key)
            elements += count
            if elements > limits.MAX_MODEL_ELEMENTS:
                raise _over("total declared element count", elements, "MAX_MODEL_ELEMENTS")
            out[key] = arr
        return out


def read_npz(path: str | os.PathLike[str], fail: Fail) -> dict[str, np.ndarray[Any, Any]]:
    """The arrays of the ``.npz`` archive ``path`` by name; problems raise ``fail(message)``;
    :class:`OSError` if the file cannot be opened."""
    with open(path, "rb") as fh:
        try:
            return _read(fh)
        except _Problem as exc:
            raise fail(str(exc)) from None
        except (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, EOFError) as exc:
            raise fail(f"not a readable .npz archive ({type(exc).__name__}: {exc})") from None
        except (ValueError, NotImplementedError, OSError, UnicodeDecodeError) as exc:
            # numpy's header parser (ValueError), unsupported zip compression
            # (NotImplementedError), a read error in the middle of the file
            raise fail(f"not a readable .npz archive ({type(exc).__name__}: {exc})") from None
