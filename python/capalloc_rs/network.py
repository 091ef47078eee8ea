"""The network model of Chen, Belabbas and Başar and its fast-sampling cost η(r).

A network is the linear stochastic system ``dx = A x dt + G dw`` observed by ``N`` sensors: sensor
``i`` measures ``ĉ_iᵀ x`` (``ĉ_i`` an ``n × p_i`` matrix) with unit noise intensity, at rate
``r_i > 0``. In the fast-sampling limit the steady-state error covariance ``Σ(r)`` of the
Kalman–Bucy filter is the stabilising solution of the filter-form Riccati equation

    A Σ + Σ Aᵀ − Σ W(r) Σ + G Gᵀ = 0,    W(r) = Σ_i r_i ĉ_i ĉ_iᵀ,

and the cost is ``η(r) = tr Σ(r)``. The paper parametrises rates as ``r = γ + r_min`` with
``γ`` on a simplex; every method here takes the rates ``r`` themselves (see
:meth:`Network.rates_from_gamma`).

The paper's networks are *block* networks: subsystem ``i`` has state ``x_i`` (size ``n_i``),
dynamics ``A_i``, noise ``G_i`` and one sensor ``c_i`` (``n_i × p_i``), and subsystems are coupled
through ``ε A_ij``. :meth:`Network.from_blocks` assembles ``A``, ``G = blockdiag(G_i)`` and the
zero-padded ``ĉ_i`` and keeps the block description for validation (observability of each
``(A_i, c_i)``), reports (regular triplets, Definition 1) and human-readable files.

Everything heavy (the Riccati equation, the adjoint and sensitivity Lyapunov equations) runs in the
Rust core with the GIL released.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _core
from ._arrays import F64, MAX_SEED, as_count, as_float_array, as_real
from .errors import (
    InvalidInputError,
    NotDetectableError,
    NotObservableError,
    ShapeError,
)
from .limits import check_limit

__all__ = [
    "BlockStructure",
    "CostEvaluation",
    "CostPoint",
    "Network",
    "NetworkReport",
    "SubsystemReport",
    "PBH_RTOL",
]

#: Relative tolerance of the PBH tests: a mode ``λ`` counts as unobservable (uncontrollable) when
#: ``σ_min([A − λI; Cᵀ]) ≤ PBH_RTOL · max(‖A‖_F, ‖C‖_F)``. About ``√ε_mach``: eigenvalues of a
#: defective matrix are only that accurate, so an exactly unobservable Jordan mode still passes.
PBH_RTOL = 1e-8

#: Eigenvalues closer than this (relative to the scale above) are tested together, by an SVD of the
#: PBH matrix at their mean, instead of one eigenvector at a time.
_CLUSTER_RTOL = 1e-6


def _frozen(x: F64) -> F64:
    """A private, read-only copy."""
    out = np.array(x, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out


def _as_sensor(name: str, x: Any) -> F64:
    """A 2-D float array; a 1-D vector becomes one column."""
    arr = as_float_array(name, x, (1, 2))
    if arr.ndim == 1:
        arr = arr.reshape(-1, 1)
    return as_float_array(name, arr, 2)


def _threads(threads: Any) -> int | None:
    """``threads`` checked: ``None`` (every core) or ``1 … MAX_THREADS``."""
    return None if threads is None else as_count("threads", threads, minimum=1, maximum=MAX_THREADS)


#: Largest ``threads`` argument accepted.
MAX_THREADS = 4096


def _sequence(name: str, x: Any) -> Sequence[Any]:
    if isinstance(x, np.ndarray | str | bytes) or not isinstance(x, Sequence):
        if isinstance(x, np.ndarray) and x.ndim >= 1:
            return list(x)
        raise InvalidInputError(
            f"{name} must be a list (one entry per subsystem), got {type(x).__name__}"
        )
    return x


def _square(name: str, x: Any) -> F64:
    arr = as_float_array(name, x, 2)
    if arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        raise ShapeError(f"{name} must be square and non-empty, got shape {arr.shape}")
    return arr


def _rcond(g: F64) -> float:
    """``σ_min / σ_max`` (0 for a zero matrix)."""
    s = np.linalg.svd(g, compute_uv=False)
    return float(s[-1] / s[0]) if s[0] > 0 else 0.0


def _pbh_margin(a: F64, c: F64, *, unstable_only: bool = False) -> tuple[float, complex | None]:
    """Observability margin of ``(A, C)`` (outputs ``Cᵀx``) by the PBH test.

    Returns ``(m, λ)``: ``m = min_λ σ_min([A − λI; Cᵀ]) / max(‖A‖_F, ‖C‖_F)`` over the eigenvalues
    ``λ`` of ``A`` (only those with ``Re λ ≥ −√ε·scale`` when ``unstable_only``), and the minimising
    ``λ``; ``(inf, None)`` when no eigenvalue is selected. For an isolated eigenvalue ``σ_min`` is
    bounded by ``‖Cᵀv‖`` for its unit eigenvector ``v`` (used instead of an SVD); clusters of close
    eigenvalues get an SVD at their mean. Controllability of ``(A, B)`` is observability of
    ``(Aᵀ, B)``.
    """
    n = a.shape[0]
    scale = max(float(np.linalg.norm(a)), float(np.linalg.norm(c)), np.finfo(float).tiny)
    lam, vecs = np.linalg.eig(a)
    keep = lam.imag >= 0  # conjugate eigenvalues have the same margin
    if unstable_only:
        keep &= lam.real >= -np.sqrt(np.finfo(float).eps) * scale
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return float("inf"), None
    lam_k = lam[idx]
    close = np.abs(lam_k[:, None] - lam_k[None, :]) <= _CLUSTER_RTOL * scale
    best, arg = float("inf"), None
    done = np.zeros(idx.size, dtype=bool)
    for k in range(idx.size):
        if done[k]:
            continue
        group = np.flatnonzero(close[k] & ~done)
        done[group] = True
        if group.size == 1:
            v = vecs[:, idx[k]]
            m = float(np.linalg.norm(c.T @ v) / np.linalg.norm(v)) / scale
            lam_g = complex(lam_k[k])
        else:
            lam_g = complex(np.mean(lam_k[group]))
            pbh = np.vstack([a - lam_g * np.eye(n), c.T.astype(complex)])
            m = float(np.linalg.svd(pbh, compute_uv=False)[-1]) / scale
        if m < best:
            best, arg = m, lam_g
    return best, arg


def _fmt_mode(lam: complex | None) -> str:
    if lam is None:
        return "-"
    if lam.imag == 0:
        return f"{lam.real:.6g}"
    return f"{lam.real:.6g}{lam.imag:+.6g}j"


@dataclass(frozen=True, eq=False)
class BlockStructure:
    """The block description of a network (the paper's model).

    Attributes:
        a_blocks: ``A_i`` (``n_i × n_i``).
        g_blocks: ``G_i`` (``n_i × n_i``, nonsingular).
        c_blocks: ``c_i`` (``n_i × p_i``): sensor ``i`` measures ``c_iᵀ x_i``.
        coupling: the ``n × n`` matrix of the couplings ``A_ij`` (zero diagonal blocks), *before*
            multiplication by ``eps``: ``A = blockdiag(A_i) + eps · coupling``.
        eps: the coupling strength ``ε``.
    """

    a_blocks: tuple[F64, ...]
    g_blocks: tuple[F64, ...]
    c_blocks: tuple[F64, ...]
    coupling: F64
    eps: float

    @property
    def sizes(self) -> tuple[int, ...]:
        """``(n_1, …, n_N)``."""
        return tuple(int(a.shape[0]) for a in self.a_blocks)

    @property
    def offsets(self) -> tuple[int, ...]:
        """Start of each block in the state vector, and ``n`` at the end."""
        return tuple(int(v) for v in np.concatenate([[0], np.cumsum(self.sizes)]))

    def block(self, i: int, j: int) -> F64:
        """The unscaled coupling block ``A_ij`` (``n_i × n_j``; zero when ``i == j``)."""
        o = self.offsets
        return self.coupling[o[i] : o[i + 1], o[j] : o[j + 1]]

    @property
    def couplings(self) -> dict[tuple[int, int], F64]:
        """The nonzero coupling blocks ``{(i, j): A_ij}`` (unscaled, ``i ≠ j``)."""
        nn = len(self.a_blocks)
        out: dict[tuple[int, int], F64] = {}
        for i in range(nn):
            for j in range(nn):
                if i != j:
                    b = self.block(i, j)
                    if np.any(b != 0):
                        out[(i, j)] = b
        return out

    def _equal(self, other: BlockStructure) -> bool:
        return (
            self.eps == other.eps
            and len(self.a_blocks) == len(other.a_blocks)
            and all(
                np.array_equal(x, y)
                for xs, ys in (
                    (self.a_blocks, other.a_blocks),
                    (self.g_blocks, other.g_blocks),
                    (self.c_blocks, other.c_blocks),
                )
                for x, y in zip(xs, ys, strict=True)
            )
            and np.array_equal(self.coupling, other.coupling)
        )


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

    _network: Network
    _point: _core.CostPoint
    _rates: F64
    _gradient: F64
    _sigma: F64 | None

    def __init__(self, network: Network, r: Any) -> None:
        rr = network._rates(r)
        point = network._model.at(rr)
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

    @property
    def network(self) -> Network:
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


@dataclass(frozen=True)
class SubsystemReport:
    """Checks of one subsystem ``(A_i, c_i, G_i G_iᵀ)``.

    Attributes:
        index: ``i`` (from 0).
        n: ``n_i``.
        p: ``p_i``.
        observable: ``(A_i, c_i)`` observable (PBH, tolerance :data:`PBH_RTOL`).
        observability_margin: the PBH margin (relative; small means nearly unobservable).
        g_rcond: ``σ_min(G_i)/σ_max(G_i)``.
        regular: whether ``(A_i, c_i, G_iG_iᵀ)`` is a regular triplet (Definition 1):
            ``(A_i, Σ_i c_i)`` controllable, ``Σ_i`` the subsystem's own Riccati solution at
            ``r = r_min`` (by Proposition 1 the answer does not depend on ``r``). ``None`` when the
            subsystem's Riccati equation could not be solved.
        regularity_margin: the PBH margin of ``(A_i, Σ_i c_i)``, or ``None``.
        least_controllable_mode: the eigenvalue of ``A_i`` attaining that margin.
    """

    index: int
    n: int
    p: int
    observable: bool
    observability_margin: float
    g_rcond: float
    regular: bool | None
    regularity_margin: float | None
    least_controllable_mode: complex | None


@dataclass(frozen=True)
class NetworkReport:
    """What :meth:`Network.check` found.

    Attributes:
        n: state dimension.
        num_sensors: ``N``.
        eps: coupling strength (block networks) or ``None``.
        open_loop_abscissa: ``max Re λ(A)``.
        g_rcond: ``σ_min(G)/σ_max(G)``.
        detectable: ``(A, [ĉ_1 … ĉ_N])`` detectable.
        detectability_margin: PBH margin over the modes with ``Re λ ≥ 0`` (``inf`` if none).
        observable: ``(A, [ĉ_1 … ĉ_N])`` observable.
        observability_margin: PBH margin over all modes.
        subsystems: one :class:`SubsystemReport` per subsystem (block networks, or a general network
            with one sensor, which is its own subsystem); empty otherwise.
    """

    n: int
    num_sensors: int
    eps: float | None
    open_loop_abscissa: float
    g_rcond: float
    detectable: bool
    detectability_margin: float
    observable: bool
    observability_margin: float
    subsystems: tuple[SubsystemReport, ...]

    @property
    def regular(self) -> bool | None:
        """All subsystems are regular triplets (``None`` without subsystems or if unknown)."""
        if not self.subsystems or any(s.regular is None for s in self.subsystems):
            return None
        return all(bool(s.regular) for s in self.subsystems)

    @property
    def ok(self) -> bool:
        """The assumptions of the paper hold: detectable, every subsystem observable and regular."""
        return self.detectable and all(s.observable and s.regular for s in self.subsystems)

    def __str__(self) -> str:
        lines = [
            f"network: n = {self.n}, N = {self.num_sensors}"
            + ("" if self.eps is None else f", eps = {self.eps:g}"),
            f"  open-loop abscissa max Re λ(A) = {self.open_loop_abscissa:.4g}",
            f"  G: rcond = {self.g_rcond:.3g}",
            f"  detectable: {self.detectable} (margin {self.detectability_margin:.3g})",
            f"  observable: {self.observable} (margin {self.observability_margin:.3g})",
        ]
        if self.subsystems:
            lines.append(
                "  subsystem  n_i  p_i  observable (margin)   regular triplet (margin, mode)"
            )
            for s in self.subsystems:
                reg = (
                    "unknown"
                    if s.regular is None
                    else f"{s.regular} ({s.regularity_margin:.3g}, "
                    f"λ = {_fmt_mode(s.least_controllable_mode)})"
                )
                lines.append(
                    f"  {s.index:>9}  {s.n:>3}  {s.p:>3}  {str(s.observable):>5} "
                    f"({s.observability_margin:9.3g})   {reg}"
                )
        return "\n".join(lines)


def _pair(key: Any) -> tuple[Any, Any]:
    try:
        i, j = key
    except (TypeError, ValueError):
        raise InvalidInputError(f"couplings: keys must be pairs (i, j), got {key!r}") from None
    return i, j


def _assemble_couplings(couplings: Any, sizes: Sequence[int]) -> F64:
    """The unscaled ``n × n`` coupling matrix from ``None``, ``{(i, j): A_ij}``, an iterable of
    ``(i, j, A_ij)`` or a full ``n × n`` array with zero diagonal blocks."""
    nn = len(sizes)
    off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    n = int(off[-1])
    out = np.zeros((n, n))
    if couplings is None:
        return out
    if isinstance(couplings, np.ndarray) and couplings.ndim == 2:
        full = as_float_array("couplings", couplings, 2)
        if full.shape != (n, n):
            raise ShapeError(f"couplings as a matrix must be {n}×{n}, got {full.shape}")
        for i in range(nn):
            if np.any(full[off[i] : off[i + 1], off[i] : off[i + 1]] != 0):
                raise InvalidInputError(
                    f"couplings: the diagonal block of subsystem {i} must be zero "
                    "(put it in A_blocks)"
                )
        return full
    items: Iterable[tuple[Any, Any, Any]]
    if isinstance(couplings, Mapping):
        items = ((*_pair(k), v) for k, v in couplings.items())
    elif isinstance(couplings, Iterable) and not isinstance(couplings, str | bytes):
        items = couplings
    else:
        raise InvalidInputError(
            "couplings must be a mapping {(i, j): A_ij}, an iterable of (i, j, A_ij) or an n×n "
            f"array, got {type(couplings).__name__}"
        )
    seen: set[tuple[int, int]] = set()
    for item in items:
        try:
            i_raw, j_raw, block = item
        except (TypeError, ValueError):
            raise InvalidInputError(
                "couplings must be a mapping {(i, j): A_ij}, an iterable of (i, j, A_ij) or an "
                f"n×n array; got an item {item!r}"
            ) from None
        if isinstance(i_raw, bool | np.bool_) or isinstance(j_raw, bool | np.bool_):
            raise InvalidInputError(f"couplings: indices must be integers, got ({i_raw}, {j_raw})")
        try:
            i, j = int(i_raw), int(j_raw)
        except (TypeError, ValueError):
            raise InvalidInputError(
                f"couplings: indices must be integers, got ({i_raw!r}, {j_raw!r})"
            ) from None
        if i != i_raw or j != j_raw:
            raise InvalidInputError(f"couplings: indices must be integers, got ({i_raw}, {j_raw})")
        if not (0 <= i < nn and 0 <= j < nn):
            raise InvalidInputError(
                f"couplings: pair ({i}, {j}) is out of range for {nn} subsystems (indices from 0)"
            )
        if i == j:
            raise InvalidInputError(
                f"couplings: pair ({i}, {i}) couples a subsystem to itself (put it in A_blocks)"
            )
        if (i, j) in seen:
            raise InvalidInputError(f"couplings: pair ({i}, {j}) is given twice")
        seen.add((i, j))
        name = f"couplings[({i}, {j})]"
        b = as_float_array(name, block, 2)
        if b.shape != (sizes[i], sizes[j]):
            raise ShapeError(
                f"{name} must be {sizes[i]}×{sizes[j]} (n_{i} × n_{j}), got {b.shape[0]}×"
                f"{b.shape[1]}"
            )
        out[off[i] : off[i + 1], off[j] : off[j + 1]] = b
    return out


def _is_system(obj: Any) -> bool:
    """A single python-control system (state space or transfer function), not a list of them."""
    return (hasattr(obj, "A") and hasattr(obj, "C")) or (
        hasattr(obj, "num") and hasattr(obj, "den")
    )


def _check_statespace(name: str, s: Any) -> None:
    """A continuous-time state-space system (duck-typed ``.A``, ``.C``; python-control ``dt``)."""
    if hasattr(s, "num") and hasattr(s, "den") and not hasattr(s, "A"):
        raise InvalidInputError(
            f"{name} is a transfer function ({type(s).__name__}); Network.from_statespace needs "
            "a state-space model: convert it with control.ss(tf), or build the network from "
            "matrices with Network.from_blocks"
        )
    if not (hasattr(s, "A") and hasattr(s, "C")):
        raise InvalidInputError(
            f"{name} has no .A and .C (expected a python-control StateSpace), got "
            f"{type(s).__name__}"
        )
    dt = getattr(s, "dt", 0)
    if dt is not None and dt is not False and dt != 0:
        raise InvalidInputError(
            f"{name} is a discrete-time system (dt = {dt!r}); the network model is "
            "continuous-time (dx = A x dt + G dw) and capalloc samples it itself at the period τ "
            "(best_schedule, sampled_cost): give the continuous-time system (dt = 0)"
        )


class Network:
    """An immutable network ``(A, G, ĉ_1 … ĉ_N, r_min)`` and the evaluators of its cost.

    General form: ``Network(a, g, sensors, r_min=1.0)`` with ``a`` and ``g`` ``n × n`` (``g``
    nonsingular) and ``sensors`` a list of ``N`` full-size ``n × p_i`` matrices ``ĉ_i`` (a vector
    of length ``n`` is one column): sensor ``i`` measures ``ĉ_iᵀ x`` with unit noise. Use
    :meth:`from_blocks`, :meth:`from_statespace` or :meth:`random` for the paper's block networks.

    Construction validates shapes, finiteness, ``r_min > 0``, ``G`` nonsingular, observability of
    each subsystem ``(A_i, c_i)`` (block networks) and detectability of ``(A, [ĉ_1 … ĉ_N])``; the
    errors name the subsystem and field. Arrays are private read-only copies; networks compare
    equal when all their data are equal, hash accordingly and pickle cleanly.

    Rates ``r`` (length ``N``, every ``r_i > 0``) are the paper's ``γ + r_min``.
    """

    __slots__ = ("_a", "_g", "_sensors", "_r_min", "_structure", "_model", "_digest")

    _a: F64
    _g: F64
    _sensors: tuple[F64, ...]
    _r_min: float
    _structure: BlockStructure | None
    _model: _core.CostModel
    _digest: str | None

    def __init__(self, a: Any, g: Any, sensors: Sequence[Any], r_min: float = 1.0) -> None:
        a_arr = _square("A", a)
        n = a_arr.shape[0]
        check_limit("the state dimension n", n, "MAX_STATE_DIMENSION")
        g_arr = as_float_array("G", g, 2)
        if g_arr.shape != (n, n):
            raise ShapeError(f"G must be {n}×{n} like A, got shape {g_arr.shape}")
        if isinstance(sensors, np.ndarray) or not isinstance(sensors, Sequence):
            raise InvalidInputError(
                "sensors must be a list of n×p_i arrays (one per sensor); for one column per "
                "sensor from a matrix C (n×N) pass list(C.T)"
            )
        if len(sensors) == 0:
            raise ShapeError("the network needs at least one sensor")
        check_limit("the number of sensors", len(sensors), "MAX_SENSORS")
        cs = []
        for i, c in enumerate(sensors):
            arr = _as_sensor(f"sensors[{i}]", c)
            if arr.shape[0] != n or arr.shape[1] == 0:
                raise ShapeError(f"sensors[{i}] must be {n}×p_i with p_i ≥ 1, got {arr.shape}")
            cs.append(arr)
        rc = _rcond(g_arr)
        if rc <= n * np.finfo(float).eps:
            raise InvalidInputError(f"G must be nonsingular (σ_min/σ_max = {rc:.2e})")
        self._init(a_arr, g_arr, cs, r_min, None, validate=True)

    # -- construction -----------------------------------------------------------------------

    def _init(
        self,
        a: F64,
        g: F64,
        sensors: Sequence[F64],
        r_min: float,
        structure: BlockStructure | None,
        *,
        validate: bool,
    ) -> None:
        r = as_real("r_min", r_min, positive=True)
        set_ = object.__setattr__
        set_(self, "_a", _frozen(a))
        set_(self, "_g", _frozen(g))
        set_(self, "_sensors", tuple(_frozen(c) for c in sensors))
        set_(self, "_r_min", r)
        set_(self, "_structure", structure)
        set_(self, "_digest", None)
        if validate:
            self._validate_system()
        set_(self, "_model", _core.CostModel(self._a, self._g, list(self._sensors)))

    @classmethod
    def _build(
        cls,
        a: F64,
        g: F64,
        sensors: Sequence[F64],
        r_min: float,
        structure: BlockStructure | None,
        validate: bool = True,
    ) -> Network:
        net = cls.__new__(cls)
        net._init(a, g, sensors, r_min, structure, validate=validate)
        return net

    def _validate_system(self) -> None:
        """Observability of each subsystem, detectability of the whole."""
        st = self._structure
        if st is not None:
            for i, (ai, ci) in enumerate(zip(st.a_blocks, st.c_blocks, strict=True)):
                m, lam = _pbh_margin(ai, ci)
                if m <= PBH_RTOL:
                    raise NotObservableError(
                        f"subsystem {i}: (A_{i}, c_{i}) is not observable: the mode "
                        f"λ = {_fmt_mode(lam)} is not seen by c_{i} (PBH margin {m:.1e})"
                    )
            if st.eps == 0 or not np.any(st.coupling):
                return  # block diagonal: observable subsystems make the whole observable
        m, lam = _pbh_margin(self._a, self.sensor_matrix, unstable_only=True)
        if m <= PBH_RTOL:
            raise NotDetectableError(
                f"(A, [ĉ_1 … ĉ_N]) is not detectable: the mode λ = {_fmt_mode(lam)} "
                f"(Re λ ≥ 0) is seen by no sensor (PBH margin {m:.1e})"
            )

    @classmethod
    def from_blocks(
        cls,
        a_blocks: Sequence[Any],
        g_blocks: Sequence[Any],
        c_blocks: Sequence[Any],
        couplings: Any = None,
        eps: float = 0.0,
        r_min: float = 1.0,
    ) -> Network:
        """The paper's block network with subsystems of sizes ``n_i`` and outputs ``p_i``.

        ``A = [A_ij]`` with ``A_ii = A_i`` and ``A_ij = ε·couplings[(i, j)]``,
        ``G = blockdiag(G_i)``, and sensor ``i`` is ``c_i`` (``n_i × p_i``, or a vector of length
        ``n_i``) padded with zeros to ``n × p_i``. ``couplings`` is ``None``, a mapping
        ``{(i, j): A_ij}`` (``n_i × n_j``, indices from 0), an iterable of ``(i, j, A_ij)``, or an
        ``n × n`` array with zero diagonal blocks.

        Raises:
            ShapeError, NonFiniteError, InvalidInputError: malformed blocks (the message names the
                subsystem), ``G_i`` singular, bad couplings, ``r_min ≤ 0``.
            NotObservableError: some ``(A_i, c_i)`` is not observable.
            NotDetectableError: the coupled network is not detectable.
        """
        a_blocks = _sequence("a_blocks", a_blocks)
        g_blocks = _sequence("g_blocks", g_blocks)
        c_blocks = _sequence("c_blocks", c_blocks)
        nn = len(a_blocks)
        if nn == 0:
            raise ShapeError("the network needs at least one subsystem")
        if len(g_blocks) != nn or len(c_blocks) != nn:
            raise ShapeError(
                f"a_blocks, g_blocks and c_blocks must have the same length, got "
                f"{nn}, {len(g_blocks)}, {len(c_blocks)}"
            )
        a_list, g_list, c_list = [], [], []
        for i in range(nn):
            ai = _square(f"subsystem {i}: A_{i}", a_blocks[i])
            ni = ai.shape[0]
            gi = as_float_array(f"subsystem {i}: G_{i}", g_blocks[i], 2)
            if gi.shape != (ni, ni):
                raise ShapeError(
                    f"subsystem {i}: G_{i} must be {ni}×{ni} like A_{i}, got {gi.shape}"
                )
            rc = _rcond(gi)
            if rc <= ni * np.finfo(float).eps:
                raise InvalidInputError(
                    f"subsystem {i}: G_{i} must be nonsingular (σ_min/σ_max = {rc:.2e})"
                )
            ci = _as_sensor(f"subsystem {i}: c_{i}", c_blocks[i])
            if ci.shape[0] != ni or ci.shape[1] == 0:
                raise ShapeError(
                    f"subsystem {i}: c_{i} must be {ni}×p_{i} with p_{i} ≥ 1 (or a vector of "
                    f"length {ni}), got {ci.shape}"
                )
            a_list.append(ai)
            g_list.append(gi)
            c_list.append(ci)
        e = as_real("eps", eps)
        sizes = [a.shape[0] for a in a_list]
        coupling = _assemble_couplings(couplings, sizes)
        off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        n = int(off[-1])
        a = e * coupling
        g = np.zeros((n, n))
        sensors = []
        for i in range(nn):
            sl = slice(off[i], off[i + 1])
            a[sl, sl] = a_list[i]
            g[sl, sl] = g_list[i]
            c = np.zeros((n, c_list[i].shape[1]))
            c[sl] = c_list[i]
            sensors.append(c)
        structure = BlockStructure(
            tuple(_frozen(x) for x in a_list),
            tuple(_frozen(x) for x in g_list),
            tuple(_frozen(x) for x in c_list),
            _frozen(coupling),
            e,
        )
        return cls._build(a, g, sensors, r_min, structure)

    @classmethod
    def from_statespace(
        cls,
        systems: Any,
        g_blocks: Sequence[Any],
        couplings: Any = None,
        eps: float = 0.0,
        r_min: float = 1.0,
    ) -> Network:
        """A block network from python-control ``StateSpace`` objects (duck-typed: anything with
        ``.A`` and ``.C``), one per subsystem: ``A_i = sys.A``, ``c_i = sys.Cᵀ`` (so the outputs
        ``y = C x`` are the sensor's). ``B`` and ``D`` are ignored: the process noise enters through
        ``G_i``, which must be given explicitly (``g_blocks``, ``n_i × n_i`` nonsingular). A single
        system is accepted in place of a list. See :meth:`from_blocks` for the other arguments.

        Refused with :class:`~capalloc_rs.errors.InvalidInputError`: a discrete-time system
        (python-control ``dt`` other than ``0``/``None``: the model is continuous-time, sampling
        at period τ is done by the sampled functions) and a transfer function (convert it first
        with ``control.ss(tf)``).
        """
        if _is_system(systems):
            systems = [systems]
        if isinstance(systems, str | bytes) or not hasattr(systems, "__iter__"):
            raise InvalidInputError(
                f"systems must be a python-control StateSpace or a list of them, got "
                f"{type(systems).__name__}"
            )
        a_blocks, c_blocks = [], []
        for i, s in enumerate(systems):
            _check_statespace(f"systems[{i}]", s)
            a_blocks.append(np.asarray(s.A, dtype=np.float64))
            c_blocks.append(np.asarray(s.C, dtype=np.float64).T)
        if isinstance(g_blocks, np.ndarray) and g_blocks.ndim == 2 and len(a_blocks) == 1:
            g_blocks = [g_blocks]
        return cls.from_blocks(a_blocks, g_blocks, c_blocks, couplings, eps, r_min)

    @classmethod
    def random(
        cls,
        num_subsystems: int,
        n: int | Sequence[int] = 2,
        p: int | Sequence[int] = 1,
        eps: float = 0.1,
        seed: int | None = None,
        r_min: float = 1.0,
    ) -> Network:
        """A reproducible random block network, observable by construction.

        Subsystem ``i`` (size ``n_i``, ``p_i`` outputs; ``n`` and ``p`` may be per-subsystem
        sequences) is ``A_i = U_i F_i U_iᵀ``, ``c_i = U_i [e_1, ξ]`` with ``F_i`` the observer
        companion matrix of a random spectrum (real parts in ``[−1.5, 0.5]``, so some modes are
        unstable; imaginary parts in ``[0.2, 2]``), ``(F_i, e_1)`` observable for every spectrum,
        ``U_i`` a random orthogonal matrix and ``ξ`` Gaussian extra outputs.
        ``G_i`` is lower triangular with diagonal in ``[0.5, 1.5]``. Every pair ``i ≠ j`` is coupled
        by Gaussian ``A_ij`` with entries of variance ``1/n``, so ``‖ε·coupling‖₂ ≈ 2ε`` whatever
        the size. The same ``seed`` gives the same network.
        """
        nn = as_count("num_subsystems", num_subsystems, minimum=1)
        check_limit("num_subsystems (one sensor each)", nn, "MAX_SENSORS")
        if isinstance(n, int | np.integer):
            # Checked before the per-subsystem lists and spectra are built.
            check_limit("the state dimension num_subsystems·n", nn * int(n), "MAX_STATE_DIMENSION")

        def per(name: str, v: int | Sequence[int]) -> list[int]:
            if isinstance(v, Sequence) and not isinstance(v, str | bytes):
                vals = [as_count(f"{name}[{k}]", x, minimum=1) for k, x in enumerate(v)]
            else:
                vals = [as_count(name, v, minimum=1)] * nn
            if len(vals) != nn:
                raise InvalidInputError(
                    f"{name} must be a positive integer or {nn} positive integers, got {len(vals)}"
                )
            return vals

        sizes, outs = per("n", n), per("p", p)
        check_limit("the state dimension n = Σ n_i", sum(sizes), "MAX_STATE_DIMENSION")
        eps = as_real("eps", eps)
        r_min = as_real("r_min", r_min, positive=True)
        if seed is not None:
            seed = as_count("seed", seed, maximum=MAX_SEED)
        rng = np.random.default_rng(seed)
        a_blocks, g_blocks, c_blocks = [], [], []
        for ni, pi in zip(sizes, outs, strict=True):
            eig: list[complex] = []
            while len(eig) < ni:
                if ni - len(eig) >= 2 and rng.random() < 0.5:
                    re, im = rng.uniform(-1.5, 0.5), rng.uniform(0.2, 2.0)
                    eig += [complex(re, im), complex(re, -im)]
                else:
                    eig.append(complex(rng.uniform(-1.5, 0.5), 0.0))
            coeffs = np.real(np.poly(np.array(eig)))  # [1, a_1, …, a_n]
            f = np.zeros((ni, ni))
            f[:, 0] = -coeffs[1:]
            f[: ni - 1, 1:] = np.eye(ni - 1)
            u, _ = np.linalg.qr(rng.standard_normal((ni, ni)))
            c = np.zeros((ni, pi))
            c[0, 0] = 1.0
            c[:, 1:] = rng.standard_normal((ni, pi - 1))
            g = np.tril(0.3 * rng.standard_normal((ni, ni)), -1) + np.diag(
                rng.uniform(0.5, 1.5, ni)
            )
            a_blocks.append(u @ f @ u.T)
            c_blocks.append(u @ c)
            g_blocks.append(g)
        ntot = sum(sizes)
        coupling = rng.standard_normal((ntot, ntot)) / np.sqrt(ntot)
        off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        for i in range(nn):
            coupling[off[i] : off[i + 1], off[i] : off[i + 1]] = 0.0
        return cls.from_blocks(a_blocks, g_blocks, c_blocks, coupling, eps, r_min)

    # -- immutability, equality, pickling -------------------------------------------------------

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"Network is immutable (cannot set {name!r})")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"Network is immutable (cannot delete {name!r})")

    def __reduce__(self) -> tuple[Any, ...]:
        return (
            _restore,
            (self._a, self._g, self._sensors, self._r_min, self._structure),
        )

    def _key(self) -> str:
        if self._digest is None:
            h = hashlib.sha256()
            for arr in (self._a, self._g, *self._sensors):
                h.update(str(arr.shape).encode())
                h.update(np.ascontiguousarray(arr).tobytes())
            h.update(repr(self._r_min).encode())
            object.__setattr__(self, "_digest", h.hexdigest())
        assert self._digest is not None
        return self._digest

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Network):
            return NotImplemented
        if self._key() != other._key():
            return False
        if (self._structure is None) != (other._structure is None):
            return False
        if self._structure is not None and other._structure is not None:
            return self._structure._equal(other._structure)
        return True

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        kind = "block" if self._structure is not None else "general"
        extra = "" if self._structure is None else f", eps={self._structure.eps:g}"
        return (
            f"Network({kind}, n={self.n}, N={self.num_sensors}, p={list(self.outputs)}"
            f"{extra}, r_min={self._r_min:g})"
        )

    # -- data -----------------------------------------------------------------------------------

    @property
    def a(self) -> F64:
        """``A`` (``n × n``, read-only)."""
        return self._a

    @property
    def g(self) -> F64:
        """``G`` (``n × n``, nonsingular, read-only)."""
        return self._g

    @property
    def q(self) -> F64:
        """``Q = G Gᵀ`` (exactly symmetric)."""
        q = self._g @ self._g.T
        return 0.5 * (q + q.T)

    @property
    def sensors(self) -> tuple[F64, ...]:
        """``(ĉ_1, …, ĉ_N)``, each ``n × p_i`` (read-only)."""
        return self._sensors

    @property
    def sensor_matrix(self) -> F64:
        """``[ĉ_1 … ĉ_N]`` (``n × Σp_i``)."""
        return np.hstack(self._sensors)

    @property
    def r_min(self) -> float:
        """The minimum rate ``r_min > 0`` (rates are ``r = γ + r_min``)."""
        return self._r_min

    @property
    def n(self) -> int:
        """The state dimension."""
        return int(self._a.shape[0])

    @property
    def num_sensors(self) -> int:
        """``N``."""
        return len(self._sensors)

    @property
    def outputs(self) -> tuple[int, ...]:
        """``(p_1, …, p_N)``."""
        return tuple(int(c.shape[1]) for c in self._sensors)

    @property
    def structure(self) -> BlockStructure | None:
        """The block description (block networks), else ``None``."""
        return self._structure

    @property
    def eps(self) -> float | None:
        """The coupling strength ``ε`` (block networks), else ``None``."""
        return None if self._structure is None else self._structure.eps

    def rates_from_gamma(self, gamma: Any) -> F64:
        """The paper's rates ``r = γ + r_min``."""
        return as_float_array("gamma", gamma, 1) + self._r_min

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

    def at(self, r: Any) -> CostPoint:
        """The evaluation point at ``r`` (:class:`CostPoint`): one Riccati solve, one Schur form of
        ``A_cl`` and one adjoint solve, kept for repeated Hessian-vector products (two Lyapunov
        solves each) — the building block of Newton–CG.

        Raises:
            as :meth:`cost`.
        """
        return CostPoint(self, r)

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

    # -- checks ---------------------------------------------------------------------------------

    def _subsystems(self) -> list[tuple[F64, F64, F64]]:
        st = self._structure
        if st is not None:
            return list(zip(st.a_blocks, st.g_blocks, st.c_blocks, strict=True))
        if self.num_sensors == 1:
            return [(self._a, self._g, self._sensors[0])]
        return []

    def check(self) -> NetworkReport:
        """Checks the paper's assumptions and reports margins.

        For the whole network: open-loop abscissa, ``G``'s conditioning, detectability and
        observability of ``(A, [ĉ_1 … ĉ_N])``. For each subsystem (block networks; a general network
        with one sensor is its own subsystem): observability of ``(A_i, c_i)``, ``G_i``'s
        conditioning, and the regular-triplet test of Definition 1 — ``(A_i, Σ_i c_i)``
        controllable, with ``Σ_i`` the subsystem's own Riccati solution at ``r = r_min``. The
        paper's Example 1 is *not* regular. Regularity is sufficient (not necessary) for
        ``η_i'' > 0``.
        """
        a, cmat = self._a, self.sensor_matrix
        det_m, _ = _pbh_margin(a, cmat, unstable_only=True)
        obs_m, _ = _pbh_margin(a, cmat)
        subs = []
        for i, (ai, gi, ci) in enumerate(self._subsystems()):
            om, _ = _pbh_margin(ai, ci)
            regular: bool | None = None
            reg_m: float | None = None
            mode: complex | None = None
            try:
                model = _core.CostModel(ai, gi, [ci])
                sigma = model.evaluate(np.array([self._r_min]), 0).sigma
                reg_m, mode = _pbh_margin(ai.T, sigma @ ci)
                regular = reg_m > PBH_RTOL
            except (ValueError, np.linalg.LinAlgError):
                pass
            subs.append(
                SubsystemReport(
                    i,
                    int(ai.shape[0]),
                    int(ci.shape[1]),
                    om > PBH_RTOL,
                    om,
                    _rcond(gi),
                    regular,
                    reg_m,
                    mode,
                )
            )
        return NetworkReport(
            n=self.n,
            num_sensors=self.num_sensors,
            eps=self.eps,
            open_loop_abscissa=float(np.max(np.linalg.eigvals(a).real)),
            g_rcond=_rcond(self._g),
            detectable=det_m > PBH_RTOL,
            detectability_margin=det_m,
            observable=obs_m > PBH_RTOL,
            observability_margin=obs_m,
            subsystems=tuple(subs),
        )

    # -- files ----------------------------------------------------------------------------------

    def save(self, path: str | os.PathLike[str], format: str | None = None) -> None:
        """Writes the network to ``path``: ``"toml"`` or ``"json"`` (human-readable, small models;
        block networks keep their blocks) or ``"npz"`` (large models). ``format`` defaults to the
        file extension. See :mod:`capalloc_rs.model_io` for the schema."""
        from . import model_io

        model_io.save(self, path, format)

    @classmethod
    def load(cls, path: str | os.PathLike[str], format: str | None = None) -> Network:
        """Reads a network written by :meth:`save` (or by hand, see :mod:`capalloc_rs.model_io`).

        Raises:
            ModelFormatError: malformed file; the message names the field.
            InputError subclasses: the model itself is invalid (e.g. not observable).
        """
        from . import model_io

        return model_io.load(path, format)


def _restore(
    a: F64, g: F64, sensors: tuple[F64, ...], r_min: float, structure: BlockStructure | None
) -> Network:
    """Unpickling: the data were validated when the network was first built."""
    if structure is not None:  # unpickled arrays are writeable again
        structure = BlockStructure(
            tuple(_frozen(x) for x in structure.a_blocks),
            tuple(_frozen(x) for x in structure.g_blocks),
            tuple(_frozen(x) for x in structure.c_blocks),
            _frozen(structure.coupling),
            structure.eps,
        )
    return Network._build(a, g, sensors, r_min, structure, validate=False)
