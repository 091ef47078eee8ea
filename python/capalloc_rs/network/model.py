"""The network model of Chen, Belabbas and Başar and its fast-sampling cost η(r).

A network is the linear stochastic system ``dx = A x dt + G dw`` (``G`` any ``n × m``, so the
process noise covariance ``Q = G Gᵀ`` may be singular) observed by ``N`` sensors: sensor
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

import dataclasses
import hashlib
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .. import _core
from .._arrays import F64
from ..limits import check_limit
from . import io
from .constructors import (
    block_network,
    general_network,
    random_blocks,
    square,
    statespace_blocks,
)
from .cost import BlockStructure, CostFacade, _frozen
from .diagnostics import NetworkReport, network_report, validate_network
from .sensor_limits import SensorLimits, SensorLimitsView, channel_sensors, check_zero_minima
from .stochastic import error_weight, whiten

__all__ = ["Network"]


class Network(SensorLimitsView, CostFacade):
    """An immutable network ``(A, G, ĉ_1 … ĉ_N, r_min)`` and the evaluators of its cost.

    General form: ``Network(a, g, sensors, r_min=1.0)`` with ``a`` ``n × n``, ``g`` ``n × m``
    (any ``m ≥ 1``; ``Q = G Gᵀ`` may be singular) and ``sensors`` a list of ``N`` full-size
    ``n × p_i`` matrices ``ĉ_i`` (a vector of length ``n`` is one column): sensor ``i`` measures
    ``ĉ_iᵀ x`` with unit noise. :meth:`from_blocks`, :meth:`from_statespace`, :meth:`random`
    build the paper's block networks, :meth:`from_model` the standard stochastic model.

    Construction validates shapes, finiteness, ``r_min > 0``, observability of each subsystem
    ``(A_i, c_i)`` (block networks), detectability of ``(A, [ĉ_1 … ĉ_N])`` and — the condition for
    a stabilising Riccati solution when ``Q`` is singular — that every mode of ``A`` on the
    imaginary axis receives noise (``(A, G)`` has no uncontrollable mode there); the errors name
    the subsystem and field. Arrays are private read-only copies; networks compare equal when all
    their data are equal, hash accordingly and pickle cleanly.

    Rates ``r`` (length ``N``, every ``r_i > 0``) are the paper's ``γ + r_min``. Every
    constructor also takes the sensors' sample costs ``costs``, minima ``r_min`` and caps ``r_max``
    (scalars or one value per sensor; :mod:`capalloc_rs.network.sensor_limits`), which every
    allocation and schedule respects.
    """

    __slots__ = ("_a", "_g", "_sensors", "_limits", "_weight", "_structure", "_model", "_digest")

    _a: F64
    _g: F64
    _sensors: tuple[F64, ...]
    _limits: SensorLimits
    _weight: F64 | None
    _structure: BlockStructure | None
    _model: _core.CostModel
    _digest: str | None

    def __init__(
        self,
        a: Any,
        g: Any,
        sensors: Sequence[Any],
        r_min: Any = 1.0,
        *,
        weight: Any = None,
        costs: Any = None,
        r_max: Any = None,
    ) -> None:
        a_arr, g_arr, cs = general_network(a, g, sensors)
        limits = SensorLimits.of(len(cs), costs, r_min, r_max)
        self._init(a_arr, g_arr, cs, limits, None, validate=True, weight=weight)

    def _init(
        self,
        a: F64,
        g: F64,
        sensors: Sequence[F64],
        limits: SensorLimits,
        structure: BlockStructure | None,
        *,
        validate: bool,
        weight: Any = None,
    ) -> None:
        m = error_weight(weight, a.shape[0])
        set_ = object.__setattr__
        set_(self, "_weight", m)
        set_(self, "_a", _frozen(a))
        set_(self, "_g", _frozen(g))
        set_(self, "_sensors", tuple(_frozen(c) for c in sensors))
        set_(self, "_limits", limits)
        set_(self, "_structure", structure)
        set_(self, "_digest", None)
        if validate:
            self._validate_system()
        set_(
            self,
            "_model",
            _core.CostModel(self._a, self._g, list(self._sensors), error_weight=self._weight),
        )

    @classmethod
    def _build(
        cls,
        a: F64,
        g: F64,
        sensors: Sequence[F64],
        limits: SensorLimits,
        structure: BlockStructure | None,
        validate: bool = True,
        weight: Any = None,
    ) -> Network:
        net = cls.__new__(cls)
        net._init(a, g, sensors, limits, structure, validate=validate, weight=weight)
        return net

    def _validate_system(self) -> None:
        """See :func:`~capalloc_rs.network.diagnostics.validate_network`."""
        validate_network(self._a, self._g, self.sensor_matrix, self._structure)
        check_zero_minima(self._a, self._sensors, self._limits)

    @classmethod
    def from_blocks(
        cls,
        a_blocks: Sequence[Any],
        g_blocks: Sequence[Any],
        c_blocks: Sequence[Any],
        couplings: Any = None,
        eps: float = 0.0,
        r_min: Any = 1.0,
        *,
        weight: Any = None,
        costs: Any = None,
        r_max: Any = None,
    ) -> Network:
        """The paper's block network with subsystems of sizes ``n_i`` and outputs ``p_i``.

        ``A = [A_ij]`` with ``A_ii = A_i`` and ``A_ij = ε·couplings[(i, j)]``,
        ``G = blockdiag(G_i)``, and sensor ``i`` is ``c_i`` (``n_i × p_i``, or a vector of length
        ``n_i``) padded with zeros to ``n × p_i``. ``couplings`` is ``None``, a mapping
        ``{(i, j): A_ij}`` (``n_i × n_j``, indices from 0), an iterable of ``(i, j, A_ij)``, or an
        ``n × n`` array with zero diagonal blocks. ``weight`` is the matrix ``M`` of a weighted
        error ``tr(M Σ)`` (see :attr:`error_weight`; default the plain trace). ``costs``,
        ``r_min`` and ``r_max`` are the sensors' sample costs, minimum rates and rate caps
        (scalars or one value per sensor; see :attr:`costs`).

        Raises:
            ShapeError, NonFiniteError, InvalidInputError: malformed blocks (the message names the
                subsystem), bad couplings, ``r_min ≤ 0``, ``costs ≤ 0``, ``r_max ≤ r_min``.
            NotObservableError: some ``(A_i, c_i)`` is not observable.
            NotDetectableError: the coupled network is not detectable.
            UnexcitedAxisModeError: a mode on the imaginary axis receives no noise (``G`` singular).
        """
        a, g, sensors, structure = block_network(a_blocks, g_blocks, c_blocks, couplings, eps)
        limits = SensorLimits.of(len(sensors), costs, r_min, r_max)
        return cls._build(a, g, sensors, limits, structure, weight=weight)

    @classmethod
    def from_model(
        cls,
        A: Any,  # noqa: N803 - the model's usual names
        B_w: Any,  # noqa: N803
        W: Any,  # noqa: N803
        C: Sequence[Any],  # noqa: N803
        R: Any,  # noqa: N803
        *,
        costs: Any = None,
        r_min: Any = 1.0,
        r_max: Any = None,
        weight: Any = None,
    ) -> Network:
        """A network from the standard stochastic model of control engineering::

            dx = A x dt + B_w dw,  E[dw dwᵀ] = W dt;   y_i = C_i x + v_i,  E[v_i v_iᵀ] = R_i

        (``A`` ``n × n``; ``B_w`` ``n × m``; ``W`` ``m × m`` ⪰ 0, so ``Q = B_w W B_wᵀ`` may be
        singular; one ``C_i`` per sensor, ``p_i × n`` as everywhere in control; ``R_i``
        ``p_i × p_i`` ≻ 0, the covariance of one sample's noise). It is whitened once into the
        paper's form, ``G = B_w W^{1/2}``, ``ĉ_i = C_iᵀ R_i^{-1/2}``
        (:mod:`capalloc_rs.network.stochastic`), so sensor ``i`` sampled at rate ``r_i``
        contributes ``r_i C_iᵀ R_i⁻¹ C_i`` to the information rate ``W(r)``.

        Args:
            A: the drift matrix.
            B_w: the noise input matrix (a vector of length ``n`` is one column).
            W: the noise intensity (a scalar ``s`` means ``s·I``).
            C: a list with one output matrix per sensor (a vector of length ``n`` is one output;
                for one output per sensor from a ``N × n`` matrix pass ``list(C)``).
            R: a list with one sample noise covariance per sensor (a scalar ``s`` means ``s·I``), or
                one scalar for every sensor.
            costs: channel units per sample ``b_i > 0`` (scalar or per sensor; default 1): the
                budget is ``B = Σ b_i r_i``.
            r_min: the least rate ``r_min,i ≥ 0`` of each sensor (scalar or per sensor).
            r_max: each sensor's rate cap ``r_max,i > r_min,i`` (scalar or per sensor; ``None``
                or ``inf`` for none).
            weight: the matrix ``M ⪰ 0`` (``n × n``) of the weighted error ``tr(M Σ)`` every
                method minimises (state weights, or ``M = LᵀL`` to estimate the outputs ``L x``);
                default the plain trace.

        Raises:
            ShapeError, NonFiniteError, InvalidInputError: malformed data (the message names the
                argument: ``W`` or ``R[i]`` not symmetric or not semidefinite/definite, …).
            NotDetectableError: ``(A, [C_i])`` not detectable.
            UnexcitedAxisModeError: a mode of ``A`` on the imaginary axis receives no noise.
        """
        a = square("A", A)
        g, sensors = whiten(a, B_w, W, C, R)
        limits = SensorLimits.of(len(sensors), costs, r_min, r_max)
        check_limit("the state dimension n", a.shape[0], "MAX_STATE_DIMENSION")
        check_limit("the number of sensors", len(sensors), "MAX_SENSORS")
        return cls._build(a, g, sensors, limits, None, weight=weight)

    @classmethod
    def from_statespace(
        cls,
        systems: Any,
        g_blocks: Sequence[Any] | None = None,
        couplings: Any = None,
        eps: float = 0.0,
        r_min: Any = 1.0,
        *,
        w: Any = None,
        r: Any = None,
        weight: Any = None,
        costs: Any = None,
        r_max: Any = None,
    ) -> Network:
        """A block network from python-control ``StateSpace`` objects (duck-typed: anything with
        ``.A``, ``.B`` and ``.C``), one per subsystem: ``A_i = sys.A``; the process noise either
        given as ``g_blocks`` (``G_i``, ``n_i × m_i``) or entering through ``sys.B`` with
        intensity ``w`` (``W_i``: a scalar for ``s·I``, or one matrix/scalar per system), so
        ``G_i = B_i W_i^{1/2}``; the sensor measures ``y = C x`` with sample noise covariance
        ``r`` (``R_i``, default ``I``), so ``c_i = C_iᵀ R_i^{-1/2}`` (:meth:`from_model`'s
        whitening). ``D`` is ignored. A single system is accepted in place of a list. See
        :meth:`from_blocks` for the other arguments (and ``weight``, ``costs``, ``r_max``).

        Refused with :class:`~capalloc_rs.errors.InvalidInputError`: both or neither of
        ``g_blocks`` and ``w``; a discrete-time system (python-control ``dt`` other than
        ``0``/``None``: the model is continuous-time, sampling at period τ is done by the sampled
        functions) and a transfer function (convert it first with ``control.ss(tf)``).
        """
        a_blocks, g_blocks, c_blocks = statespace_blocks(systems, g_blocks, w, r)
        extra = {"weight": weight, "costs": costs, "r_max": r_max}
        return cls.from_blocks(a_blocks, g_blocks, c_blocks, couplings, eps, r_min, **extra)

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
        a_blocks, g_blocks, c_blocks, coupling, e, rm = random_blocks(
            num_subsystems, n, p, eps, seed, r_min
        )
        return cls.from_blocks(a_blocks, g_blocks, c_blocks, coupling, e, rm)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"Network is immutable (cannot set {name!r})")

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"Network is immutable (cannot delete {name!r})")

    def __reduce__(self) -> tuple[Any, ...]:
        return (
            _restore,
            (self._a, self._g, self._sensors, self.r_min, self._structure, self._weight)
            + (() if self.is_paper_form else (self._limits.costs, self._limits.rate_max)),
        )

    def _key(self) -> str:
        if self._digest is None:
            h = hashlib.sha256()
            for arr in (self._a, self._g, *self._sensors):
                h.update(str(arr.shape).encode())
                h.update(np.ascontiguousarray(arr).tobytes())
            if self.is_paper_form:
                h.update(repr(float(self._limits.rate_min[0])).encode())
            else:
                h.update(b"limits" + self._limits.key())
            if self._weight is not None:
                h.update(b"weight" + np.ascontiguousarray(self._weight).tobytes())
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
        return self._limits.equal(other._limits)

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        kind = "block" if self._structure is not None else "general"
        extra = "" if self._structure is None else f", eps={self._structure.eps:g}"
        return (
            f"Network({kind}, n={self.n}, N={self.num_sensors}, p={list(self.outputs)}"
            f"{extra}, {self._limits.describe()}{'' if self._weight is None else ', weighted'})"
        )

    @property
    def a(self) -> F64:
        """``A`` (``n × n``, read-only)."""
        return self._a

    @property
    def error_weight(self) -> F64 | None:
        """The matrix ``M ⪰ 0`` of the weighted error ``η_M(r) = tr(M Σ(r))`` that every method
        minimises (read-only; the ``weight`` argument of the constructors); ``None`` for the plain
        trace (``M = I``). Not to be confused with :meth:`weight`, the information rate
        ``W(r)``."""
        return self._weight

    @property
    def g(self) -> F64:
        """``G`` (``n × m``, read-only; ``Q = G Gᵀ`` may be singular)."""
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
    def n(self) -> int:
        """The state dimension."""
        return int(self._a.shape[0])

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

    def in_channel_units(self) -> Network:
        """The same problem in the variable ``s = b ∘ r`` (channel units per unit time spent on
        each sensor): unit costs, sensors ``ĉ_i/√b_i``, bounds ``b ∘ r_min`` and ``b ∘ r_max``, the
        same ``A``, ``G``, weight and block structure; its cost at ``s`` is this network's at
        ``r = s/b``. ``self`` itself when every cost is 1."""
        b = self._limits.costs
        if np.all(b == 1.0):
            return self
        sensors, st = channel_sensors(self._sensors, self._structure, b)
        limits = self._limits.in_channel_units()
        return Network._build(self._a, self._g, sensors, limits, st, False, self._weight)

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
        ``η_i'' > 0``. With sample costs or rate limits, the feasible budgets.
        """
        report = network_report(
            self._a,
            self._g,
            self.sensor_matrix,
            self.num_sensors,
            self._subsystems(),
            self._limits.report_rate,
            self.eps,
        )
        return dataclasses.replace(report, **self._limits.report_fields(self._a, self._sensors))

    def save(self, path: str | os.PathLike[str], format: str | None = None) -> None:
        """Writes the network to ``path``: ``"toml"`` or ``"json"`` (human-readable, small models;
        block networks keep their blocks) or ``"npz"`` (large models). ``format`` defaults to the
        file extension. See :mod:`capalloc_rs.model_io` for the schema."""
        io.save(self, path, format)

    @classmethod
    def load(cls, path: str | os.PathLike[str], format: str | None = None) -> Network:
        """Reads a network written by :meth:`save` (or by hand, see :mod:`capalloc_rs.model_io`).

        Raises:
            ModelFormatError: malformed file; the message names the field.
            InputError subclasses: the model itself is invalid (e.g. not observable).
        """
        spec, source = io.read(path, format)
        with io.model_errors(source):
            return cls._from_spec(spec)

    @classmethod
    def _from_spec(cls, spec: Mapping[str, Any]) -> Network:
        """The network of a constructor specification made by ``capalloc_rs.network.io.parse``
        (``a_blocks``, ``g_blocks``, ``c_blocks``, ``couplings``, ``eps``, ``r_min`` for a block
        network, ``a``, ``g``, ``sensors``, ``r_min`` for a general one).

        Raises:
            as :meth:`from_blocks` and :class:`Network`.
        """
        if "a_blocks" in spec:
            return cls.from_blocks(**spec)
        return cls(**spec)


def _restore(
    a: F64,
    g: F64,
    sensors: tuple[F64, ...],
    r_min: float | F64,
    structure: BlockStructure | None,
    weight: F64 | None = None,
    costs: F64 | None = None,
    r_max: F64 | None = None,
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
    limits = SensorLimits.of(len(sensors), costs, r_min, r_max)
    return Network._build(a, g, sensors, limits, structure, validate=False, weight=weight)
