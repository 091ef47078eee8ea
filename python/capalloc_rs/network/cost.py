"""The cost ``η(r) = tr Σ(r)`` of a network and its derivatives: the evaluation façade over the
Rust ``_core.CostModel``.

``Σ(r)`` is the stabilising solution of the filter Riccati equation
``AΣ + ΣAᵀ − ΣW(r)Σ + GGᵀ = 0`` with ``W(r) = Σ_i r_i ĉ_iĉ_iᵀ``. The gradient needs one adjoint
Lyapunov solve (``A_clᵀY + YA_cl = −I``, ``A_cl = A − ΣW``), the Hessian ``N`` more and a
Hessian-vector product two. :class:`CostFacade` gives a network these evaluations,
:class:`CostPoint` keeps one evaluation point for repeated products, :class:`CostEvaluation` holds
one evaluation and :class:`BlockStructure` the block description of the paper's networks.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _core
from .._arrays import F64, as_count, as_float_array
from .._json import plain
from ..errors import InvalidInputError, NonFiniteError, ShapeError
from .block_structure import BlockStructure

__all__ = ["BlockStructure", "CostEvaluation", "CostFacade", "CostPoint", "MAX_THREADS"]


def _frozen(x: F64) -> F64:
    """A private, read-only copy."""
    out = np.array(x, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out


def _threads(threads: Any) -> int | None:
    """``threads`` checked: ``None`` (every core) or ``1 … MAX_THREADS``."""
    return None if threads is None else as_count("threads", threads, minimum=1, maximum=MAX_THREADS)


#: Largest ``threads`` argument accepted.
MAX_THREADS = 4096


@dataclass(frozen=True)
class CostEvaluation:
    """Everything one evaluation at a rate vector ``r`` produced (arrays are read-only).

    Attributes:
        rates: ``r``.
        value: ``η(r) = tr Σ(r)``.
        sigma: ``Σ(r)``, the stabilising solution of ``AΣ + ΣAᵀ − ΣW(r)Σ + GGᵀ = 0``.
        care_residual: relative residual of the Riccati solution.
        closed_loop_abscissa: ``max Re λ(A − ΣW) < 0``.
        gradient: ``∇η(r)`` (``order ≥ 1``), else ``None``.
        hessian: ``∇²η(r)`` (``order = 2``), else ``None``.
    """

    rates: F64
    value: float
    sigma: F64
    care_residual: float
    closed_loop_abscissa: float
    gradient: F64 | None
    hessian: F64 | None

    def to_dict(self) -> dict[str, Any]:
        """The evaluation as plain JSON-ready values (arrays as nested lists)."""
        return {
            "rates": plain(self.rates),
            "value": plain(self.value),
            "sigma": plain(self.sigma),
            "care_residual": plain(self.care_residual),
            "closed_loop_abscissa": plain(self.closed_loop_abscissa),
            "gradient": plain(self.gradient),
            "hessian": plain(self.hessian),
        }

    def __repr__(self) -> str:
        return f"CostEvaluation(N={self.rates.size}, value={self.value:.12g})"


def _products(hvp: Callable[[F64], F64], nn: int, v: Any) -> F64:
    """``hvp`` (an ``N × k`` → ``N × k`` product) applied to ``v`` of shape ``(N,)`` or
    ``(N, k)``; the result has the shape of ``v``. ShapeError/NonFiniteError for a bad ``v``."""
    varr = as_float_array("v", v, (1, 2))
    if varr.shape[0] != nn:
        raise ShapeError(f"v must have shape ({nn},) or ({nn}, k), got {varr.shape}")
    out = hvp(varr.reshape(nn, -1))
    return out[:, 0].copy() if varr.ndim == 1 else out


class CostPoint:
    """One evaluation point of ``η`` at rates ``r``, kept in Rust: the Riccati solution ``Σ(r)``,
    the real Schur form of ``A_cl = A − ΣW(r)`` and the adjoint ``Y`` (``A_clᵀY + YA_cl = −I``),
    from which the gradient follows. Made by :meth:`Network.at`; immutable.

    Every :meth:`hvp` reuses the cached Schur form, so a product costs two Lyapunov solves — no
    Riccati solve, no refactorisation (``Network.hvp(r, v)`` redoes both at every call). This is
    what Newton–CG needs: many products at one point. :meth:`hessian` costs ``N`` solves.
    Arrays returned are read-only. Pickling stores the network and the rates and re-evaluates.
    """

    __slots__ = ("_network", "_point", "_rates", "_gradient", "_sigma")

    _network: CostFacade
    _point: _core.CostPoint
    _rates: F64
    _gradient: F64
    _sigma: F64 | None

    def __init__(
        self, network: CostFacade, r: Any, *, _point: _core.CostPoint | None = None
    ) -> None:
        rr = network._rates(r)
        point = network._model.at(rr) if _point is None else _point
        set_ = object.__setattr__
        set_(self, "_network", network)
        set_(self, "_point", point)
        set_(self, "_rates", _frozen(rr))
        set_(self, "_gradient", _frozen(point.gradient))
        set_(self, "_sigma", None)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"CostPoint is immutable (cannot set {name!r})")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"CostPoint is immutable (cannot delete {name!r})")

    def __reduce__(self) -> tuple[Any, ...]:
        return (CostPoint, (self._network, self._rates))

    def __repr__(self) -> str:
        return f"CostPoint(N={self._network.num_sensors}, value={self.value:.12g})"

    def to_dict(self) -> dict[str, Any]:
        """The point's rates, value, gradient and solver diagnostics as plain JSON-ready values
        (``Σ`` is left out: it is ``n × n``; see :attr:`sigma`)."""
        return {
            "rates": plain(self.rates),
            "value": plain(self.value),
            "gradient": plain(self.gradient),
            "care_residual": plain(self.care_residual),
            "value_error": plain(self.value_error),
            "closed_loop_abscissa": plain(self.closed_loop_abscissa),
        }

    @property
    def network(self) -> CostFacade:
        """The network evaluated."""
        return self._network

    @property
    def rates(self) -> F64:
        """``r`` (read-only)."""
        return self._rates

    @property
    def value(self) -> float:
        """``η(r) = tr Σ(r)``."""
        return self._point.value

    @property
    def gradient(self) -> F64:
        """``∇η(r)`` (read-only); see :meth:`Network.gradient`."""
        return self._gradient

    @property
    def sigma(self) -> F64:
        """``Σ(r)`` (read-only)."""
        if self._sigma is None:
            object.__setattr__(self, "_sigma", _frozen(self._point.sigma))
        assert self._sigma is not None
        return self._sigma

    @property
    def care_residual(self) -> float:
        """Relative residual of the Riccati solution."""
        return self._point.care_residual

    @property
    def value_error(self) -> float:
        """An upper bound on ``|η − η_exact|``: the Riccati solver's error bound for ``tr Σ``
        (``tr(Y)·(‖R‖ + ‖E‖)`` with ``Y`` the adjoint, ``R`` the residual and ``E`` its rounding;
        see :class:`capalloc_rs.linalg.CareResult`). ``inf`` when no bound can be established."""
        return self._point.value_error

    @property
    def closed_loop_abscissa(self) -> float:
        """``max Re λ(A − ΣW) < 0``."""
        return self._point.closed_loop_abscissa

    @property
    def forward_error(self) -> float:
        """A bound on ``‖Σ − Σ_exact‖_F / ‖Σ_exact‖_F`` (as ``linalg.CareResult.forward_error``)."""
        return self._point.forward_error

    @property
    def warm_started(self) -> bool:
        """Whether ``Σ(r)`` was reached from a nearby point (:meth:`warm`), not solved cold."""
        return self._point.warm_started

    @property
    def warm_fallback(self) -> str | None:
        """Why a warm start (:meth:`warm`) fell back to the cold solve (``None``: it did not)."""
        return self._point.warm_fallback

    @property
    def warm_factorizations(self) -> int:
        """Schur forms of ``n × n`` closed loops its warm start computed (0: a cold point)."""
        return self._point.warm_factorizations

    @property
    def warm_chord_steps(self) -> int:
        """Chord corrections (:meth:`warm`) its warm start applied (0: a cold point, or none)."""
        return self._point.warm_chord_steps

    def warm(self, r: Any, *, chord_steps: int = 0, compensated: bool = True) -> CostPoint:
        """The point at ``r`` from this one: Newton–Kleinman ``A_k Δ + Δ A_kᵀ = −R(Σ_k)``,
        ``A_k = A − Σ_k W(r)``, from this ``Σ`` (a predictor step on its factored closed loop
        first), an ``n × n`` Schur form per correction, not the ``2n × 2n`` Hamiltonian's. Answer
        and diagnostics are :meth:`Network.at`'s (to rounding, same error bounds); from a start
        not stabilising, without contraction or certificate, the cold solve (:attr:`warm_fallback`).

        Args:
            r: the rates.
            chord_steps: at most this many chord corrections ``Σ + Ω⁻¹(−R(Σ))`` with this
                point's factored closed-loop operator ``Ω`` first (a Lyapunov solve each, not a
                Schur form; stopped when one does not contract by 4): near this point Newton
                then needs one Schur form. 0 (default): the predictor step alone.
            compensated: ``True`` (default): an iteration stalled at a large rounding floor (stiff
                models, state order ≤ 64) is refined with double-double residuals, as the cold
                solve may be. ``False``: it ends at the working-precision floor and reports the
                error bounds of that floor, a few times the cold solve's (the filtration's
                path points: faster there).

        Raises:
            InvalidInputError: ``chord_steps`` not an integer in ``[0, 64]``, or ``compensated``
                not ``True`` or ``False``.
            as :meth:`Network.cost`.
        """
        steps = as_count("chord_steps", chord_steps, maximum=64)
        if not isinstance(compensated, bool | np.bool_):
            raise InvalidInputError(f"compensated must be True or False, got {compensated!r}")
        rr = self._network._rates(r)
        point = self._point.warm(rr, steps, bool(compensated))
        return CostPoint(self._network, rr, _point=point)

    def hvp(self, v: Any) -> F64:
        """``∇²η(r) v`` without forming the Hessian: two Lyapunov solves per vector on the cached
        Schur form (formula in :meth:`Network.hvp`). ``v`` is ``(N,)`` or ``(N, k)``; the result
        has the shape of ``v``.

        Raises:
            ShapeError: ``v`` of the wrong shape.
            NonFiniteError: ``v`` with NaN or infinite entries.
        """
        return _products(self._point.hvp, self._network.num_sensors, v)

    def hessian(self, *, threads: int | None = None) -> F64:
        """``∇²η(r)`` (``N`` Lyapunov solves on the cached Schur form; ``threads`` as in
        :meth:`Network.hessian`)."""
        return self._point.hessian(_threads(threads))

    def hessian_block(self, idx: Any, *, threads: int | None = None) -> F64:
        """The principal block ``[∇²η(r)]_JJ`` on the sensors ``idx = J`` (in that order): the
        ``|J|`` Lyapunov solves for ``Σ'_i, i ∈ J`` only, the entries as in :meth:`hessian`
        (what Newton's method on a face ``J`` of the simplex needs).

        Raises:
            InvalidInputError: ``idx`` is not a sequence of sensor indices in ``[0, N)``.
        """
        nn = self._network.num_sensors
        try:
            items = [operator.index(i) for i in np.asarray(idx).ravel().tolist()]
        except TypeError:
            raise InvalidInputError(f"idx must be sensor indices, got {idx!r}") from None
        if any(not 0 <= i < nn for i in items):
            raise InvalidInputError(f"idx must be sensor indices in [0, {nn}), got {items}")
        return self._point.hessian_block(items, _threads(threads))


class CostFacade:
    """The evaluations of ``η`` a network offers (mixed into :class:`~capalloc_rs.Network`):
    every method takes the rates ``r`` (length ``N``, every ``r_i > 0``) and runs in Rust with the
    GIL released."""

    __slots__ = ()

    _sensors: tuple[F64, ...]
    _model: _core.CostModel

    @property
    def num_sensors(self) -> int:
        """``N``."""
        return len(self._sensors)

    def weight(self, r: Any) -> F64:
        """``W(r) = Σ_i r_i ĉ_i ĉ_iᵀ``."""
        return self._model.weight(self._rates(r))

    # -- evaluation -----------------------------------------------------------------------------

    def _rates(self, r: Any) -> F64:
        arr = as_float_array("r", r, 1)
        if arr.shape[0] != self.num_sensors:
            raise ShapeError(
                f"r must have one rate per sensor ({self.num_sensors}), got length {arr.shape[0]}"
            )
        return arr

    def _batch(self, rates: Any) -> F64:
        arr = as_float_array("rates", rates, 2)
        if arr.shape[1] != self.num_sensors:
            raise ShapeError(f"rates must have shape (K, {self.num_sensors}), got {arr.shape}")
        return arr

    def cost(self, r: Any) -> float:
        """``η(r) = tr Σ(r)``, ``Σ`` the stabilising solution of
        ``AΣ + ΣAᵀ − ΣW(r)Σ + GGᵀ = 0``.

        Raises:
            ShapeError, NonFiniteError, InvalidInputError: ``r`` of the wrong length, non-finite or
                not positive.
            NoStabilizingSolutionError, SingularProblemError: the Riccati solver failed.
        """
        return self._model.cost(self._rates(r))

    def covariance(self, r: Any) -> F64:
        """``Σ(r)``, the steady-state error covariance (see :meth:`cost`)."""
        return self._model.evaluate(self._rates(r), 0).sigma

    def gradient(self, r: Any) -> F64:
        """``∇η(r)``: ``∂η/∂r_i = −tr(ĉ_iᵀ Σ Y Σ ĉ_i) ≤ 0`` with ``Y`` the solution of the single
        adjoint equation ``A_clᵀY + YA_cl = −I``, ``A_cl = A − ΣW(r)``."""
        return self._model.value_gradient(self._rates(r)).gradient

    def value_and_gradient(self, r: Any) -> tuple[float, F64]:
        """``(η(r), ∇η(r))`` from one Riccati and one Lyapunov solve."""
        vg = self._model.value_gradient(self._rates(r))
        return vg.value, vg.gradient

    def hessian(self, r: Any, *, threads: int | None = None) -> F64:
        """``∇²η(r)`` (``N × N``, symmetric positive semidefinite).

        ``Σ'_i`` solves ``A_clΣ'_i + Σ'_iA_clᵀ = Σ C_i Σ`` (``C_i = ĉ_iĉ_iᵀ``) and
        ``∂²η/∂r_i∂r_j = −2[tr(YΣ'_iWΣ'_j) + tr(YΣ'_iC_jΣ) + tr(YΣ'_jC_iΣ)]``: ``N + 1`` Lyapunov
        solves sharing one real Schur form of ``A_cl``, spread over ``threads`` threads (default:
        every core; pass 1 inside process-pool workers to avoid oversubscription; the result does
        not depend on it). Memory ``O(N·n·Σp_i)``; for large ``N`` prefer :meth:`hvp`.
        """
        h = self._model.evaluate(self._rates(r), 2, _threads(threads)).hessian
        assert h is not None
        return h

    def value_gradient_hessian(
        self, r: Any, *, threads: int | None = None
    ) -> tuple[float, F64, F64]:
        """``(η(r), ∇η(r), ∇²η(r))`` in one call (one Riccati solve, one Schur form); ``threads``
        as in :meth:`hessian`."""
        ev = self._model.evaluate(self._rates(r), 2, _threads(threads))
        assert ev.gradient is not None and ev.hessian is not None
        return ev.value, ev.gradient, ev.hessian

    def evaluate(self, r: Any, order: int = 1, *, threads: int | None = None) -> CostEvaluation:
        """Value, ``Σ``, solver diagnostics and derivatives up to ``order`` (0, 1 or 2);
        ``threads`` as in :meth:`hessian`."""
        order = as_count("order", order, maximum=2)
        rr = self._rates(r)
        ev = self._model.evaluate(rr, order, _threads(threads))
        return CostEvaluation(
            _frozen(rr),
            ev.value,
            _frozen(ev.sigma),
            ev.care_residual,
            ev.closed_loop_abscissa,
            None if ev.gradient is None else _frozen(ev.gradient),
            None if ev.hessian is None else _frozen(ev.hessian),
        )

    def hvp(self, r: Any, v: Any) -> F64:
        """Hessian-vector product ``∇²η(r) v`` without forming the Hessian.

        With ``C_v = Σ v_j C_j``: ``A_clΣ'_v + Σ'_vA_clᵀ = ΣC_vΣ``, ``M = (WΣ'_v + C_vΣ)Y``,
        ``A_clᵀZ + ZA_cl = −(M + Mᵀ)/2``, and
        ``(∇²η v)_i = 2 tr(ĉ_iᵀΣZΣĉ_i) − 2 tr(ĉ_iᵀΣYΣ'_vĉ_i)``: two Lyapunov solves per vector
        after the gradient's. ``v`` may be ``(N,)`` or ``(N, k)`` (``k`` products sharing one
        Riccati solve); the result has the shape of ``v``.
        """
        rr = self._rates(r)
        return _products(lambda v2: self._model.hvp(rr, v2), self.num_sensors, v)

    def at(self, r: Any, *, start: Any = None) -> CostPoint:
        """The evaluation point at ``r`` (:class:`CostPoint`): one Riccati solve, one Schur form of
        ``A_cl`` and one adjoint solve, kept for repeated Hessian-vector products (two Lyapunov
        solves each) — the building block of Newton–CG.

        Args:
            r: the rates.
            start: optional symmetric ``n × n`` matrix close to ``Σ(r)`` (e.g. the block-diagonal
                ``Σ`` of the decoupled network): ``Σ(r)`` is then reached from it by
                Newton–Kleinman as in :meth:`CostPoint.warm` — the same numbers to rounding, the
                same error bounds, the cold solve when the start is not stabilising or the result
                cannot be certified (:attr:`CostPoint.warm_fallback`).

        Raises:
            ShapeError, NonFiniteError: ``start`` not ``n × n`` or not finite.
            as :meth:`cost`.
        """
        if start is None:
            return CostPoint(self, r)
        nn = int(self._model.n)
        s0 = as_float_array("start", start, 2)
        if s0.shape != (nn, nn):
            raise ShapeError(f"start must have shape ({nn}, {nn}), got {s0.shape}")
        if not np.all(np.isfinite(s0)):
            raise NonFiniteError("start has NaN or infinite entries")
        rr = self._rates(r)
        return CostPoint(self, rr, _point=self._model.warm_at(rr, s0))

    def cost_many(
        self, rates: Any, *, nan_on_error: bool = False, threads: int | None = None
    ) -> F64:
        """``η`` at each row of a ``(K, N)`` array, evaluated in parallel in Rust (GIL released).

        Entry ``k`` is bitwise identical to ``cost(rates[k])``. A failing row raises its error
        (message prefixed ``row k:``) unless ``nan_on_error``, which puts NaN there. ``threads``
        limits the worker threads (default: every core, on a pool that is rebuilt in forked child
        processes, so networks work inside ``ProcessPoolExecutor`` workers).
        """
        return self._model.cost_many(self._batch(rates), nan_on_error, threads)

    def value_and_gradient_many(
        self, rates: Any, *, nan_on_error: bool = False, threads: int | None = None
    ) -> tuple[F64, F64]:
        """``(η, ∇η)`` at each row of a ``(K, N)`` array, in parallel: ``(K,)`` values and
        ``(K, N)`` gradients, bitwise identical to :meth:`value_and_gradient` row by row."""
        batch = self._model.value_gradient_many(self._batch(rates), nan_on_error, threads)
        return batch.values, batch.gradients

    def gradient_many(
        self, rates: Any, *, nan_on_error: bool = False, threads: int | None = None
    ) -> F64:
        """``∇η`` at each row of a ``(K, N)`` array, in parallel (``(K, N)``)."""
        return self.value_and_gradient_many(rates, nan_on_error=nan_on_error, threads=threads)[1]
