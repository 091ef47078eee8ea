"""Extended-precision references for Riccati tests (mpmath): Lyapunov equations by their Kronecker
systems and Newton–Kleinman for the CARE, started from a double-precision solution. For small
problems only (the Kronecker system has n² unknowns)."""

from __future__ import annotations

from typing import Any

import mpmath as mp
import numpy as np

DPS = 50


def mpm(a: Any) -> Any:
    """A float array as an mpmath matrix."""
    return mp.matrix(np.atleast_2d(np.asarray(a, dtype=float)).tolist())


def to_float(m: Any) -> np.ndarray:
    return np.array(m.tolist(), dtype=float)


def relative_error(x: np.ndarray, ref: Any, dps: int = DPS) -> float:
    """``‖x − ref‖_F / ‖ref‖_F`` for a float ``x`` and an mpmath reference, in ``dps`` digits."""
    with mp.workdps(dps):
        return float(mp.mnorm(mpm(x) - ref, "f") / mp.mnorm(ref, "f"))


def lyap(a: Any, c: Any) -> Any:
    """Solves ``a X + X aᵀ = c`` (mpmath matrices) by its Kronecker system."""
    n = a.rows
    k = mp.zeros(n * n, n * n)
    rhs = mp.zeros(n * n, 1)
    for i in range(n):
        for j in range(n):
            row = i * n + j
            rhs[row] = c[i, j]
            for m in range(n):
                k[row, m * n + j] += a[i, m]
                k[row, i * n + m] += a[j, m]
    sol = mp.lu_solve(k, rhs)
    return mp.matrix([[sol[i * n + j] for j in range(n)] for i in range(n)])


def care(a: Any, g: Any, q: Any, x0: Any, dps: int = DPS, steps: int = 40) -> Any:
    """The solution of ``AᵀX + XA − XGX + Q = 0`` near ``x0`` (all mpmath matrices or arrays) by
    Newton–Kleinman at ``dps`` digits: ``(A − GX)ᵀX⁺ + X⁺(A − GX) = −(Q + XGX)``."""
    with mp.workdps(dps):
        a, g, q, x = (v if isinstance(v, mp.matrix) else mpm(v) for v in (a, g, q, x0))
        for _ in range(steps):
            acl = a - g * x
            xn = lyap(acl.T, -(q + x * g * x))
            xn = (xn + xn.T) / 2
            delta = mp.mnorm(xn - x, 1)
            x = xn
            if delta <= mp.mpf(10) ** (-dps + 8) * mp.mnorm(x, 1):
                break
        return x


def care_bqr(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: Any, x0: np.ndarray) -> np.ndarray:
    """scipy's form ``AᵀX + XA − XBR⁻¹BᵀX + Q = 0`` in extended precision, rounded to float."""
    with mp.workdps(DPS):
        bm = mpm(b)
        g = bm * mp.inverse(mpm(np.atleast_2d(r))) * bm.T
        return to_float(care(mpm(a), g, mpm(q), mpm(x0)))


def error_by_residual(
    a: np.ndarray, b: np.ndarray, q: np.ndarray, x: np.ndarray, dps: int = 40
) -> float:
    """``‖Ω⁻¹(R(X))‖_F / ‖X‖_F``, the first-order error of ``X`` for ``AᵀX + XA − XBBᵀX + Q = 0``:
    the residual formed in mpmath at ``dps`` digits (exact for double data), mapped through the
    closed-loop Lyapunov operator by scipy. Unlike a long-double residual (whose rounding,
    ~1e-19·|A||X|, maps to ~1e-9 relative on stiff models) it resolves errors at the ulp level."""
    import scipy.linalg as sla

    with mp.workdps(dps):
        am, bm, qm, xm = (mpm(v) for v in (a, b, q, x))
        xb = xm * bm
        res = to_float(am.T * xm + xm * am - xb * xb.T + qm)
    acl = a - b @ (b.T @ x)
    d = sla.solve_continuous_lyapunov(acl.T, -res)
    return float(np.linalg.norm(d) / np.linalg.norm(x))
