//! Tests of the generalised CARE route.

use super::*;
use crate::care::solve_care_weighted;
use crate::linalg::testing::Rng;

fn opts() -> CareOptions {
    CareOptions::default()
}

/// The residual of the original equation, computed naively with explicit products.
fn naive_residual(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: &DMatrix<f64>,
    e: &DMatrix<f64>,
    s: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    let c = e.transpose() * x * b + s;
    let rinv = r.clone().try_inverse().unwrap();
    let f = a.transpose() * x * e + e.transpose() * x * a - &c * rinv * c.transpose() + q;
    f.norm() / (q.norm() + 2.0 * (a.transpose() * x * e).norm() + (&c * c.transpose()).norm())
}

#[test]
fn identity_e_and_zero_s_reduce_to_the_standard_equation() {
    let mut rng = Rng::new(3);
    let n = 5;
    let a = rng.matrix(n, n);
    let b = rng.matrix(n, 2);
    let q = rng.psd(n, n) + DMatrix::identity(n, n);
    let r = rng.psd(2, 2) + DMatrix::identity(2, 2);
    let x0 = solve_care_weighted(&a, &b, &q, Some(&r), &opts())
        .unwrap()
        .x;
    let e = DMatrix::identity(n, n);
    let s = DMatrix::zeros(n, 2);
    let x1 = solve_care_generalized(&a, &b, &q, Some(&r), Some(&e), Some(&s), &opts())
        .unwrap()
        .x;
    assert!((&x1 - &x0).norm() <= 1e-12 * x0.norm());
}

#[test]
fn random_generalized_problems_with_cross_terms_are_solved_to_small_residuals() {
    let mut rng = Rng::new(11);
    for &n in &[1usize, 2, 3, 6, 12] {
        let m = (n / 2).max(1);
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, m);
        let e = rng.matrix(n, n) + DMatrix::identity(n, n) * 3.0;
        let r = rng.psd(m, m) + DMatrix::identity(m, m);
        let s = rng.matrix(n, m) * 0.3;
        // Q ≥ S R⁻¹ Sᵀ keeps the problem well posed.
        let q = rng.psd(n, n)
            + DMatrix::identity(n, n)
            + &s * r.clone().try_inverse().unwrap() * s.transpose();
        let sol =
            solve_care_generalized(&a, &b, &q, Some(&r), Some(&e), Some(&s), &opts()).unwrap();
        let res = naive_residual(&a, &b, &q, &r, &e, &s, &sol.x);
        assert!(res < 1e-13, "n={n}: residual {res:e}");
        assert!(sol.residual < 1e-14, "n={n}: {:e}", sol.residual);
        // The closed-loop pencil (A − BK, E) is stable.
        let k = r.clone().try_inverse().unwrap() * (b.transpose() * &sol.x * &e + s.transpose());
        let acl = (&a - &b * k) * e.clone().try_inverse().unwrap();
        assert!(
            acl.complex_eigenvalues().iter().all(|l| l.re < 0.0),
            "n={n}"
        );
    }
}

#[test]
fn indefinite_r_is_accepted_when_a_stabilising_solution_exists() {
    // Scalar: 2ax − x²/r + q = 0 with r < 0: x = r(a − sqrt(a² + q/r))... choose a = −2,
    // q = 1, r = −1: 2(−2)x + x² + 1 = 0 ⇒ x = 2 − √3 (stabilising: a − x/r = −2 + x < 0).
    let a = DMatrix::from_element(1, 1, -2.0);
    let b = DMatrix::from_element(1, 1, 1.0);
    let q = DMatrix::from_element(1, 1, 1.0);
    let r = DMatrix::from_element(1, 1, -1.0);
    let s = DMatrix::zeros(1, 1);
    let x = solve_care_generalized(&a, &b, &q, Some(&r), None, Some(&s), &opts())
        .unwrap()
        .x;
    assert!((x[(0, 0)] - (2.0 - 3f64.sqrt())).abs() < 1e-15);
}

#[test]
fn an_ill_conditioned_e_gives_an_accurate_answer_or_an_error_naming_e() {
    let mut rng = Rng::new(17);
    let n = 6;
    let u = rng.matrix(n, n).qr().q();
    let v = rng.matrix(n, n).qr().q();
    let a = rng.matrix(n, n);
    let b = rng.matrix(n, 2);
    let q = DMatrix::identity(n, n);
    let r = DMatrix::identity(2, 2);
    let s = DMatrix::zeros(n, 2);
    for &k in &[2.0, 6.0, 8.0, 10.0, 14.0] {
        // σ(E) from 1 down to 10^−k: nonsingular by scipy's test, κ(E) = 10^k.
        let d = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                10f64.powf(-k * i as f64 / (n - 1) as f64)
            } else {
                0.0
            }
        });
        let e = &u * d * v.transpose();
        match solve_care_generalized(&a, &b, &q, Some(&r), Some(&e), None, &opts()) {
            Ok(sol) => {
                // (A residual formed in working precision has a rounding floor ~eps·κ(E): X is
                // large where EᵀX is not.)
                let res = naive_residual(&a, &b, &q, &r, &e, &s, &sol.x);
                assert!(res <= 1e-9 || k > 6.0, "κ(E) = 1e{k}: residual {res:e}");
                assert!(sol.forward_error.is_finite());
                // Refined on the pencil with compensated residuals: a few ulps up to κ(E) = 1e8
                // (refused before at 1e8).
                if k <= 8.0 {
                    assert!(
                        sol.forward_error <= 1e-12,
                        "κ(E) = 1e{k}: {:e}",
                        sol.forward_error
                    );
                }
            }
            Err(Error::SingularProblem(m)) => {
                assert!(k >= 10.0, "κ(E) = 1e{k} refused: {m}");
                assert!(m.starts_with("E is too ill-conditioned"), "{m}");
            }
            Err(other) => panic!("κ(E) = 1e{k}: unexpected {other:?}"),
        }
    }
}

#[test]
fn singular_r_and_e_are_refused_as_input_errors() {
    let i2 = DMatrix::<f64>::identity(2, 2);
    let sing = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
    assert!(matches!(
        solve_care_generalized(&i2, &i2, &i2, Some(&sing), None, None, &opts()),
        Err(Error::InvalidInput(m)) if m.contains('R')
    ));
    assert!(matches!(
        solve_care_generalized(&i2, &i2, &i2, None, Some(&sing), None, &opts()),
        Err(Error::InvalidInput(m)) if m.contains('E')
    ));
    let s_bad = DMatrix::<f64>::zeros(3, 2);
    assert!(matches!(
        solve_care_generalized(&i2, &i2, &i2, None, None, Some(&s_bad), &opts()),
        Err(Error::Shape(_))
    ));
}
