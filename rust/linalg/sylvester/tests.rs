// Why this module is long: the unit tests of the Sylvester and Lyapunov solvers (accuracy, scaling,
// singular and near-singular operators, cancellation), in one place.
use super::*;
use crate::linalg::dense::Lu;
use crate::linalg::testing::Rng;

const EPS: f64 = f64::EPSILON;

fn lyap_residual(a: &DMatrix<f64>, x: &DMatrix<f64>, q: &DMatrix<f64>) -> f64 {
    let r = a * x + x * a.transpose() - q;
    r.norm() / (2.0 * a.norm() * x.norm() + q.norm())
}

fn sylv_residual(a: &DMatrix<f64>, b: &DMatrix<f64>, x: &DMatrix<f64>, q: &DMatrix<f64>) -> f64 {
    let r = a * x + x * b - q;
    r.norm() / ((a.norm() + b.norm()) * x.norm() + q.norm())
}

/// `X` from `(I ⊗ A + Bᵀ ⊗ I) vec X = vec Q` by LU.
fn sylv_kron(a: &DMatrix<f64>, b: &DMatrix<f64>, q: &DMatrix<f64>) -> DMatrix<f64> {
    let (m, n) = (a.nrows(), b.nrows());
    let k = DMatrix::<f64>::identity(n, n).kronecker(a)
        + b.transpose().kronecker(&DMatrix::<f64>::identity(m, m));
    let mut v = DMatrix::from_column_slice(m * n, 1, q.as_slice());
    Lu::new(&k).unwrap().solve_in_place(&mut v);
    DMatrix::from_column_slice(m, n, v.as_slice())
}

/// The reported residual agrees with one recomputed independently (both are rounding noise of
/// order eps, so only their size can be compared).
fn same_residual(reported: f64, recomputed: f64) {
    assert!(
        (reported - recomputed).abs() <= 4.0 * EPS,
        "reported {reported:e} vs {recomputed:e}"
    );
}

fn rel_diff(x: &DMatrix<f64>, y: &DMatrix<f64>) -> f64 {
    (x - y).norm() / y.norm().max(f64::MIN_POSITIVE)
}

fn is_singular_with(r: &Result<DMatrix<f64>>, needle: &str) -> bool {
    matches!(r, Err(Error::SingularProblem(m)) if m.contains(needle))
}

/// Random upper quasi-triangular matrix with 2×2 blocks at the given starts, not standardised
/// (arbitrary 2×2 blocks, some with real eigenvalues).
fn quasi_triangular(rng: &mut Rng, n: usize, every: usize) -> DMatrix<f64> {
    let mut t = DMatrix::zeros(n, n);
    for j in 0..n {
        for i in 0..=j {
            t[(i, j)] = rng.normal();
        }
    }
    let mut k = 0;
    while k + 1 < n {
        if k % every == 0 {
            t[(k + 1, k)] = rng.normal();
            k += 2;
        } else {
            k += 1;
        }
    }
    // Garbage below the subdiagonal must be ignored.
    for j in 0..n {
        for i in (j + 2)..n {
            t[(i, j)] = 1e30;
        }
    }
    t
}

fn clean(t: &DMatrix<f64>) -> DMatrix<f64> {
    let mut t = t.clone();
    let n = t.nrows();
    for j in 0..n {
        for i in (j + 2)..n {
            t[(i, j)] = 0.0;
        }
    }
    t
}

const SIZES: [usize; 7] = [1, 2, 3, 5, 10, 50, 200];

#[test]
fn lyapunov_random_sizes_symmetric_q() {
    let mut rng = Rng::new(1);
    for &n in &SIZES {
        // Generic Gaussian A: mixed spectrum, complex pairs; shifted: stable.
        let g = rng.matrix(n, n);
        let stable = &g - DMatrix::identity(n, n) * (2.0 * (n as f64).sqrt() + 1.0);
        for a in [g, stable] {
            let q = rng.psd(n, n.min(3)) - rng.psd(n, 2);
            let lyap = Lyapunov::new(&a).unwrap();
            let sol = lyap.solve_with_info(&q).unwrap();
            let res = lyap_residual(&a, &sol.x, &q);
            assert!(res <= 1e-13 * n as f64, "n={n}: residual {res:e}");
            same_residual(sol.residual, res);
            assert!(sol.pivot_ratio > 0.0);
            assert_eq!(
                sol.x,
                sol.x.transpose(),
                "symmetric Q must give an exactly symmetric X"
            );
        }
    }
}

#[test]
fn lyapunov_random_sizes_nonsymmetric_q() {
    let mut rng = Rng::new(2);
    for &n in &SIZES {
        let a = rng.matrix(n, n) - DMatrix::identity(n, n) * (n as f64).sqrt();
        let q = rng.matrix(n, n);
        let x = solve_lyapunov(&a, &q).unwrap();
        let res = lyap_residual(&a, &x, &q);
        assert!(res <= 1e-13 * n as f64, "n={n}: residual {res:e}");
    }
}

#[test]
fn lyapunov_many_complex_pairs() {
    let mut rng = Rng::new(3);
    for &(npairs, nreal) in &[(1usize, 0usize), (2, 1), (5, 0), (12, 3), (40, 5), (90, 20)] {
        // Stable, unstable and mixed real parts.
        let pairs: Vec<(f64, f64)> = (0..npairs)
            .map(|k| {
                let re = match k % 3 {
                    0 => -0.5 - rng.uniform(),
                    1 => 0.3 + rng.uniform(),
                    _ => -2.0 * rng.uniform() - 0.1,
                };
                (re, 0.5 + 3.0 * rng.uniform())
            })
            .collect();
        let real: Vec<f64> = (0..nreal)
            .map(|k| {
                if k % 2 == 0 {
                    -1.0 - k as f64
                } else {
                    0.7 * k as f64
                }
            })
            .collect();
        let a = rng.with_eigenvalues(&real, &pairs);
        let n = a.nrows();
        let lyap = Lyapunov::new(&a).unwrap();
        let q = rng.psd(n, 2);
        let x = lyap.solve(&q).unwrap();
        let res = lyap_residual(&a, &x, &q);
        assert!(res <= 1e-13 * n as f64, "n={n}: residual {res:e}");
        let qn = rng.matrix(n, n);
        let xn = lyap.solve(&qn).unwrap();
        let res = lyap_residual(&a, &xn, &qn);
        assert!(
            res <= 1e-13 * n as f64,
            "n={n}: residual {res:e} (non-symmetric Q)"
        );
        if n <= 12 {
            let k = sylv_kron(&a, &a.transpose(), &qn);
            assert!(
                rel_diff(&xn, &k) <= 1e-11,
                "n={n}: differs from Kronecker by {:e}",
                rel_diff(&xn, &k)
            );
        }
    }
}

#[test]
fn lyapunov_agrees_with_kronecker_system() {
    let mut rng = Rng::new(4);
    for n in 1..=12 {
        for shift in [0.0, 3.0, -3.0] {
            let a = rng.matrix(n, n) + DMatrix::identity(n, n) * shift;
            let g = rng.matrix(n, n);
            for q in [&g + g.transpose(), g.clone()] {
                let lyap = match Lyapunov::new(&a) {
                    Ok(l) => l,
                    Err(e) => panic!("n={n}: {e}"),
                };
                let x = match lyap.solve(&q) {
                    Ok(x) => x,
                    // A generic Gaussian A can have λ_i + λ_j tiny; the Kronecker system would be
                    // ill-conditioned then too. Never seen with these seeds, but don't mask it.
                    Err(e) => panic!("n={n}, shift={shift}: {e}"),
                };
                let k = sylv_kron(&a, &a.transpose(), &q);
                let sep = lyap.sep_estimate().unwrap();
                // Forward error bound ~ eps·‖A‖/sep; allow generous slack.
                let tol = 1e3 * EPS * (a.norm() / sep).max(1.0) * n as f64;
                assert!(
                    rel_diff(&x, &k) <= tol,
                    "n={n} shift={shift}: {:e} > {tol:e}",
                    rel_diff(&x, &k)
                );
            }
        }
    }
}

#[test]
fn lyapunov_adjoint() {
    let mut rng = Rng::new(5);
    for &n in &[1usize, 2, 4, 9, 33, 80] {
        let a = rng.with_eigenvalues(
            &(0..n % 3).map(|k| -1.0 - k as f64).collect::<Vec<_>>(),
            &(0..n / 3)
                .map(|k| (-0.2 - 0.1 * k as f64, 1.0 + k as f64))
                .collect::<Vec<_>>(),
        );
        let n = a.nrows();
        if n == 0 {
            continue;
        }
        let lyap = Lyapunov::new(&a).unwrap();
        for q in [rng.psd(n, 2), rng.matrix(n, n)] {
            let sol = lyap.solve_adjoint_with_info(&q).unwrap();
            let at = a.transpose();
            let res = lyap_residual(&at, &sol.x, &q);
            assert!(res <= 1e-13 * n as f64, "n={n}: adjoint residual {res:e}");
            same_residual(sol.residual, res);
            let fresh = Lyapunov::new(&at).unwrap().solve(&q).unwrap();
            assert!(
                rel_diff(&sol.x, &fresh) <= 1e-10,
                "{:e}",
                rel_diff(&sol.x, &fresh)
            );
        }
    }
}

#[test]
fn repeated_solves_with_one_factor_equal_fresh_solves() {
    let mut rng = Rng::new(6);
    for &n in &[3usize, 40, 70] {
        let a = rng.matrix(n, n) - DMatrix::identity(n, n) * 10.0;
        let lyap = Lyapunov::new(&a).unwrap();
        let mut qs: Vec<DMatrix<f64>> = (0..3).map(|_| rng.psd(n, 2)).collect();
        qs.push(rng.matrix(n, n));
        let first: Vec<_> = qs.iter().map(|q| lyap.solve(q).unwrap()).collect();
        for (q, x1) in qs.iter().zip(&first) {
            assert_eq!(&lyap.solve(q).unwrap(), x1, "second solve differs");
            assert_eq!(
                &Lyapunov::new(&a).unwrap().solve(q).unwrap(),
                x1,
                "fresh solve differs"
            );
            assert_eq!(&solve_lyapunov(&a, q).unwrap(), x1);
            assert_eq!(
                &lyap.solve_adjoint(q).unwrap(),
                &Lyapunov::new(&a).unwrap().solve_adjoint(q).unwrap()
            );
        }
    }
}

#[test]
fn lyapunov_closed_forms() {
    for &(a, q) in &[(-1.5, 3.0), (2.0, -1.0), (1e-5, 1.0), (-7.0e8, 2.0e3)] {
        let am = DMatrix::from_element(1, 1, a);
        let qm = DMatrix::from_element(1, 1, q);
        let x = solve_lyapunov(&am, &qm).unwrap();
        assert!((x[(0, 0)] - q / (2.0 * a)).abs() <= 2.0 * EPS * (q / (2.0 * a)).abs());
        let xa = Lyapunov::new(&am).unwrap().solve_adjoint(&qm).unwrap();
        assert_eq!(x, xa);
    }
    // Diagonal A: x_ij = q_ij / (a_i + a_j).
    let d = [-1.0, -2.5, 0.5, 3.0, -0.25];
    let a = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&d));
    let mut rng = Rng::new(7);
    let g = rng.matrix(5, 5);
    for q in [&g + g.transpose(), g.clone()] {
        let x = solve_lyapunov(&a, &q).unwrap();
        for i in 0..5 {
            for j in 0..5 {
                let exact = q[(i, j)] / (d[i] + d[j]);
                assert!(
                    (x[(i, j)] - exact).abs() <= 4.0 * EPS * exact.abs(),
                    "({i},{j})"
                );
            }
        }
    }
    // Sylvester with diagonal A, B: x_ij = q_ij / (a_i + b_j).
    let b = [2.0, -0.75, 4.0];
    let bm = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&b));
    let q = rng.matrix(5, 3);
    let x = solve_sylvester(&a, &bm, &q).unwrap();
    for i in 0..5 {
        for j in 0..3 {
            let exact = q[(i, j)] / (d[i] + b[j]);
            assert!((x[(i, j)] - exact).abs() <= 4.0 * EPS * exact.abs());
        }
    }
}

#[test]
fn sylvester_rectangular_and_kronecker() {
    let mut rng = Rng::new(8);
    for &(m, n) in &[
        (1usize, 1usize),
        (1, 4),
        (4, 1),
        (3, 5),
        (7, 2),
        (6, 6),
        (12, 9),
        (40, 70),
        (130, 45),
        (200, 200),
    ] {
        let a = rng.matrix(m, m) + DMatrix::identity(m, m) * 2.0;
        let b = rng.matrix(n, n) + DMatrix::identity(n, n) * 2.0;
        let q = rng.matrix(m, n);
        let syl = Sylvester::new(&a, &b).unwrap();
        let sol = syl.solve_with_info(&q).unwrap();
        let res = sylv_residual(&a, &b, &sol.x, &q);
        assert!(
            res <= 1e-13 * m.max(n) as f64,
            "({m},{n}): residual {res:e}"
        );
        same_residual(sol.residual, res);
        let adj = syl.solve_adjoint(&q).unwrap();
        let res = sylv_residual(&a.transpose(), &b.transpose(), &adj, &q);
        assert!(
            res <= 1e-13 * m.max(n) as f64,
            "({m},{n}): adjoint residual {res:e}"
        );
        assert_eq!(sol.x, solve_sylvester(&a, &b, &q).unwrap());
        if m * n <= 144 {
            let k = sylv_kron(&a, &b, &q);
            let sep = syl.sep_estimate().unwrap();
            let tol = 1e3 * EPS * ((a.norm() + b.norm()) / sep).max(1.0) * (m * n) as f64;
            assert!(
                rel_diff(&sol.x, &k) <= tol,
                "({m},{n}): {:e}",
                rel_diff(&sol.x, &k)
            );
        }
    }
}

#[test]
fn sylvester_with_complex_pairs_both_sides() {
    let mut rng = Rng::new(9);
    let a = rng.with_eigenvalues(&[1.0, -3.0], &[(0.5, 2.0), (-1.0, 0.3), (2.0, 5.0)]);
    let b = rng.with_eigenvalues(&[0.25], &[(1.5, 1.0), (0.2, 4.0)]);
    let q = rng.matrix(8, 5);
    let x = solve_sylvester(&a, &b, &q).unwrap();
    assert!(sylv_residual(&a, &b, &x, &q) <= 1e-14 * 8.0);
    let k = sylv_kron(&a, &b, &q);
    assert!(rel_diff(&x, &k) <= 1e-11, "{:e}", rel_diff(&x, &k));
}

#[test]
fn quasi_triangular_direct_non_standard_blocks() {
    let mut rng = Rng::new(10);
    for &(m, n, ea, eb) in &[
        (1usize, 1usize, 2usize, 2usize),
        (2, 2, 2, 2),
        (5, 4, 2, 3),
        (33, 31, 3, 2),
        (100, 37, 2, 4),
        (64, 129, 5, 2),
    ] {
        // Shift to keep λ_i(T) + λ_j(S) away from 0 (random 2×2 blocks may have real eigenvalues).
        let t = quasi_triangular(&mut rng, m, ea) + DMatrix::identity(m, m) * 6.0;
        let s = quasi_triangular(&mut rng, n, eb) + DMatrix::identity(n, n) * 6.0;
        let c0 = rng.matrix(m, n);
        let mut c = c0.clone();
        let ratio =
            solve_quasi_triangular_with_rtol(&t, &s, &mut c, DEFAULT_SINGULAR_RTOL).unwrap();
        assert!(ratio > 0.0);
        let (tc, sc) = (clean(&t), clean(&s));
        let res = sylv_residual(&tc, &sc, &c, &c0);
        assert!(res <= 1e-14 * (m + n) as f64, "({m},{n}): residual {res:e}");
        if m * n <= 144 {
            assert!(rel_diff(&c, &sylv_kron(&tc, &sc, &c0)) <= 1e-11);
        }
    }
}

/// Upper quasi-triangular matrix with the given diagonal blocks (`[b00, b10, b01, b11]` for 2×2,
/// `[b00]` for 1×1) and a random strictly upper part.
fn with_blocks(rng: &mut Rng, blocks: &[&[f64]]) -> DMatrix<f64> {
    let n: usize = blocks
        .iter()
        .map(|b| if b.len() == 4 { 2 } else { 1 })
        .sum();
    let mut t = DMatrix::zeros(n, n);
    for j in 0..n {
        for i in 0..j {
            t[(i, j)] = 0.5 * rng.normal();
        }
    }
    let mut k = 0;
    for b in blocks {
        if b.len() == 4 {
            t[(k, k)] = b[0];
            t[(k + 1, k)] = b[1];
            t[(k, k + 1)] = b[2];
            t[(k + 1, k + 1)] = b[3];
            k += 2;
        } else {
            t[(k, k)] = b[0];
            k += 1;
        }
    }
    t
}

#[test]
fn two_by_two_blocks_of_every_kind() {
    // Normal complex pair (complex-column path), mildly and strongly non-normal complex pairs (the
    // latter falls back to the 4×4 real system), real-eigenvalue 2×2 blocks (fallback), 1×1 blocks.
    let kinds: [&[f64]; 7] = [
        &[1.0, -2.0, 2.0, 1.0],
        &[-0.5, -0.3, 3.0, -0.5],
        &[2.0, -0.01, 400.0, 2.0],
        &[1.5, 0.7, 0.4, -0.2],
        &[0.8],
        &[-1.3, -1e-3, 1e3, 0.7],
        &[3.0, -1.0, 1.0, 3.0],
    ];
    let mut rng = Rng::new(17);
    for rep in 0..6 {
        let mut blocks: Vec<&[f64]> = Vec::new();
        for q in 0..(6 + 5 * rep) {
            blocks.push(kinds[(q * 5 + rep) % kinds.len()]);
        }
        let t = with_blocks(&mut rng, &blocks);
        let mut sblocks = blocks.clone();
        sblocks.rotate_left(rep % 3);
        let s = with_blocks(&mut rng, &sblocks) + DMatrix::identity(t.nrows(), t.nrows()) * 0.25;
        let (m, n) = (t.nrows(), s.nrows());
        // N,N through the quasi-triangular entry point.
        let c0 = rng.matrix(m, n);
        let mut c = c0.clone();
        solve_quasi_triangular(&t, &s, &mut c).unwrap();
        let res = sylv_residual(&t, &s, &c, &c0);
        assert!(
            res <= 1e-14 * (m + n) as f64,
            "rep {rep}: N,N residual {res:e}"
        );
        if m * n <= 400 {
            let k = sylv_kron(&t, &s, &c0);
            let syl = Sylvester::from_schur(
                RealSchur {
                    t: t.clone(),
                    z: DMatrix::identity(m, m),
                },
                RealSchur {
                    t: s.clone(),
                    z: DMatrix::identity(n, n),
                },
            );
            let tol =
                1e3 * EPS * ((t.norm() + s.norm()) / syl.sep_estimate().unwrap()) * (m * n) as f64;
            assert!(
                rel_diff(&c, &k) <= tol,
                "rep {rep}: {:e} > {tol:e}",
                rel_diff(&c, &k)
            );
        }
        // N,T and the symmetric kernel through Lyapunov with a Schur factor Z = I (T shifted stable).
        let ts = &t - DMatrix::identity(m, m) * 4.0;
        let lyap = Lyapunov::from_schur(RealSchur {
            t: ts.clone(),
            z: DMatrix::identity(m, m),
        });
        let g = rng.matrix(m, m);
        for q in [&g + g.transpose(), g.clone()] {
            let x = lyap.solve(&q).unwrap();
            let res = lyap_residual(&ts, &x, &q);
            assert!(
                res <= 1e-14 * m as f64,
                "rep {rep}: Lyapunov residual {res:e}"
            );
            if m <= 20 {
                let k = sylv_kron(&ts, &ts.transpose(), &q);
                let tol = 1e3 * EPS * (ts.norm() / lyap.sep_estimate().unwrap()) * (m * m) as f64;
                assert!(
                    rel_diff(&x, &k) <= tol,
                    "rep {rep}: {:e} > {tol:e}",
                    rel_diff(&x, &k)
                );
            }
            let xa = lyap.solve_adjoint(&q).unwrap();
            assert!(lyap_residual(&ts.transpose(), &xa, &q) <= 1e-14 * m as f64);
        }
    }
}

#[test]
fn lyapunov_from_non_standardised_schur_form() {
    // A = Z T Zᵀ with T having 2×2 blocks that are neither standardised nor of complex type.
    let mut rng = Rng::new(11);
    for &n in &[2usize, 7, 40, 90] {
        let t = quasi_triangular(&mut rng, n, 2) - DMatrix::identity(n, n) * 8.0;
        let z = rng.orthogonal(n);
        let a = &z * clean(&t) * z.transpose();
        let lyap = Lyapunov::from_schur(RealSchur { t, z });
        for q in [rng.psd(n, 3), rng.matrix(n, n)] {
            let sol = lyap.solve_with_info(&q).unwrap();
            let res = lyap_residual(&a, &sol.x, &q);
            assert!(res <= 1e-13 * n as f64, "n={n}: {res:e}");
            same_residual(sol.residual, res);
            let xa = lyap.solve_adjoint(&q).unwrap();
            assert!(lyap_residual(&a.transpose(), &xa, &q) <= 1e-13 * n as f64);
        }
    }
}

#[test]
fn singular_lyapunov_is_reported() {
    let mut rng = Rng::new(12);
    // Eigenvalues ±1: λ_i + λ_j = 0.
    for &extra in &[0usize, 1, 3, 8, 40] {
        let mut real = vec![1.0, -1.0];
        real.extend((0..extra).map(|k| -2.0 - k as f64));
        let a = rng.with_eigenvalues(&real, &[]);
        let q = rng.psd(a.nrows(), 2);
        let r = solve_lyapunov(&a, &q);
        assert!(
            is_singular_with(&r, "λ_i(A) + λ_j(A) ≈ 0"),
            "extra={extra}: {r:?}"
        );
        let rn = solve_lyapunov(&a, &rng.matrix(a.nrows(), a.nrows()));
        assert!(
            is_singular_with(&rn, "λ_i(A) + λ_j(A) ≈ 0"),
            "extra={extra}: {rn:?}"
        );
        let ra = Lyapunov::new(&a).unwrap().solve_adjoint(&q);
        assert!(
            is_singular_with(&ra, "singular or nearly so"),
            "extra={extra}: {ra:?}"
        );
    }
    // Eigenvalue pair ±2i: λ + λ̄ = 0 inside one 2×2 block.
    for &extra in &[0usize, 3, 20] {
        let real: Vec<f64> = (0..extra).map(|k| -1.0 - k as f64).collect();
        let a = rng.with_eigenvalues(&real, &[(0.0, 2.0)]);
        let r = solve_lyapunov(&a, &rng.psd(a.nrows(), 1));
        assert!(
            is_singular_with(&r, "singular or nearly so"),
            "extra={extra}: {r:?}"
        );
    }
    // A zero eigenvalue, and A = 0.
    let a = rng.with_eigenvalues(&[0.0, -1.0, -2.0], &[(-1.0, 1.0)]);
    assert!(is_singular_with(&solve_lyapunov(&a, &rng.psd(5, 5)), "≈ 0"));
    let z = DMatrix::<f64>::zeros(3, 3);
    assert!(is_singular_with(
        &solve_lyapunov(&z, &DMatrix::identity(3, 3)),
        "≈ 0"
    ));
    assert!(is_singular_with(
        &solve_lyapunov(&DMatrix::zeros(1, 1), &DMatrix::from_element(1, 1, 1.0)),
        "≈ 0"
    ));
    // Nearly singular: eigenvalues 1 and −1 + 1e-14.
    let a = rng.with_eigenvalues(&[1.0, -1.0 + 1e-14, -3.0], &[]);
    assert!(is_singular_with(&solve_lyapunov(&a, &rng.psd(3, 3)), "≈ 0"));
    // Just far enough: eigenvalues 1 and −1 + 1e-6 solve, with a small pivot ratio.
    let a = rng.with_eigenvalues(&[1.0, -1.0 + 1e-6, -3.0], &[]);
    let q = rng.psd(3, 3);
    let sol = Lyapunov::new(&a).unwrap().solve_with_info(&q).unwrap();
    assert!(
        sol.pivot_ratio < 1e-5 && sol.pivot_ratio > 1e-9,
        "{}",
        sol.pivot_ratio
    );
    assert!(sol.residual <= 1e-12, "{}", sol.residual);
    // And with rtol = 0 the nearly singular one is attempted (as LAPACK would) — or overflows.
    let lyap = Lyapunov::new(&a).unwrap().with_singular_rtol(0.0).unwrap();
    assert!(lyap.solve(&q).is_ok());
}

#[test]
fn cancelling_spectra_are_caught_with_a_wide_margin() {
    // Over many random similarity transforms, exactly cancelling eigenvalue pairs give pivot
    // ratios near eps, far below the default tolerance: no silent garbage, no flakiness.
    let mut worst: f64 = 0.0;
    for seed in 0..60u64 {
        let mut rng = Rng::new(500 + seed);
        let extra = (seed % 12) as usize;
        let mut real = vec![1.0, -1.0];
        real.extend((0..extra).map(|k| -2.0 - 0.3 * k as f64));
        let pairs: Vec<(f64, f64)> = (0..(seed % 4) as usize)
            .map(|k| (-0.4 - 0.1 * k as f64, 1.0 + k as f64))
            .collect();
        let a = rng.with_eigenvalues(&real, &pairs);
        let n = a.nrows();
        let q = rng.psd(n, 2);
        assert!(
            is_singular_with(&solve_lyapunov(&a, &q), "≈ 0"),
            "seed {seed}"
        );
        if let Ok(sol) = Lyapunov::new(&a)
            .unwrap()
            .with_singular_rtol(0.0)
            .unwrap()
            .solve_with_info(&q)
        {
            worst = worst.max(sol.pivot_ratio);
        }
        let b = -&a;
        assert!(
            is_singular_with(&solve_sylvester(&a, &b, &rng.matrix(n, n)), "≈ 0"),
            "seed {seed}"
        );
    }
    assert!(
        worst < 1e-3 * DEFAULT_SINGULAR_RTOL,
        "largest pivot ratio {worst:e}"
    );
}

#[test]
fn singular_sylvester_is_reported() {
    let mut rng = Rng::new(13);
    for &n in &[1usize, 2, 5, 20, 60] {
        let a = rng.matrix(n, n);
        let b = -&a;
        let q = rng.matrix(n, n);
        let r = solve_sylvester(&a, &b, &q);
        assert!(is_singular_with(&r, "λ_i(A) + λ_j(B) ≈ 0"), "n={n}: {r:?}");
    }
    // Rectangular, one shared eigenvalue pair.
    let a = rng.with_eigenvalues(&[2.0, 5.0], &[(1.0, 1.0)]);
    let b = rng.with_eigenvalues(&[-5.0], &[(3.0, 2.0), (0.5, 4.0)]);
    let r = solve_sylvester(&a, &b, &rng.matrix(4, 5));
    assert!(is_singular_with(&r, "λ_i(A) + λ_j(B) ≈ 0"), "{r:?}");
    // Complex pair against its negative.
    let a = rng.with_eigenvalues(&[2.0], &[(1.0, 3.0)]);
    let b = rng.with_eigenvalues(&[0.5, 0.7], &[(-1.0, 3.0)]);
    let r = solve_sylvester(&a, &b, &rng.matrix(3, 4));
    assert!(is_singular_with(&r, "±"), "{r:?}");
    // The quasi-triangular entry point.
    let t = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 0.0, 3.0]);
    let s = DMatrix::from_row_slice(2, 2, &[-3.0, 1.0, 0.0, 4.0]);
    let mut c = DMatrix::from_element(2, 2, 1.0);
    assert!(
        matches!(solve_quasi_triangular(&t, &s, &mut c), Err(Error::SingularProblem(m)) if m.contains("λ_i(T) + λ_j(S)"))
    );
}

#[test]
fn overflow_is_reported_not_returned() {
    let a = DMatrix::from_element(1, 1, 1e-300);
    let q = DMatrix::from_element(1, 1, 1e300);
    let r = solve_lyapunov(&a, &q);
    assert!(is_singular_with(&r, "overflow"), "{r:?}");
    let mut rng = Rng::new(14);
    let a = rng.with_eigenvalues(&[-1e-3, -1.0], &[(-1e-3, 1.0)]);
    let q = DMatrix::identity(4, 4) * 1e306;
    let r = solve_lyapunov(&a, &q);
    assert!(is_singular_with(&r, "overflow"), "{r:?}");
}

#[test]
fn sep_estimate_is_close_to_the_true_separation() {
    let mut rng = Rng::new(15);
    for &n in &[1usize, 2, 4, 7, 10] {
        let a = rng.matrix(n, n) - DMatrix::identity(n, n) * 0.5;
        let lyap = Lyapunov::new(&a).unwrap();
        let k = DMatrix::<f64>::identity(n, n).kronecker(&a)
            + a.kronecker(&DMatrix::<f64>::identity(n, n));
        // 1-norm separation exactly: 1/‖K⁻¹‖₁ (T-coordinates differ by an orthogonal similarity,
        // which changes 1-norms by at most a factor n).
        let kinv = k.clone().try_inverse().unwrap();
        let sep1 = 1.0 / crate::linalg::dense::norm_1(&kinv);
        let est = lyap.sep_estimate().unwrap();
        let nn = (n * n) as f64;
        assert!(
            est >= sep1 / nn / 1.01 && est <= sep1 * nn * 1.01,
            "n={n}: est {est:e} vs {sep1:e}"
        );
        let smin = k.singular_values().min();
        assert!(
            est >= smin / nn / 1.01 && est <= smin * nn * 1.01,
            "n={n}: est {est:e} vs σmin {smin:e}"
        );
    }
    let a = rng.with_eigenvalues(&[1.0, -1.0, -2.0], &[]);
    assert_eq!(Lyapunov::new(&a).unwrap().sep_estimate().unwrap(), 0.0);
    let syl = Sylvester::new(
        &rng.matrix(3, 3),
        &(rng.matrix(4, 4) + DMatrix::identity(4, 4) * 6.0),
    )
    .unwrap();
    assert!(syl.sep_estimate().unwrap() > 0.0);
}

#[test]
fn factors_can_be_shared_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Lyapunov>();
    assert_send_sync::<Sylvester>();
    let mut rng = Rng::new(18);
    let a = rng.matrix(20, 20) - DMatrix::identity(20, 20) * 6.0;
    let lyap = Lyapunov::new(&a).unwrap();
    let qs: Vec<DMatrix<f64>> = (0..4).map(|_| rng.psd(20, 2)).collect();
    let serial: Vec<_> = qs.iter().map(|q| lyap.solve(q).unwrap()).collect();
    let parallel: Vec<_> = std::thread::scope(|sc| {
        let hs: Vec<_> = qs
            .iter()
            .map(|q| sc.spawn(|| lyap.solve(q).unwrap()))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(serial, parallel);
}

#[test]
fn input_errors() {
    let mut rng = Rng::new(16);
    let a = rng.matrix(3, 3);
    let q = rng.matrix(3, 3);
    assert!(matches!(
        solve_lyapunov(&rng.matrix(3, 4), &q),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        solve_lyapunov(&DMatrix::zeros(0, 0), &DMatrix::zeros(0, 0)),
        Err(Error::Shape(_))
    ));
    assert!(
        matches!(solve_lyapunov(&a, &rng.matrix(3, 2)), Err(Error::Shape(m)) if m.contains("Q"))
    );
    let lyap = Lyapunov::new(&a).unwrap();
    assert!(matches!(
        lyap.solve(&rng.matrix(2, 2)),
        Err(Error::Shape(_))
    ));
    let mut qn = q.clone();
    qn[(1, 2)] = f64::NAN;
    assert!(matches!(lyap.solve(&qn), Err(Error::NonFinite(m)) if m.contains("Q")));
    assert!(matches!(lyap.solve_adjoint(&qn), Err(Error::NonFinite(_))));
    let mut an = a.clone();
    an[(0, 0)] = f64::INFINITY;
    assert!(matches!(solve_lyapunov(&an, &q), Err(Error::NonFinite(_))));
    assert!(matches!(
        solve_sylvester(&a, &rng.matrix(2, 2), &rng.matrix(2, 3)),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        solve_sylvester(&a, &rng.matrix(2, 3), &rng.matrix(3, 2)),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        solve_sylvester(&a, &an, &q),
        Err(Error::NonFinite(_))
    ));
    assert!(matches!(
        Lyapunov::new(&a).unwrap().with_singular_rtol(-1.0),
        Err(Error::InvalidInput(_))
    ));
    // Quasi-triangular entry point: structure, shapes, NaN.
    let mut t = DMatrix::<f64>::identity(3, 3);
    t[(1, 0)] = 1.0;
    t[(2, 1)] = 1.0;
    let s = DMatrix::<f64>::identity(2, 2);
    let mut c = DMatrix::<f64>::zeros(3, 2);
    assert!(
        matches!(solve_quasi_triangular(&t, &s, &mut c), Err(Error::InvalidInput(m)) if m.contains("quasi-triangular"))
    );
    let t = DMatrix::<f64>::identity(3, 3);
    assert!(matches!(
        solve_quasi_triangular(&t, &s, &mut DMatrix::zeros(2, 3)),
        Err(Error::Shape(_))
    ));
    let mut tn = t.clone();
    tn[(0, 2)] = f64::NAN;
    assert!(matches!(
        solve_quasi_triangular(&tn, &s, &mut c),
        Err(Error::NonFinite(_))
    ));
    // A bad Schur factor is reported at solve time.
    let bad = Lyapunov::from_schur(RealSchur {
        t: DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0]),
        z: DMatrix::identity(3, 3),
    });
    assert!(matches!(bad.solve(&q), Err(Error::InvalidInput(_))));
}

/// Timing split (Schur / transforms / triangular solve) for the report. Run with
/// `cargo test --release --lib linalg::sylvester::tests::timing -- --ignored --nocapture`.
#[test]
#[ignore]
fn timing() {
    use std::time::Instant;
    fn best<F: FnMut()>(reps: usize, mut f: F) -> f64 {
        let mut best = f64::INFINITY;
        for _ in 0..5 {
            let t0 = Instant::now();
            for _ in 0..reps {
                f();
            }
            best = best.min(t0.elapsed().as_secs_f64() / reps as f64);
        }
        best
    }
    let mut rng = Rng::new(0);
    for &n in &[4usize, 16, 64, 200] {
        let a = rng.matrix(n, n);
        let q = rng.psd(n, n);
        let qn = rng.matrix(n, n);
        let reps = (200_000 / (n * n * n)).clamp(3, 2000);
        let total = best(reps, || {
            std::hint::black_box(solve_lyapunov(&a, &q).unwrap());
        });
        let schur = best(reps, || {
            std::hint::black_box(RealSchur::new(&a).unwrap());
        });
        let lyap = Lyapunov::new(&a).unwrap();
        let solve = best(reps, || {
            std::hint::black_box(lyap.solve(&q).unwrap());
        });
        let solve_ns = best(reps, || {
            std::hint::black_box(lyap.solve(&qn).unwrap());
        });
        let (t, z) = (&lyap.schur().t, &lyap.schur().z);
        let c0 = product_upper(z, true, &product(&q, false, z, false), false);
        let tri = best(reps, || {
            let mut c = c0.clone();
            let mut ctx = Ctx::new(1e-300, Kind::Lyapunov);
            kernel::lyap(
                &mut ctx,
                View::new(t.as_slice(), n),
                c.as_mut_slice(),
                n,
                (0, n),
            )
            .unwrap();
            std::hint::black_box(c);
        });
        let tri_ns = best(reps, || {
            let mut c = c0.clone();
            let mut ctx = Ctx::new(1e-300, Kind::Lyapunov);
            let tv = View::new(t.as_slice(), n);
            kernel::sylv(&mut ctx, tv, tv, true, c.as_mut_slice(), n, (0, n), (0, n)).unwrap();
            std::hint::black_box(c);
        });
        let gemm = best(reps, || {
            std::hint::black_box(product(&q, false, z, false));
        });
        let gemm_upper = best(reps, || {
            std::hint::black_box(product_upper(z, true, &q, false));
        });
        println!(
            "n={n:4}: one n×n product {:8.1} µs, upper triangle of a product {:8.1} µs",
            gemm * 1e6,
            gemm_upper * 1e6
        );
        println!(
            "n={n:4}: total {:9.1} µs | schur {:9.1} | solve(sym Q) {:8.1} = tri {:8.1} + transforms {:8.1} | solve(general Q) {:8.1} (tri {:8.1})",
            total * 1e6,
            schur * 1e6,
            solve * 1e6,
            tri * 1e6,
            (solve - tri) * 1e6,
            solve_ns * 1e6,
            tri_ns * 1e6
        );
    }
}

#[test]
#[ignore]
fn timing_kernels() {
    use std::time::Instant;
    fn best<F: FnMut()>(reps: usize, mut f: F) -> f64 {
        let mut best = f64::INFINITY;
        for _ in 0..7 {
            let t0 = Instant::now();
            for _ in 0..reps {
                f();
            }
            best = best.min(t0.elapsed().as_secs_f64() / reps as f64);
        }
        best
    }
    let mut rng = Rng::new(0);
    let every: usize = std::env::var("EVERY")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3);
    for &n in &[32usize, 64, 100, 200, 400] {
        // EVERY=0: the real Schur form of a Gaussian matrix (mostly standardised complex pairs).
        let t = if every == 0 {
            RealSchur::new(&rng.matrix(n, n)).unwrap().t
        } else {
            quasi_triangular(&mut rng, n, every) + DMatrix::identity(n, n) * 10.0
        };
        let c0 = rng.matrix(n, n);
        let reps = (2_000_000 / (n * n * n)).clamp(3, 2000);
        let tv = View::new(t.as_slice(), n);
        let nn = best(reps, || {
            let mut c = c0.clone();
            let mut ctx = Ctx::new(1e-300, Kind::Lyapunov);
            kernel::sylv(&mut ctx, tv, tv, false, c.as_mut_slice(), n, (0, n), (0, n)).unwrap();
            std::hint::black_box(c);
        });
        let nt = best(reps, || {
            let mut c = c0.clone();
            let mut ctx = Ctx::new(1e-300, Kind::Lyapunov);
            kernel::sylv(&mut ctx, tv, tv, true, c.as_mut_slice(), n, (0, n), (0, n)).unwrap();
            std::hint::black_box(c);
        });
        let ly = best(reps, || {
            let mut c = c0.clone();
            let mut ctx = Ctx::new(1e-300, Kind::Lyapunov);
            kernel::lyap(&mut ctx, tv, c.as_mut_slice(), n, (0, n)).unwrap();
            std::hint::black_box(c);
        });
        let a = rng.matrix(n, n);
        let gm = best(reps, || {
            std::hint::black_box(product(&a, false, &c0, false));
        });
        let f = (n * n * n) as f64;
        println!(
            "n={n:4}: NN {:8.1} µs ({:.2} GF) NT {:8.1} µs ({:.2} GF) lyap {:8.1} µs ({:.2} GF) gemm {:8.1} µs ({:.2} GF)",
            nn * 1e6, 2.0 * f / nn * 1e-9, nt * 1e6, 2.0 * f / nt * 1e-9, ly * 1e6, f / ly * 1e-9, gm * 1e6, 2.0 * f / gm * 1e-9
        );
    }
}

#[test]
fn helpers_symmetry_finiteness_mirror() {
    let mut rng = Rng::new(19);
    for &n in &[1usize, 2, 7, 31, 32, 33, 70] {
        let g = rng.matrix(n, n);
        let s = &g + g.transpose();
        assert!(is_exactly_symmetric(&s));
        if n > 1 {
            let mut t = s.clone();
            t[(n - 1, 0)] = f64::from_bits(t[(n - 1, 0)].to_bits() + 1); // one ulp
            assert!(!is_exactly_symmetric(&t), "n={n}");
            let mut t = s.clone();
            t[(n / 2, n - 1)] += 1.0;
            assert!(n / 2 == n - 1 || !is_exactly_symmetric(&t), "n={n}");
        }
        let mut u = g.clone();
        mirror_upper(&mut u);
        assert!(is_exactly_symmetric(&u));
        for j in 0..n {
            for i in 0..=j {
                assert_eq!(u[(i, j)], g[(i, j)]);
            }
        }
        assert!(all_finite(g.as_slice()));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for k in [0, n * n / 2, n * n - 1] {
                let mut h = g.clone();
                h[k] = bad;
                assert!(!all_finite(h.as_slice()), "n={n} k={k} {bad}");
            }
        }
    }
    assert!(all_finite(&[]));
    assert!(all_finite(&[f64::MAX, -f64::MAX, f64::MIN_POSITIVE]));
}

/// Runs one operation `REPS` times for `perf stat -e cycles:u` (contention-robust timing). `OP` is
/// `full`, `schur`, `solve` (factored, symmetric Q), `solve_general`, `tri`; `N` the order.
#[test]
#[ignore]
fn timing_repeat() {
    let env = |k: &str, d: &str| std::env::var(k).unwrap_or_else(|_| d.to_string());
    let n: usize = env("N", "200").parse().unwrap();
    let reps: usize = env("REPS", "10").parse().unwrap();
    let op = env("OP", "full");
    let mut rng = Rng::new(0);
    let a = rng.matrix(n, n);
    let q = rng.psd(n, n);
    let qn = rng.matrix(n, n);
    let lyap = Lyapunov::new(&a).unwrap();
    let (t, z) = (&lyap.schur().t, &lyap.schur().z);
    let c0 = product_upper(z, true, &product(&q, false, z, false), false);
    for _ in 0..reps {
        match op.as_str() {
            "full" => drop(std::hint::black_box(solve_lyapunov(&a, &q).unwrap())),
            "schur" => drop(std::hint::black_box(RealSchur::new(&a).unwrap())),
            "solve" => drop(std::hint::black_box(lyap.solve(&q).unwrap())),
            "solve_general" => drop(std::hint::black_box(lyap.solve(&qn).unwrap())),
            "tri" => {
                let mut c = c0.clone();
                let mut ctx = Ctx::new(1e-300, Kind::Lyapunov);
                kernel::lyap(
                    &mut ctx,
                    View::new(t.as_slice(), n),
                    c.as_mut_slice(),
                    n,
                    (0, n),
                )
                .unwrap();
                std::hint::black_box(c);
            }
            _ => panic!("unknown OP"),
        }
    }
}

#[test]
fn singular_messages_are_readable() {
    let a = DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&[1.0, -1.0]));
    let Err(Error::SingularProblem(m)) = solve_lyapunov(&a, &DMatrix::identity(2, 2)) else {
        panic!("expected a singular error")
    };
    assert!(m.contains("λ_i ∈ {1}") && m.contains("λ_j ∈ {-1}"), "{m}");
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 2.0, -2.0, 0.0]);
    let Err(Error::SingularProblem(m)) = solve_lyapunov(&a, &DMatrix::identity(2, 2)) else {
        panic!("expected a singular error")
    };
    assert!(m.contains("0 ± 2i"), "{m}");
    let a = DMatrix::from_element(1, 1, 1e-300);
    let Err(Error::SingularProblem(m)) = solve_sylvester(&a, &(-&a), &DMatrix::identity(1, 1))
    else {
        panic!("expected a singular error")
    };
    assert!(m.contains("1.000000e-300"), "{m}");
}

#[test]
fn lyapunov_scalar_identity_and_schur_coordinates() {
    // Schur-coordinate solves skip both congruences: they must agree with the general route, in
    // both directions; αI (which is αI in every orthonormal basis) solves the equation either way.
    let mut rng = Rng::new(7);
    for &n in &SIZES {
        let a = rng.matrix(n, n) - DMatrix::identity(n, n) * (2.0 * (n as f64).sqrt() + 1.0);
        let lyap = Lyapunov::new(&a).unwrap();
        let eye = DMatrix::identity(n, n) * -1.5;
        let mut general = eye.clone();
        if n > 1 {
            general[(0, 1)] = 1e-300;
            general[(1, 0)] = 1e-300;
        }
        for adjoint in [false, true] {
            let (x, y) = if adjoint {
                (
                    lyap.solve_adjoint(&eye).unwrap(),
                    lyap.solve_adjoint(&general).unwrap(),
                )
            } else {
                (lyap.solve(&eye).unwrap(), lyap.solve(&general).unwrap())
            };
            assert_eq!(x, x.transpose());
            let scale = norm_fro(&y);
            assert!(norm_fro(&(&x - &y)) <= 1e-13 * n as f64 * scale, "n={n}");
            let at = if adjoint { a.transpose() } else { a.clone() };
            assert!(lyap_residual(&at, &x, &eye) <= 1e-13 * n as f64);
            // Schur coordinates: Zᵀ Q Z in, Zᵀ X Z out.
            let q = rng.psd(n, n.min(3)) - rng.psd(n, 2);
            let z = lyap.schur_vectors();
            let c = z.transpose() * &q * z;
            let c = (&c + c.transpose()) * 0.5;
            let xt = lyap.solve_schur_coordinates(c, adjoint).unwrap();
            assert_eq!(xt, xt.transpose());
            let full = z * &xt * z.transpose();
            let direct = if adjoint {
                lyap.solve_adjoint(&q).unwrap()
            } else {
                lyap.solve(&q).unwrap()
            };
            assert!(norm_fro(&(&full - &direct)) <= 1e-12 * n as f64 * norm_fro(&direct));
        }
    }
}
