"""capalloc_rs.linalg against scipy, closed forms and residuals; error handling."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from conftest import random_care
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import capalloc_rs.linalg as cl
from capalloc_rs import errors

EPS = np.finfo(float).eps


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300))


def care_residual(a, b, q, r, x):
    g = b @ np.linalg.solve(r, b.T)
    res = a.T @ x + x @ a - x @ g @ x + q
    nx = np.linalg.norm(x)
    return np.linalg.norm(res) / (
        np.linalg.norm(q) + 2 * np.linalg.norm(a) * nx + np.linalg.norm(g) * nx**2
    )


# --------------------------------------------------------------------------------------- CARE


@pytest.mark.parametrize("n", [1, 2, 3, 5, 10, 30, 64, 120, 200])
def test_care_agrees_with_scipy(rng, n):
    a, b, q, r = random_care(rng, n)
    res = cl.care(a, b, q, r)
    ref = sla.solve_continuous_are(a, b, q, r)
    assert rel(res.x, ref) < 1e-9
    # Our residual is computed independently here and reported by the solver.
    assert care_residual(a, b, q, r, res.x) < 1e-12
    assert res.residual < 1e-12
    assert res.residual == pytest.approx(care_residual(a, b, q, r, res.x), rel=1e-3, abs=1e-15)
    g = b @ np.linalg.solve(r, b.T)
    eig = np.linalg.eigvals(a - g @ res.x)
    assert np.max(eig.real) < 0
    assert res.closed_loop_abscissa == pytest.approx(np.max(eig.real), rel=1e-6)
    assert 0 < res.rcond <= 1
    np.testing.assert_array_equal(res.x, res.x.T)


def test_solve_continuous_are_is_a_drop_in(rng):
    a, b, q, r = random_care(rng, 7, 3)
    np.testing.assert_allclose(
        cl.solve_continuous_are(a, b, q, r), sla.solve_continuous_are(a, b, q, r), rtol=1e-10
    )


def test_care_scalar_closed_form():
    # 2ax − x²b²/r + q = 0 ⇒ x = r(a + sqrt(a² + b²q/r))/b².
    for a, b, q, r in [(1.0, 1.0, 1.0, 1.0), (-3.0, 2.0, 0.5, 4.0), (10.0, 0.1, 1e3, 1.0)]:
        x = cl.care([[a]], [[b]], [[q]], [[r]]).x[0, 0]
        exact = r * (a + np.sqrt(a * a + b * b * q / r)) / (b * b)
        assert x == pytest.approx(exact, rel=1e-13)


def test_care_r_none_means_identity(rng):
    a, b, q, _ = random_care(rng, 5, 2)
    np.testing.assert_allclose(cl.care(a, b, q).x, cl.care(a, b, q, np.eye(2)).x, rtol=1e-13)


def test_care_newton_polish_does_not_hurt(rng):
    a, b, q, r = random_care(rng, 25)
    plain = cl.care(a, b, q, r)
    polished = cl.care(a, b, q, r, newton_steps=2)
    assert polished.residual <= plain.residual
    assert rel(polished.x, plain.x) < 1e-10


def test_care_badly_scaled_needs_scaling():
    # Q ~ 1e12, G ~ 1e-12: scaling makes the Hamiltonian balanced; the answer is the scalar
    # closed form on each decoupled mode.
    a = np.diag([-1.0, 2.0])
    b = np.diag([1e-6, 1e-6])
    q = np.diag([1e12, 1e12])
    res = cl.care(a, b, q, np.eye(2))
    g = 1e-12
    exact = [(ai + np.sqrt(ai * ai + g * 1e12)) / g for ai in (-1.0, 2.0)]
    np.testing.assert_allclose(np.diag(res.x), exact, rtol=1e-13)
    # The scaling is the power of two nearest sqrt(‖Q‖/‖G‖) = 1e12 (exact in floating point).
    assert res.scaling == 2.0**40
    assert res.forward_error <= 1e-12


def test_care_imaginary_axis_raises():
    # Undamped oscillator, Q = 0: the unobservable modes ±i are Hamiltonian eigenvalues.
    a = np.array([[0.0, 1.0], [-1.0, 0.0]])
    b = np.array([[0.0], [1.0]])
    with pytest.raises(errors.NoStabilizingSolutionError, match="imaginary axis"):
        cl.care(a, b, np.zeros((2, 2)), np.eye(1))
    with pytest.raises(np.linalg.LinAlgError):
        cl.solve_continuous_are(a, b, np.zeros((2, 2)), np.eye(1))


def test_care_unstabilisable_raises():
    a = np.diag([1.0, -1.0])
    b = np.array([[0.0], [1.0]])
    with pytest.raises(np.linalg.LinAlgError):
        cl.care(a, b, np.eye(2), np.eye(1))


@pytest.mark.parametrize(
    "args, exc, pattern",
    [
        ((np.ones((2, 3)), np.ones((2, 1)), np.eye(2), np.eye(1)), errors.ShapeError, "square"),
        ((np.eye(2), np.ones((3, 1)), np.eye(2), np.eye(1)), errors.ShapeError, "B must"),
        ((np.eye(2), np.ones((2, 1)), np.eye(3), np.eye(1)), errors.ShapeError, "Q must"),
        ((np.eye(2), np.ones((2, 1)), np.eye(2), np.eye(2)), errors.ShapeError, "R must"),
        # scipy's np.atleast_2d makes a 1-D a a 1×2 row: not square.
        ((np.ones(2), np.ones((2, 1)), np.eye(2), np.eye(1)), errors.ShapeError, "square"),
        (
            ([[np.nan, 0], [0, 1]], np.ones((2, 1)), np.eye(2), np.eye(1)),
            errors.NonFiniteError,
            "a",
        ),
        ((np.eye(2), [[np.inf], [1]], np.eye(2), np.eye(1)), errors.NonFiniteError, "b"),
        ((np.eye(2), [[np.nan], [1]], np.eye(2), np.eye(1)), errors.NonFiniteError, "b"),
        (
            (np.eye(2), np.ones((2, 1)), [[1, 1], [0, 1]], np.eye(1)),
            errors.InvalidInputError,
            "sym",
        ),
        ((np.eye(2), np.ones((2, 1)), np.eye(2), [[0.0]]), errors.InvalidInputError, "singular"),
        ((np.eye(2) * 1j, np.ones((2, 1)), np.eye(2), np.eye(1)), errors.InvalidInputError, "real"),
        (
            ([["x", 1], [1, 1]], np.ones((2, 1)), np.eye(2), np.eye(1)),
            errors.InvalidInputError,
            "numeric",
        ),
    ],
)
def test_care_bad_input(args, exc, pattern):
    with pytest.raises(exc, match=pattern):
        cl.care(*args)
    assert issubclass(exc, ValueError)


def test_any_memory_layout_is_accepted(rng):
    a, b, q, r = random_care(rng, 6, 2)
    ref = cl.care(a, b, q, r).x
    big = np.zeros((12, 12))
    big[::2, ::2] = a
    strided = big[::2, ::2]
    assert not strided.flags.c_contiguous
    np.testing.assert_array_equal(cl.care(np.asfortranarray(a), b, q, r).x, ref)
    np.testing.assert_array_equal(cl.care(strided, b, q, r).x, ref)
    np.testing.assert_array_equal(
        cl.care(a.astype(np.float32).astype(float), b, q, r).x,
        cl.care(a.astype(np.float32), b, q, r).x,
    )


# --------------------------------------------------------------------------- Lyapunov, Sylvester


@pytest.mark.parametrize("n", [1, 2, 4, 16, 64, 200])
def test_lyapunov_agrees_with_scipy(rng, n):
    a = rng.standard_normal((n, n)) - np.sqrt(n) * np.eye(n)
    q = rng.standard_normal((n, n))
    q = q + q.T
    x = cl.solve_continuous_lyapunov(a, q)
    resid = np.linalg.norm(a @ x + x @ a.T - q) / (
        2 * np.linalg.norm(a) * np.linalg.norm(x) + np.linalg.norm(q)
    )
    assert resid < 1e-13
    assert rel(x, sla.solve_continuous_lyapunov(a, q)) < 1e-9


def test_lyapunov_nonsymmetric_rhs(rng):
    a = rng.standard_normal((9, 9)) - 3 * np.eye(9)
    q = rng.standard_normal((9, 9))
    x = cl.solve_continuous_lyapunov(a, q)
    np.testing.assert_allclose(a @ x + x @ a.T, q, atol=1e-11)


@pytest.mark.parametrize("m, n", [(1, 1), (3, 5), (20, 7), (60, 60)])
def test_sylvester_agrees_with_scipy(rng, m, n):
    a = rng.standard_normal((m, m)) + 2 * np.eye(m)
    b = rng.standard_normal((n, n)) + 2 * np.eye(n)
    q = rng.standard_normal((m, n))
    x = cl.solve_sylvester(a, b, q)
    np.testing.assert_allclose(a @ x + x @ b, q, atol=1e-10 * np.linalg.norm(q))
    assert rel(x, sla.solve_sylvester(a, b, q)) < 1e-9


def test_singular_lyapunov_raises():
    a = np.diag([1.0, -1.0])  # λ1 + λ2 = 0
    with pytest.raises(errors.SingularProblemError):
        cl.solve_continuous_lyapunov(a, np.eye(2))


def test_singular_sylvester_raises(rng):
    a = rng.standard_normal((4, 4))
    with pytest.raises(errors.SingularProblemError):
        cl.solve_sylvester(a, -a, np.eye(4))


def test_lyapunov_shape_errors():
    with pytest.raises(errors.ShapeError):
        cl.solve_continuous_lyapunov(np.eye(2), np.eye(3))
    with pytest.raises(errors.NonFiniteError):
        cl.solve_continuous_lyapunov(np.eye(2), [[np.nan, 0], [0, 1]])


# ------------------------------------------------------------------------------------- Schur


def check_schur(a: np.ndarray, t: np.ndarray, z: np.ndarray) -> None:
    n = a.shape[0]
    scale = max(np.linalg.norm(a), 1e-300)
    assert np.linalg.norm(z @ t @ z.T - a) <= 100 * n * EPS * scale
    assert np.linalg.norm(z.T @ z - np.eye(n)) <= 100 * n * EPS
    assert np.all(np.tril(t, -2) == 0)
    k = 0
    while k < n - 1:  # standardised 2×2 blocks, no two consecutive nonzero subdiagonals
        if t[k + 1, k] != 0:
            assert t[k, k] == t[k + 1, k + 1]
            assert np.sign(t[k, k + 1]) * np.sign(t[k + 1, k]) < 0
            if k + 2 < n:
                assert t[k + 2, k + 1] == 0
            k += 2
        else:
            k += 1


@pytest.mark.parametrize("n", [1, 2, 3, 8, 40, 200])
def test_schur_matches_scipy_spectrum(rng, n):
    a = rng.standard_normal((n, n))
    t, z = cl.schur(a)
    check_schur(a, t, z)
    ours = np.sort_complex(np.linalg.eigvals(t))
    ref = np.sort_complex(np.linalg.eigvals(a))
    np.testing.assert_allclose(ours, ref, atol=1e-9 * max(1, np.abs(ref).max()))


@pytest.mark.parametrize("sort", ["lhp", "rhp", "iuc", "ouc"])
def test_schur_sorted_like_scipy(rng, sort):
    a = rng.standard_normal((30, 30))
    t, z, sdim = cl.schur(a, sort=sort)
    _, _, sdim_ref = sla.schur(a, output="real", sort=sort)
    assert sdim == sdim_ref
    check_schur(a, t, z)
    ev = np.linalg.eigvals(t[:sdim, :sdim]) if sdim else np.array([])
    pred = {
        "lhp": lambda v: v.real < 0,
        "rhp": lambda v: v.real >= 0,
        "iuc": lambda v: np.abs(v) <= 1,
        "ouc": lambda v: np.abs(v) > 1,
    }[sort]
    assert np.all(pred(ev))
    rest = np.linalg.eigvals(t[sdim:, sdim:]) if sdim < 30 else np.array([])
    assert not np.any(pred(rest))


def test_schur_bad_sort():
    with pytest.raises(errors.InvalidInputError, match="sort"):
        cl.schur(np.eye(2), sort="bogus")  # type: ignore[arg-type]


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 9)).map(lambda t: (t[0], t[0])),
        elements=st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False),
    )
)
def test_schur_property(a):
    t, z = cl.schur(a)
    check_schur(a, t, z)


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 9)).map(lambda t: (t[0], t[0])),
        elements=st.floats(-100, 100, allow_nan=False, allow_infinity=False),
    )
)
def test_reorder_property(a):
    t, z, sdim = cl.schur(a, sort="lhp")
    check_schur(a, t, z)
    ev_all = np.linalg.eigvals(a)
    scale = max(1.0, float(np.abs(ev_all).max()))
    tol = 1e-6 * scale
    ev_lead = np.linalg.eigvals(t[:sdim, :sdim]) if sdim else np.array([])
    assert np.all(ev_lead.real < tol)
    if sdim < a.shape[0]:
        assert np.all(np.linalg.eigvals(t[sdim:, sdim:]).real > -tol)


@settings(max_examples=60, deadline=None)
@given(
    hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 8)).map(lambda t: (t[0], t[0])),
        elements=st.floats(-10, 10, allow_nan=False, allow_infinity=False),
    ),
    st.lists(st.booleans(), min_size=8, max_size=8),
)
def test_callable_sort_moves_exactly_the_selected_eigenvalues(a, bits):
    """A callable sort selects eigenvalues by their position; the leading sdim eigenvalues of the
    reordered T are the selected ones (a pair when either member is selected), the rest follow."""
    n = a.shape[0]
    calls: list[tuple[float, float]] = []

    def pick(re: float, im: float) -> bool:
        calls.append((re, im))
        return bits[len(calls) - 1]

    try:
        t, z, sdim = cl.schur(a, sort=pick)
    except errors.ReorderError:
        return  # eigenvalues too close to separate: refused, never a wrong answer
    check_schur(a, t, z)
    assert len(calls) == n
    chosen, want, j = [], 0, 0
    while j < n:  # a pair (+im first, then −im) counts 2 if either member is chosen
        re, im = calls[j]
        size = 2 if im != 0 else 1
        if any(bits[j : j + size]):
            chosen.append((re, abs(im)))
            want += size
        j += size
    assert sdim == want
    scale = max(1.0, float(np.abs(np.linalg.eigvals(a)).max()))
    lead = np.linalg.eigvals(t[:sdim, :sdim]) if sdim else np.array([])
    for lam in lead:
        d = min(abs(lam - complex(re, s * im)) for re, im in chosen for s in (1, -1))
        assert d <= 1e-6 * scale


# -------------------------------------------------------------------------------- expm, Van Loan


@pytest.mark.parametrize("n", [1, 3, 10, 50])
@pytest.mark.parametrize("scale", [1e-3, 1.0, 30.0])
def test_expm_agrees_with_scipy(rng, n, scale):
    a = rng.standard_normal((n, n)) * scale / np.sqrt(n)
    e, ref = cl.expm(a), sla.expm(a)
    # Padé scaling and squaring is accurate in norm (Higham 2005); at scale 30 the entries span
    # ~1e4..1e8, so small entries carry cancellation and only the normwise error is meaningful.
    assert np.linalg.norm(e - ref) <= 1e-13 * np.linalg.norm(ref)
    if scale <= 1.0:
        np.testing.assert_allclose(e, ref, rtol=1e-11, atol=1e-13)


def test_van_loan_identity(rng):
    n = 5
    a = rng.standard_normal((n, n)) - np.eye(n)
    g = rng.standard_normal((n, n))
    q = g @ g.T
    e, h = cl.van_loan(a, q, 0.3)
    np.testing.assert_allclose(e, sla.expm(0.3 * a), rtol=1e-12)
    # d/dt H = A H + H Aᵀ + Q integrated gives A H + H Aᵀ = E Q Eᵀ − Q.
    np.testing.assert_allclose(a @ h + h @ a.T, e @ q @ e.T - q, atol=1e-12)
    np.testing.assert_array_equal(h, h.T)


def test_care_result_to_dict_and_repr() -> None:
    """CareResult serialises like every other result: plain JSON-ready values under its field
    names, the numbers unchanged; its repr is one short line, not the matrix."""
    import dataclasses
    import json

    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    res = cl.care(a, np.array([[0.0], [1.0]]), np.eye(2), np.eye(1))
    d = res.to_dict()
    assert list(d) == [f.name for f in dataclasses.fields(res)]
    back = json.loads(json.dumps(d, allow_nan=False))
    assert np.array_equal(np.array(back["x"]), res.x)
    assert back["forward_error"] == res.forward_error and back["newton_steps"] == res.newton_steps
    r = repr(res)
    assert "\n" not in r and len(r) < 200 and r.startswith("CareResult(n=2")
