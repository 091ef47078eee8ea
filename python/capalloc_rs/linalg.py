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

from dataclasses import dataclass
from typing import Any, Literal

from . import _core
from ._arrays import F64, as_count, as_matrix, as_matrix_checked_downstream, as_real

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
        residual: relative residual ``‖R(X)‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)``,
            ``G = B R⁻¹ Bᵀ``.
        rcond: reciprocal condition estimate of ``U11`` in ``X U11 = U21`` (the basis of the stable
            invariant subspace of the Hamiltonian); small values mean X is sensitive.
        closed_loop_abscissa: ``max Re λ(A − G X) < 0``.
        newton_steps: Newton–Kleinman refinement steps taken.
        scaling: the factor ``s`` with ``G ← sG``, ``Q ← Q/s`` used in the Schur step.
    """

    x: F64
    residual: float
    rcond: float
    closed_loop_abscissa: float
    newton_steps: int
    scaling: float


def care(
    a: Any,
    b: Any,
    q: Any,
    r: Any = None,
    *,
    scale: bool = True,
    newton_steps: int = 0,
) -> CareResult:
    """Solves ``AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0`` by the Hamiltonian/Schur method.

    ``r=None`` means ``R = I``. ``scale`` applies SLICOT SB02RD's norm scaling; ``newton_steps``
    allows up to that many Newton–Kleinman refinement steps (each kept only if it lowers the
    residual).

    Raises:
        ShapeError, NonFiniteError, InvalidInputError: bad input.
        NoStabilizingSolutionError: Hamiltonian eigenvalues on/near the imaginary axis or the wrong
            number of stable eigenvalues.
        SingularProblemError: ``U11`` singular or too ill-conditioned.
    """
    newton_steps = as_count("newton_steps", newton_steps, maximum=1000)
    m = as_matrix_checked_downstream  # the Rust core rejects NaN/inf in A, B, Q and R
    rr = None if r is None else m("r", r)
    x, residual, rcond, abscissa, steps, scaling = _core.care(
        m("a", a), m("b", b), m("q", q), rr, scale, newton_steps
    )
    return CareResult(x, residual, rcond, abscissa, steps, scaling)


def solve_continuous_are(a: Any, b: Any, q: Any, r: Any) -> F64:
    """scipy-compatible ``solve_continuous_are(a, b, q, r)``: returns X only (the diagnostics of
    :func:`care` are computed but not wrapped)."""
    m = as_matrix_checked_downstream  # the Rust core rejects NaN/inf in A, B, Q and R
    rr = None if r is None else m("r", r)
    x: F64 = _core.care(m("a", a), m("b", b), m("q", q), rr, True, 0)[0]
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
    return _core.van_loan(as_matrix("a", a), as_matrix("q", q), as_real("t", t))
