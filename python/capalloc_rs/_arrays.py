"""Input normalisation shared by the Python layer: everything becomes a float64 numpy array of the
right dimension, or a :class:`~capalloc_rs.errors.InputError` naming the argument."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from .errors import InvalidInputError, NonFiniteError, ShapeError

F64 = npt.NDArray[np.float64]


def as_float_array(name: str, x: Any, ndim: int) -> F64:
    """Converts ``x`` to a float64 array with exactly ``ndim`` dimensions (no NaN/inf)."""
    if np.iscomplexobj(x):
        raise InvalidInputError(f"{name} must be real, got a complex array")
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a real numeric array: {exc}") from None
    if arr.ndim != ndim:
        raise ShapeError(f"{name} must be {ndim}-dimensional, got shape {arr.shape}")
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
