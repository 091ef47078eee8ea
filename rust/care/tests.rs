use super::*;
use crate::linalg::testing::Rng;

fn opts() -> CareOptions {
    CareOptions::default()
}

#[test]
fn scalar_closed_form() {
    // 2ax − g x² + q = 0 ⇒ x = (a + sqrt(a² + g q))/g.
    for &(a, g, q) in &[
        (1.0, 1.0, 1.0),
        (-2.0, 0.5, 3.0),
        (0.0, 1.0, 1.0),
        (5.0, 1e-3, 1e2),
    ] {
        let s = solve_care(
            &DMatrix::from_element(1, 1, a),
            &DMatrix::from_element(1, 1, g),
            &DMatrix::from_element(1, 1, q),
            &opts(),
        )
        .unwrap();
        let exact = (a + (a * a + g * q).sqrt()) / g;
        assert!(
            (s.x[(0, 0)] - exact).abs() <= 1e-13 * exact.abs().max(1.0),
            "{a} {g} {q}"
        );
        assert!((s.closed_loop_abscissa + (a * a + g * q).sqrt()).abs() < 1e-12 * exact.max(1.0));
    }
}

#[test]
fn random_problems_have_small_residuals_and_stable_closed_loops() {
    let mut rng = Rng::new(5);
    for &n in &[1usize, 2, 3, 5, 10, 30, 80] {
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, (n / 2).max(1));
        let g = &b * b.transpose();
        let q = rng.psd(n, n) + DMatrix::identity(n, n);
        let s = solve_care(&a, &g, &q, &opts()).unwrap();
        assert!(s.residual < 1e-13, "n={n}: residual {}", s.residual);
        assert!(s.closed_loop_abscissa < 0.0);
        let acl = &a - &g * &s.x;
        let ev = acl.complex_eigenvalues();
        assert!(ev.iter().all(|l| l.re < 0.0));
        assert!((&s.x - s.x.transpose()).norm() == 0.0);
        assert!(
            s.x.clone().cholesky().is_some(),
            "X should be positive definite for Q > 0"
        );
    }
}

#[test]
fn newton_polish_keeps_or_lowers_the_residual() {
    let mut rng = Rng::new(9);
    let n = 20;
    let a = rng.matrix(n, n) * 3.0;
    let b = rng.matrix(n, 2);
    let g = &b * b.transpose();
    let q = rng.psd(n, 3);
    let unrefined = CareOptions {
        newton_steps: 0,
        ..opts()
    };
    let plain = solve_care(&a, &g, &q, &unrefined).unwrap();
    let polished = solve_care(&a, &g, &q, &opts()).unwrap();
    // This problem is ill-conditioned (rcond(U11) ≈ 6e-8): the Schur solution is accurate to
    // about eps/rcond, and the polish may move X by that much while lowering the residual.
    let diff = (&polished.x - &plain.x).norm() / plain.x.norm();
    assert!(polished.residual <= plain.residual);
    assert!(
        diff <= 1e3 * f64::EPSILON / plain.rcond,
        "{diff:e} vs rcond {:e}",
        plain.rcond
    );
}

#[test]
fn weighted_form_matches_explicit_g() {
    let mut rng = Rng::new(2);
    let n = 6;
    let a = rng.matrix(n, n);
    let b = rng.matrix(n, 2);
    let r = rng.psd(2, 2) + DMatrix::identity(2, 2);
    let q = rng.psd(n, n);
    let g = &b * r.clone().try_inverse().unwrap() * b.transpose();
    let x1 = solve_care_weighted(&a, &b, &q, Some(&r), &opts())
        .unwrap()
        .x;
    let x2 = solve_care(&a, &g, &q, &opts()).unwrap().x;
    assert!((&x1 - &x2).norm() <= 1e-11 * x2.norm());
}

#[test]
fn imaginary_axis_eigenvalues_are_refused() {
    // Undamped oscillator with Q = 0: its unobservable modes ±i are Hamiltonian eigenvalues.
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, 0.0]);
    let g = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1.0]);
    let q = DMatrix::zeros(2, 2);
    let err = solve_care(&a, &g, &q, &opts()).unwrap_err();
    assert!(matches!(err, Error::NoStabilizingSolution(_)), "{err:?}");
}

#[test]
fn double_axis_eigenvalues_split_by_rounding_are_refused() {
    // CAREX 2.5 at ε = 0: the closed loop would be [[0, −1], [1, 0]]; the Hamiltonian has the
    // double eigenvalues ±i, which rounding splits by ~1e-8 (the √eps effect).
    let a = DMatrix::from_row_slice(2, 2, &[3.0, 1.0, 4.0, 2.0]);
    let g = DMatrix::from_element(2, 2, 1.0);
    let q = DMatrix::from_row_slice(2, 2, &[-11.0, -5.0, -5.0, -2.0]);
    let err = solve_care(&a, &g, &q, &opts()).unwrap_err();
    assert!(matches!(err, Error::NoStabilizingSolution(_)), "{err:?}");
    // Slightly damped (ε = 1e-2) it is solvable and X = [[2, 1], [1, 1]] exactly.
    let e = 1e-2;
    let a = DMatrix::from_row_slice(2, 2, &[3.0 - e, 1.0, 4.0, 2.0 - e]);
    let q = DMatrix::from_row_slice(
        2,
        2,
        &[4.0 * e - 11.0, 2.0 * e - 5.0, 2.0 * e - 5.0, 2.0 * e - 2.0],
    );
    let x = solve_care(&a, &g, &q, &opts()).unwrap().x;
    let exact = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 1.0]);
    assert!((x - exact).norm() < 1e-12);
}

#[test]
fn unstabilisable_data_are_refused() {
    // Unstable mode 1 not reached by G.
    let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
    let g = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1.0]);
    let q = DMatrix::identity(2, 2);
    assert!(solve_care(&a, &g, &q, &opts()).is_err());
}

#[test]
fn bad_input_is_refused() {
    let a = DMatrix::<f64>::identity(2, 2);
    let g = DMatrix::<f64>::identity(3, 3);
    assert!(matches!(
        solve_care(&a, &g, &a, &opts()),
        Err(Error::Shape(_))
    ));
    let mut q = DMatrix::<f64>::identity(2, 2);
    q[(0, 1)] = f64::INFINITY;
    assert!(matches!(
        solve_care(&a, &a, &q, &opts()),
        Err(Error::NonFinite(_))
    ));
    let mut q = DMatrix::<f64>::identity(2, 2);
    q[(0, 1)] = 1.0;
    assert!(matches!(
        solve_care(&a, &a, &q, &opts()),
        Err(Error::InvalidInput(_))
    ));
    let r = DMatrix::from_row_slice(1, 1, &[-1.0]);
    let b = DMatrix::from_row_slice(2, 1, &[1.0, 1.0]);
    assert!(matches!(
        solve_care_weighted(&a, &b, &a, Some(&r), &opts()),
        Err(Error::InvalidInput(_))
    ));
}

/// The audit's `stiff2` seed 55 (tests/test_care_closed_loop.py `_stiff_pairs(55)`, row-major):
/// `A = V blockdiag(pairs) V⁻¹` with `|λ|` over 1e-6 … 1e6, cond V = 1e3, `B` 7 × 2.
const STIFF_A: [f64; 49] = [
    68591186.42107302,
    50751887.20903877,
    65384014.88458555,
    9287004.914553473,
    -1422509.7926350113,
    43359206.04068991,
    -85655138.08572377,
    -21259373.34718408,
    -13665623.367043085,
    -21350403.37372566,
    -2392044.4230554514,
    -4715169.674769028,
    -12033458.295396242,
    31124837.54676414,
    -155030545.95723915,
    -119361039.73420297,
    -145337221.3624837,
    -22086344.100844264,
    14830741.007634304,
    -101167092.14300692,
    183288511.3587769,
    -9674169.628263798,
    -6806931.252380453,
    -9406387.315542419,
    -1227117.8681899505,
    -676369.0361454185,
    -5876376.427780776,
    12859326.705204563,
    -60017672.87026986,
    -46251924.015637316,
    -56242375.701223224,
    -8560549.77187676,
    5849252.327056461,
    -39194641.26825163,
    70861656.43898086,
    -12944632.46034743,
    -11515353.539005535,
    -11321150.81361404,
    -2209087.469534804,
    5106863.6033739345,
    -9501656.084960608,
    11870321.18364219,
    -82085753.19596891,
    -63901641.286045715,
    -76584258.4832952,
    -11859738.928858368,
    9606321.634074382,
    -54044092.07486714,
    95491180.73454808,
];
const STIFF_B: [f64; 14] = [
    2.2790315173560587,
    -3.048200061911762,
    -0.19876169476094024,
    -0.44934782022088116,
    -0.262869613522981,
    -0.008938770759982758,
    0.8122994922769796,
    0.9074460227251121,
    -0.5544838159560753,
    -0.49768021797698964,
    1.4840148808176028,
    1.33114525884219,
    0.26035659878141704,
    -0.7669844599608936,
];

#[test]
fn stiff_subspace_that_is_not_lagrangian_is_solved_on_the_closed_loop() {
    // ‖H‖ ≈ 5e8, slowest closed-loop eigenvalue −0.46: the Hamiltonian route's stable subspace
    // is not Lagrangian (asymmetry 6.7e-8); the closed loop is 1.7e5 bounds from the axis.
    let a = DMatrix::from_row_slice(7, 7, &STIFF_A);
    let b = DMatrix::from_row_slice(7, 2, &STIFF_B);
    let q = DMatrix::identity(7, 7);
    let s = solve_care_factored(&a, &b, &q, &opts()).unwrap();
    assert!(s.rcond.is_nan() && !s.marginal, "{s:?}");
    assert!(s.forward_error <= 1e-15, "{}", s.forward_error);
    assert!((s.closed_loop_abscissa + 0.4617).abs() < 1e-3);
}

#[test]
fn carex_14_stays_refused_as_not_lagrangian() {
    // CAREX 2.8 at ε = 1e-6: closed-loop pair −5e-13 ± i, certified by the closed loop only 137
    // bounds from the axis (below NOT_LAGRANGIAN_MARGIN): marginal.
    let e = 1e-6;
    #[rustfmt::skip]
    let a = DMatrix::from_row_slice(4, 4, &[
        -e, 1.0, 0.0, 0.0, -1.0, -e, 0.0, 0.0, 0.0, 0.0, e, 1.0, 0.0, 0.0, -1.0, e,
    ]);
    let b = DMatrix::from_element(4, 1, 1.0);
    let q = DMatrix::from_element(4, 4, 1.0);
    let err = solve_care_factored(&a, &b, &q, &opts()).unwrap_err();
    assert!(err.to_string().contains("not Lagrangian"), "{err}");
    let marginal = CareOptions {
        accept_marginal: true,
        ..opts()
    };
    assert!(solve_care_factored(&a, &b, &q, &marginal).unwrap().marginal);
}

/// The audit's `scaled/simA seed=30` (`A = D A₀ D⁻¹`) with its state balanced by `A`'s own diagonal
/// scaling: `A` well scaled, `B` rows `2⁻¹²…2²²`, `Q = diag(2^2k)`. Its stabilising solution, from
/// 100-digit Newton–Kleinman (row-major, rounded).
#[rustfmt::skip]
const STATE_SCALED_A: [f64; 16] = [
    -0.018845669551952254, -0.7265047274134814, 0.15869683555872674, 0.3412796287621016,
    0.4146518424509026, 0.29476344745483535, -0.14005852288880735, 0.6964372487808254,
    -0.8302719927683448, 0.12336442368446054, -1.1216931449863272, -0.21553382456193146,
    0.6334178304258002, -0.6626892833006479, -1.3862261906855795, 0.44265850176974236,
];
const STATE_SCALED_B: [f64; 4] = [
    4.951078253141303,
    8805.148888538242,
    -1115033.4255686305,
    0.000285593768244422,
];
const STATE_SCALED_Q: [f64; 4] = [
    0.015625,
    3.725290298461914e-09,
    5.684341886080802e-14,
    16777216.0,
];
#[rustfmt::skip]
const STATE_SCALED_X: [f64; 16] = [
    9921090.518967196, -1245705.569447798, -9792.98271769748, 1317733.8663375315,
    -1245705.569447798, 33164556.439882323, 261886.93251017606, -3780290.3529628348,
    -9792.98271769748, 261886.93251017606, 2068.014146470327, -29846.189240422063,
    1317733.8663375315, -3780290.3529628348, -29846.189240422063, 571194.8402073632,
];

#[test]
fn a_closed_loop_answer_stopped_at_a_newton_floor_is_not_reported_too_accurate() {
    // The closed-loop route (dearer-input start) stops at a floor 3.9e-5 from X* whose first
    // correction is 4.4e-6 of X (the quadratic term dominates); without the quadratic term at the
    // computed correction its estimate was 5.5e-6.
    let a = DMatrix::from_row_slice(4, 4, &STATE_SCALED_A);
    let b = DMatrix::from_column_slice(4, 1, &STATE_SCALED_B);
    let q = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&STATE_SCALED_Q));
    let exact = DMatrix::from_row_slice(4, 4, &STATE_SCALED_X);
    let r = DMatrix::identity(1, 1);
    for r in [None, Some(&r)] {
        let s = solve_care_weighted(&a, &b, &q, r, &opts()).unwrap();
        let err = (&s.x - &exact).norm() / exact.norm();
        assert!(err <= s.forward_error, "{err} > {}", s.forward_error);
    }
}
