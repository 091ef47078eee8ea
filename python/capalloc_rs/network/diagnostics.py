"""Diagnostics of a network: the PBH tests of observability, detectability and controllability
and the paper's assumptions (regular triplets, Definition 1), reported by :class:`NetworkReport`.

The PBH margin of ``(A, C)`` (outputs ``Cᵀx``) is ``min_λ σ_min([A − λI; Cᵀ]) / max(‖A‖_F, ‖C‖_F)``
over the eigenvalues ``λ`` of ``A``; the pair is observable when it exceeds :data:`PBH_RTOL`.
Controllability of ``(A, B)`` is observability of ``(Aᵀ, B)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _core
from .._arrays import F64
from .._json import plain
from ..errors import NotDetectableError, NotObservableError, UnexcitedAxisModeError
from .cost import BlockStructure

__all__ = ["PBH_RTOL", "NetworkReport", "SubsystemReport", "network_report"]

#: Relative tolerance of the PBH tests: a mode ``λ`` counts as unobservable (uncontrollable) when
#: ``σ_min([A − λI; Cᵀ]) ≤ PBH_RTOL · max(‖A‖_F, ‖C‖_F)``. About ``√ε_mach``: eigenvalues of a
#: defective matrix are only that accurate, so an exactly unobservable Jordan mode still passes.
PBH_RTOL = 1e-8

#: Eigenvalues closer than this (relative to the scale above) are tested together, by an SVD of the
#: PBH matrix at their mean, instead of one eigenvector at a time.
_CLUSTER_RTOL = 1e-6


def rcond(g: F64) -> float:
    """``σ_n / σ_1`` of an ``n × m`` matrix: 0 for a zero matrix and when ``m < n`` (then
    ``G Gᵀ`` is singular)."""
    n, m = g.shape
    if m < n or n == 0:
        return 0.0
    s = np.linalg.svd(g, compute_uv=False)
    return float(s[n - 1] / s[0]) if s[0] > 0 else 0.0


def full_row_rank(g: F64) -> bool:
    """Whether ``G`` (``n × m``) has rank ``n`` to working accuracy (``σ_n > n·ε·σ_1``)."""
    return bool(rcond(g) > g.shape[0] * np.finfo(float).eps)


def pbh_margin(
    a: F64, c: F64, *, unstable_only: bool = False, axis_only: bool = False
) -> tuple[float, complex | None]:
    """Observability margin of ``(A, C)`` (outputs ``Cᵀx``) by the PBH test.

    Returns ``(m, λ)``: ``m = min_λ σ_min([A − λI; Cᵀ]) / max(‖A‖_F, ‖C‖_F)`` over the eigenvalues
    ``λ`` of ``A`` (only those with ``Re λ ≥ −√ε·scale`` when ``unstable_only``, only those with
    ``|Re λ| ≤ √ε·scale`` — on the imaginary axis to working accuracy — when ``axis_only``), and the
    minimising
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
    if axis_only:
        keep &= np.abs(lam.real) <= np.sqrt(np.finfo(float).eps) * scale
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


def check_axis_noise(a: F64, g: F64, g_blocks: Sequence[F64] | None) -> None:
    """``(A, G)`` without uncontrollable modes on the imaginary axis (PBH), the condition for a
    stabilising Riccati solution when ``Q = G Gᵀ`` is singular; skipped when ``G`` (or every block
    ``G_i`` of a block-diagonal ``G``) has full row rank, since then every mode receives noise.

    Raises:
        UnexcitedAxisModeError: a mode on the axis receives no noise (names the mode).
    """
    if all(full_row_rank(x) for x in ([g] if g_blocks is None else g_blocks)):
        return
    m, lam = pbh_margin(a.T, g, axis_only=True)
    if m <= PBH_RTOL:
        raise UnexcitedAxisModeError(
            f"the mode λ = {fmt_mode(lam)} of A lies on the imaginary axis and receives no "
            f"process noise ((A, G) is not controllable there, PBH margin {m:.1e}): the "
            "Riccati equation has no stabilising solution; add noise to that mode"
        )


def validate_network(a: F64, g: F64, sensor_matrix: F64, structure: BlockStructure | None) -> None:
    """The network's assumptions: noise on every mode on the imaginary axis
    (:func:`check_axis_noise`), observability of each subsystem ``(A_i, c_i)`` (block networks) and
    detectability of ``(A, [ĉ_1 … ĉ_N])`` (skipped for an uncoupled block network, which observable
    subsystems make observable).

    Raises:
        UnexcitedAxisModeError, NotObservableError, NotDetectableError: naming the mode.
    """
    st = structure
    check_axis_noise(a, g, None if st is None else st.g_blocks)
    if st is not None:
        for i, (ai, ci) in enumerate(zip(st.a_blocks, st.c_blocks, strict=True)):
            m, lam = pbh_margin(ai, ci)
            if m <= PBH_RTOL:
                raise NotObservableError(
                    f"subsystem {i}: (A_{i}, c_{i}) is not observable: the mode "
                    f"λ = {fmt_mode(lam)} is not seen by c_{i} (PBH margin {m:.1e})"
                )
        if st.eps == 0 or not np.any(st.coupling):
            return
    m, lam = pbh_margin(a, sensor_matrix, unstable_only=True)
    if m <= PBH_RTOL:
        raise NotDetectableError(
            f"(A, [ĉ_1 … ĉ_N]) is not detectable: the mode λ = {fmt_mode(lam)} "
            f"(Re λ ≥ 0) is seen by no sensor (PBH margin {m:.1e})"
        )


def fmt_mode(lam: complex | None) -> str:
    if lam is None:
        return "-"
    if lam.imag == 0:
        return f"{lam.real:.6g}"
    return f"{lam.real:.6g}{lam.imag:+.6g}j"


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

    def to_dict(self) -> dict[str, Any]:
        """The checks as plain JSON-ready values (a complex mode as ``[re, im]``)."""
        return {
            "index": self.index,
            "n": self.n,
            "p": self.p,
            "observable": self.observable,
            "observability_margin": plain(self.observability_margin),
            "g_rcond": plain(self.g_rcond),
            "regular": self.regular,
            "regularity_margin": plain(self.regularity_margin),
            "least_controllable_mode": plain(self.least_controllable_mode),
        }


@dataclass(frozen=True)
class NetworkReport:
    """What :meth:`Network.check` found.

    Attributes:
        n: state dimension.
        num_sensors: ``N``.
        eps: coupling strength (block networks) or ``None``.
        open_loop_abscissa: ``max Re λ(A)``.
        g_rcond: ``σ_min(G)/σ_max(G)`` over the ``min(n, m)`` singular values (0 when ``G`` has
            fewer than ``n`` columns or is rank deficient: ``Q`` singular).
        detectable: ``(A, [ĉ_1 … ĉ_N])`` detectable.
        detectability_margin: PBH margin over the modes with ``Re λ ≥ 0`` (``inf`` if none).
        observable: ``(A, [ĉ_1 … ĉ_N])`` observable.
        observability_margin: PBH margin over all modes.
        subsystems: one :class:`SubsystemReport` per subsystem (block networks, or a general network
            with one sensor, which is its own subsystem); empty otherwise.
        axis_modes_excited: every mode of ``A`` on the imaginary axis receives process noise
            (``(A, G)`` has no uncontrollable mode there — needed for a stabilising solution when
            ``Q = G Gᵀ`` is singular).
        axis_excitation_margin: PBH margin of ``(A, G)`` over the modes on the axis (``inf`` if
            none).
        budget_range: the feasible budgets ``(Σ b_i r_min,i, Σ b_i r_max,i)`` of a network with
            sample costs, per-sensor minima or caps (``None`` in the paper's problem, where any
            ``r_tot ≥ N·r_min`` is feasible).
        detectability_without_off_sensors: with some minima ``r_min,i = 0``, the PBH margin of
            ``(A, [ĉ_i : r_min,i > 0])`` over the modes with ``Re λ ≥ 0`` — the condition for ``η``
            to be finite where those sensors are off (``None`` without zero minima).
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
    axis_modes_excited: bool = True
    axis_excitation_margin: float = float("inf")
    budget_range: tuple[float, float] | None = None
    detectability_without_off_sensors: float | None = None

    @property
    def regular(self) -> bool | None:
        """All subsystems are regular triplets (``None`` without subsystems or if unknown)."""
        if not self.subsystems or any(s.regular is None for s in self.subsystems):
            return None
        return all(bool(s.regular) for s in self.subsystems)

    @property
    def ok(self) -> bool:
        """The assumptions hold: detectable, noise on every mode on the imaginary axis, every
        subsystem observable and regular."""
        return (
            self.detectable
            and self.axis_modes_excited
            and all(s.observable and s.regular for s in self.subsystems)
        )

    def to_dict(self) -> dict[str, Any]:
        """The report as plain JSON-ready values (non-finite margins as ``None``)."""
        return {
            "n": self.n,
            "num_sensors": self.num_sensors,
            "eps": plain(self.eps),
            "open_loop_abscissa": plain(self.open_loop_abscissa),
            "g_rcond": plain(self.g_rcond),
            "detectable": self.detectable,
            "detectability_margin": plain(self.detectability_margin),
            "observable": self.observable,
            "observability_margin": plain(self.observability_margin),
            "axis_modes_excited": self.axis_modes_excited,
            "axis_excitation_margin": plain(self.axis_excitation_margin),
            "regular": self.regular,
            "ok": self.ok,
            "budget_range": plain(self.budget_range),
            "detectability_without_off_sensors": plain(self.detectability_without_off_sensors),
            "subsystems": [s.to_dict() for s in self.subsystems],
        }

    def __repr__(self) -> str:
        return (
            f"NetworkReport(n={self.n}, N={self.num_sensors}, detectable={self.detectable}, "
            f"observable={self.observable}, regular={self.regular}, ok={self.ok})"
        )

    def __str__(self) -> str:
        lines = [
            f"network: n = {self.n}, N = {self.num_sensors}"
            + ("" if self.eps is None else f", eps = {self.eps:g}"),
            f"  open-loop abscissa max Re λ(A) = {self.open_loop_abscissa:.4g}",
            f"  G: rcond = {self.g_rcond:.3g}",
            f"  detectable: {self.detectable} (margin {self.detectability_margin:.3g})",
            f"  observable: {self.observable} (margin {self.observability_margin:.3g})",
            f"  noise on the modes on the imaginary axis: {self.axis_modes_excited} "
            f"(margin {self.axis_excitation_margin:.3g})",
        ]
        if self.budget_range is not None:
            lo, hi = self.budget_range
            lines.append(
                f"  sample costs and rate limits: feasible budgets {lo:.6g} ≤ B ≤ {hi:.6g}"
            )
        if self.detectability_without_off_sensors is not None:
            m = self.detectability_without_off_sensors
            lines.append(f"  detectable with the zero-minimum sensors off: margin {m:.3g}")
        if self.subsystems:
            lines.append(
                "  subsystem  n_i  p_i  observable (margin)   regular triplet (margin, mode)"
            )
            for s in self.subsystems:
                reg = (
                    "unknown"
                    if s.regular is None
                    else f"{s.regular} ({s.regularity_margin:.3g}, "
                    f"λ = {fmt_mode(s.least_controllable_mode)})"
                )
                lines.append(
                    f"  {s.index:>9}  {s.n:>3}  {s.p:>3}  {str(s.observable):>5} "
                    f"({s.observability_margin:9.3g})   {reg}"
                )
        return "\n".join(lines)


def _subsystem_report(i: int, ai: F64, gi: F64, ci: F64, r_min: float) -> SubsystemReport:
    """The checks of subsystem ``i``: observability of ``(A_i, c_i)``, ``G_i``'s conditioning and
    the regular-triplet test, ``(A_i, Σ_i c_i)`` controllable with ``Σ_i`` the subsystem's own
    Riccati solution at ``r = r_min``."""
    om, _ = pbh_margin(ai, ci)
    regular: bool | None = None
    reg_m: float | None = None
    mode: complex | None = None
    try:
        model = _core.CostModel(ai, gi, [ci])
        sigma = model.evaluate(np.array([r_min]), 0).sigma
        reg_m, mode = pbh_margin(ai.T, sigma @ ci)
        regular = reg_m > PBH_RTOL
    except (ValueError, np.linalg.LinAlgError):
        pass
    return SubsystemReport(
        i, int(ai.shape[0]), int(ci.shape[1]), om > PBH_RTOL, om, rcond(gi), regular, reg_m, mode
    )


def network_report(
    a: F64,
    g: F64,
    sensor_matrix: F64,
    num_sensors: int,
    subsystems: Sequence[tuple[F64, F64, F64]],
    r_min: float,
    eps: float | None,
) -> NetworkReport:
    """The report of :meth:`Network.check <capalloc_rs.Network.check>`.

    Args:
        a: ``A`` (``n × n``).
        g: ``G`` (``n × m``).
        sensor_matrix: ``[ĉ_1 … ĉ_N]``.
        num_sensors: ``N``.
        subsystems: ``(A_i, G_i, c_i)`` of each subsystem checked on its own.
        r_min: the rate at which the subsystems' Riccati solutions are taken.
        eps: the coupling strength (block networks) or ``None``.

    Returns:
        The margins of the whole network and one :class:`SubsystemReport` per subsystem.
    """
    det_m, _ = pbh_margin(a, sensor_matrix, unstable_only=True)
    axis_m, _ = pbh_margin(a.T, g, axis_only=True)
    obs_m, _ = pbh_margin(a, sensor_matrix)
    subs = tuple(
        _subsystem_report(i, ai, gi, ci, r_min) for i, (ai, gi, ci) in enumerate(subsystems)
    )
    return NetworkReport(
        n=int(a.shape[0]),
        num_sensors=num_sensors,
        eps=eps,
        open_loop_abscissa=float(np.max(np.linalg.eigvals(a).real)),
        g_rcond=rcond(g),
        detectable=det_m > PBH_RTOL,
        detectability_margin=det_m,
        observable=obs_m > PBH_RTOL,
        observability_margin=obs_m,
        subsystems=subs,
        axis_modes_excited=axis_m > PBH_RTOL,
        axis_excitation_margin=axis_m,
    )
