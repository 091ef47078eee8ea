"""The standard stochastic model of a control engineer, whitened into the paper's form.

The model (:meth:`capalloc_rs.Network.from_model`)::

    dx = A x dt + B_w dw,   E[dw dwᵀ] = W dt        (B_w n × m, W ⪰ 0 m × m)
    y_i(t_k) = C_i x(t_k) + v_i,   E[v_i v_iᵀ] = R_i  (C_i p_i × n, R_i ≻ 0 p_i × p_i)

sampled by sensor ``i`` at rate ``r_i``. In the fast-sampling limit its samples carry the
information ``r_i C_iᵀ R_i⁻¹ C_i`` per unit time, so the model is the paper's network with

    G = B_w W^{1/2}   (Q = G Gᵀ = B_w W B_wᵀ, possibly singular),
    ĉ_i = C_iᵀ R_i^{-1/2}   (so that ĉ_i ĉ_iᵀ = C_iᵀ R_i⁻¹ C_i),

``W^{1/2}`` and ``R_i^{-1/2}`` the symmetric square roots (any other factor gives the same ``Q`` and
``ĉ_i ĉ_iᵀ``, hence the same costs and schedules). This module only maps and checks the data; the
system-theoretic conditions (detectability of ``(A, [C_i])``, noise on the modes on the imaginary
axis) are checked by :class:`~capalloc_rs.Network` itself.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._arrays import F64, as_float_array, as_real
from ..errors import InvalidInputError, ShapeError

__all__ = [
    "as_noise",
    "whiten",
    "noise_factor",
    "whitened_sensor",
    "error_weight",
]

#: Relative tolerance of the symmetry and semidefiniteness tests of ``W`` and ``R_i``.
SYM_RTOL = 1e-12


def as_noise(name: str, g: Any, n: int) -> F64:
    """The noise matrix ``G`` (``n × m``, ``m ≥ 1``; a vector of length ``n`` is one column)."""
    arr = as_float_array(name, g, (1, 2))
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.shape[0] != n or arr.shape[1] == 0:
        raise ShapeError(
            f"{name} must be {n}×m with m ≥ 1 ({n} rows like the state; a vector of length {n} is "
            f"one column), got shape {arr.shape}"
        )
    return arr


def _symmetric(name: str, x: F64) -> F64:
    """``x`` checked symmetric to ``SYM_RTOL`` (relative to its largest entry) and symmetrised."""
    scale = float(np.max(np.abs(x), initial=0.0))
    if float(np.max(np.abs(x - x.T), initial=0.0)) > SYM_RTOL * scale:
        raise InvalidInputError(
            f"{name} must be symmetric, got ‖{name} − {name}ᵀ‖_max > 1e-12·‖{name}‖"
        )
    return 0.5 * (x + x.T)


def _is_scalar(x: Any) -> bool:
    return isinstance(x, numbers.Number) or (isinstance(x, np.ndarray | np.generic) and x.ndim == 0)


def _cov(name: str, x: Any, size: int) -> F64:
    """A ``size × size`` covariance (a scalar ``s`` means ``s·I``), checked symmetric."""
    if _is_scalar(x):
        return as_real(name, x) * np.eye(size)
    arr = as_float_array(name, x, 2)
    if arr.shape != (size, size):
        raise ShapeError(
            f"{name} must be {size}×{size} (or a scalar s for s·I), got shape {arr.shape}"
        )
    return _symmetric(name, arr)


def _sqrt_psd(name: str, w: F64) -> F64:
    """A factor ``F`` with ``F Fᵀ = W`` (``W^{1/2}``), after checking ``W ⪰ 0``."""
    lam, v = np.linalg.eigh(w)
    top = float(np.max(np.abs(lam), initial=0.0))
    if lam.size and float(lam[0]) < -w.shape[0] * np.finfo(float).eps * top:
        raise InvalidInputError(
            f"{name} must be positive semidefinite, its smallest eigenvalue is {lam[0]:.3e}"
        )
    root: F64 = (v * np.sqrt(np.maximum(lam, 0.0))) @ v.T
    return root


def _inv_sqrt_pd(name: str, r: F64) -> F64:
    """``R^{-1/2}`` (symmetric), after checking ``R ≻ 0`` (smallest eigenvalue above
    ``p·ε·λ_max``)."""
    lam, v = np.linalg.eigh(r)
    top = float(np.max(np.abs(lam), initial=0.0))
    if top == 0.0 or float(lam[0]) <= r.shape[0] * np.finfo(float).eps * top:
        raise InvalidInputError(
            f"{name} must be positive definite (a sample noise covariance), its smallest "
            f"eigenvalue is {lam[0]:.3e}"
        )
    out: F64 = (v / np.sqrt(lam)) @ v.T
    return out


def _sensor_output(name: str, c: Any, n: int) -> F64:
    """``C`` as ``p × n`` (a vector of length ``n`` is one output)."""
    arr = as_float_array(name, c, (1, 2))
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.shape[1] != n or arr.shape[0] == 0:
        raise ShapeError(
            f"{name} must be p×{n} (outputs y = C x, one row per output; a vector of length {n} "
            f"is one output), got shape {arr.shape}"
        )
    return arr


def _per_sensor_list(name: str, x: Any, count: int | None) -> list[Any]:
    if isinstance(x, np.ndarray) or not isinstance(x, Sequence) or isinstance(x, str | bytes):
        raise InvalidInputError(
            f"{name} must be a list with one entry per sensor, got {type(x).__name__} (for one "
            f"scalar output per sensor from a matrix, pass list(matrix))"
        )
    if len(x) == 0:
        raise ShapeError(f"{name} must name at least one sensor")
    if count is not None and len(x) != count:
        raise ShapeError(f"{name} must have one entry per sensor ({count}), got {len(x)}")
    return list(x)


def whiten(a: F64, b_w: Any, w: Any, c: Any, r: Any) -> tuple[F64, list[F64]]:
    """``(G, [ĉ_1 … ĉ_N])`` of the standard model (module docstring): ``G = B_w W^{1/2}``,
    ``ĉ_i = C_iᵀ R_i^{-1/2}``.

    Args:
        a: ``A`` (``n × n``, already checked square).
        b_w: ``B_w`` (``n × m``; a vector of length ``n`` is one column).
        w: ``W`` (``m × m``, symmetric ⪰ 0; a scalar ``s`` is ``s·I``).
        c: list of ``C_i`` (``p_i × n``; a vector is one output).
        r: list of ``R_i`` (``p_i × p_i``, symmetric ≻ 0; a scalar ``s`` is ``s·I``), or one scalar
            for every sensor.

    Raises:
        ShapeError, NonFiniteError, InvalidInputError: the message names the argument.
    """
    n = a.shape[0]
    g = noise_factor("B_w", "W", b_w, w, n)
    cs = _per_sensor_list("C", c, None)
    rs = [r] * len(cs) if _is_scalar(r) else _per_sensor_list("R", r, len(cs))
    sensors = [
        whitened_sensor(f"C[{i}]", f"R[{i}]", ci, ri, n)
        for i, (ci, ri) in enumerate(zip(cs, rs, strict=True))
    ]
    return g, sensors


def noise_factor(b_name: str, w_name: str, b_w: Any, w: Any, n: int) -> F64:
    """``G = B_w W^{1/2}`` (``n × m``) after checking ``B_w`` (``n × m``, a vector is one column)
    and ``W`` (``m × m`` symmetric ⪰ 0, a scalar ``s`` is ``s·I``); errors name ``b_name`` or
    ``w_name``."""
    bw = as_noise(b_name, b_w, n)
    root: F64 = bw @ _sqrt_psd(w_name, _cov(w_name, w, bw.shape[1]))
    return root


def whitened_sensor(c_name: str, r_name: str, c: Any, r: Any, n: int) -> F64:
    """``ĉ = Cᵀ R^{-1/2}`` (``n × p``) after checking ``C`` (``p × n``, a vector is one output)
    and ``R`` (``p × p`` symmetric ≻ 0, a scalar ``s`` is ``s·I``); errors name ``c_name`` or
    ``r_name``."""
    ci = _sensor_output(c_name, c, n)
    out: F64 = ci.T @ _inv_sqrt_pd(r_name, _cov(r_name, r, ci.shape[0]))
    return out


def error_weight(weight: Any, n: int) -> F64 | None:
    """The weight ``M`` of the error ``tr(M Σ)`` as an ``n × n`` array, ``None`` for the plain
    trace (``None`` or exactly the identity). Symmetry, semidefiniteness and ``M ≠ 0`` are checked
    by the core (errors name "the weight M")."""
    if weight is None:
        return None
    m = as_float_array("weight", weight, 2)
    if m.shape != (n, n):
        raise ShapeError(f"weight must be {n}×{n} like A, got shape {m.shape}")
    return None if np.array_equal(m, np.eye(n)) else m
