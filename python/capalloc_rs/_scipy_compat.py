"""scipy's argument conventions for the drop-ins in :mod:`capalloc_rs.linalg`: which inputs are
promoted by ``np.atleast_2d``, which result dtype scipy returns, and the package errors for complex
or non-numeric input. The numerics stay in the Rust core, which always works in float64."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import InvalidInputError, NonFiniteError, ShapeError

F64 = npt.NDArray[np.float64]
Real = npt.NDArray[np.floating[Any]]

#: dtypes for which scipy's LAPACK-backed routines compute and return single precision.
_SINGLE = (np.dtype(np.float32), np.dtype(np.float16))


def real_array(name: str, x: Any, alternative: str, *, check_finite: bool = True) -> Real:
    """``x`` as a real floating array of its own precision (integers and bools become float64).

    Complex input raises :class:`InvalidInputError` naming ``alternative`` (the scipy function that
    handles it); non-numeric input raises :class:`InvalidInputError`; NaN/inf raise
    :class:`NonFiniteError` when ``check_finite``.
    """
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError, OverflowError) as exc:
        raise InvalidInputError(f"{name} must be a real numeric array: {exc}") from None
    if np.iscomplexobj(arr):
        raise InvalidInputError(
            f"{name} is complex: capalloc_rs solves real problems only (use {alternative} "
            "for complex data)"
        )
    if arr.dtype not in _SINGLE and arr.dtype != np.float64:
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError, OverflowError) as exc:
            raise InvalidInputError(f"{name} must be a real numeric array: {exc}") from None
    if check_finite and not np.all(np.isfinite(arr)):
        raise NonFiniteError(f"{name} contains NaN or infinite entries")
    return arr


def as_f64(arr: Real) -> F64:
    """The float64 copy the Rust core takes (no copy when ``arr`` already is float64)."""
    return np.asarray(arr, dtype=np.float64)


def result_dtype(*arrays: Real) -> np.dtype[Any]:
    """scipy's result dtype for real LAPACK-backed routines: single precision when every input
    is float32/float16, else float64."""
    if arrays and all(a.dtype in _SINGLE for a in arrays):
        return np.dtype(np.float32)
    return np.dtype(np.float64)


def square(name: str, a: Real) -> int:
    """The order of the square 2-D array ``a`` (:class:`ShapeError` otherwise)."""
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ShapeError(f"{name} must be a square 2-dimensional array, got shape {a.shape}")
    return int(a.shape[0])


def shaped(name: str, a: Real, shape: tuple[int, int]) -> None:
    """:class:`ShapeError` unless ``a`` has exactly ``shape``."""
    if a.shape != shape:
        raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
