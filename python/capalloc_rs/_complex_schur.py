"""The complex Schur form ``A = Z T Zᴴ`` (T upper triangular) from the real one, and its reordering
by a selection of single eigenvalues: what ``scipy.linalg.schur(..., output="complex")`` returns
for real input. Each 2×2 block of the real form is triangularised by one unitary 2×2 rotation whose
first column is an eigenvector of the block; a reordering swap of adjacent diagonal entries is the
rotation whose first column is the eigenvector of the lower one (as LAPACK's ztrexc)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

C128 = npt.NDArray[np.complex128]


def _apply(t: C128, z: C128, k: int, g: C128) -> None:
    """``T ← Gᴴ T G`` and ``Z ← Z G`` for the unitary ``G`` acting on rows/columns ``k, k+1``."""
    t[:, k : k + 2] = t[:, k : k + 2] @ g
    t[k : k + 2, :] = g.conj().T @ t[k : k + 2, :]
    z[:, k : k + 2] = z[:, k : k + 2] @ g


def _rotation(x0: complex, x1: complex) -> C128:
    """The unitary ``[[c, −s̄], [s, c̄]]`` whose first column is ``(x0, x1)/‖(x0, x1)‖`` (scaled
    first, so subnormal or huge entries neither underflow to 0 nor overflow; ``(0, 0)`` is not a
    direction: the caller never passes it)."""
    m = max(abs(x0), abs(x1))
    x0, x1 = x0 / m, x1 / m
    nrm = float(np.hypot(abs(x0), abs(x1)))
    c, s = x0 / nrm, x1 / nrm
    return np.array([[c, -np.conj(s)], [s, np.conj(c)]], dtype=np.complex128)


def real_to_complex(
    t_real: npt.NDArray[np.float64], z_real: npt.NDArray[np.float64]
) -> tuple[C128, C128]:
    """Upper-triangular complex ``(T, Z)`` from a standardised real Schur form (each pair
    ``a ± iω`` appears with ``+iω`` first)."""
    t = t_real.astype(np.complex128)
    z = z_real.astype(np.complex128)
    n = t.shape[0]
    k = 0
    while k < n - 1:
        if t_real[k + 1, k] == 0.0:
            k += 1
            continue
        a, b, c = t_real[k, k], t_real[k, k + 1], t_real[k + 1, k]
        lam = complex(a, np.sqrt(abs(b)) * np.sqrt(abs(c)))
        # (a − λ) v0 + b v1 = 0  ⇒  v = (b, λ − a); when b underflowed to 0 the block
        # [[a, 0], [c, a]] has the double real eigenvalue a with eigenvector e₂.
        v = (complex(b), lam - a) if b != 0.0 else (0j, 1 + 0j)
        _apply(t, z, k, _rotation(*v))
        t[k + 1, k] = 0.0
        t[k, k], t[k + 1, k + 1] = lam, lam.conjugate()
        k += 2
    return t, z


def reorder(t: C128, z: C128, select: npt.NDArray[np.bool_]) -> int:
    """Moves the diagonal entries with ``select`` true (indexed on entry) to the top, in place,
    keeping their relative order; returns how many were moved."""
    n = t.shape[0]
    ks = 0
    for k in range(n):
        if not select[k]:
            continue
        for j in range(k - 1, ks - 1, -1):  # bubble entry j+1 up to j
            t11, t22 = complex(t[j, j]), complex(t[j + 1, j + 1])
            x0, x1 = complex(t[j, j + 1]), t22 - t11
            if x0 == 0 and x1 == 0:
                continue
            _apply(t, z, j, _rotation(x0, x1))
            t[j + 1, j] = 0.0
            t[j, j], t[j + 1, j + 1] = t22, t11
        ks += 1
    return ks


def eigenvalues_of_real_schur(t: npt.NDArray[np.float64]) -> list[tuple[float, float]]:
    """``(re, im)`` of each diagonal position of a standardised real Schur form (positive
    imaginary part first in a pair), as LAPACK's dgees reports them."""
    n = t.shape[0]
    out: list[tuple[float, float]] = []
    k = 0
    while k < n:
        if k < n - 1 and t[k + 1, k] != 0.0:
            w = float(np.sqrt(abs(t[k, k + 1])) * np.sqrt(abs(t[k + 1, k])))
            out += [(float(t[k, k]), w), (float(t[k, k]), -w)]
            k += 2
        else:
            out.append((float(t[k, k]), 0.0))
            k += 1
    return out


def positional_arity(f: Any) -> int:
    """How many positional arguments the callable ``f`` takes (2 if it takes ``*args`` or its
    signature cannot be read): scipy's real-output sort callables get ``(re, im)``, but
    one-argument callables are called with ``re`` only (f2py's callback convention)."""
    import inspect

    try:
        params = inspect.signature(f).parameters.values()
    except (TypeError, ValueError):
        return 2
    count = 0
    for p in params:
        if p.kind is p.VAR_POSITIONAL:
            return 2
        if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD):
            count += 1
    return count
