"""The Hessian ``η''_JJ`` of the cost on a face ``J`` of the simplex at one rate vector, as the
path follower (:mod:`.kkt_newton`) needs it: products ``η''·v``, solves ``η''_JJ x = b`` and the
diagonal dominance of ``[η''_JJ]⁻¹`` (Theorem 2's condition).

Three ways to hold it:

* :class:`ExactFace` — the full Hessian formed at the point (``N+1`` Lyapunov solves): solves
  are direct.
* :class:`BlockFace` — the principal block on the face and the sensor of an enter condition
  (``|J| + 1`` Lyapunov solves instead of ``N``): solves are direct, the full product of a
  solution (the events' slopes at a node) costs one Hessian-vector product.
* :class:`KrylovFace` — only Hessian-vector products at the point (two Lyapunov solves each),
  with a *reference* Hessian formed at an earlier point as preconditioner: ``η''_JJ x = b`` is
  solved by preconditioned conjugate gradients (``η''`` is symmetric positive definite on the
  path), converging in a few products while the path stays close to where the reference was
  formed; it is re-formed (at the current point) when the conjugate gradients slow down.

Two ways of reusing the products already computed (no new product):

* **Deflation at one point.** A second solve at the same point starts from the Galerkin
  approximation in the span ``S`` of the first solve's directions (``η''S`` is known), and
  its own directions are then ``η''``-orthogonal to ``S`` through the preconditioner below.
* **Limited-memory preconditioner** (the LMP of Gratton, Sartenaer and Tshimanga): with
  ``Y = η''S`` from the latest point and ``G = SᵀY``, ``P·M⁻¹·Pᵀ + S G⁻¹ Sᵀ`` (``P = I −
  S G⁻¹Yᵀ``, ``M`` the reference block) is symmetric positive definite and inverts ``η''_JJ``
  exactly on ``S`` — the directions where the reference was found wanting; the path moves
  little between points, so the next point's solves converge in fewer products. With
  ``seed_faces`` (the path's sixth version) a face without solves at this point — the new face
  after an enter — gets that preconditioner from the solves on the old face inside it (0 at the
  entering sensor; their products on the new face are known exactly).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__: list[str] = []

F64 = npt.NDArray[np.float64]
Index = npt.NDArray[np.intp]
#: A solve's result: ``x`` on the face (length |J|) and the full product ``η''_{:,J}·x``
#: (length N) — kept along the conjugate-gradient recurrence at no extra product, it gives the
#: event rows, the event slopes and the extrapolated gradient without further products.
Solved = tuple[F64, F64]

#: Relative residual of the conjugate-gradient solves (the tangent is then exact to rounding
#: level for the predictor, the event slopes and the stored node derivatives).
CG_TOL = 1e-13
#: Conjugate-gradient iterations after which the reference Hessian is re-formed (here, at the
#: current point: the solve is then direct).
CG_REFRESH = 6


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

    def solve(self, jj: Index, b: F64, tol: float = 0.0) -> Solved:
        """``x = [η''_JJ]⁻¹ b`` and ``η''_{:,J}·x`` (length N), direct (``tol`` unused)."""
        x = np.asarray(np.linalg.solve(_sym_block(self.h, jj), b), dtype=np.float64)
        return x, np.asarray(self.h[:, jj] @ x, dtype=np.float64)

    def tangent(self, jj: Index, tol: float = 0.0) -> Solved:
        """``x' = [η''_JJ]⁻¹ 1`` and ``η''_{:,J}·x'``."""
        return self.solve(jj, np.ones(jj.size), tol)

    @staticmethod
    def complete(jj: Index, x: F64, hx: F64) -> F64:
        """The full product ``η''_{:,J}·x``: ``hx`` itself (always complete here)."""
        return hx

    def dominant(self, jj: Index) -> bool:
        """``[η''_JJ]⁻¹`` strictly diagonally dominant at this point."""
        return dominant_inverse(np.asarray(np.linalg.inv(_sym_block(self.h, jj)), dtype=np.float64))


class BlockFace:
    """The principal block ``η''_KK`` of the Hessian on the sensors ``K ⊇ J`` the Newton step at
    this point can need (the face ``J`` and the sensor of an enter condition), formed by the
    ``|K|`` Lyapunov solves of :meth:`~capalloc_rs.network.CostPoint.hessian_block` instead of
    ``N``. Solves on a face inside ``K`` are direct; the products ``η''_{:,J}·x`` they return
    are exact on the rows ``K`` and NaN elsewhere until :meth:`complete` fills them in (one
    Hessian-vector product: only where the full product is used, at a path node)."""

    def __init__(self, point: Any, idx: Index) -> None:
        self.point = point
        self.idx = np.asarray(idx, dtype=np.intp)
        self.h = np.asarray(point.hessian_block([int(i) for i in self.idx]), dtype=np.float64)
        self.size = int(np.asarray(point.gradient).size)

    def _pos(self, jj: Index) -> Index:
        """The positions of the face ``jj`` in the block (the block is extended, by the
        missing sensors' solves, if the face is not inside it)."""
        pos = np.searchsorted(self.idx, jj)
        top = self.idx.size - 1
        if np.any(pos > top) or np.any(self.idx[np.minimum(pos, top)] != jj):
            self.__init__(self.point, np.union1d(self.idx, jj))  # type: ignore[misc]
            pos = np.searchsorted(self.idx, jj)
        return np.asarray(pos, dtype=np.intp)

    def solve(self, jj: Index, b: F64, tol: float = 0.0) -> Solved:
        """``x = [η''_JJ]⁻¹ b`` (direct; ``tol`` unused) and ``η''_{:,J}·x`` on the rows ``K``
        (NaN elsewhere)."""
        pos = self._pos(jj)
        x = np.asarray(np.linalg.solve(_sym_block(self.h, pos), b), dtype=np.float64)
        hx = np.full(self.size, np.nan)
        hx[self.idx] = self.h[:, pos] @ x
        return x, hx

    def tangent(self, jj: Index, tol: float = 0.0) -> Solved:
        """``x' = [η''_JJ]⁻¹ 1`` and ``η''_{:,J}·x'`` on the rows ``K``."""
        return self.solve(jj, np.ones(jj.size), tol)

    def complete(self, jj: Index, x: F64, hx: F64) -> F64:
        """The full product ``η''_{:,J}·x`` (``hx`` filled in by one Hessian-vector product if
        it has rows missing)."""
        if not np.any(np.isnan(hx)):
            return hx
        full = np.zeros(self.size)
        full[jj] = x
        return np.asarray(self.point.hvp(full), dtype=np.float64)

    def dominant(self, jj: Index) -> bool:
        """``[η''_JJ]⁻¹`` strictly diagonally dominant at this point."""
        block = _sym_block(self.h, self._pos(jj))
        return dominant_inverse(np.asarray(np.linalg.inv(block), dtype=np.float64))


class Reference:
    """The reference Hessian shared by the Krylov faces (formed at some earlier point), with
    the inverse of its ``J`` block cached per face; counts how often it is formed."""

    def __init__(self, seed_faces: bool = False) -> None:
        self.h: F64 | None = None
        self.formed = 0
        #: Seed a new face's preconditioner with the solves on a face inside it at the same
        #: point (:meth:`KrylovFace.tangent` after an enter; the path's sixth version).
        self.seed_faces = seed_faces
        self._inv: dict[bytes, F64] = {}
        #: The last tangent solved on each face: the start of the next one's iteration.
        self.last_tangent: dict[bytes, F64] = {}
        self._pre: dict[bytes, F64] = {}

    def form(self, point: Any) -> None:
        """Form the Hessian at ``point`` (a :class:`~capalloc_rs.network.CostPoint`)."""
        self.h = np.asarray(point.hessian(), dtype=np.float64)
        self.formed += 1
        self._inv.clear()
        self._pre.clear()

    def start(self, jj: Index, x: F64) -> None:
        """Start the next tangent solve on the face ``jj`` from ``x`` (a predicted tangent)
        instead of the last one solved there."""
        self.last_tangent[jj.tobytes()] = np.asarray(x, dtype=np.float64)

    def preconditioner(self, jj: Index) -> F64:
        """The preconditioner of the face: ``[H_ref,JJ]⁻¹``, updated by the last
        :meth:`update`."""
        pre = self._pre.get(jj.tobytes())
        return self.inverse(jj) if pre is None else pre

    def update(self, jj: Index, s: F64, y: F64) -> None:
        """The limited-memory preconditioner ``P·[H_ref,JJ]⁻¹·Pᵀ + S G⁻¹ Sᵀ`` (``G = SᵀY``,
        ``P = I − S G⁻¹ Yᵀ``) from the directions ``S`` and their products ``Y = η''_JJ S`` at
        the latest point: symmetric positive definite, it inverts ``η''_JJ`` exactly on the
        span of ``S`` — the directions where the reference was found wanting — and is the
        reference elsewhere. Kept as it was if ``G`` is not safely positive definite."""
        gram = 0.5 * (s.T @ y + y.T @ s)
        scale = np.sqrt(np.maximum(np.diag(gram), 1e-300))
        normed = gram / np.outer(scale, scale)
        if not (np.all(np.diag(gram) > 0.0) and np.min(np.linalg.eigvalsh(normed)) > 1e-8):
            return
        ginv = np.linalg.inv(gram)
        proj = np.eye(jj.size) - s @ ginv @ y.T
        pre = proj @ self.inverse(jj) @ proj.T + s @ ginv @ s.T
        self._pre[jj.tobytes()] = np.asarray(0.5 * (pre + pre.T), dtype=np.float64)

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
        #: Per face, the vectors ``v`` (on ``J``) of the last solve at this point with their
        #: products ``η''v`` (length N): the Galerkin start of the next solve at this point.
        self._span: dict[bytes, tuple[Index, list[F64], list[F64]]] = {}

    def hvp(self, v: F64) -> F64:
        """``η''·v`` (length N), one Hessian-vector product."""
        self.products += 1
        return np.asarray(self.point.hvp(v), dtype=np.float64)

    def tangent(self, jj: Index, tol: float = CG_TOL) -> Solved:
        """``x' = [η''_JJ]⁻¹ 1`` and ``η''_{:,J}·x'`` by conjugate gradients started from the
        Galerkin start if solves were made at this point (on this face or on a smaller one:
        after an enter), else from the last tangent solved on this face (the path moved little
        since)."""
        key = jj.tobytes()
        out = None
        if not self.fresh:
            x0 = None if self._span_on(jj) is not None else self.ref.last_tangent.get(key)
            out = self._pcg(jj, np.ones(jj.size), tol, x0)
        if out is None:
            out = self._direct(jj, np.ones(jj.size))
        self.ref.last_tangent[key] = out[0]
        return out

    def solve(self, jj: Index, b: F64, tol: float = CG_TOL) -> Solved:
        """``x = [η''_JJ]⁻¹ b`` and ``η''_{:,J}·x`` by preconditioned conjugate gradients to
        relative residual ``tol``; when they need more than :data:`CG_REFRESH` products the
        reference is re-formed here and the solve is direct."""
        out = None if self.fresh else self._pcg(jj, b, tol, None)
        return self._direct(jj, b) if out is None else out

    def _span_on(self, jj: Index) -> tuple[list[F64], list[F64]] | None:
        """The vectors of the solves at this point on the face ``J`` or, if none, on the
        latest face contained in ``J`` (embedded: 0 at the other sensors), with their products
        (length N); ``None`` if there were none."""
        found = self._span.get(jj.tobytes())
        if found is None:
            inside = [f for f in self._span.values() if np.all(np.isin(f[0], jj))]
            if not inside:
                return None
            found = inside[-1]
        pos = np.searchsorted(jj, found[0]) if np.all(np.diff(jj) > 0) else None
        if pos is None:
            pos = np.array([int(np.flatnonzero(jj == i)[0]) for i in found[0]], dtype=np.intp)
        vs = []
        for v in found[1]:
            e = np.zeros(jj.size)
            e[pos] = v
            vs.append(e)
        return vs, list(found[2])

    def _galerkin(self, jj: Index, b: F64) -> Solved | None:
        """The best approximation of ``[η''_JJ]⁻¹b`` (in the ``η''`` norm) in the span of the
        solves' vectors at this point (:meth:`_span_on`), and its product: no new product."""
        span = self._span_on(jj)
        if span is None:
            return None
        v, hv = np.column_stack(span[0]), np.column_stack(span[1])
        gram = v.T @ hv[jj]
        coef = np.linalg.lstsq(0.5 * (gram + gram.T), v.T @ b, rcond=1e-12)[0]
        return np.asarray(v @ coef, dtype=np.float64), np.asarray(hv @ coef, dtype=np.float64)

    def _direct(self, jj: Index, b: F64) -> Solved:
        """The solve with the reference formed at this point (formed now if needed)."""
        self.refresh()
        assert self.ref.h is not None
        x = np.asarray(self.ref.inverse(jj) @ b, dtype=np.float64)
        return x, np.asarray(self.ref.h[:, jj] @ x, dtype=np.float64)

    def refresh(self) -> None:
        """Form the reference Hessian at this point (once)."""
        if not self.fresh:
            self.ref.form(self.point)
            self.fresh = True

    def _pcg(self, jj: Index, b: F64, tol: float, x0: F64 | None = None) -> Solved | None:
        """PCG for ``η''_JJ x = b`` from ``x₀`` (without it from the Galerkin start, or 0),
        preconditioned by the face's preconditioner
        (:meth:`Reference.preconditioner`), with the full product ``η''·x`` updated along
        (``x += αp`` ⇒ ``η''x += α·η''p``); ``None`` if not converged within
        :data:`CG_REFRESH` products (or the curvature is not positive). Its directions and
        products update the preconditioner."""
        if self.ref.seed_faces and x0 is None and jj.tobytes() not in self._span:
            self._seed(jj)
        minv = self.ref.preconditioner(jj)
        full = np.zeros(self.point_size)
        start = self._galerkin(jj, b) if x0 is None else None
        span: tuple[list[F64], list[F64]] = ([], [])
        if start is not None:  # the span grows: the directions so far at this point
            x, hx = start
            old = self._span_on(jj)
            assert old is not None
            span = old
        elif x0 is None:  # from 0: the first step goes along [H_ref,JJ]⁻¹b, optimally scaled
            x, hx = np.zeros(jj.size), np.zeros(self.point_size)
        else:
            x = x0.copy()
            full[jj] = x
            hx = self.hvp(full)
            span[0].append(x.copy())
            span[1].append(hx.copy())
        r = b - hx[jj]
        out = self._iterate(jj, (b, x, hx, r), tol, minv, span)
        if span[0]:
            self._span[jj.tobytes()] = (jj.copy(), span[0], span[1])
            self.ref.update(jj, np.column_stack(span[0]), np.column_stack(span[1])[jj])
        return out

    def _seed(self, jj: Index) -> None:
        """The preconditioner of a face without solves at this point made exact on the span of
        the solves on a face inside it (after an enter: the old face's directions, 0 at the
        entering sensor, whose products on the new face are known): the new face's conjugate
        gradients then only work on what the old face's did not see."""
        span = self._span_on(jj)
        if span is not None:
            s, y = np.column_stack(span[0]), np.column_stack(span[1])[jj]
            self.ref.update(jj, s, y)

    def _iterate(
        self,
        jj: Index,
        state: tuple[F64, F64, F64, F64],
        tol: float,
        minv: F64,
        span: tuple[list[F64], list[F64]],
    ) -> Solved | None:
        """The PCG iterations of :meth:`_pcg` from ``state = (b, x, η''x, residual)``,
        recording the directions and their products in ``span``."""
        b, x, hx, r = state
        full = np.zeros(self.point_size)
        bnorm = float(np.max(np.abs(b)))
        z = minv @ r
        p = z.copy()
        rz = float(r @ z)
        for _ in range(CG_REFRESH):
            if float(np.max(np.abs(r))) <= tol * bnorm:
                return x, hx
            full[jj] = p
            hp = self.hvp(full)
            ap = hp[jj]
            span[0].append(p.copy())
            span[1].append(hp)
            curv = float(p @ ap)
            if not curv > 0.0:
                return None
            alpha = rz / curv
            x = x + alpha * p
            hx = hx + alpha * hp
            r = r - alpha * ap
            z = minv @ r
            rz_new = float(r @ z)
            p = z + (rz_new / rz) * p
            rz = rz_new
        return (x, hx) if float(np.max(np.abs(r))) <= tol * bnorm else None

    @staticmethod
    def complete(jj: Index, x: F64, hx: F64) -> F64:
        """The full product ``η''_{:,J}·x``: ``hx`` itself (always complete here)."""
        return hx

    def dominant(self, jj: Index) -> bool:
        """``[η''_JJ]⁻¹`` strictly diagonally dominant, checked with the reference Hessian (the
        Hessian at the last point where it was formed)."""
        return dominant_inverse(self.ref.inverse(jj))
