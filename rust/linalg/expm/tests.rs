// Why this module is long: the unit tests of expm and Van Loan's integral against closed forms and
// published hard cases, in one place.
use super::*;
use crate::linalg::testing::Rng;
use crate::linalg::van_loan::{van_loan, VanLoan};

const U: f64 = f64::EPSILON / 2.0;

fn rel_err(x: &DMatrix<f64>, exact: &DMatrix<f64>) -> f64 {
    (x - exact).norm() / exact.norm()
}

/// `e^A` through the eigendecomposition of a symmetric `A`.
fn expm_sym_eig(a: &DMatrix<f64>) -> DMatrix<f64> {
    let eig = a.clone().symmetric_eigen();
    let v = &eig.eigenvectors;
    let d = DMatrix::from_diagonal(&eig.eigenvalues.map(f64::exp));
    v * d * v.transpose()
}

fn random_symmetric(rng: &mut Rng, n: usize, norm2: f64) -> DMatrix<f64> {
    let g = rng.matrix(n, n);
    let s = (&g + g.transpose()) * 0.5;
    let nrm = s.clone().symmetric_eigen().eigenvalues.amax();
    s * (norm2 / nrm)
}

#[test]
fn pade_coefficients_follow_the_closed_form() {
    // p_m(x) = Σ_j (2m−j)! m! / ((2m)! j! (m−j)!) x^j, so b_j / b_{j+1} = (j+1)(2m−j)/(m−j).
    let tables: [&[f64]; 5] = [&B3, &B5, &B7, &B9, &B13];
    for b in tables {
        let m = b.len() - 1;
        assert_eq!(b[m], 1.0);
        for j in 0..m {
            let ratio = ((j + 1) * (2 * m - j)) as f64 / (m - j) as f64;
            assert!(
                (b[j] / b[j + 1] - ratio).abs() <= 4.0 * U * ratio,
                "m = {m}, j = {j}"
            );
        }
    }
}

#[test]
fn zero_scalar_and_diagonal() {
    let z = DMatrix::<f64>::zeros(4, 4);
    assert_eq!(expm(&z).unwrap(), DMatrix::identity(4, 4));
    let mut worst = 0.0f64;
    for &x in &[-700.0, -30.0, -1.0, -1e-3, 1e-12, 0.3, 2.0, 20.0, 700.0] {
        let e = expm(&DMatrix::from_element(1, 1, x)).unwrap()[(0, 0)];
        let rel = (e - x.exp()).abs() / x.exp();
        worst = worst.max(rel);
        assert!(rel <= 2.0 * U, "x = {x}: rel {rel:e}");
    }
    eprintln!("scalar: worst rel error = {worst:.2e}");
    let mut rng = Rng::new(1);
    let d: Vec<f64> = (0..7).map(|_| 40.0 * rng.uniform() - 20.0).collect();
    let a = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(d.clone()));
    let e = expm(&a).unwrap();
    let mut worst = 0.0f64;
    for i in 0..7 {
        for j in 0..7 {
            if i != j {
                assert_eq!(e[(i, j)], 0.0);
            }
        }
        let rel = (e[(i, i)] - d[i].exp()).abs() / d[i].exp();
        worst = worst.max(rel);
        assert!(rel <= 2.0 * U, "{i}: {rel:e}");
    }
    eprintln!("diagonal (|d| ≤ 20): worst entrywise rel error = {worst:.2e}");
}

#[test]
fn nilpotent_matches_finite_series() {
    let mut rng = Rng::new(2);
    for &(n, scale) in &[(2usize, 1.0), (6, 1.0), (6, 5.0), (10, 2.0)] {
        let mut a = rng.matrix(n, n) * scale;
        for j in 0..n {
            for i in j..n {
                a[(i, j)] = 0.0;
            }
        }
        let mut exact = DMatrix::identity(n, n);
        let mut term = DMatrix::identity(n, n);
        for k in 1..n {
            term = &term * &a / k as f64;
            exact += &term;
        }
        let rel = rel_err(&expm(&a).unwrap(), &exact);
        eprintln!("nilpotent n = {n}, scale {scale}: rel error {rel:.2e}");
        assert!(rel <= 1e-13, "n = {n}: {rel:e}");
    }
    // A² = 0 with a huge entry: r_m is exact, e^A = I + A.
    let mut a = DMatrix::zeros(2, 2);
    a[(0, 1)] = 1e150;
    let e = expm(&a).unwrap();
    assert_eq!(e, DMatrix::from_row_slice(2, 2, &[1.0, 1e150, 0.0, 1.0]));
}

#[test]
fn rotation_generator_gives_cos_and_sin() {
    for &theta in &[1e-8, 0.1, 1.0, 3.0, 10.0, 100.0, 1000.0] {
        let a = DMatrix::from_row_slice(2, 2, &[0.0, theta, -theta, 0.0]);
        let e = expm(&a).unwrap();
        let (c, s) = (f64::cos(theta), f64::sin(theta));
        let exact = DMatrix::from_row_slice(2, 2, &[c, s, -s, c]);
        let err = (&e - &exact).amax();
        eprintln!(
            "rotation θ = {theta}: max abs error {err:.2e} (= {:.1} θu)",
            err / (theta.max(1.0) * U)
        );
        // cos/sin of θ are themselves only determined to ~θu by the rounding of θ.
        assert!(err <= 16.0 * U * theta.max(1.0), "θ = {theta}: {err:e}");
    }
}

#[test]
fn jordan_blocks() {
    for &lambda in &[-5.0, -0.5, 0.0, 0.5, 3.0] {
        let a = DMatrix::from_row_slice(2, 2, &[lambda, 1.0, 0.0, lambda]);
        let el = f64::exp(lambda);
        let exact = DMatrix::from_row_slice(2, 2, &[el, el, 0.0, el]);
        let rel = rel_err(&expm(&a).unwrap(), &exact);
        assert!(
            rel <= 8.0 * U * f64::max(1.0, lambda.abs()),
            "λ = {lambda}: {rel:e}"
        );
        // 4×4 block: e^λ times the upper Toeplitz matrix of 1/k!.
        let n = 4;
        let a4 = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                lambda
            } else if j == i + 1 {
                1.0
            } else {
                0.0
            }
        });
        let fact = [1.0, 1.0, 2.0, 6.0];
        let exact4 = DMatrix::from_fn(n, n, |i, j| if j >= i { el / fact[j - i] } else { 0.0 });
        let rel4 = rel_err(&expm(&a4).unwrap(), &exact4);
        eprintln!("Jordan λ = {lambda}: rel error 2×2 {rel:.2e}, 4×4 {rel4:.2e}");
        assert!(
            rel4 <= 16.0 * U * f64::max(1.0, lambda.abs()),
            "λ = {lambda}: {rel4:e}"
        );
    }
}

#[test]
fn triangular_matches_parlett_recurrence() {
    // Parlett (from F T = T F): F_ii = e^{t_ii},
    // F_ij = (t_ij (F_jj − F_ii) − Σ_{i<k<j} (F_ik t_kj − t_ik F_kj)) / (t_jj − t_ii),
    // accurate for well separated diagonal entries.
    let mut rng = Rng::new(12);
    let n = 6;
    let diag = [-20.0, -13.0, -6.5, 0.5, 3.0, 7.0];
    let t = DMatrix::from_fn(n, n, |i, j| {
        if i == j {
            diag[i]
        } else if j > i {
            3.0 * rng.normal()
        } else {
            0.0
        }
    });
    let mut f = DMatrix::<f64>::zeros(n, n);
    for i in 0..n {
        f[(i, i)] = t[(i, i)].exp();
    }
    for d in 1..n {
        for i in 0..(n - d) {
            let j = i + d;
            let mut num = t[(i, j)] * (f[(j, j)] - f[(i, i)]);
            for k in (i + 1)..j {
                num -= f[(i, k)] * t[(k, j)] - t[(i, k)] * f[(k, j)];
            }
            f[(i, j)] = num / (t[(j, j)] - t[(i, i)]);
        }
    }
    let (e, plan) = expm_with_plan(&t).unwrap();
    let rel = rel_err(&e, &f);
    eprintln!(
        "upper triangular n = 6 vs Parlett: s = {}, rel error {rel:.2e}",
        plan.squarings
    );
    assert!(rel <= 1e-13, "{rel:e}");
    for i in 0..n {
        assert!(((e[(i, i)] - f[(i, i)]) / f[(i, i)]).abs() <= 2.0 * U);
    }
    let el = expm(&t.transpose()).unwrap();
    assert_eq!(el, e.transpose());
}

#[test]
fn moler_van_loan_example() {
    // A = [[−49, 24], [−64, 31]] = V diag(−1, −17) V⁻¹, V = [[1, 3], [2, 4]]: the Taylor series
    // suffers catastrophic cancellation here (Moler & Van Loan 1978).
    let a = DMatrix::from_row_slice(2, 2, &[-49.0, 24.0, -64.0, 31.0]);
    let (x, y) = (f64::exp(-1.0), f64::exp(-17.0));
    let exact = DMatrix::from_row_slice(
        2,
        2,
        &[
            -2.0 * x + 3.0 * y,
            1.5 * x - 1.5 * y,
            -4.0 * x + 4.0 * y,
            3.0 * x - 2.0 * y,
        ],
    );
    let (e, plan) = expm_with_plan(&a).unwrap();
    let rel = rel_err(&e, &exact);
    eprintln!(
        "Moler–Van Loan example: m = {}, s = {}, rel error {rel:.2e}",
        plan.degree, plan.squarings
    );
    // κ_exp(A) ≈ ‖A‖ ≈ 10², so ~1e-14 is the best one can expect.
    assert!(rel <= 1e-13, "{rel:e}");
}

#[test]
fn commuting_sum_inverse_and_doubling() {
    let mut rng = Rng::new(3);
    for &(n, scale) in &[(3usize, 0.5), (6, 1.0), (12, 2.0), (60, 3.0)] {
        let m = rng.matrix(n, n) * (scale / (n as f64).sqrt());
        let ident = DMatrix::<f64>::identity(n, n);
        // Polynomials in M commute.
        let a = &m + &m * &m * 0.3;
        let b = &ident * 0.7 - &m * 2.0;
        let ea = expm(&a).unwrap();
        let eb = expm(&b).unwrap();
        let eab = expm(&(&a + &b)).unwrap();
        let rel_sum = rel_err(&(&ea * &eb), &eab);
        let ema = expm(&(-&a)).unwrap();
        let inv = (&ea * &ema - &ident).norm() / (ea.norm() * ema.norm());
        let e2a = expm(&(&a * 2.0)).unwrap();
        let rel_dbl = rel_err(&(&ea * &ea), &e2a);
        eprintln!(
            "n = {n}: e^(A+B) vs e^A e^B {rel_sum:.2e}, e^A e^-A − I {inv:.2e}, e^2A vs (e^A)² {rel_dbl:.2e}"
        );
        let tol = 200.0 * n as f64 * U;
        assert!(rel_sum <= tol, "{rel_sum:e}");
        assert!(inv <= tol, "{inv:e}");
        assert!(rel_dbl <= tol, "{rel_dbl:e}");
    }
}

#[test]
fn agrees_with_diagonalisation_for_symmetric_matrices() {
    let mut rng = Rng::new(4);
    for &n in &[2usize, 5, 20, 64] {
        for &norm2 in &[1e-3, 0.2, 1.0, 5.0, 20.0, 50.0] {
            let a = random_symmetric(&mut rng, n, norm2);
            let rel = rel_err(&expm(&a).unwrap(), &expm_sym_eig(&a));
            eprintln!("symmetric n = {n}, ‖A‖₂ = {norm2}: rel error vs eig {rel:.2e}");
            // Both routes err by O(n u ‖A‖) relative to ‖e^A‖.
            assert!(
                rel <= 20.0 * n as f64 * U * norm2.max(1.0),
                "n = {n}, ‖A‖ = {norm2}: {rel:e}"
            );
        }
    }
}

#[test]
fn large_norm_is_stable() {
    let mut rng = Rng::new(5);
    // Symmetric, spectrum in [−1000, 0.5]: 8 or more squarings, no blow-up.
    for &n in &[4usize, 16] {
        let q = rng.orthogonal(n);
        let mut d: Vec<f64> = (0..n).map(|_| -1000.0 * rng.uniform()).collect();
        d[0] = 0.5;
        d[1] = -1000.0;
        let a =
            &q * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(d.clone())) * q.transpose();
        let (e, plan) = expm_with_plan(&a).unwrap();
        let rel = rel_err(&e, &expm_sym_eig(&a));
        eprintln!(
            "‖A‖ ≈ 1e3 symmetric n = {n}: s = {}, rel error {rel:.2e}",
            plan.squarings
        );
        assert!(plan.degree == 13 && plan.squarings >= 8);
        assert!(rel <= 1e-11, "{rel:e}");
    }
    // Non-normal triangular with a large off-diagonal entry: exact divided difference formula.
    for &(a11, a22, a12) in &[
        (-1.0, -2.0, 1e3),
        (-1.0, -2.0, 1e8),
        (0.5, -3.0, -1e4),
        (-10.0, -12.0, 1e6),
    ] {
        let a = DMatrix::from_row_slice(2, 2, &[a11, a12, 0.0, a22]);
        let (e, plan) = expm_with_plan(&a).unwrap();
        let (e1, e2) = (f64::exp(a11), f64::exp(a22));
        let f12 = a12 * (e1 - e2) / (a11 - a22);
        let errs = [
            ((e[(0, 0)] - e1) / e1).abs(),
            ((e[(1, 1)] - e2) / e2).abs(),
            ((e[(0, 1)] - f12) / f12).abs(),
        ];
        let worst = errs.iter().cloned().fold(0.0, f64::max);
        eprintln!(
            "non-normal [[{a11}, {a12:e}], [0, {a22}]]: m = {}, s = {}, entrywise rel error {worst:.2e}",
            plan.degree, plan.squarings
        );
        assert_eq!(e[(1, 0)], 0.0);
        // ‖A‖₁ = |a12| would ask for log₂(|a12|/4.25) squarings; the d_k-based choice needs few.
        assert!(plan.squarings <= 6, "s = {}", plan.squarings);
        assert!(worst <= 1e-13, "{worst:e}");
    }
}

#[test]
fn tiny_norm() {
    let mut rng = Rng::new(6);
    for &scale in &[1e-300, 1e-20, 1e-10, 1e-5] {
        let a = rng.matrix(5, 5) * scale;
        let (e, plan) = expm_with_plan(&a).unwrap();
        let ident = DMatrix::<f64>::identity(5, 5);
        // Taylor: the remainder after A²/2 is O(‖A‖³/6) ≤ 1e-15·(‖A‖/1e-5)³.
        let taylor = &ident + &a + &a * &a * 0.5 + &a * &a * &a / 6.0;
        let rel = rel_err(&e, &taylor);
        eprintln!("‖A‖ ~ {scale:e}: m = {}, rel error {rel:.2e}", plan.degree);
        assert!(rel <= 4.0 * U, "{rel:e}");
        assert!(plan.degree <= 5 && plan.squarings == 0);
        // The correction e^A − I carries A to full relative accuracy for these tiny norms.
        let rel_a = rel_err(&(&e - &ident), &(&taylor - &ident));
        if scale >= 1e-20 {
            assert!(rel_a <= 1e-6, "{rel_a:e}");
        }
    }
}

#[test]
fn overflow_and_underflow() {
    // e^1000 overflows: a clear error, not infinities.
    let a = DMatrix::from_diagonal_element(3, 3, 1000.0);
    assert!(matches!(expm(&a), Err(Error::InvalidInput(m)) if m.contains("overflows")));
    let a = DMatrix::from_element(2, 2, 1e300);
    assert!(matches!(expm(&a), Err(Error::InvalidInput(_))));
    // ‖A‖₁ itself overflows.
    let a = DMatrix::from_element(3, 3, 1e308);
    assert!(matches!(expm(&a), Err(Error::InvalidInput(m)) if m.contains("‖A‖₁")));
    // A huge rotation: e^A is orthogonal but not computable to any accuracy; must not be ∞/NaN.
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1e300, -1e300, 0.0]);
    match expm(&a) {
        Ok(e) => assert!(e.iter().all(|v| v.is_finite())),
        Err(e) => assert!(matches!(e, Error::InvalidInput(_))),
    }
    // e^{−10³⁰⁰ I} underflows to 0, which is the correctly rounded answer.
    let a = DMatrix::from_diagonal_element(2, 2, -1e300);
    let e = expm(&a).unwrap();
    assert!(e.iter().all(|&v| v == 0.0));
    // Just below the overflow threshold.
    let a = DMatrix::from_diagonal_element(2, 2, 700.0);
    let e = expm(&a).unwrap();
    assert!(((e[(0, 0)] - 700f64.exp()) / 700f64.exp()).abs() <= 1e-12);
}

#[test]
fn power_of_two_scaling_is_bounded_for_any_exponent() {
    // The subnormal-Q hang: log₂(∞) cast to i64 is i64::MAX, which the old loop walked down
    // 1000 at a time.
    assert_eq!(ldexp(1.0, i64::MAX), f64::INFINITY);
    assert_eq!(ldexp(1.0, i64::MIN), 0.0);
    assert_eq!(ldexp(3.0, -1075 - 2), 0.0);
    assert_eq!(
        ldexp(f64::MIN_POSITIVE, 1100),
        f64::MIN_POSITIVE * 2f64.powi(1000) * 2f64.powi(100)
    );
    let m = DMatrix::from_element(1, 1, 5e-324);
    assert_eq!(scale_pow2(&m, i64::MAX)[(0, 0)], f64::INFINITY);
    assert_eq!(scale_pow2(&m, 1074)[(0, 0)], 1.0);
    assert_eq!(log2_ratio(0.7, 7e-311), 1030);
    assert_eq!(log2_ratio(1.0, 5e-324), 1074);
}

#[test]
fn van_loan_with_subnormal_tiny_and_huge_q() {
    // A = −I: H = q (1 − e^{−2t})/2 · I exactly; the case is q = 1e-310, t = 0.7.
    let a = -DMatrix::<f64>::identity(2, 2);
    for &q in &[5e-324, 1e-310, 6e-309, 1e-300, 1e-200, 1e200, 1e300] {
        let vl = van_loan(&a, &(DMatrix::identity(2, 2) * q), 0.7).unwrap();
        let exact = q * -f64::exp_m1(-1.4) / 2.0;
        let err = (vl.h[(0, 0)] - exact).abs();
        // Relative accuracy down to the subnormal range, where the spacing is 5e-324.
        assert!(err <= 8.0 * U * exact + 2.0 * 5e-324, "q = {q:e}: {err:e}");
        assert_eq!(vl.h[(0, 1)], 0.0);
        assert!((vl.e[(0, 0)] - (-0.7f64).exp()).abs() <= 4.0 * U);
    }
    // Non-normal A: H is linear in Q, so H(qQ) = q H(Q) (exact scaling by powers of two aside,
    // to rounding; to the subnormal spacing below 2^-1022).
    let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.3, 0.2, -2.0]);
    let q0 = DMatrix::from_row_slice(2, 2, &[1.0, 0.2, 0.2, 0.5]);
    let h0 = van_loan(&a, &q0, 0.7).unwrap().h;
    for &q in &[1e-310, 1e-300, 1e300] {
        let h = van_loan(&a, &(&q0 * q), 0.7).unwrap().h;
        let err = (&h - &h0 * q).amax();
        assert!(
            err <= 1e-14 * q * h0.amax() + 4.0 * 5e-324,
            "q = {q:e}: {err:e}"
        );
    }
}

#[test]
fn bad_input_is_rejected() {
    assert!(matches!(expm(&DMatrix::zeros(2, 3)), Err(Error::Shape(_))));
    assert!(matches!(expm(&DMatrix::zeros(0, 0)), Err(Error::Shape(_))));
    let mut a = DMatrix::<f64>::zeros(2, 2);
    a[(1, 0)] = f64::NAN;
    assert!(matches!(expm(&a), Err(Error::NonFinite(_))));
    a[(1, 0)] = f64::INFINITY;
    assert!(matches!(expm(&a), Err(Error::NonFinite(_))));

    let a = DMatrix::<f64>::identity(2, 2);
    let q = DMatrix::<f64>::identity(2, 2);
    assert!(matches!(
        van_loan(&a, &DMatrix::zeros(3, 3), 1.0),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        van_loan(&DMatrix::zeros(2, 3), &q, 1.0),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        van_loan(&a, &q, -1.0),
        Err(Error::InvalidInput(_))
    ));
    assert!(matches!(
        van_loan(&a, &q, f64::NAN),
        Err(Error::NonFinite(_))
    ));
    assert!(matches!(
        van_loan(&a, &q, f64::INFINITY),
        Err(Error::NonFinite(_))
    ));
    let mut qn = q.clone();
    qn[(0, 1)] = f64::NAN;
    assert!(matches!(van_loan(&a, &qn, 1.0), Err(Error::NonFinite(_))));
    let mut qa = q.clone();
    qa[(0, 1)] = 0.5;
    assert!(
        matches!(van_loan(&a, &qa, 1.0), Err(Error::InvalidInput(m)) if m.contains("symmetric"))
    );
    let big = DMatrix::from_diagonal_element(2, 2, 1000.0);
    assert!(matches!(
        van_loan(&big, &q, 1.0),
        Err(Error::InvalidInput(_))
    ));
    // ‖Q‖₁ overflows although every entry is finite.
    let qbig = DMatrix::from_element(2, 2, 1e308);
    assert!(matches!(van_loan(&a, &qbig, 1.0), Err(Error::InvalidInput(m)) if m.contains("‖Q‖₁")));
    // H itself overflows: Q (e^{2t} − 1)/2 with Q = 1e300, t = 10.
    let q300 = DMatrix::from_diagonal_element(2, 2, 1e300);
    assert!(matches!(
        van_loan(&a, &q300, 10.0),
        Err(Error::InvalidInput(_))
    ));
    // … while a huge but representable H is computed: A = 0 gives H = Q t exactly.
    let vl = van_loan(&DMatrix::zeros(2, 2), &q300, 10.0).unwrap();
    assert_eq!(vl.h[(0, 0)], 1e301);
}

/// Relative residual of the Lyapunov identity `A H + H Aᵀ = E Q Eᵀ − Q` (exact for Van Loan's H).
fn lyapunov_residual(a: &DMatrix<f64>, q: &DMatrix<f64>, vl: &VanLoan) -> f64 {
    let (e, h) = (&vl.e, &vl.h);
    let lhs = a * h + h * a.transpose();
    let rhs = e * q * e.transpose() - q;
    let scale = 2.0 * a.norm() * h.norm() + e.norm().powi(2) * q.norm() + q.norm();
    (lhs - rhs).norm() / scale
}

/// `∫₀ᵗ e^{As} Q e^{Aᵀs} ds` by composite 5-point Gauss–Legendre quadrature.
fn van_loan_quadrature(a: &DMatrix<f64>, q: &DMatrix<f64>, t: f64, panels: usize) -> DMatrix<f64> {
    let nodes = [
        0.0,
        -0.538_469_310_105_683_1,
        0.538_469_310_105_683_1,
        -0.906_179_845_938_664,
        0.906_179_845_938_664,
    ];
    let weights = [
        0.568_888_888_888_888_9,
        0.478_628_670_499_366_5,
        0.478_628_670_499_366_5,
        0.236_926_885_056_189_1,
        0.236_926_885_056_189_1,
    ];
    let n = a.nrows();
    let h = t / panels as f64;
    let mut sum = DMatrix::zeros(n, n);
    for p in 0..panels {
        let mid = (p as f64 + 0.5) * h;
        for (x, w) in nodes.iter().zip(&weights) {
            let s = mid + 0.5 * h * x;
            let e = expm(&(a * s)).unwrap();
            sum += (&e * q * e.transpose()) * (0.5 * h * w);
        }
    }
    sum
}

#[test]
fn van_loan_satisfies_the_lyapunov_identity() {
    let mut rng = Rng::new(7);
    for &n in &[1usize, 3, 8, 30] {
        for &t in &[1e-6, 0.1, 1.0, 5.0] {
            let a = rng.matrix(n, n) * (1.0 / (n as f64).sqrt());
            let q = rng.psd(n, n.div_ceil(2));
            let vl = van_loan(&a, &q, t).unwrap();
            let res = lyapunov_residual(&a, &q, &vl);
            let e_ref = expm(&(&a * t)).unwrap();
            let e_rel = rel_err(&vl.e, &e_ref);
            eprintln!(
                "van Loan n = {n}, t = {t}: Lyapunov residual {res:.2e}, E vs expm(At) {e_rel:.2e}"
            );
            assert!(res <= 50.0 * n as f64 * U, "n = {n}, t = {t}: {res:e}");
            assert!(e_rel <= 100.0 * n as f64 * U * (1.0 + t), "{e_rel:e}");
            assert_eq!(vl.h, vl.h.transpose());
            let min_eig = vl.h.clone().symmetric_eigen().eigenvalues.min();
            assert!(min_eig >= -50.0 * n as f64 * U * vl.h.norm(), "{min_eig:e}");
        }
    }
}

#[test]
fn van_loan_matches_quadrature() {
    let mut rng = Rng::new(8);
    for &(n, t) in &[(2usize, 0.5), (4, 1.0), (5, 3.0)] {
        let a = rng.matrix(n, n) * 0.7;
        let q = rng.psd(n, 2);
        let vl = van_loan(&a, &q, t).unwrap();
        let quad = van_loan_quadrature(&a, &q, t, 200);
        let rel = rel_err(&vl.h, &quad);
        eprintln!("van Loan vs Gauss–Legendre (n = {n}, t = {t}): rel {rel:.2e}");
        assert!(rel <= 1e-12, "{rel:e}");
    }
}

#[test]
fn van_loan_matches_closed_form_for_symmetric_a() {
    // A = V Λ Vᵀ: H = V [ (VᵀQV)_ij (e^{(λi+λj)t} − 1)/(λi+λj) ] Vᵀ.
    let mut rng = Rng::new(9);
    for &(n, norm2, t) in &[
        (3usize, 1.0, 1.0),
        (6, 10.0, 2.0),
        (10, 100.0, 0.5),
        (8, 0.01, 100.0),
    ] {
        let g = random_symmetric(&mut rng, n, norm2);
        // Shift to make A stable: long horizons then test the doubling path.
        let a = &g - DMatrix::identity(n, n) * (1.05 * norm2);
        let q = rng.psd(n, n);
        let eig = a.clone().symmetric_eigen();
        let v = &eig.eigenvectors;
        let lam = &eig.eigenvalues;
        let qt = v.transpose() * &q * v;
        let core = DMatrix::from_fn(n, n, |i, j| {
            let s = lam[i] + lam[j];
            qt[(i, j)] * f64::exp_m1(s * t) / s
        });
        let exact = v * core * v.transpose();
        let vl = van_loan(&a, &q, t).unwrap();
        let rel = rel_err(&vl.h, &exact);
        eprintln!(
            "van Loan vs closed form (n = {n}, ‖A‖ ≈ {:.0}, t = {t}): rel {rel:.2e}",
            2.05 * norm2
        );
        assert!(rel <= 1e-12, "{rel:e}");
    }
    // A long horizon with a stable A: e^{−At} = e^{1000} would overflow in the one-shot block.
    let a = DMatrix::from_diagonal_element(2, 2, -10.0);
    let q = DMatrix::identity(2, 2);
    let vl = van_loan(&a, &q, 100.0).unwrap();
    let exact = -f64::exp_m1(-2000.0) / 20.0;
    assert!(((vl.h[(0, 0)] - exact) / exact).abs() <= 1e-14);
    assert_eq!(vl.h[(0, 1)], 0.0);
    assert!(vl.e.iter().all(|&v| v.abs() < 1e-300));
}

#[test]
fn van_loan_scalar_zero_q_and_zero_t() {
    for &(a, q, t) in &[
        (-2.0, 3.0, 0.7),
        (0.5, 1e-30, 2.0),
        (1e-9, 1e20, 1.0),
        (-1e-3, 1.0, 1e4),
    ] {
        let vl = van_loan(
            &DMatrix::from_element(1, 1, a),
            &DMatrix::from_element(1, 1, q),
            t,
        )
        .unwrap();
        let exact = q * f64::exp_m1(2.0 * a * t) / (2.0 * a);
        let rel = ((vl.h[(0, 0)] - exact) / exact).abs();
        assert!(rel <= 1e-13, "a = {a}, q = {q}, t = {t}: {rel:e}");
        assert!(((vl.e[(0, 0)] - f64::exp(a * t)) / f64::exp(a * t)).abs() <= 1e-13);
    }
    let mut rng = Rng::new(10);
    let a = rng.matrix(4, 4);
    let q = rng.psd(4, 2);
    let vl = van_loan(&a, &q, 0.0).unwrap();
    assert_eq!(vl.e, DMatrix::identity(4, 4));
    assert_eq!(vl.h, DMatrix::zeros(4, 4));
    let vl = van_loan(&a, &DMatrix::zeros(4, 4), 1.5).unwrap();
    assert_eq!(vl.h, DMatrix::zeros(4, 4));
    assert!(rel_err(&vl.e, &expm(&(&a * 1.5)).unwrap()) <= 1e-15);
    // A = 0: H = Q t exactly (nilpotent block, r_m exact).
    let vl = van_loan(&DMatrix::zeros(4, 4), &q, 2.5).unwrap();
    assert!(rel_err(&vl.h, &(&q * 2.5)) <= 4.0 * U);
}
