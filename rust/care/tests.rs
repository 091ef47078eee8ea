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
