"""The standard stochastic model (``Network.from_model``): whitening, singular process noise and
its existence condition, checked against hand-whitened models and scipy's Riccati solver."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.optimize import minimize_scalar

import capalloc_rs as cr
from capalloc_rs.errors import (
    InvalidInputError,
    ShapeError,
    UnexcitedAxisModeError,
)


def _model(seed: int = 0, n: int = 5, m: int = 2, ps: tuple[int, ...] = (1, 2, 1)):
    """A coupled stable model with singular Q (m < n), non-diagonal W and R_i, C_i p_i × n."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, n)) / np.sqrt(n) - 1.5 * np.eye(n)
    b_w = rng.standard_normal((n, m))
    x = rng.standard_normal((m, m))
    w = x @ x.T + 0.1 * np.eye(m)
    c = [rng.standard_normal((p, n)) for p in ps]
    r = []
    for p in ps:
        y = rng.standard_normal((p, p))
        r.append(y @ y.T + 0.5 * np.eye(p))
    return a, b_w, w, c, r


def _scipy_sigma(a, b_w, w, c, r, rates):
    """The filter Riccati solution of the standard model by scipy: sensor i at rate r_i has noise
    intensity R_i / r_i."""
    ctot = np.vstack(c)
    rtot = sla.block_diag(*[ri / k for ri, k in zip(r, rates, strict=True)])
    return sla.solve_continuous_are(a.T, ctot.T, b_w @ w @ b_w.T, rtot)


def test_whitening_equals_the_hand_whitened_paper_model() -> None:
    a, b_w, w, c, r = _model()
    net = cr.Network.from_model(a, b_w, w, c, r)
    g = b_w @ np.real(sla.sqrtm(w))
    sensors = [ci.T @ np.linalg.inv(np.real(sla.sqrtm(ri))) for ci, ri in zip(c, r, strict=True)]
    hand = cr.Network(a, g, sensors)
    q = b_w @ w @ b_w.T
    assert np.max(np.abs(net.q - q)) <= 1e-14 * np.max(np.abs(q))
    for got, ci, ri in zip(net.sensors, c, r, strict=True):
        info = ci.T @ np.linalg.solve(ri, ci)
        assert np.max(np.abs(got @ got.T - info)) <= 1e-14 * np.max(np.abs(info))
    for rates in (np.array([1.0, 2.0, 3.0]), np.array([0.1, 50.0, 7.0])):
        assert net.cost(rates) == pytest.approx(hand.cost(rates), rel=1e-14)
        np.testing.assert_allclose(net.gradient(rates), hand.gradient(rates), rtol=1e-12)


def test_cost_against_scipy_with_singular_q() -> None:
    a, b_w, w, c, r = _model(seed=1, n=6, m=1)
    net = cr.Network.from_model(a, b_w, w, c, r)
    assert np.linalg.matrix_rank(net.q) == 1
    for rates in (np.array([1.0, 1.0, 1.0]), np.array([0.01, 3.0, 200.0])):
        sigma = _scipy_sigma(a, b_w, w, c, r, rates)
        assert net.cost(rates) == pytest.approx(np.trace(sigma), rel=1e-10)
        np.testing.assert_allclose(net.at(rates).sigma, sigma, rtol=1e-8, atol=1e-12)


def test_outputs_are_rows_of_c() -> None:
    """A square C is read as p × n (y = C x), never transposed."""
    a = np.array([[-1.0, 2.0], [0.0, -0.5]])
    c = np.array([[1.0, 3.0], [0.0, 1.0]])
    net = cr.Network.from_model(a, np.eye(2), np.eye(2), [c], [np.eye(2)])
    want = np.trace(_scipy_sigma(a, np.eye(2), np.eye(2), [c], [np.eye(2)], [2.0]))
    wrong = np.trace(_scipy_sigma(a, np.eye(2), np.eye(2), [c.T], [np.eye(2)], [2.0]))
    assert net.cost([2.0]) == pytest.approx(want, rel=1e-12)
    assert abs(want - wrong) > 1e-3 * want


def test_scalar_shortcuts_and_vectors() -> None:
    a, b_w, _, c, _ = _model(seed=2, m=1, ps=(1, 1))
    one = cr.Network.from_model(a, b_w[:, 0], 4.0, [c[0][0], c[1][0]], 0.25)
    full = cr.Network.from_model(a, b_w, [[4.0]], [c[0], c[1]], [[[0.25]], np.array([[0.25]])])
    rates = np.array([2.0, 5.0])
    assert one.cost(rates) == full.cost(rates)
    per_sensor = cr.Network.from_model(a, b_w, 4.0, c, 0.25, r_min=[2.0, 2.0], costs=[1, 1])
    assert per_sensor.r_min == 2.0


def test_noise_free_mode_on_the_axis_is_refused_with_its_mode() -> None:
    a = np.array([[0.0, 0.0], [0.0, -1.0]])  # an integrator and a stable mode
    b_w = np.array([[0.0], [1.0]])  # noise only on the stable mode
    with pytest.raises(UnexcitedAxisModeError, match="λ = 0"):
        cr.Network.from_model(a, b_w, 1.0, [[1.0, 1.0]], 1.0)
    with pytest.raises(UnexcitedAxisModeError):
        cr.Network(a, b_w, [np.array([1.0, 1.0])])
    # the same integrator with noise: a stabilising solution exists (scipy agrees)
    net = cr.Network.from_model(a, np.array([[1.0], [0.0]]), 1.0, [[1.0, 1.0]], 1.0)
    sigma = _scipy_sigma(
        a, np.array([[1.0], [0.0]]), np.eye(1), [np.array([[1.0, 1.0]])], [np.eye(1)], [3.0]
    )
    assert net.cost([3.0]) == pytest.approx(np.trace(sigma), rel=1e-10)
    report = net.check()
    assert report.axis_modes_excited and report.axis_excitation_margin > 1e-3
    assert report.to_dict()["axis_modes_excited"] is True


def test_noise_free_stable_or_unstable_modes_are_fine() -> None:
    """Only modes on the axis need noise: a noise-free stable mode has zero error, a noise-free
    unstable one the stabilising solution scipy finds."""
    a = np.diag([-2.0, 1.0, -0.5])
    b_w = np.array([[0.0], [0.0], [1.0]])
    c = [np.array([[1.0, 1.0, 0.0]]), np.array([[0.0, 1.0, 1.0]])]
    net = cr.Network.from_model(a, b_w, 1.0, c, [1.0, 2.0])
    rates = np.array([1.5, 0.5])
    sigma = _scipy_sigma(a, b_w, np.eye(1), c, [np.eye(1), 2 * np.eye(1)], rates)
    assert net.cost(rates) == pytest.approx(np.trace(sigma), rel=1e-10)


def test_optimal_allocation_with_singular_q_against_a_scalar_search() -> None:
    a, b_w, w, c, r = _model(seed=3, n=4, m=1, ps=(1, 1))
    net = cr.Network.from_model(a, b_w, w, c, r, r_min=0.5)
    total = 6.0

    def eta(x: float) -> float:
        rates = np.array([x, total - x])
        return float(np.trace(_scipy_sigma(a, b_w, w, c, r, rates)))

    ref = minimize_scalar(eta, bounds=(0.5, total - 0.5), method="bounded", options={"xatol": 1e-9})
    got = cr.optimal_allocation(net, total)
    assert got.eta == pytest.approx(eta(got.r[0]), rel=1e-10)  # its η is scipy's at its rates
    assert got.eta <= ref.fun * (1 + 1e-12)  # no worse than the scalar search
    assert got.gap <= 1e-10 * got.eta
    assert got.r[0] == pytest.approx(ref.x, abs=1e-3)


def test_sampled_cost_tends_to_eta_with_singular_q() -> None:
    """Corollary 1 for a model with singular Q: η̄(τ) → η(counts) at first order as τ → 0."""
    a, b_w, w, c, r = _model(seed=4, n=4, m=1, ps=(1, 1))
    net = cr.Network.from_model(a, b_w, w, c, r)
    limit = net.cost(np.array([1.0, 2.0]))
    errs = [abs(cr.sampled_cost(net, tau, [0, 1, 1]) - limit) for tau in (0.01, 0.001)]
    assert 5 < errs[0] / errs[1] < 20


def test_rectangular_noise_round_trips_through_model_files(tmp_path) -> None:
    a, b_w, w, c, r = _model(seed=5)
    net = cr.Network.from_model(a, b_w, w, c, r)
    for fmt in ("toml", "json", "npz"):
        path = tmp_path / f"m.{fmt}"
        net.save(path)
        back = cr.Network.load(path)
        assert back.g.shape == (5, 2)
        assert back.cost([1.0, 2.0, 3.0]) == pytest.approx(net.cost([1.0, 2.0, 3.0]), rel=1e-14)


def test_rectangular_noise_blocks() -> None:
    a1 = np.array([[0.0, 1.0], [-1.0, -0.2]])
    net = cr.Network.from_blocks(
        [a1, a1], [[0.0, 1.0], np.array([[0.0, 1.0], [1.0, 0.0]])], [[1.0, 0.0], [1.0, 0.0]]
    )
    assert net.g.shape == (4, 3)
    np.testing.assert_array_equal(net.q[:2, :2], [[0.0, 0.0], [0.0, 1.0]])


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"W": [[1.0, 0.5], [0.0, 1.0]]}, InvalidInputError, "W must be symmetric"),
        ({"W": [[1.0, 0.0], [0.0, -1.0]]}, InvalidInputError, "W must be positive semidefinite"),
        ({"W": np.eye(3)}, ShapeError, "W must be 2×2"),
        ({"B_w": np.ones((4, 2))}, ShapeError, "B_w must be 5×m"),
        (
            {"R": [1.0, [[1.0, 2.0], [2.0, 1.0]], 1.0]},
            InvalidInputError,
            r"R\[1\] must be positive definite",
        ),
        ({"R": [1.0, 1.0]}, ShapeError, "R must have one entry per sensor"),
        ({"R": [1.0, np.eye(3), 1.0]}, ShapeError, r"R\[1\] must be 2×2"),
        ({"C": np.ones((3, 5))}, InvalidInputError, "C must be a list"),
        ({"C": [np.ones((1, 4))] * 3}, ShapeError, r"C\[0\] must be p×5"),
        ({"C": []}, ShapeError, "C must name at least one sensor"),
        ({"costs": [1.0, 0.0, 1.0]}, InvalidInputError, r"costs\[1\] must be positive"),
        ({"costs": "2"}, InvalidInputError, "costs"),
        ({"r_max": 1.0}, InvalidInputError, r"r_max\[0\] = 1 must exceed"),
        ({"weight": -np.eye(5)}, cr.errors.InputError, "weight M must be positive semidefinite"),
        ({"weight": np.eye(4)}, ShapeError, "weight must be 5×5"),
        ({"r_min": [1.0, 2.0, -0.5]}, InvalidInputError, r"r_min\[2\] must be non-negative"),
        ({"r_min": [1.0, 2.0]}, ShapeError, "r_min must be a scalar or have one entry per sensor"),
        ({"r_min": -1.0}, InvalidInputError, "r_min"),
    ],
)
def test_bad_input_names_the_argument(kwargs, error, match) -> None:
    a, b_w, w, c, r = _model()
    args = {"A": a, "B_w": b_w, "W": w, "C": c, "R": r}
    extra = {k: v for k, v in kwargs.items() if k not in args}
    args.update({k: v for k, v in kwargs.items() if k in args})
    if kwargs.get("W") is not None and np.shape(kwargs["W"]) == (2, 2):
        args["B_w"] = b_w
    with pytest.raises(error, match=match):
        cr.Network.from_model(args["A"], args["B_w"], args["W"], args["C"], args["R"], **extra)


def test_paper_defaults_are_accepted() -> None:
    a, b_w, w, c, r = _model()
    base = cr.Network.from_model(a, b_w, w, c, r)
    same = cr.Network.from_model(
        a, b_w, w, c, r, costs=1.0, r_max=np.inf, weight=np.eye(5), r_min=[1.0, 1.0, 1.0]
    )
    assert same == base


def test_monte_carlo_of_a_singular_noise_model_contains_the_prediction() -> None:
    a, b_w, w, c, r = _model(seed=6, n=4, m=1, ps=(1, 1))
    net = cr.Network.from_model(a, b_w, w, c, r)
    mc = cr.simulate(net, 0.3, [0, 1, 1], periods=300, seed=11, runs=48, level=0.999)
    assert mc.contains(cr.sampled_cost(net, 0.3, [0, 1, 1]))


def test_filtration_integer_counts_and_schedules_run_on_singular_noise() -> None:
    """The methods above the cost need nothing of Q but the cost: each result is checked against
    the plain optimum (its η at the continuous optimum, a schedule no worse than round robin)."""
    a, b_w, w, c, r = _model(seed=3, n=4, m=1, ps=(1, 1, 1))
    net = cr.Network.from_model(a, b_w, w, c, r)
    f = cr.filtration(net, 6.0, progress=False)
    opt = cr.optimal_allocation(net, 3 * net.r_min + 6.0)
    np.testing.assert_allclose(f.allocation(6.0), opt.r - net.r_min, atol=1e-8)
    ints = cr.integer_allocation(net, 9)
    assert ints.eta >= opt.eta - 1e-12 * opt.eta
    best = cr.best_schedule(net, 0.2, 9, progress=False)
    assert best.eta_bar <= cr.sampled_cost(net, 0.2, cr.round_robin_schedule(net, 9)) * (1 + 1e-12)


def _toml(text: str, tmp_path) -> cr.Network:
    path = tmp_path / "m.toml"
    path.write_text(text)
    return cr.Network.load(path)


def test_model_files_take_the_standard_model(tmp_path) -> None:
    """B_w/W and C/R in a block file give the network whitened by hand (from_blocks)."""
    net = _toml(
        """
        eps = 0.1
        [[subsystems]]
        A = [[0.0, 1.0], [-2.0, -0.3]]
        B_w = [0.0, 1.0]
        W = [[4.0]]
        C = [1.0, 0.0]
        R = [[0.25]]
        [[subsystems]]
        A = [[-1.0]]
        G = [[1.0]]
        C = [[2.0], [1.0]]
        R = [[1.0, 0.5], [0.5, 1.0]]
        [[couplings]]
        i = 0
        j = 1
        A = [[1.0], [1.0]]
        """,
        tmp_path,
    )
    r2 = np.array([[1.0, 0.5], [0.5, 1.0]])
    c2 = np.array([[2.0], [1.0]]).T @ np.linalg.inv(np.real(sla.sqrtm(r2)))
    hand = cr.Network.from_blocks(
        [np.array([[0.0, 1.0], [-2.0, -0.3]]), np.array([[-1.0]])],
        [np.array([[0.0], [2.0]]), np.array([[1.0]])],
        [np.array([[2.0], [0.0]]), c2],
        couplings={(0, 1): np.array([[1.0], [1.0]])},
        eps=0.1,
    )
    rates = np.array([1.0, 3.0])
    assert net.cost(rates) == pytest.approx(hand.cost(rates), rel=1e-14)


def test_general_model_file_with_b_w_and_c_rows(tmp_path) -> None:
    a, b_w, w, c, r = _model(seed=7, n=3, m=1, ps=(1, 2))

    def rows(x):
        return (
            "[" + ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in x) + "]"
        )

    text = f"A = {rows(a)}\nB_w = {rows(b_w)}\nW = {rows(w)}\n" + "".join(
        f"[[sensors]]\nC = {rows(ci)}\nR = {rows(ri)}\n" for ci, ri in zip(c, r, strict=True)
    )
    net = _toml(text, tmp_path)
    ref = cr.Network.from_model(a, b_w, w, c, r)
    assert net.cost([1.0, 2.0]) == pytest.approx(ref.cost([1.0, 2.0]), rel=1e-14)


@pytest.mark.parametrize(
    ("table", "match"),
    [
        ("A = [[-1.0]]\nG = [[1.0]]\nB_w = [[1.0]]\nc = [1.0]", "either as G or as B_w"),
        ("A = [[-1.0]]\nc = [1.0]", "either as G or as B_w"),
        ("A = [[-1.0]]\nG = [[1.0]]\nc = [1.0]\nC = [1.0]", "either as c"),
        ("A = [[-1.0]]\nG = [[1.0]]\nc = [1.0]\nR = [[1.0]]", "either as c"),
        (
            "A = [[-1.0]]\nB_w = [[1.0]]\nW = [[-1.0]]\nc = [1.0]",
            r"subsystems\[0\]\.W must be positive",
        ),
        (
            "A = [[-1.0]]\nG = [[1.0]]\nC = [1.0]\nR = [[0.0]]",
            r"subsystems\[0\]\.R must be positive definite",
        ),
        ("A = [[-1.0]]\nG = [[1.0]]\nC = [1.0, 2.0]", r"subsystems\[0\]\.C must be p×1"),
        ("A = [[0.0]]\nB_w = [[0.0]]\nC = [1.0]", "imaginary axis"),
    ],
)
def test_bad_standard_model_tables_name_the_field(table, match, tmp_path) -> None:
    with pytest.raises(cr.errors.InputError, match=match):
        _toml("[[subsystems]]\n" + table, tmp_path)


def test_from_statespace_with_noise_intensity_and_sample_noise() -> None:
    """python-control style systems with explicit W (through B) and R equal from_model."""
    from types import SimpleNamespace

    a1 = np.array([[0.0, 1.0], [-2.0, -0.3]])
    b1 = np.array([[0.0], [1.0]])
    c1 = np.array([[1.0, 0.0]])
    a2 = np.array([[-1.0]])
    b2 = np.array([[1.0, 0.5]])
    c2 = np.array([[2.0], [1.0]])
    r2 = np.array([[1.0, 0.5], [0.5, 1.0]])
    sys1 = SimpleNamespace(A=a1, B=b1, C=c1, D=np.zeros((1, 1)), dt=0)
    sys2 = SimpleNamespace(A=a2, B=b2, C=c2, D=np.zeros((2, 2)), dt=0)
    net = cr.Network.from_statespace([sys1, sys2], w=[4.0, np.eye(2)], r=[0.25, r2])
    a = sla.block_diag(a1, a2)
    b_w = sla.block_diag(b1, b2)
    w = sla.block_diag(4.0 * np.eye(1), np.eye(2))
    c = [np.hstack([c1, np.zeros((1, 1))]), np.hstack([np.zeros((2, 2)), c2])]
    ref = cr.Network.from_model(a, b_w, w, c, [0.25, r2])
    assert net.cost([1.0, 2.0]) == pytest.approx(ref.cost([1.0, 2.0]), rel=1e-14)
    with pytest.raises(InvalidInputError, match="either as g_blocks"):
        cr.Network.from_statespace([sys1, sys2])
    with pytest.raises(InvalidInputError, match="either as g_blocks"):
        cr.Network.from_statespace([sys1, sys2], [np.eye(2), np.eye(1)], w=1.0)
    with pytest.raises(InvalidInputError, match="w must be a scalar or a list"):
        cr.Network.from_statespace([sys1, sys2], w=[1.0])
    with pytest.raises(InvalidInputError, match=r"r\[1\] must be positive definite"):
        cr.Network.from_statespace([sys1, sys2], w=1.0, r=[1.0, -r2])


def test_from_statespace_accepts_python_control_systems() -> None:
    control = pytest.importorskip("control")
    a = np.array([[0.0, 1.0], [-2.0, -0.3]])
    b = np.array([[0.0], [1.0]])
    c = np.array([[1.0, 0.0]])
    net = cr.Network.from_statespace(control.ss(a, b, c, 0), w=3.0, r=0.5)
    ref = cr.Network.from_model(a, b, 3.0, [c], [0.5])
    assert net.cost([2.0]) == pytest.approx(ref.cost([2.0]), rel=1e-14)
