"""Dense solvers backed by the Rust core.

Drop-ins with exactly scipy's equations and argument conventions:

* :func:`solve_continuous_are` — ``AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0`` (stabilising X);
* :func:`solve_continuous_lyapunov` — ``A X + X Aᵀ = Q``;
* :func:`solve_sylvester` — ``A X + X B = Q``;
* :func:`schur` — real Schur form ``A = Z T Zᵀ`` with optional ordering, ``(T, Z, sdim)``;
* :func:`expm` — ``e^A``;

plus :func:`care` returning a :class:`CareResult` with diagnostics, and :func:`van_loan`.
All functions accept any array-like of real numbers and return float64 arrays; errors are the
package's exceptions (:mod:`capalloc_rs.errors`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any, Literal

from . import _core
from ._arrays import F64, as_matrix, as_matrix_checked_downstream
from .errors import InvalidInputError, MarginalSolutionWarning

__all__ = [
    "CareResult",
    "care",
    "solve_continuous_are",
    "solve_continuous_lyapunov",
    "solve_sylvester",
    "schur",
    "expm",
    "van_loan",
]


@dataclass(frozen=True)
class CareResult:
    """The stabilising solution of ``AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0`` and its diagnostics.

    Attributes:
        x: the stabilising solution (symmetric; ``A − B R⁻¹ Bᵀ X`` is Hurwitz).
        forward_error: an upper bound on the relative error ``‖X − X*‖_F / ‖X*‖_F``: the norm of
            the inverse closed-loop Lyapunov operator ``Ω(Δ) = A_clᵀΔ + ΔA_cl`` (exactly
            ``‖Ω⁻¹(I)‖₂``, a positive map) times the residual plus its rounding error, with a
            Newton–Kantorovich factor for the quadratic term; ``inf`` when no bound can be
            established (a marginal problem).
        trace_error: an upper bound on ``|tr X − tr X*|`` from the same estimate.
        residual: relative residual ``‖R(X)‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)``,
            ``G = B R⁻¹ Bᵀ`` — a backward error: small does not mean X is accurate.
        rcond: reciprocal condition estimate of ``U11`` in ``X U11 = U21`` (the basis of the stable
            invariant subspace of the Hamiltonian); small values mean X is sensitive.
        closed_loop_abscissa: ``max Re λ(A − G X) < 0``.
        axis_margin: distance of the Hamiltonian eigenvalue nearest the imaginary axis in units of
            its own perturbation bound ``κ(λ)·eps·‖H‖`` (``inf`` when none is near); below 10 it
            counts as on the axis.
        marginal: the problem has eigenvalues on the axis and was solved only because
            ``accept_marginal=True`` asked for it.
        newton_steps: Newton refinement steps taken.
        scaling: the factor ``s`` with ``G ← sG``, ``Q ← Q/s`` used in the Schur step.
    """

    x: F64
    forward_error: float
    trace_error: float
    residual: float
    rcond: float
    closed_loop_abscissa: float
    axis_margin: float
    marginal: bool
    newton_steps: int
    scaling: float


#: Default bound on the Newton refinement steps after the Schur solution.
DEFAULT_NEWTON_STEPS = 8


def care(
    a: Any,
    b: Any,
    q: Any,
    r: Any = None,
    *,
    scale: bool = True,
    balance: bool = True,
    newton_steps: int = DEFAULT_NEWTON_STEPS,
    accept_marginal: bool = False,
) -> CareResult:
    """Solves ``AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0`` by the Hamiltonian/Schur method.

    ``r=None`` means ``R = I``. ``scale`` applies SLICOT SB02RD's norm scaling; ``balance`` a
    symplectic diagonal balancing of the Hamiltonian (scipy's ``balanced=True``); the Schur solution
    is then refined by up to ``newton_steps`` Newton steps while its residual is above rounding
    level (each kept only if it lowers the residual). ``accept_marginal=True`` returns a solution
    (marked ``marginal``) when Hamiltonian eigenvalues lie on the imaginary axis to within their
    perturbation bounds, instead of raising.

    Raises:
        ShapeError, NonFiniteError, InvalidInputError: bad input.
        NoStabilizingSolutionError: Hamiltonian eigenvalues on the imaginary axis (unless
            ``accept_marginal``) or the wrong number of stable eigenvalues.
        SingularProblemError: ``U11`` singular or too ill-conditioned.
    """
    if newton_steps < 0:
        raise InvalidInputError(f"newton_steps must be >= 0, got {newton_steps}")
    m = as_matrix_checked_downstream  # the Rust core rejects NaN/inf in A, B, Q and R
    rr = None if r is None else m("r", r)
    x, res, rcond, abscissa, steps, scaling, ferr, terr, margin, marginal = _core.care(
        m("a", a), m("b", b), m("q", q), rr, scale, newton_steps, balance, accept_marginal
    )
    return CareResult(
        x=x,
        forward_error=ferr,
        trace_error=terr,
        residual=res,
        rcond=rcond,
        closed_loop_abscissa=abscissa,
        axis_margin=margin,
        marginal=marginal,
        newton_steps=steps,
        scaling=scaling,
    )


def solve_continuous_are(a: Any, b: Any, q: Any, r: Any) -> F64:
    """scipy-compatible ``solve_continuous_are(a, b, q, r)``: returns X only.

    Like scipy it returns a solution for marginal problems (Hamiltonian eigenvalues on the
    imaginary axis to within rounding), with a :class:`~capalloc_rs.errors.MarginalSolutionWarning`
    naming the margin; :func:`care` raises for those unless asked.
    """
    m = as_matrix_checked_downstream  # the Rust core rejects NaN/inf in A, B, Q and R
    rr = None if r is None else m("r", r)
    out = _core.care(
        m("a", a), m("b", b), m("q", q), rr, True, DEFAULT_NEWTON_STEPS, True, True
    )
    x: F64 = out[0]
    if out[9]:
        warnings.warn(
            "marginal Riccati problem: a Hamiltonian eigenvalue is on the imaginary axis to "
            f"within {out[8]:.2g} times its perturbation bound; the returned solution is not "
            f"stabilising and may be inaccurate (error bound {out[6]:.1e})",
            MarginalSolutionWarning,
            stacklevel=2,
        )
    return x


def solve_continuous_lyapunov(a: Any, q: Any) -> F64:
    """scipy-compatible: solves ``A X + X Aᵀ = Q`` (Bartels–Stewart)."""
    return _core.solve_lyapunov(as_matrix("a", a), as_matrix("q", q))


def solve_sylvester(a: Any, b: Any, q: Any) -> F64:
    """scipy-compatible: solves ``A X + X B = Q`` (Bartels–Stewart)."""
    return _core.solve_sylvester(as_matrix("a", a), as_matrix("b", b), as_matrix("q", q))


def schur(a: Any, sort: Literal["lhp", "rhp", "iuc", "ouc"] | None = None) -> tuple[F64, F64, int]:
    """Real Schur form ``A = Z T Zᵀ`` like ``scipy.linalg.schur(a, output="real", sort=...)``.

    T is quasi-upper-triangular with standardised 2×2 blocks (complex pairs); with ``sort`` the
    selected eigenvalues (``"lhp"``: Re λ < 0, ``"rhp"``: Re λ > 0, ``"iuc"``: |λ| ≤ 1,
    ``"ouc"``: |λ| > 1) come first and ``sdim`` counts them (0 without ``sort``).
    """
    return _core.schur(as_matrix("a", a), sort)


def expm(a: Any) -> F64:
    """``e^A`` by Padé scaling and squaring."""
    return _core.expm(as_matrix("a", a))


def van_loan(a: Any, q: Any, t: float) -> tuple[F64, F64]:
    """``(E, H)`` with ``E = e^{At}`` and ``H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`` (Van Loan 1978)."""
    return _core.van_loan(as_matrix("a", a), as_matrix("q", q), float(t))
