"""Dense solvers backed by the Rust core.

Drop-ins with exactly scipy's equations and argument conventions:

* :func:`solve_continuous_are` — ``AᵀXE + EᵀXA − (EᵀXB + S) R⁻¹ (BᵀXE + Sᵀ) + Q = 0``
  (stabilising X; ``E = I``, ``S = 0`` by default);
* :func:`solve_continuous_lyapunov` — ``A X + X Aᵀ = Q``;
* :func:`solve_sylvester` — ``A X + X B = Q``;
* :func:`schur` — Schur form ``A = Z T Zᵀ``: ``(T, Z)``, or ``(T, Z, sdim)`` with ``sort``;
* :func:`expm` — ``e^A``;

plus :func:`care` returning a :class:`CareResult` with diagnostics, and :func:`van_loan`.

Conventions (scipy's, checked against scipy 1.17's source and tests): 0×0 problems return empty
results of scipy's shapes; ``solve_continuous_are`` and ``solve_continuous_lyapunov`` pass their
arguments through ``np.atleast_2d`` (scalars and 1-D ``r`` are accepted); ``expm`` of a scalar is a
1×1 matrix and stacks ``(..., n, n)`` are mapped over; float32/float16 input gives float32 output
where scipy's does (Lyapunov, Sylvester, Schur, expm — the CARE always returns float64), while the
Rust core computes in float64 throughout. Complex input raises
:class:`~capalloc_rs.errors.InvalidInputError` naming the scipy function to use instead. Bad input
raises the package's :class:`ValueError` subclasses, numerical failure its
:class:`numpy.linalg.LinAlgError` subclasses (:mod:`capalloc_rs.errors`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from . import _complex_schur, _core
from ._arrays import F64, as_count, as_matrix, as_real
from ._json import plain
from ._scipy_compat import as_f64, real_array, result_dtype, shaped, square
from .errors import (
    InaccurateSolutionWarning,
    InvalidInputError,
    MarginalSolutionWarning,
    NonFiniteError,
    ShapeError,
)

__all__ = [
    "INACCURATE_BOUND",
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
    """The stabilising solution of ``AᵀXE + EᵀXA − (EᵀXB + S) R⁻¹ (BᵀXE + Sᵀ) + Q = 0`` (with
    ``E = I``, ``S = 0``: ``AᵀX + XA − X G X + Q = 0``, ``G = B R⁻¹ Bᵀ``) and its diagnostics.

    Attributes:
        x: the stabilising solution (symmetric; ``A − B R⁻¹ Bᵀ X`` is Hurwitz, in general the
            pencil ``(A − BK, E)`` with ``K = R⁻¹(BᵀXE + Sᵀ)``).
        forward_error: an upper bound on the relative error ``‖X − X*‖_F / ‖X*‖_F``: the norm of
            the inverse closed-loop Lyapunov operator ``Ω(Δ) = A_clᵀΔ + ΔA_cl`` (exactly
            ``‖Ω⁻¹(I)‖₂``, a positive map) times the residual plus its rounding error, with a
            Newton–Kantorovich factor for the quadratic term where it applies; ``inf`` when no
            bound can be established. With ``e`` it includes ``eps/rcond(E)`` for the congruence
            by ``E⁻¹``.
        trace_error: an upper bound on ``|tr X − tr X*|`` from the same estimate.
        residual: relative residual — a backward error: small does not mean X is accurate.
            For ``E = I``, ``S = 0`` ``‖R(X)‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)``; with
            ``e``/``s`` that of the original equation,
            ``‖F‖_F / (‖Q‖_F + 2‖AᵀXE‖_F + ‖(EᵀXB + S)K‖_F)``.
        rcond: reciprocal condition estimate of ``U11`` in ``X U11 = U21`` (the basis of the stable
            invariant subspace of the Hamiltonian); small values mean X is sensitive. NaN for a
            solution of the closed-loop route (see ``care``), which forms no ``U11``.
        closed_loop_abscissa: ``max Re λ(A − G X) < 0`` (with ``e``/``s``: of the pencil
            ``(A − BK, E)``, before the refinement on the original equation).
        axis_margin: distance of the Hamiltonian eigenvalue nearest the imaginary axis in units of
            its own perturbation bound ``κ(λ)·eps·‖H‖`` (``inf`` when none is near); below 10 it
            counts as on the axis. NaN for a solution of the closed-loop route, whose stability
            is judged on the closed loop ``A − GX`` itself.
        marginal: the problem has eigenvalues on (or too near) the axis and was solved only
            because ``accept_marginal=True`` asked for it.
        newton_steps: Newton refinement steps taken (with ``e``/``s``, including those on the
            original equation).
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

    def to_dict(self) -> dict[str, Any]:
        """The solution and its diagnostics as plain JSON-ready values (``x`` as nested lists;
        non-finite numbers as ``None``)."""
        return {
            "x": plain(self.x),
            "forward_error": plain(self.forward_error),
            "trace_error": plain(self.trace_error),
            "residual": plain(self.residual),
            "rcond": plain(self.rcond),
            "closed_loop_abscissa": plain(self.closed_loop_abscissa),
            "axis_margin": plain(self.axis_margin),
            "marginal": bool(self.marginal),
            "newton_steps": int(self.newton_steps),
            "scaling": plain(self.scaling),
        }

    def __repr__(self) -> str:
        n = self.x.shape[0]
        flag = ", marginal" if self.marginal else ""
        return (
            f"CareResult(n={n}, forward_error={self.forward_error:.1e}, "
            f"residual={self.residual:.1e}, newton_steps={self.newton_steps}{flag})"
        )


#: Default bound on the Newton refinement steps after the Schur solution.
DEFAULT_NEWTON_STEPS = 8

#: :func:`care` (and so :func:`solve_continuous_are`) warns with
#: :class:`~capalloc_rs.errors.InaccurateSolutionWarning` when a returned solution's
#: ``forward_error`` is above this (relative; every CAREX example's bound is below 4e-5 except
#: the marginal 2.8 at ε = 1e-6, which has its own warning).
INACCURATE_BOUND = 1e-3


def care(
    a: Any,
    b: Any,
    q: Any,
    r: Any = None,
    e: Any = None,
    s: Any = None,
    *,
    scale: bool = True,
    balance: bool = True,
    newton_steps: int = DEFAULT_NEWTON_STEPS,
    accept_marginal: bool = False,
) -> CareResult:
    """Solves ``AᵀXE + EᵀXA − (EᵀXB + S) R⁻¹ (BᵀXE + Sᵀ) + Q = 0`` for the stabilising X.

    ``r=None`` means ``R = I``, ``e=None`` means ``E = I``, ``s=None`` means ``S = 0``; without
    ``e`` and ``s`` the equation is ``AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0``, solved by the
    Hamiltonian/Schur method. ``R`` must be symmetric and nonsingular (indefinite is allowed), ``E``
    nonsingular. With ``e`` or ``s`` the problem is transformed to the standard one (``Â = AE⁻¹``,
    ``Q̂ = E⁻ᵀQE⁻¹``, ``Ŝ = E⁻ᵀS``, cross term folded into ``Â`` and ``Q̂``), solved as below, and
    then refined by Newton's iteration on the original equation: each correction solves
    ``A_KᵀΔE+EᵀΔA_K = −F(X)`` (``A_K = A − BK``) — for an ill-conditioned ``E`` (``rcond₁(E) ≤
    1e-4``) on the QZ form of the pencil ``(A_K, E)``, never with ``E⁻¹`` (a well-conditioned ``E``
    by the congruence with ``E⁻¹``), with the residual's products ``EᵀXA``, ``EᵀXB`` in
    double-double from ``rcond₁(E) ≤ 1e-2``; ``forward_error`` is then a Newton–Kantorovich bound
    for the original equation (which also proves the closed-loop pencil of the exact solution
    stable), or the first-order estimate with the quadratic term at the computed correction when
    that test fails; and ``residual`` is the relative residual of the original equation, ``‖F‖_F /
    (‖Q‖_F + 2‖EᵀXA‖_F + ‖(EᵀXB+S)R⁻¹(BᵀXE+Sᵀ)‖_F)``.

    ``scale`` applies SLICOT SB02RD's norm scaling; ``balance`` a symplectic diagonal balancing of
    the Hamiltonian (scipy's ``balanced=True``); the Schur solution is then refined by up to
    ``newton_steps`` Newton steps until the corrections fall below a few ulps (a step is kept only
    while the corrections contract). ``accept_marginal=True`` returns a solution (marked
    ``marginal``) when Hamiltonian eigenvalues lie on the imaginary axis to within their
    perturbation bounds, instead of raising. Arguments go through ``np.atleast_2d`` as in scipy;
    a 0×0 problem returns a 0×0 ``x``.

    When the Hamiltonian route refuses for an eigenvalue on the axis to within its bound, the wrong
    stable count or a computed stable subspace that is not Lagrangian (or returns a marginal
    solution), a second route runs: Newton–Kleinman on the ``n × n`` closed loop from a stabilising
    start, refined with double-double residuals. Its solution (``rcond`` and ``axis_margin`` NaN,
    not ``marginal``) is returned only when a Kantorovich-type certificate proves a solution within
    ``forward_error`` (at most 1e-6; the bound is for the data as given in double precision) and
    every eigenvalue of the closed loop ``A − GX`` is left of the axis by more than its first-order
    perturbation bound, including the proven distance to the exact solution's closed loop. In place
    of a stable subspace that is not Lagrangian that margin must be 1e3 bounds: stiff models (slow
    eigenvalues ~1e-9 of the Hamiltonian's norm, thousands of bounds from the axis) are solved,
    CAREX 14 (a closed-loop pair 137 bounds from the axis) keeps the refusal. See
    docs/guide/linalg.md.

    A solution whose ``forward_error`` is above :data:`INACCURATE_BOUND` (1e-3) is returned with
    an :class:`~capalloc_rs.errors.InaccurateSolutionWarning`: the bound covers its error, but
    fewer than three digits are guaranteed.

    Raises:
        ShapeError, NonFiniteError, InvalidInputError: bad input (including a numerically
            singular ``R`` or ``E``, and complex data).
        NoStabilizingSolutionError: Hamiltonian eigenvalues on the imaginary axis (unless
            ``accept_marginal``) or the wrong number of stable eigenvalues.
        SingularProblemError: ``U11`` singular or too ill-conditioned, or ``E`` too ill-conditioned
            for an accurate solution (the transformed problem refused and no certified answer).
    """
    if type(newton_steps) is not int or not 0 <= newton_steps <= 1000:
        newton_steps = as_count("newton_steps", newton_steps, maximum=1000)
    alt = "scipy.linalg.solve_continuous_are"

    def mat(name: str, x: Any) -> F64:
        if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 2 and x.size:
            return x  # the common case: the Rust core checks shapes and NaN/inf itself
        return as_f64(np.atleast_2d(real_array(name, x, alt)))

    aa, bb, qq = mat("a", a), mat("b", b), mat("q", q)
    rr = None if r is None else mat("r", r)
    ee = None if e is None else mat("e", e)
    ss = None if s is None else mat("s", s)
    if aa.shape[0] == 0:
        n = square("a", aa)
        m = bb.shape[1]
        shaped("b", bb, (n, m))
        shaped("q", qq, (n, n))
        for name, arr, shape in (("r", rr, (m, m)), ("e", ee, (n, n)), ("s", ss, (n, m))):
            if arr is not None:
                shaped(name, arr, shape)
        return CareResult(np.zeros((0, 0)), 0.0, 0.0, 0.0, 1.0, -np.inf, np.inf, False, 0, 1.0)
    sol = _core.care(aa, bb, qq, rr, ee, ss, scale, newton_steps, balance, accept_marginal)
    if not sol.marginal and not sol.forward_error <= INACCURATE_BOUND:
        warnings.warn(
            f"the Riccati solution's error bound is {sol.forward_error:.1e} (relative): fewer "
            "than three correct digits are guaranteed (an ill-conditioned stable subspace, "
            "e.g. a badly scaled model); check CareResult.forward_error",
            InaccurateSolutionWarning,
            stacklevel=2,
        )
    return CareResult(
        x=sol.x,
        forward_error=sol.forward_error,
        trace_error=sol.trace_error,
        residual=sol.residual,
        rcond=sol.rcond,
        closed_loop_abscissa=sol.closed_loop_abscissa,
        axis_margin=sol.axis_margin,
        marginal=sol.marginal,
        newton_steps=sol.newton_steps,
        scaling=sol.scaling,
    )


def solve_continuous_are(
    a: Any, b: Any, q: Any, r: Any, e: Any = None, s: Any = None, balanced: bool = True
) -> F64:
    """scipy-compatible ``solve_continuous_are``: the stabilising X of
    ``AᵀXE + EᵀXA − (EᵀXB + S) R⁻¹ (BᵀXE + Sᵀ) + Q = 0`` (float64, symmetric).

    This is :func:`care` with its defaults, X only; ``balanced=False`` turns off the symplectic
    balancing (as scipy's). Like scipy it returns a solution for marginal problems (Hamiltonian
    eigenvalues on the imaginary axis to within rounding), with a
    :class:`~capalloc_rs.errors.MarginalSolutionWarning` naming the margin; :func:`care` raises
    for those unless asked.
    Errors are scipy's kinds: ``ValueError`` subclasses for bad input (shapes, NaN, asymmetric
    ``q``/``r``, numerically singular ``r`` or ``e``), ``LinAlgError`` subclasses when no
    stabilising solution can be computed accurately.
    """
    res = care(a, b, q, r, e, s, balance=bool(balanced), accept_marginal=True)
    if res.marginal:
        warnings.warn(
            "marginal Riccati problem: a Hamiltonian eigenvalue is on (or too near) the imaginary "
            f"axis ({res.axis_margin:.2g} times its perturbation bound); the returned solution "
            f"is not stabilising and may be inaccurate (error bound {res.forward_error:.1e})",
            MarginalSolutionWarning,
            stacklevel=2,
        )
    return res.x


def solve_continuous_lyapunov(a: Any, q: Any) -> npt.NDArray[np.floating[Any]]:
    """scipy-compatible: solves ``A X + X Aᵀ = Q`` (Bartels–Stewart). Arguments go through
    ``np.atleast_2d``; float32 in gives float32 out (as scipy); a 0×0 problem returns 0×0."""
    alt = "scipy.linalg.solve_continuous_lyapunov"
    aa = np.atleast_2d(real_array("a", a, alt))
    qq = np.atleast_2d(real_array("q", q, alt))
    n = square("a", aa)
    square("q", qq)
    shaped("q", qq, (n, n))
    dtype = result_dtype(aa, qq)
    if n == 0:
        return np.empty((0, 0), dtype=dtype)
    return _core.solve_lyapunov(as_f64(aa), as_f64(qq)).astype(dtype, copy=False)


def solve_sylvester(a: Any, b: Any, q: Any) -> npt.NDArray[np.floating[Any]]:
    """scipy-compatible: solves ``A X + X B = Q`` (Bartels–Stewart). float32 in gives float32 out
    (as scipy); an empty ``a`` or ``b`` gives an empty result of ``q``'s shape (whatever the
    entries of the other, which the empty answer does not depend on)."""
    alt = "scipy.linalg.solve_sylvester"
    args = (("a", a), ("b", b), ("q", q))
    aa, bb, qq = (real_array(k, v, alt, check_finite=False) for k, v in args)
    m, n = square("a", aa), square("b", bb)
    if qq.ndim != 2:
        raise ShapeError(f"q must be 2-dimensional, got shape {qq.shape}")
    shaped("q", qq, (m, n))
    dtype = result_dtype(aa, bb, qq)
    if m == 0 or n == 0:
        return np.empty((m, n), dtype=dtype)
    for (name, _), arr in zip(args, (aa, bb, qq), strict=True):
        if not np.all(np.isfinite(arr)):
            raise NonFiniteError(f"{name} contains NaN or infinite entries")
    return _core.solve_sylvester(as_f64(aa), as_f64(bb), as_f64(qq)).astype(dtype, copy=False)


SortRule = Literal["lhp", "rhp", "iuc", "ouc"]

#: scipy's sort rules, exactly as scipy.linalg.schur defines them (``rhp`` includes Re λ = 0).
_SORT_RULES: dict[str, Callable[[complex], bool]] = {
    "lhp": lambda z: z.real < 0.0,
    "rhp": lambda z: z.real >= 0.0,
    "iuc": lambda z: abs(z) <= 1.0,
    "ouc": lambda z: abs(z) > 1.0,
}


def schur(
    a: Any,
    output: Literal["real", "complex", "r", "c"] = "real",
    lwork: int | None = None,
    overwrite_a: bool = False,
    sort: SortRule | Callable[..., Any] | None = None,
    check_finite: bool = True,
) -> tuple[Any, ...]:
    """Schur form ``A = Z T Zᴴ`` like ``scipy.linalg.schur``: ``(T, Z)`` without ``sort``,
    ``(T, Z, sdim)`` with it.

    ``output="real"``: T quasi-upper-triangular with standardised 2×2 blocks (complex pairs).
    ``output="complex"``: T upper triangular, complex. ``sort`` moves the selected eigenvalues to
    the top and ``sdim`` counts them: ``"lhp"`` Re λ < 0, ``"rhp"`` Re λ ≥ 0, ``"iuc"``
    ``|λ| ≤ 1``, ``"ouc"`` ``|λ| > 1``, or a callable — called as ``sort(re, im)`` for real output
    (``sort(re)`` if it takes one argument) and as ``sort(λ)`` for complex output. In real output
    a conjugate pair moves as a whole (and counts 2) when either member is selected, as in
    LAPACK. ``lwork`` and ``overwrite_a`` are accepted and ignored; ``check_finite=False`` skips
    the Python-side scan (the Rust core refuses NaN/inf anyway). float32 in gives float32
    (complex64) out, as scipy.

    Raises:
        InvalidInputError: complex ``a`` (use ``scipy.linalg.schur``), a bad ``output`` or
            ``sort`` (``ValueError`` as in scipy).
        ShapeError: ``a`` not square.
        ReorderError: a reordering swap was rejected (eigenvalues too close to separate).
    """
    del lwork, overwrite_a
    if output not in ("real", "complex", "r", "c"):
        raise InvalidInputError(f"output must be 'real' or 'complex', got {output!r}")
    cplx = output in ("complex", "c")
    if sort is not None and not callable(sort) and sort not in _SORT_RULES:
        raise InvalidInputError(
            f"sort must be None, a callable or one of 'lhp', 'rhp', 'iuc', 'ouc'; got {sort!r}"
        )
    arr = real_array("a", a, "scipy.linalg.schur", check_finite=check_finite)
    n = square("a", arr)
    dtype = result_dtype(arr)
    out_dtype = np.result_type(dtype, np.complex64) if cplx else dtype
    if n == 0:
        t0 = np.empty((0, 0), dtype=out_dtype)
        return (t0, t0.copy()) if sort is None else (t0, t0.copy(), 0)
    if cplx:
        tc, zc, sdim = _schur_complex(as_f64(arr), sort)
        res: tuple[Any, ...] = (tc.astype(out_dtype, copy=False), zc.astype(out_dtype, copy=False))
    else:
        t, z, sdim = _schur_real(as_f64(arr), sort)
        res = (t.astype(dtype, copy=False), z.astype(dtype, copy=False))
    return res if sort is None else (*res, sdim)


def _schur_real(a: F64, sort: str | Callable[..., Any] | None) -> tuple[F64, F64, int]:
    """Real Schur form; a callable ``sort`` is evaluated here on the eigenvalues and the Rust core
    reorders by the resulting selection (a pair moves when either member is selected)."""
    if callable(sort):
        plain = _core.schur(a, None)
        two = _complex_schur.positional_arity(sort) >= 2
        select = [
            bool(sort(re, im) if two else sort(re))
            for re, im in _complex_schur.eigenvalues_of_real_schur(plain.t)
        ]
        form = _core.schur_reorder(plain.t, plain.z, select)
    else:
        form = _core.schur(a, sort)
    return form.t, form.z, form.sdim


def _schur_complex(
    a: F64, sort: str | Callable[..., Any] | None
) -> tuple[_complex_schur.C128, _complex_schur.C128, int]:
    """Complex Schur form from the real one; ``sort`` selects single eigenvalues (as zgees)."""
    form = _core.schur(a, None)
    tc, zc = _complex_schur.real_to_complex(form.t, form.z)
    if sort is None:
        return tc, zc, 0
    pick = sort if callable(sort) else _SORT_RULES[sort]
    select = np.array([bool(pick(complex(lam))) for lam in np.diag(tc)])
    return tc, zc, _complex_schur.reorder(tc, zc, select)


def expm(a: Any) -> npt.NDArray[np.floating[Any]]:
    """``e^A`` by Padé scaling and squaring, with scipy's conventions: a scalar gives a 1×1
    matrix, a stack ``(..., n, n)`` is mapped over, empty input gives an empty result, float32 in
    gives float32 out."""
    arr = real_array("a", a, "scipy.linalg.expm")
    dtype = result_dtype(arr)
    if arr.size == 1 and arr.ndim < 2:
        return np.array([[np.exp(as_f64(arr).item())]]).astype(dtype)
    if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
        raise ShapeError(
            f"a must be a square matrix or a stack of them (..., n, n), got shape {arr.shape}"
        )
    if arr.size == 0:
        return np.empty(arr.shape, dtype=dtype)
    if arr.ndim == 2:
        return _core.expm(as_f64(arr)).astype(dtype, copy=False)
    out = np.empty(arr.shape, dtype=dtype)
    for idx in np.ndindex(*arr.shape[:-2]):
        out[idx] = _core.expm(as_f64(arr[idx]))
    return out


def van_loan(a: Any, q: Any, t: float) -> tuple[F64, F64]:
    """``(E, H)`` with ``E = e^{At}`` and ``H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`` (Van Loan 1978)."""
    vl = _core.van_loan(as_matrix("a", a), as_matrix("q", q), as_real("t", t))
    return vl.e, vl.h
