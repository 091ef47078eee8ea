"""The Hessian ``η''_JJ`` of the cost on a face ``J`` of the simplex at one rate vector, as the
path follower (:mod:`.kkt_newton`) needs it: products ``η''·v``, solves ``η''_JJ x = b`` and the
diagonal dominance of ``[η''_JJ]⁻¹`` (Theorem 2's condition).

Two ways to hold it:

* :class:`ExactFace` — the full Hessian formed at the point (``N+1`` Lyapunov solves): solves
  are direct.
* :class:`KrylovFace` — only Hessian-vector products at the point (two Lyapunov solves each),
  with a *reference* Hessian formed at an earlier point as preconditioner: ``η''_JJ x = b`` is
  solved by preconditioned conjugate gradients (``η''`` is symmetric positive definite on the
  path), converging in a few products while the path stays close to where the reference was
  formed. The reference also serves as the chord matrix of the Newton corrector; it is
  re-formed when the conjugate gradients or the chord iteration slow down.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
Index = npt.NDArray[np.intp]

#: Relative residual of the conjugate-gradient solves (the tangent is then exact to rounding
#: level for the predictor, the event slopes and the stored node derivatives).
CG_TOL = 1e-13
#: Conjugate-gradient iterations after which the reference Hessian is re-formed (here, at the
#: current point: the solve is then direct).
CG_REFRESH = 8


def _sym_block(h: F64, jj: Index) -> F64:
    block = h[np.ix_(jj, jj)]
    return np.asarray(0.5 * (block + block.T), dtype=np.float64)


def dominant_inverse(minv: F64) -> bool:
    """``minv`` strictly diagonally dominant (every row; trivially for one row)."""
    if minv.shape[0] <= 1:
        return True
    off = np.sum(np.abs(minv), axis=1) - np.abs(np.diag(minv))
    return bool(np.all(np.abs(np.diag(minv)) > off))


class ExactFace:
    """The full Hessian ``h`` at the point."""

    def __init__(self, h: F64) -> None:
        self.h = h

    def hvp(self, v: F64) -> F64:
        """``η''·v`` (length N)."""
        return np.asarray(self.h @ v, dtype=np.float64)

    def solve(self, jj: Index, b: F64, tol: float = 0.0) -> F64:
        """``[η''_JJ]⁻¹ b`` (``b``: one or more columns), direct (``tol`` unused)."""
        return np.asarray(np.linalg.solve(_sym_block(self.h, jj), b), dtype=np.float64)

    def tangent(self, jj: Index, tol: float = 0.0) -> F64:
        """``x' = [η''_JJ]⁻¹ 1``."""
        return self.solve(jj, np.ones(jj.size), tol)

    def row(self, j: int, jj: Index, cols: F64, exact: bool = True) -> tuple[float, ...]:
        """``η''_jJ·c`` for every column ``c`` of ``cols`` (always exact)."""
        return tuple(float(v) for v in self.h[j, jj] @ cols)

    def dominant(self, jj: Index) -> bool:
        """``[η''_JJ]⁻¹`` strictly diagonally dominant at this point."""
        return dominant_inverse(np.asarray(np.linalg.inv(_sym_block(self.h, jj)), dtype=np.float64))


class Reference:
    """The reference Hessian shared by the Krylov faces (formed at some earlier point), with
    the inverse of its ``J`` block cached per face; counts how often it is formed."""

    def __init__(self) -> None:
        self.h: F64 | None = None
        self.formed = 0
        self._inv: dict[bytes, F64] = {}
        #: The last tangent solved on each face: the start of the next one's iteration.
        self.last_tangent: dict[bytes, F64] = {}

    def form(self, point: Any) -> None:
        """Form the Hessian at ``point`` (a :class:`~capalloc_rs.network.CostPoint`)."""
        self.h = np.asarray(point.hessian(), dtype=np.float64)
        self.formed += 1
        self._inv.clear()

    def inverse(self, jj: Index) -> F64:
        """``[H_ref,JJ]⁻¹``."""
        assert self.h is not None
        key = jj.tobytes()
        if key not in self._inv:
            self._inv[key] = np.asarray(np.linalg.inv(_sym_block(self.h, jj)), dtype=np.float64)
        return self._inv[key]


class KrylovFace:
    """Hessian-vector products at ``point`` with the shared reference Hessian (module
    docstring). ``fresh`` says whether the reference was formed at this very point."""

    def __init__(self, point: Any, ref: Reference, fresh: bool) -> None:
        self.point = point
        self.ref = ref
        self.fresh = fresh
        self.products = 0
        self.point_size = 0 if ref.h is None else ref.h.shape[0]

    def hvp(self, v: F64) -> F64:
        """``η''·v`` (length N), one Hessian-vector product."""
        self.products += 1
        return np.asarray(self.point.hvp(v), dtype=np.float64)

    def row(self, j: int, jj: Index, cols: F64, exact: bool = False) -> tuple[float, ...]:
        """``η''_jJ·c`` for every column ``c`` of ``cols``: with ``exact`` by products (one a
        column), else with the reference Hessian — only the enter condition's row of the
        Newton matrix is then approximate (an inexact Newton step; on the benchmark paths it
        needs no more iterations). The last step of a solve needs the exact row."""
        if exact:
            full = np.zeros((self.point_size, cols.shape[1]))
            full[jj] = cols
            self.products += cols.shape[1] - 1
            return tuple(float(v) for v in self.hvp(full)[j])
        assert self.ref.h is not None
        return tuple(float(v) for v in self.ref.h[j, jj] @ cols)

    def tangent(self, jj: Index, tol: float = CG_TOL) -> F64:
        """``x' = [η''_JJ]⁻¹ 1`` by conjugate gradients started from the last tangent solved on
        this face (the path moved little since)."""
        key = jj.tobytes()
        x = None
        if not self.fresh:
            x = self._pcg(jj, np.ones(jj.size), tol, self.ref.last_tangent.get(key))
        if x is None:
            self.refresh()
            x = self.ref.inverse(jj) @ np.ones(jj.size)
        self.ref.last_tangent[key] = x
        return x

    def solve(self, jj: Index, b: F64, tol: float = CG_TOL) -> F64:
        """``[η''_JJ]⁻¹ b`` column by column, by preconditioned conjugate gradients to relative
        residual ``tol``; when they need more than :data:`CG_REFRESH` products the reference is
        re-formed here and the solve is direct."""
        cols = b.reshape(b.shape[0], -1)
        out = np.empty_like(cols)
        for c in range(cols.shape[1]):
            x = None if self.fresh else self._pcg(jj, cols[:, c], tol, None)
            if x is None:
                self.refresh()
                x = self.ref.inverse(jj) @ cols[:, c]
            out[:, c] = x
        return out.reshape(b.shape)

    def refresh(self) -> None:
        """Form the reference Hessian at this point (once)."""
        if not self.fresh:
            self.ref.form(self.point)
            self.fresh = True

    def _pcg(self, jj: Index, b: F64, tol: float, x0: F64 | None = None) -> F64 | None:
        """PCG for ``η''_JJ x = b`` preconditioned by ``[H_ref,JJ]⁻¹``; ``None`` if not converged
        within :data:`CG_REFRESH` products (or the curvature is not positive)."""
        minv = self.ref.inverse(jj)
        full = np.zeros(self.point_size)
        x = minv @ b if x0 is None else x0.copy()
        full[jj] = x
        r = b - self.hvp(full)[jj]
        bnorm = float(np.max(np.abs(b)))
        z = minv @ r
        p = z.copy()
        rz = float(r @ z)
        for _ in range(CG_REFRESH):
            if float(np.max(np.abs(r))) <= tol * bnorm:
                return x
            full[jj] = p
            ap = self.hvp(full)[jj]
            curv = float(p @ ap)
            if not curv > 0.0:
                return None
            alpha = rz / curv
            x = x + alpha * p
            r = r - alpha * ap
            z = minv @ r
            rz_new = float(r @ z)
            p = z + (rz_new / rz) * p
            rz = rz_new
        return x if float(np.max(np.abs(r))) <= tol * bnorm else None

    def dominant(self, jj: Index) -> bool:
        """``[η''_JJ]⁻¹`` strictly diagonally dominant, checked with the reference Hessian (the
        Hessian at the last point where it was formed)."""
        return dominant_inverse(self.ref.inverse(jj))
