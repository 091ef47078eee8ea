use super::*;
use crate::linalg::testing::Rng;

#[test]
fn norm_fro_neither_overflows_nor_underflows() {
    let mut rng = Rng::new(3);
    let m = rng.matrix(4, 3);
    // The usual range: the plain formula (summed in four lanes).
    assert!((norm_fro(&m) - m.norm()).abs() <= 4.0 * f64::EPSILON * m.norm());
    assert!(norm_fro(&DMatrix::from_element(3, 3, f64::NAN)).is_nan());
    assert_eq!(
        norm_fro(&DMatrix::from_element(3, 3, f64::INFINITY)),
        f64::INFINITY
    );
    for &s in &[1e300, 1e200, 1e-200, 1e-300] {
        let rel = (norm_fro(&(&m * s)) - s * m.norm()).abs() / (s * m.norm());
        assert!(rel <= 8.0 * f64::EPSILON, "scale {s:e}: {rel:e}");
    }
    // Q = 1e300·I: ‖Q‖_F = √2·1e300 (the plain sum of squares overflows to ∞).
    let q = DMatrix::from_diagonal_element(2, 2, 1e300);
    assert!((norm_fro(&q) / (2f64.sqrt() * 1e300) - 1.0).abs() <= 4.0 * f64::EPSILON);
    // Subnormal entries: relative accuracy of the (few-bit) data, not 0.
    let t = DMatrix::from_diagonal_element(2, 2, 1e-310);
    assert!((norm_fro(&t) / (2f64.sqrt() * 1e-310) - 1.0).abs() <= 1e-10);
    assert_eq!(norm_fro(&DMatrix::from_element(1, 1, 5e-324)), 5e-324);
    // A sum that really overflows stays ∞; zeros stay 0.
    assert_eq!(norm_fro(&DMatrix::from_element(3, 3, 1e308)), f64::INFINITY);
    assert_eq!(norm_fro(&DMatrix::zeros(2, 2)), 0.0);
}

#[test]
fn lu_solves_and_transposed_solves() {
    let mut rng = Rng::new(7);
    for &n in &[1usize, 3, 10, 60, 64, 97, 130] {
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, 3);
        let lu = Lu::new(&a).unwrap();
        let mut x = b.clone();
        lu.solve_in_place(&mut x);
        assert!((&a * &x - &b).norm() <= 1e-10 * (a.norm() * x.norm()).max(1.0));
        let mut y = b.clone();
        lu.solve_transpose_in_place(&mut y);
        assert!((a.transpose() * &y - &b).norm() <= 1e-10 * (a.norm() * y.norm()).max(1.0));
        // Many right-hand sides take the blocked triangular solves.
        let b6 = rng.matrix(n, 6);
        let mut x6 = b6.clone();
        lu.solve_in_place(&mut x6);
        assert!((&a * &x6 - &b6).norm() <= 1e-10 * (a.norm() * x6.norm()).max(1.0));
    }
    // The blocked factorisation refuses a zero pivot like the unblocked one.
    let mut sing = rng.matrix(70, 70);
    sing.column_mut(40).fill(0.0);
    assert!(matches!(Lu::new(&sing), Err(Error::SingularProblem(_))));
}

#[test]
fn rcond_is_close_to_the_exact_value() {
    let mut rng = Rng::new(3);
    for &n in &[2usize, 8, 30] {
        let a = rng.matrix(n, n);
        let inv = a.clone().try_inverse().unwrap();
        let exact = 1.0 / (norm_1(&a) * norm_1(&inv));
        let est = Lu::new(&a).unwrap().rcond();
        // The estimator never overestimates ‖A⁻¹‖₁, so rcond ≥ exact; it is rarely off by > 10.
        assert!(est >= exact * (1.0 - 1e-12), "{est} < {exact}");
        assert!(est <= 10.0 * exact, "{est} ≫ {exact}");
    }
    let mut sing = DMatrix::<f64>::identity(3, 3);
    sing[(2, 2)] = 0.0;
    assert!(matches!(Lu::new(&sing), Err(Error::SingularProblem(_))));
}

#[test]
fn products_agree_across_kernels() {
    let mut rng = Rng::new(11);
    for &n in &[5usize, 64] {
        let a = rng.matrix(n, n + 1);
        let b = rng.matrix(n + 1, n);
        let c = matmul(&a, &b);
        assert!((&c - &a * &b).norm() <= 1e-12 * c.norm());
        let at = a.transpose();
        assert!((matmul_tn(&at, &b) - &c).norm() <= 1e-12 * c.norm());
        let bt = b.transpose();
        assert!((matmul_nt(&a, &bt) - &c).norm() <= 1e-12 * c.norm());
    }
}

#[test]
fn validation_names_the_problem() {
    let a = DMatrix::<f64>::zeros(2, 3);
    assert!(
        matches!(check_square("A", &a), Err(Error::Shape(m)) if m.contains("A must be square"))
    );
    let mut b = DMatrix::<f64>::zeros(2, 2);
    b[(1, 0)] = f64::NAN;
    assert!(matches!(check_finite("Q", &b), Err(Error::NonFinite(m)) if m.contains("(1, 0)")));
}

#[test]
fn symmetrize_is_the_halved_sum_with_the_transpose_bit_for_bit() {
    let mut rng = Rng::new(11);
    for n in [0usize, 1, 2, 5, 64, 131] {
        let mut a = rng.matrix(n, n);
        if n >= 2 {
            a[(0, 1)] = 1e308; // the pair's sum overflows, as in the formula
            a[(1, 0)] = 1e308;
            a[(n - 1, 0)] = 5e-324; // subnormal, halved to 0 with its partner 0
            a[(0, n - 1)] = 0.0;
        }
        let s = symmetrize(&a);
        let reference = (&a + a.transpose()) * 0.5;
        for (x, y) in s.iter().zip(reference.iter()) {
            assert_eq!(x.to_bits(), y.to_bits(), "n = {n}");
        }
        assert_eq!(s, s.transpose());
    }
}
