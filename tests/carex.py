"""The CAREX benchmark collection for continuous-time algebraic Riccati equations, as test data.

Why this module is long: it is data — the twenty CAREX examples with their parameters.

Source: J. Abels and P. Benner, "CAREX — A collection of benchmark examples for continuous-time
algebraic Riccati equations (version 2.0)", SLICOT Working Note 1999-14 (an update of P. Benner,
A. J. Laub and V. Mehrmann, TU Chemnitz-Zwickau report SPC 95_22, 1995), as implemented by SLICOT's
generator ``BB01AD`` and its data files. The examples are re-derived here from their mathematical
definitions (and, for the fixed-size real-world models 1.3–1.5, from the published data); no code
is taken from the collection.

Every generator returns a :class:`CarexProblem` ``(a, b, q, r, x, description)`` for scipy's form
of the equation::

    Aᵀ X + X A − X B R⁻¹ Bᵀ X + Q = 0,        (BB01AD: 0 = Q + AᵀX + XA − XGX, G = B R⁻¹ Bᵀ)

with ``Q = Cᵀ W C`` formed from the collection's factors. ``x`` is the stabilising solution in
closed form where the collection states one, else ``None``.

Numbering follows BB01AD: group 1 = parameter-free fixed size, 2 = parameter-dependent fixed
size, 3 = parameter-free scalable, 4 = parameter-dependent scalable. Not reproduced: 1.6 (J-100 jet
engine, n = 30) and 2.9 (Boeing 767 flutter, n = 55), whose data are too long to transcribe
reliably by hand, and 4.4 (rotating axle), whose data come from a user file.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg as sla

__all__ = [
    "CarexProblem",
    "CASES",
    "care_condition",
    "care_residual",
    "closed_loop",
    "ex1_1",
    "ex1_2",
    "ex1_3",
    "ex1_4",
    "ex1_5",
    "ex2_1",
    "ex2_2",
    "ex2_3",
    "ex2_4",
    "ex2_5",
    "ex2_6",
    "ex2_7",
    "ex2_8",
    "ex3_1",
    "ex3_2",
    "ex4_1",
    "ex4_2",
    "ex4_3",
    "no_stabilizing_solution_example",
    "reference_solution",
    "schur_condition",
]


class CarexProblem(NamedTuple):
    """One CARE ``AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0``; ``x`` is the exact solution or ``None``."""

    a: np.ndarray
    b: np.ndarray
    q: np.ndarray
    r: np.ndarray
    x: np.ndarray | None
    description: str


def _arr(rows: list[list[float]]) -> np.ndarray:
    return np.array(rows, dtype=float)


def _sym(m: np.ndarray) -> np.ndarray:
    """(M + Mᵀ)/2: exactly symmetric storage for matrices that are symmetric by definition."""
    return 0.5 * (m + m.T)


# --------------------------------------------------------------------------------------------------
# Group 1: parameter-free problems of fixed size
# --------------------------------------------------------------------------------------------------


def ex1_1() -> CarexProblem:
    """1.1, Laub (1979) Ex. 1: double integrator. X = [[2, 1], [1, 2]]."""
    a = _arr([[0, 1], [0, 0]])
    b = _arr([[0], [1]])
    q = np.diag([1.0, 2.0])
    r = np.eye(1)
    x = _arr([[2, 1], [1, 2]])
    return CarexProblem(a, b, q, r, x, "CAREX 1.1: Laub 1979, Ex. 1 (n = 2)")


def ex1_2() -> CarexProblem:
    """1.2, Laub (1979) Ex. 2: uncontrollable–unobservable data. X = (1 + √2) [[9, 6], [6, 4]]."""
    a = _arr([[4, 3], [-4.5, -3.5]])
    b = _arr([[1], [-1]])
    q = _arr([[9, 6], [6, 4]])
    r = np.eye(1)
    x = (1.0 + math.sqrt(2.0)) * _arr([[9, 6], [6, 4]])
    return CarexProblem(a, b, q, r, x, "CAREX 1.2: Laub 1979, Ex. 2, uncontrollable-unobservable")


def ex1_3() -> CarexProblem:
    """1.3, Beale & Shafai (1989): model of an L-1011 aircraft (n = 4, m = 2), R = I."""
    a = _arr(
        [
            [0.0, 1.0, 0.0, 0.0],
            [0.0, -1.89, 0.39, -5.53],
            [0.0, -0.034, -2.98, 2.43],
            [0.034, -0.0011, -0.99, -0.21],
        ]
    )
    b = _arr([[0.0, 0.0], [0.36, -1.6], [-0.95, -0.032], [0.03, 0.0]])
    q = _arr(
        [
            [2.313, 2.727, 0.688, 0.023],
            [2.727, 4.271, 1.148, 0.323],
            [0.688, 1.148, 0.313, 0.102],
            [0.023, 0.323, 0.102, 0.083],
        ]
    )
    return CarexProblem(a, b, q, np.eye(2), None, "CAREX 1.3: Beale/Shafai 1989, L-1011 aircraft")


def ex1_4() -> CarexProblem:
    """1.4, Bhattacharyya et al. (1983): binary distillation column (n = 8, m = 2), R = I.

    As published, Q is symmetric but indefinite (e.g. its (1, 5) principal 2×2 minor is negative);
    a stabilising solution exists nonetheless.
    """
    a = np.zeros((8, 8))
    diag = [-0.991, -1.051, -1.118, -1.548, -1.64, -1.721, -1.823, -1.943]
    sup = [0.529, 0.596, 0.596, 0.718, 0.799, 0.901, 1.021]
    sub = [0.522, 0.522, 0.522, 0.922, 0.922, 0.922, 0.922]
    a[np.arange(8), np.arange(8)] = diag
    a[np.arange(7), np.arange(1, 8)] = sup
    a[np.arange(1, 8), np.arange(7)] = sub
    b = _arr(
        [
            [3.84e-3, -2.88e-3],
            [4.00e-3, -3.04e-3],
            [3.76e-2, -2.80e-3],
            [3.08e-3, -2.32e-3],
            [2.36e-3, -3.32e-3],
            [2.88e-3, -3.82e-3],
            [3.08e-3, -4.12e-3],
            [3.00e-3, -3.96e-3],
        ]
    )
    q = np.diag([1.0, 1.0, 1.0, 1.0, 0.1, 0.1, 0.1, 0.1])
    for i, j, v in [(0, 4, 0.5), (0, 7, 0.1), (1, 4, 0.1), (2, 5, 0.5)]:
        q[i, j] = q[j, i] = v
    return CarexProblem(
        a, b, q, np.eye(2), None, "CAREX 1.4: Bhattacharyya et al. 1983, distillation column"
    )


def ex1_5() -> CarexProblem:
    """1.5, Patnaik et al. (1980): tubular ammonia reactor (n = 9, m = 3), Q = I, R = I."""
    a = _arr(
        [
            [-4.019, 5.120, 0, 0, -2.082, 0, 0, 0, 0.870],
            [-0.346, 0.986, 0, 0, -2.340, 0, 0, 0, 0.970],
            [-7.909, 15.407, -4.069, 0, -6.450, 0, 0, 0, 2.680],
            [-21.816, 35.606, -0.339, -3.870, -17.800, 0, 0, 0, 7.390],
            [-60.196, 98.188, -7.907, 0.340, -53.008, 0, 0, 0, 20.400],
            [0, 0, 0, 0, 94.0, -147.2, 0, 53.2, 0],
            [0, 0, 0, 0, 0, 94.0, -147.2, 0, 0],
            [0, 0, 0, 0, 0, 12.8, 0, -31.6, 0],
            [0, 0, 0, 0, 12.8, 0, 0, 18.8, -31.6],
        ]
    )
    b = np.zeros((9, 3))
    b[:5, :] = _arr(
        [
            [0.010, -0.011, -0.151],
            [0.003, -0.021, 0.0],
            [0.009, -0.059, 0.0],
            [0.024, -0.162, 0.0],
            [0.068, -0.445, 0.0],
        ]
    )
    return CarexProblem(
        a, b, np.eye(9), np.eye(3), None, "CAREX 1.5: Patnaik et al. 1980, ammonia reactor"
    )


# --------------------------------------------------------------------------------------------------
# Group 2: parameter-dependent problems of fixed size
# --------------------------------------------------------------------------------------------------


def ex2_1(eps: float = 1e-6) -> CarexProblem:
    """2.1, Arnold & Laub (1984) Ex. 1: (A, B) becomes unstabilisable as ε → 0.

    A = diag(1, −2), B = [ε, 0]ᵀ, R = 1, Q = [1, 1]ᵀ[1, 1]. With s = √(1 + ε²):
    x11 = (1 + s)/ε², x12 = 1/(2 + s), x22 = (1 − ε² x12²)/4.
    """
    if eps == 0.0:
        raise ValueError("Example 2.1 needs eps != 0")
    a = np.diag([1.0, -2.0])
    b = _arr([[eps], [0.0]])
    q = np.ones((2, 2))
    s = math.hypot(1.0, eps)
    x11 = (1.0 + s) / eps / eps
    x12 = 1.0 / (2.0 + s)
    x22 = (1.0 - eps * x12) * (1.0 + eps * x12) / 4.0
    x = _arr([[x11, x12], [x12, x22]])
    return CarexProblem(a, b, q, np.eye(1), x, f"CAREX 2.1: Arnold/Laub 1984, Ex. 1, eps = {eps:g}")


def ex2_2(eps: float = 1e-8) -> CarexProblem:
    """2.2, Arnold & Laub (1984) Ex. 3: the control weight R = [[1 + ε, 1], [1, 1]] is singular
    as ε → 0. No closed-form solution."""
    a = np.diag([-0.1, -0.02])
    b = _arr([[0.1, 0.0], [0.001, 0.01]])
    r = _arr([[1.0 + eps, 1.0], [1.0, 1.0]])
    c = _arr([[10.0, 100.0]])
    q = c.T @ c
    return CarexProblem(a, b, q, r, None, f"CAREX 2.2: Arnold/Laub 1984, Ex. 3, eps = {eps:g}")


def ex2_3(eps: float = 1e6) -> CarexProblem:
    """2.3, Kenney, Laub & Wette (1989) Ex. 2: ill conditioned as ε → ∞.

    A = [[0, ε], [0, 0]], B = e₂, Q = I, R = 1; X = [[√(1+2ε)/ε, 1], [1, √(1+2ε)]].
    """
    if eps == 0.0:
        raise ValueError("Example 2.3 needs eps != 0")
    a = _arr([[0.0, eps], [0.0, 0.0]])
    b = _arr([[0.0], [1.0]])
    s = math.sqrt(1.0 + 2.0 * eps)
    x = _arr([[s / eps, 1.0], [1.0, s]])
    return CarexProblem(
        a, b, np.eye(2), np.eye(1), x, f"CAREX 2.3: Kenney/Laub/Wette 1989, Ex. 2, eps = {eps:g}"
    )


def ex2_4(eps: float = 1e-7) -> CarexProblem:
    """2.4, Bai & Qian (1994): ill-conditioned Hamiltonian as ε → 0.

    A = [[1 + ε, 1], [1, 1 + ε]], B = R = I, Q = ε² I. With t = 1 + ε:
    x11 = x22 = t + (√(t² + 1) + ε)/√2, x12 = x11/(x11 − t).
    """
    t = 1.0 + eps
    a = _arr([[t, 1.0], [1.0, t]])
    q = eps * eps * np.eye(2)
    x11 = (2.0 * t + math.sqrt(2.0) * (math.sqrt(t * t + 1.0) + eps)) / 2.0
    x12 = x11 / (x11 - t)
    x = _arr([[x11, x12], [x12, x11]])
    return CarexProblem(
        a, np.eye(2), q, np.eye(2), x, f"CAREX 2.4: Bai/Qian 1994, ill-conditioned, eps = {eps:g}"
    )


def ex2_5(eps: float = 1e-2) -> CarexProblem:
    """2.5, Laub (1992): an H∞-type problem (indefinite Q) with Hamiltonian eigenvalues ±ε ± i.

    A = [[3 − ε, 1], [4, 2 − ε]], B = [1, 1]ᵀ, R = 1, Q = [[4ε − 11, 2ε − 5], [2ε − 5, 2ε − 2]].
    X = [[2, 1], [1, 1]] for every ε; the closed loop A − BBᵀX = [[−ε, −1], [1, −ε]] has
    eigenvalues −ε ± i, so X is stabilising iff ε > 0. BB01AD's default is ε = 0, the limiting
    case without a stabilising solution (see :func:`no_stabilizing_solution_example`); here the
    default is ε = 0.01.
    """
    a = _arr([[3.0 - eps, 1.0], [4.0, 2.0 - eps]])
    b = _arr([[1.0], [1.0]])
    q = _arr([[4.0 * eps - 11.0, 2.0 * eps - 5.0], [2.0 * eps - 5.0, 2.0 * eps - 2.0]])
    x = _arr([[2.0, 1.0], [1.0, 1.0]]) if eps > 0 else None
    return CarexProblem(
        a, b, q, np.eye(1), x, f"CAREX 2.5: Laub 1992, eigenvalues ±eps ± i, eps = {eps:g}"
    )


def ex2_6(eps: float = 1e6) -> CarexProblem:
    """2.6, Petkov, Christov & Konstantinov (1987): increasingly badly scaled as ε → ∞.

    V = I − (2/3) 11ᵀ (orthogonal, symmetric), A = ε V diag(1, 2, 3) V, B = I, R = ε I,
    Q = V diag(1/ε, 1, ε) V. Decoupled in the V basis: X = V diag(x1, x2, x3) V with
    x1 = ε² + √(ε⁴ + 1), x2 = 2ε² + √(4ε⁴ + ε), x3 = 3ε² + ε√(9ε² + 1).
    """
    if eps == 0.0:
        raise ValueError("Example 2.6 needs eps != 0")
    v = np.eye(3) - (2.0 / 3.0) * np.ones((3, 3))
    a = _sym(v @ np.diag([eps, 2.0 * eps, 3.0 * eps]) @ v)
    q = _sym(v @ np.diag([1.0 / eps, 1.0, eps]) @ v)
    e2 = eps * eps
    d = [e2 + math.sqrt(e2 * e2 + 1.0), 2.0 * e2 + math.sqrt(4.0 * e2 * e2 + eps)]
    d.append(3.0 * e2 + eps * math.sqrt(9.0 * e2 + 1.0))
    x = _sym(v @ np.diag(d) @ v)
    return CarexProblem(
        a,
        np.eye(3),
        q,
        eps * np.eye(3),
        x,
        f"CAREX 2.6: Petkov et al. 1987, badly scaled, eps = {eps:g}",
    )


def ex2_7(eps: float = 1e-6) -> CarexProblem:
    """2.7, Chow & Kokotovic (1976): magnetic tape control system, stiff as ε → 0 (n = 4)."""
    if eps == 0.0:
        raise ValueError("Example 2.7 needs eps != 0")
    a = np.zeros((4, 4))
    a[0, 1] = 0.4
    a[1, 2] = 0.345
    a[2, 1] = -0.524 / eps
    a[2, 2] = -0.465 / eps
    a[2, 3] = 0.262 / eps
    a[3, 3] = -1.0 / eps
    b = np.zeros((4, 1))
    b[3, 0] = 1.0 / eps
    c = np.zeros((2, 4))
    c[0, 0] = 1.0
    c[1, 2] = 1.0
    return CarexProblem(
        a, b, c.T @ c, np.eye(1), None, f"CAREX 2.7: Chow/Kokotovic 1976, tape drive, eps = {eps:g}"
    )


def ex2_8(eps: float = 1e-6) -> CarexProblem:
    """2.8, Arnold & Laub (1984) Ex. 2: poor separation of the closed-loop spectrum as ε → 0.

    A = diag([[−ε, 1], [−1, −ε]], [[ε, 1], [−1, ε]]), B = 1 (4×1), Q = 11ᵀ, R = 1.
    """
    a = _arr([[-eps, 1, 0, 0], [-1, -eps, 0, 0], [0, 0, eps, 1], [0, 0, -1, eps]])
    return CarexProblem(
        a,
        np.ones((4, 1)),
        np.ones((4, 4)),
        np.eye(1),
        None,
        f"CAREX 2.8: Arnold/Laub 1984, Ex. 2, poor spectral separation, eps = {eps:g}",
    )


# --------------------------------------------------------------------------------------------------
# Group 3: parameter-free problems of scalable size
# --------------------------------------------------------------------------------------------------


def ex3_1(vehicles: int = 20) -> CarexProblem:
    """3.1, Laub (1979) Ex. 4: a string of l high-speed vehicles, n = 2l − 1, m = l.

    States alternate velocity deviations (odd, 1-based) and distances (even): a_ii = −1 and
    b_i,(i+1)/2 = 1 for odd i; a_i,i−1 = 1, a_i,i+1 = −1 and c_i/2,i = 1 for even i;
    Q = 10 CᵀC, R = I.
    """
    if vehicles < 2:
        raise ValueError("Example 3.1 needs at least 2 vehicles")
    n = 2 * vehicles - 1
    a = np.zeros((n, n))
    b = np.zeros((n, vehicles))
    c = np.zeros((vehicles - 1, n))
    for i in range(1, n + 1):  # 1-based as in the description
        if i % 2 == 1:
            a[i - 1, i - 1] = -1.0
            b[i - 1, (i + 1) // 2 - 1] = 1.0
        else:
            a[i - 1, i - 2] = 1.0
            a[i - 1, i] = -1.0
            c[i // 2 - 1, i - 1] = 1.0
    q = 10.0 * (c.T @ c)
    return CarexProblem(
        a,
        b,
        q,
        np.eye(vehicles),
        None,
        f"CAREX 3.1: Laub 1979, Ex. 4, {vehicles} vehicles (n = {n})",
    )


def ex3_2(n: int = 64) -> CarexProblem:
    """3.2, Laub (1979) Ex. 5: circulant matrices, B = Q = R = I.

    A = circ(−2, 1, 0, …, 0, 1) (periodic second difference). A is normal with eigenvalues
    λ_k = −2 + 2 cos(2πk/n) on the Fourier basis, so X is circulant with eigenvalues
    x_k = λ_k + √(λ_k² + 1) (scalar CARE 2λx − x² + 1 = 0), i.e.
    X_ij = (1/n) Σ_k x_k cos(2πk(i−j)/n).
    """
    if n < 3:
        raise ValueError("Example 3.2 needs n >= 3")
    a = -2.0 * np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1)
    a[0, n - 1] = a[n - 1, 0] = 1.0
    k = np.arange(n)
    cosk = np.cos(2.0 * np.pi * k / n)
    lam = -2.0 + 2.0 * cosk
    # x_k = λ_k + √(λ_k² + 1) = 1/(√(λ_k² + 1) − λ_k): λ_k ≤ 0, so the second form does not cancel.
    xk = 1.0 / (np.sqrt(lam * lam + 1.0) - lam)
    first_col = np.cos(2.0 * np.pi * np.outer(k, k) / n) @ xk / n
    idx = (k[:, None] - k[None, :]) % n
    x = _sym(first_col[idx])
    return CarexProblem(
        a, np.eye(n), np.eye(n), np.eye(n), x, f"CAREX 3.2: Laub 1979, Ex. 5, circulant, n = {n}"
    )


# --------------------------------------------------------------------------------------------------
# Group 4: parameter-dependent problems of scalable size
# --------------------------------------------------------------------------------------------------


def ex4_1(n: int = 21, q: float = 1.0, r: float = 1.0) -> CarexProblem:
    """4.1, Laub (1979) Ex. 6: a chain of n integrators, ill conditioned for large n.

    A = upper shift (a_i,i+1 = 1), B = e_n, Q = q e₁e₁ᵀ, R = r. The collection gives no exact
    solution; this one is derived here (and checked in 80-digit arithmetic by the tests):

    * the return-difference identity puts the closed-loop poles at the left-half-plane roots of
      (−1)ⁿ s²ⁿ + q/r = 0, a Butterworth pattern of radius ρ = (q/r)^(1/2n). A − BK is a companion
      matrix with characteristic polynomial sⁿ + Σ_k K_(k+1) sᵏ, so K_(k+1) = c_k ρ^(n−k) with the
      Butterworth coefficients c_0 = 1, c_k = Π_{μ=1..k} cos((μ−1)γ)/sin(μγ), γ = π/(2n); and
      K = BᵀX/r gives the last row (and column) of X: X_n,k+1 = r c_k ρ^(n−k);
    * entry (i, j) of the equation reads X_(i−1),j + X_i,(j−1) = X_i,n X_j,n / r − q δ_i1 δ_j1
      (X_0,· = X_·,0 = 0), which yields column j − 1 from column j, for j = n, …, 2.

    The recursion is run in 40-digit arithmetic and rounded once (:func:`_chain_solution`); in
    double precision it reproduces the 80-digit solution only to a relative 6e-16 … 2e-15 for
    n ≤ 21 (entries range over [1, 5e8] for n = 21, q = r = 1).
    """
    if n < 2:
        raise ValueError("Example 4.1 needs n >= 2")
    a = np.eye(n, k=1)
    b = np.zeros((n, 1))
    b[n - 1, 0] = 1.0
    qq = np.zeros((n, n))
    qq[0, 0] = q
    return CarexProblem(
        a,
        b,
        qq,
        np.array([[r]]),
        _chain_solution(n, q, r),
        f"CAREX 4.1: Laub 1979, Ex. 6, n = {n}, q = {q:g}, r = {r:g}",
    )


def _chain_solution(n: int, q: float, r: float) -> np.ndarray:
    """Example 4.1's X by the recursion of :func:`ex4_1`, in 40-digit arithmetic (mpmath) and
    rounded once — in double precision the recursion is only good to ~6e-16 relative at n = 21,
    above the bounds (~4e-16) of solutions that are correct to an ulp — or in double precision
    when mpmath is not installed."""
    try:
        import mpmath as mp

        ctx: Any = mp.mp.clone()
        ctx.dps = 40
        one, pi, cos, sin = ctx.mpf(1), ctx.pi, ctx.cos, ctx.sin
        qv, rv = ctx.mpf(q), ctx.mpf(r)
    except ImportError:  # pragma: no cover
        one, pi, cos, sin = 1.0, math.pi, math.cos, math.sin
        qv, rv = q, r
    gamma = pi / (2 * n)
    rho = (qv / rv) ** (one / (2 * n))
    coeffs = [one]
    for mu in range(1, n):
        coeffs.append(coeffs[-1] * cos((mu - 1) * gamma) / sin(mu * gamma))
    x = [[0 * one] * (n + 1) for _ in range(n + 1)]  # 1-based with a zero row and column 0
    for k in range(n):
        x[n][k + 1] = x[k + 1][n] = rv * coeffs[k] * rho ** (n - k)
    for j in range(n, 1, -1):
        for i in range(1, n + 1):
            x[i][j - 1] = x[i][n] * x[j][n] / rv - x[i - 1][j] - (qv if i == j == 1 else 0)
    out = np.array([[float(x[i][j]) for j in range(1, n + 1)] for i in range(1, n + 1)])
    return _sym(out)


def _hat_integral(i: int, nodes: int, lo: float, hi: float) -> float:
    """∫_lo^hi φ_i(x) dx for the hat function φ_i(x) = max(0, 1 − |N x − i|), N = nodes + 1."""
    big_n = nodes + 1

    def antiderivative(y: float) -> float:  # ∫_{−∞}^{y} max(0, 1 − |s|) ds
        if y <= -1.0:
            return 0.0
        if y <= 0.0:
            return 0.5 * (y + 1.0) ** 2
        if y <= 1.0:
            return 1.0 - 0.5 * (1.0 - y) ** 2
        return 1.0

    if hi <= lo:
        return 0.0
    return (antiderivative(big_n * hi - i) - antiderivative(big_n * lo - i)) / big_n


def ex4_2(
    n: int = 100,
    a_coef: float = 0.01,
    b_coef: float = 1.0,
    c_coef: float = 1.0,
    beta: tuple[float, float] = (0.2, 0.3),
    gamma: tuple[float, float] = (0.2, 0.3),
) -> CarexProblem:
    """4.2, Rosen & Wang (1992): LQ control of 1-D heat flow, linear finite elements.

    On n interior nodes of [0, 1] (h = 1/(n+1)) with hat functions φ_i: mass matrix
    M = h/6 tridiag(1, 4, 1), stiffness K = a/h tridiag(1, −2, 1); A = M⁻¹K, B = M⁻¹ b_vec with
    b_vec_i = b ∫_β φ_i, the observation C = c [∫_γ φ_i]_i (1×n), Q = CᵀC, R = 1.
    """
    h = 1.0 / (n + 1)
    mass = sla.toeplitz(np.r_[4.0, 1.0, np.zeros(n - 2)]) * h / 6.0
    stiff = sla.toeplitz(np.r_[-2.0, 1.0, np.zeros(n - 2)]) * a_coef / h
    bvec = np.array([[b_coef * _hat_integral(i, n, *beta)] for i in range(1, n + 1)])
    cvec = np.array([[c_coef * _hat_integral(i, n, *gamma) for i in range(1, n + 1)]])
    a = np.linalg.solve(mass, stiff)
    b = np.linalg.solve(mass, bvec)
    return CarexProblem(
        a, b, cvec.T @ cvec, np.eye(1), None, f"CAREX 4.2: Rosen/Wang 1992, heat flow, n = {n}"
    )


def ex4_3(
    masses: int = 30, mu: float = 4.0, delta: float = 4.0, kappa: float = 1.0
) -> CarexProblem:
    """4.3, Hench et al. (1995): l coupled masses μ with springs κ and dampers δ, n = 2l.

    A = [[0, I], [−(κ/μ) L, −(δ/μ) I]] with L = tridiag(−1, 2, −1) except L_11 = L_ll = 1 (free
    ends); B has 1/μ in row l+1 (column 1) and −1/μ in row 2l (column 2); Q = I, R = I.
    """
    if masses < 2:
        raise ValueError("Example 4.3 needs at least 2 masses")
    l = masses  # noqa: E741 (the collection's name)
    lap = 2.0 * np.eye(l) - np.eye(l, k=1) - np.eye(l, k=-1)
    lap[0, 0] = lap[l - 1, l - 1] = 1.0
    a = np.block([[np.zeros((l, l)), np.eye(l)], [-(kappa / mu) * lap, -(delta / mu) * np.eye(l)]])
    b = np.zeros((2 * l, 2))
    b[l, 0] = 1.0 / mu
    b[2 * l - 1, 1] = -1.0 / mu
    n = 2 * l
    return CarexProblem(
        a, b, np.eye(n), np.eye(2), None, f"CAREX 4.3: Hench et al. 1995, {l} masses (n = {n})"
    )


# --------------------------------------------------------------------------------------------------
# No stabilising solution
# --------------------------------------------------------------------------------------------------


def no_stabilizing_solution_example() -> CarexProblem:
    """CAREX 2.5 at its BB01AD default ε = 0: Hamiltonian eigenvalues ±i (double), on the
    imaginary axis. X = [[2, 1], [1, 1]] solves the equation, but A − BBᵀX has eigenvalues ±i,
    so no stabilising solution exists and a solver must refuse."""
    p = ex2_5(0.0)
    return p._replace(description="CAREX 2.5 with eps = 0: Hamiltonian eigenvalues ±i")


# --------------------------------------------------------------------------------------------------
# Diagnostics shared by the tests
# --------------------------------------------------------------------------------------------------


def _g(b: np.ndarray, r: np.ndarray) -> np.ndarray:
    g = b @ np.linalg.solve(r, b.T)
    return 0.5 * (g + g.T)


def closed_loop(p: CarexProblem, x: np.ndarray) -> np.ndarray:
    """A − B R⁻¹ Bᵀ X."""
    return p.a - _g(p.b, p.r) @ x


def care_residual(p: CarexProblem, x: np.ndarray) -> float:
    """Relative residual ‖AᵀX + XA − XGX + Q‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²), the
    normalisation of ``capalloc_rs.linalg.CareResult.residual``."""
    g = _g(p.b, p.r)
    res = p.a.T @ x + x @ p.a - x @ g @ x + p.q
    nrm = np.linalg.norm
    denom = nrm(p.q) + 2.0 * nrm(p.a) * nrm(x) + nrm(g) * nrm(x) ** 2
    return float(nrm(res) / denom)


def reference_solution(p: CarexProblem, newton_steps: int = 4) -> np.ndarray:
    """The closed-form X if known, else scipy's solution refined by Newton–Kleinman steps.

    Each step solves (A − GX_k)ᵀ X_(k+1) + X_(k+1)(A − GX_k) = −Q − X_k G X_k and is kept only if it
    lowers :func:`care_residual`. (scipy alone is not always accurate here: its relative residual
    is 1e-12 on 4.2 and 2e-4 on 2.6 with ε = 1e6; refined, both are at rounding level.)
    """
    if p.x is not None:
        return p.x
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        x = sla.solve_continuous_are(p.a, p.b, p.q, p.r)
    x = 0.5 * (x + x.T)
    g = _g(p.b, p.r)
    res = care_residual(p, x)
    for _ in range(newton_steps):
        ac = p.a - g @ x
        xn = sla.solve_continuous_lyapunov(ac.T, -(p.q + x @ g @ x))
        xn = 0.5 * (xn + xn.T)
        rn = care_residual(p, xn)
        if not rn < res:
            break
        x, res = xn, rn
    return x


def _op_norm_power(
    apply: Callable[[np.ndarray], np.ndarray],
    apply_adj: Callable[[np.ndarray], np.ndarray],
    n: int,
    iters: int = 40,
) -> float:
    """2-norm of a linear operator on n×n matrices (Frobenius inner product) by power iteration."""
    z = np.ones((n, n)) + 0.1 * np.random.default_rng(12345).standard_normal((n, n))
    z /= np.linalg.norm(z)
    est = 0.0
    for _ in range(iters):
        w = apply_adj(apply(z))
        nw = np.linalg.norm(w)
        if nw == 0.0:
            return 0.0
        est = math.sqrt(nw)
        z = w / nw
    return est


def care_condition(p: CarexProblem, x: np.ndarray) -> float:
    """Relative condition number of the stabilising solution (Byers 1985; Kenney & Hewer 1990):

        κ = (‖Ω⁻¹‖ ‖Q‖ + ‖Θ‖ ‖A‖ + ‖Π‖ ‖G‖) / ‖X‖,

    Ω(Z) = A_cᵀZ + Z A_c (A_c = A − GX), Θ(Z) = Ω⁻¹(ZᵀX + XZ), Π(Z) = Ω⁻¹(XZX), with operator
    norms induced by the Frobenius norm: exact (Kronecker form) for n ≤ 16, power iteration
    otherwise. A first-order bound: a relative perturbation δ of A, G, Q moves X by ≲ κ δ.
    """
    g = _g(p.b, p.r)
    ac = p.a - g @ x
    n = p.a.shape[0]
    nrm = np.linalg.norm
    if n <= 16:
        eye = np.eye(n)
        omega = np.kron(eye, ac.T) + np.kron(ac.T, eye)  # vec(AcᵀZ + Z Ac), column-major vec
        perm = np.zeros((n * n, n * n))  # vec(Zᵀ) = P vec(Z)
        for i in range(n):
            for j in range(n):
                perm[i * n + j, j * n + i] = 1.0
        theta = np.linalg.solve(omega, np.kron(x.T, eye) @ perm + np.kron(eye, x))
        pi = np.linalg.solve(omega, np.kron(x.T, x))
        om_inv = 1.0 / np.linalg.svd(omega, compute_uv=False)[-1]
        n_theta = np.linalg.norm(theta, 2)
        n_pi = np.linalg.norm(pi, 2)
    else:

        def om_inv_f(w: np.ndarray) -> np.ndarray:  # Ω⁻¹
            return sla.solve_continuous_lyapunov(ac.T, w)

        def om_inv_adj(w: np.ndarray) -> np.ndarray:  # (Ω⁻¹)* = (Ω*)⁻¹, Ω*(Z) = Ac Z + Z Acᵀ
            return sla.solve_continuous_lyapunov(ac, w)

        om_inv = _op_norm_power(om_inv_f, om_inv_adj, n)

        def theta_f(z: np.ndarray) -> np.ndarray:
            return om_inv_f(z.T @ x + x @ z)

        def theta_adj(w: np.ndarray) -> np.ndarray:
            m = om_inv_adj(w)
            return x @ m.T + x.T @ m

        def pi_f(z: np.ndarray) -> np.ndarray:
            return om_inv_f(x @ z @ x)

        def pi_adj(w: np.ndarray) -> np.ndarray:
            return x.T @ om_inv_adj(w) @ x.T

        n_theta = _op_norm_power(theta_f, theta_adj, n)
        n_pi = _op_norm_power(pi_f, pi_adj, n)
    return float((om_inv * nrm(p.q) + n_theta * nrm(p.a) + n_pi * nrm(g)) / nrm(x))


def schur_condition(p: CarexProblem, x: np.ndarray) -> float:
    """An error indicator for the Hamiltonian/Schur method with SB02RD scaling.

    With s = √(‖Q‖_F/‖G‖_F), the method computes the stable invariant subspace of
    H_s = [[A, −sG], [−Q/s, −Aᵀ]] and X/s = U21 U11⁻¹ from its basis. A backward-stable Schur
    form perturbs that subspace by about u ‖H_s‖/sep, with sep ≈ 2|α| (α the closed-loop spectral
    abscissa: the stable and anti-stable eigenvalues are mirror images), and the map from the
    subspace to X_s = X/s amplifies angles by about (1 + ‖X_s‖₂²); relative to ‖X_s‖₂:

        κ_S = ‖H_s‖_F (1 + ‖X_s‖₂²) / (2 |α| ‖X_s‖₂).

    It is an upper-bound heuristic (not sharp: e.g. CAREX 2.4 with small ε has κ_S ≫ the observed
    error) that captures the cases where the method is genuinely worse than κ_CARE predicts.
    """
    g = _g(p.b, p.r)
    nq, ng = np.linalg.norm(p.q), np.linalg.norm(g)
    s = math.sqrt(nq / ng) if nq > 0 and ng > 0 else 1.0
    hs = np.block([[p.a, -s * g], [-p.q / s, -p.a.T]])
    alpha = abs(float(np.linalg.eigvals(p.a - g @ x).real.max()))
    nx = float(np.linalg.norm(x / s, 2))
    return float(np.linalg.norm(hs) * (1.0 + nx * nx) / (2.0 * alpha * nx))


# --------------------------------------------------------------------------------------------------
# The parametrised collection used by the tests
# --------------------------------------------------------------------------------------------------

#: ``(id, generator)`` for every reproduced example and the parameter values the tests sweep.
CASES: list[tuple[str, Callable[[], CarexProblem]]] = [
    ("1.1", ex1_1),
    ("1.2", ex1_2),
    ("1.3", ex1_3),
    ("1.4", ex1_4),
    ("1.5", ex1_5),
    *[(f"2.1-eps{e:g}", partial(ex2_1, e)) for e in (1.0, 1e-3, 1e-6)],
    *[(f"2.2-eps{e:g}", partial(ex2_2, e)) for e in (1.0, 1e-4, 1e-8)],
    *[(f"2.3-eps{e:g}", partial(ex2_3, e)) for e in (1.0, 1e3, 1e6)],
    *[(f"2.4-eps{e:g}", partial(ex2_4, e)) for e in (1.0, 1e-3, 1e-7)],
    *[(f"2.5-eps{e:g}", partial(ex2_5, e)) for e in (1.0, 1e-2, 1e-4)],
    *[(f"2.6-eps{e:g}", partial(ex2_6, e)) for e in (1.0, 1e2, 1e6)],
    *[(f"2.7-eps{e:g}", partial(ex2_7, e)) for e in (1e-2, 1e-6)],
    *[(f"2.8-eps{e:g}", partial(ex2_8, e)) for e in (1.0, 1e-3, 1e-6)],
    ("3.1-l20", partial(ex3_1, 20)),
    *[(f"3.2-n{n}", partial(ex3_2, n)) for n in (8, 64)],
    *[(f"4.1-n{n}", partial(ex4_1, n)) for n in (5, 10, 21)],
    ("4.2-n100", partial(ex4_2, 100)),
    ("4.3-l30", partial(ex4_3, 30)),
]
