"""Input normalisation shared by the Python layer: everything becomes a float64 numpy array of the
right dimension, a finite float or a bounded integer, or a
:class:`~capalloc_rs.errors.InputError` naming the argument (never numpy's or Python's own
``ValueError``/``OverflowError``)."""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
import numpy.typing as npt

from .errors import (
    CapallocError,
    InvalidInputError,
    NonFiniteError,
    NonFiniteValueError,
    ShapeError,
    SingularProblemError,
)

F64 = npt.NDArray[np.float64]


def _describe(x: Any) -> str:
    r = repr(x)
    return r if len(r) <= 60 else r[:57] + "…"


def as_float_array(name: str, x: Any, ndim: int | tuple[int, ...]) -> F64:
    """Converts ``x`` to a float64 array with exactly ``ndim`` dimensions (or one of a tuple of
    them; no NaN/inf).

    Refused with an :class:`~capalloc_rs.errors.InputError` naming ``name``: ragged nested lists,
    strings, booleans, complex numbers, integers too large for a float64, NaN/inf, a wrong number
    of dimensions."""
    if type(x) is np.ndarray and x.dtype == np.float64:
        arr = x
    else:
        try:
            raw = np.asarray(x)
        except (TypeError, ValueError, OverflowError) as exc:  # ragged lists (numpy ≥ 1.24)
            raise InvalidInputError(
                f"{name} must be a real numeric array (a rectangular list of numbers): "
                f"{' '.join(str(exc).split())[:160]}"
            ) from None
        kind = raw.dtype.kind
        if kind == "c":
            raise InvalidInputError(f"{name} must be real, got a complex array")
        if kind == "b":
            raise InvalidInputError(f"{name} must be numbers, got booleans")
        if kind not in "fiuO":
            raise InvalidInputError(f"{name} must be a real numeric array, got dtype {raw.dtype}")
        if kind == "O":
            for v in raw.flat:
                if isinstance(v, bool | np.bool_) or not isinstance(v, numbers.Real):
                    raise InvalidInputError(
                        f"{name} must be a real numeric array (a rectangular list of numbers), "
                        f"got an entry {_describe(v)}"
                    )
        try:
            arr = raw.astype(np.float64)
        except (TypeError, ValueError, OverflowError) as exc:
            raise InvalidInputError(f"{name} must be a real numeric array: {exc}") from None
    dims = (ndim,) if isinstance(ndim, int) else ndim
    if arr.ndim not in dims:
        want = " or ".join(str(d) for d in dims)
        raise ShapeError(f"{name} must be {want}-dimensional, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise NonFiniteError(f"{name} contains NaN or infinite entries")
    return arr


def as_matrix(name: str, x: Any) -> F64:
    """A 2-D float64 array (any memory layout is accepted)."""
    return as_float_array(name, x, 2)


def as_matrix_checked_downstream(name: str, x: Any) -> F64:
    """:func:`as_matrix` without the finiteness scan when ``x`` already is a 2-D float64 array:
    for arguments that the Rust core checks for NaN/inf itself (raising
    :class:`~capalloc_rs.errors.NonFiniteError` with the argument's name), so small problems do not
    pay for the check twice."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 2:
        return x
    return as_matrix(name, x)


def as_real(
    name: str,
    x: Any,
    *,
    positive: bool = False,
    nonnegative: bool = False,
    finite: bool = True,
) -> float:
    """A real number as a float: booleans, strings, complex numbers, integers too large for a
    float64, NaN (and ±inf if ``finite``) and the sign conditions are refused naming ``name``."""
    if isinstance(x, bool | np.bool_) or not isinstance(x, numbers.Real):
        if isinstance(x, np.ndarray) and x.shape == () and x.dtype.kind in "fiu":
            x = x.item()
        else:
            raise InvalidInputError(f"{name} must be a real number, got {_describe(x)}")
    try:
        v = float(x)
    except (OverflowError, ValueError, TypeError):
        raise InvalidInputError(f"{name} is too large for a float64: {_describe(x)}") from None
    if math.isnan(v) or (finite and math.isinf(v)):
        raise NonFiniteValueError(f"{name} must be {'finite' if finite else 'a number'}, got {v}")
    if positive and not v > 0:
        raise InvalidInputError(f"{name} must be positive, got {v:g}")
    if nonnegative and not v >= 0:
        raise InvalidInputError(f"{name} must be non-negative, got {v:g}")
    return v


#: Largest count accepted by :func:`as_count` unless told otherwise (fits the Rust core's 64-bit
#: integers).
MAX_COUNT = 2**62


#: Largest random seed accepted (numpy's SeedSequence takes any non-negative integer; this only
#: keeps seeds printable).
MAX_SEED = 2**256


def as_count(name: str, x: Any, *, minimum: int = 0, maximum: int | None = None) -> int:
    """An integer ``minimum ≤ x ≤ maximum`` (Python or numpy integers, or floats with an integer
    value; never booleans), else an :class:`~capalloc_rs.errors.InvalidInputError` naming
    ``name``."""
    if isinstance(x, np.ndarray) and x.shape == () and x.dtype.kind in "fiu":
        x = x.item()
    if isinstance(x, bool | np.bool_) or not isinstance(x, numbers.Real):
        raise InvalidInputError(f"{name} must be an integer, got {_describe(x)}")
    if not isinstance(x, numbers.Integral):
        try:
            fx = float(x)
        except (OverflowError, ValueError, TypeError):
            fx = math.nan
        if not (math.isfinite(fx) and fx.is_integer()):
            raise InvalidInputError(f"{name} must be an integer, got {_describe(x)}")
        x = int(fx)
    v = int(x)
    if v < minimum:
        raise InvalidInputError(f"{name} must be at least {minimum}, got {v}")
    if maximum is None:
        maximum = MAX_COUNT
    if v > maximum:
        raise InvalidInputError(f"{name} must be at most {maximum}, got {_describe(v)}")
    return v


def require_attrs(name: str, obj: Any, *attrs: str) -> None:
    """A :class:`TypeError` naming ``name`` unless ``obj`` has every attribute of ``attrs`` (the
    duck-typed network arguments)."""
    missing = [a for a in attrs if not hasattr(obj, a)]
    if missing:
        raise TypeError(
            f"{name} must be a capalloc_rs.Network (or have {', '.join(attrs)}), got "
            f"{type(obj).__name__}"
        )


_F = TypeVar("_F", bound=Callable[..., Any])


def numerical_errors(fn: _F) -> _F:
    """Decorator: a raw :class:`numpy.linalg.LinAlgError` (e.g. ``"Singular matrix"`` from
    ``numpy.linalg.solve``) escaping ``fn`` becomes a
    :class:`~capalloc_rs.errors.SingularProblemError` naming the function; the package's own
    errors pass unchanged."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except np.linalg.LinAlgError as exc:
            if isinstance(exc, CapallocError):
                raise
            raise SingularProblemError(
                f"{fn.__name__}: a linear system of the computation is singular or too "
                f"ill-conditioned to solve ({exc}); the data may be too close to a degenerate "
                "network (e.g. noise or sensor weights near zero)"
            ) from None

    return cast(_F, wrapper)
