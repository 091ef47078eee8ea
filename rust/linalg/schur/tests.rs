// Why this module is long: the unit tests of the real Schur form, its reordering and the Hessenberg
// reduction against LAPACK's own test matrices, in one place.
//! Tests of the real Schur form, the dlanv2 kernel and the reordering.

// Test matrices are written with 17 significant digits so they round-trip exactly.
#![allow(clippy::excessive_precision)]

use super::kernels::{lanv2, larfg, lartg};
use super::reorder::{rejection_threshold, small_sylvester, swap_accepted, swap_adjacent};
use super::RealSchur;
use crate::linalg::testing::Rng;
use crate::Error;
use nalgebra::DMatrix;

const EPS: f64 = f64::EPSILON;

/// Relative backward error `‖A − Z T Zᵀ‖_F / (n·eps·‖A‖_F)` and orthogonality
/// `‖ZᵀZ − I‖_F / (n·eps)`, both in units of `n·eps`.
fn errors(a: &DMatrix<f64>, s: &RealSchur) -> (f64, f64) {
    let n = a.nrows() as f64;
    // Scale A and T by the same power of two so that huge or tiny entries cannot overflow or
    // underflow in the check itself.
    let amax = a.amax();
    let f = if amax > 0.0 {
        2f64.powi(-(amax.log2().round() as i32))
    } else {
        1.0
    };
    let (a, t) = (a * f, &s.t * f);
    let r = &a - &s.z * &t * s.z.transpose();
    let anorm = a.norm();
    let back = if anorm == 0.0 {
        r.norm()
    } else {
        r.norm() / (n * EPS * anorm)
    };
    let o = s.z.transpose() * &s.z - DMatrix::identity(a.nrows(), a.nrows());
    (back, o.norm() / (n * EPS))
}

/// Asserts that T is quasi-triangular with exact zeros below the subdiagonal, no two adjacent
/// nonzero subdiagonals, and every 2×2 block standardised (`a = d`, `b·c < 0`).
fn assert_standardised(t: &DMatrix<f64>) {
    let n = t.nrows();
    for j in 0..n {
        for i in j + 2..n {
            assert_eq!(
                t[(i, j)],
                0.0,
                "T({i},{j}) below the subdiagonal is nonzero"
            );
        }
    }
    let mut k = 0;
    while k < n {
        if k + 1 < n && t[(k + 1, k)] != 0.0 {
            assert_eq!(
                t[(k, k)],
                t[(k + 1, k + 1)],
                "2×2 block at {k} has unequal diagonal"
            );
            let (b, c) = (t[(k, k + 1)], t[(k + 1, k)]);
            assert!(
                b != 0.0 && b.signum() != c.signum(),
                "2×2 block at {k} has b·c ≥ 0"
            );
            if k + 2 < n {
                assert_eq!(
                    t[(k + 2, k + 1)],
                    0.0,
                    "adjacent nonzero subdiagonals at {k}"
                );
            }
            k += 2;
        } else {
            k += 1;
        }
    }
}

/// Maximum distance of a greedy matching between two eigenvalue multisets.
pub(super) fn eig_distance(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut used = vec![false; b.len()];
    let mut worst = 0.0f64;
    for &(re, im) in a {
        let (mut best, mut bj) = (f64::INFINITY, usize::MAX);
        for (j, &(r2, i2)) in b.iter().enumerate() {
            if !used[j] {
                let d = (re - r2).hypot(im - i2);
                if d < best {
                    best = d;
                    bj = j;
                }
            }
        }
        used[bj] = true;
        worst = worst.max(best);
    }
    worst
}

fn reference_eigenvalues(a: &DMatrix<f64>) -> Vec<(f64, f64)> {
    a.clone()
        .complex_eigenvalues()
        .iter()
        .map(|c| (c.re, c.im))
        .collect()
}

/// Full check: decomposition, orthogonality, standardisation; returns (backward, orth) in n·eps.
pub(super) fn check(a: &DMatrix<f64>, s: &RealSchur, c: f64) -> (f64, f64) {
    assert_standardised(&s.t);
    let (b, o) = errors(a, s);
    assert!(
        b <= c,
        "backward error {b} n·eps exceeds {c} (n = {})",
        a.nrows()
    );
    assert!(
        o <= c,
        "orthogonality error {o} n·eps exceeds {c} (n = {})",
        a.nrows()
    );
    (b, o)
}

#[test]
fn random_matrices_are_decomposed_stably() {
    let mut rng = Rng::new(1);
    let mut worst = (0.0f64, 0.0f64);
    for &n in &[1usize, 2, 3, 4, 5, 7, 10, 23, 50, 200] {
        let reps = if n <= 10 { 20 } else { 2 };
        for _ in 0..reps {
            let a = rng.matrix(n, n);
            let s = RealSchur::new(&a).unwrap();
            let (b, o) = check(&a, &s, 10.0);
            worst = (worst.0.max(b), worst.1.max(o));
            if n <= 50 {
                let d = eig_distance(&s.eigenvalues(), &reference_eigenvalues(&a));
                assert!(d <= 1e-8 * a.norm(), "eigenvalues differ by {d} (n = {n})");
            }
        }
    }
    eprintln!(
        "random: worst backward {:.3} n·eps, orthogonality {:.3} n·eps",
        worst.0, worst.1
    );
}

#[test]
fn prescribed_complex_pairs_and_real_eigenvalues() {
    let mut rng = Rng::new(2);
    for &(nr, np) in &[(0usize, 1usize), (0, 5), (1, 4), (3, 10), (0, 40), (10, 45)] {
        let real: Vec<f64> = (0..nr).map(|k| -2.0 + k as f64 * 0.37).collect();
        let pairs: Vec<(f64, f64)> = (0..np)
            .map(|k| (0.5 - 0.11 * k as f64, 0.3 + 0.07 * k as f64))
            .collect();
        let a = rng.with_eigenvalues(&real, &pairs);
        let s = RealSchur::new(&a).unwrap();
        check(&a, &s, 10.0);
        let mut expect: Vec<(f64, f64)> = real.iter().map(|&r| (r, 0.0)).collect();
        for &(re, im) in &pairs {
            expect.push((re, im));
            expect.push((re, -im));
        }
        let got = s.eigenvalues();
        assert_eq!(
            got.iter().filter(|e| e.1 != 0.0).count(),
            2 * np,
            "wrong number of complex eigenvalues"
        );
        let d = eig_distance(&got, &expect);
        assert!(d <= 1e-9, "eigenvalue error {d}");
    }
}

#[test]
fn clustered_nearly_equal_and_repeated_eigenvalues() {
    let mut rng = Rng::new(3);
    // Clusters of nearly equal real eigenvalues and complex pairs.
    let real: Vec<f64> = (0..12).map(|k| 1.0 + 1e-9 * k as f64).collect();
    let pairs: Vec<(f64, f64)> = (0..6).map(|k| (-1.0 + 1e-10 * k as f64, 1.0)).collect();
    let a = rng.with_eigenvalues(&real, &pairs);
    let s = RealSchur::new(&a).unwrap();
    check(&a, &s, 10.0);
    // Exactly repeated eigenvalues (a multiple of a non-trivial orthogonal similarity of I + N).
    let real = vec![2.0; 8];
    let a = rng.with_eigenvalues(&real, &[(0.0, 3.0), (0.0, 3.0)]);
    let s = RealSchur::new(&a).unwrap();
    check(&a, &s, 10.0);
    // Repeated eigenvalues with trivial Jordan structure.
    let q = rng.orthogonal(9);
    let d = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![
        3.0, 3.0, 3.0, -1.0, -1.0, 0.5, 0.5, 0.5, 0.5,
    ]));
    let a = &q * d * q.transpose();
    let s = RealSchur::new(&a).unwrap();
    check(&a, &s, 10.0);
    let e = s.eigenvalues();
    for &(re, im) in &e {
        assert!(im == 0.0);
        assert!(
            [3.0, -1.0, 0.5].iter().any(|&x| (x - re).abs() < 1e-12),
            "{re}"
        );
    }
}

#[test]
fn jordan_blocks() {
    let mut rng = Rng::new(4);
    for &n in &[2usize, 3, 6, 12, 30] {
        // A single Jordan block J_n(λ), hidden by an orthogonal similarity.
        let lambda = 0.7;
        let mut j = DMatrix::from_element(n, n, 0.0);
        for i in 0..n {
            j[(i, i)] = lambda;
            if i + 1 < n {
                j[(i, i + 1)] = 1.0;
            }
        }
        let q = rng.orthogonal(n);
        let a = &q * &j * q.transpose();
        let s = RealSchur::new(&a).unwrap();
        check(&a, &s, 10.0);
        // Eigenvalues of a Jordan block are perturbed by O(eps^(1/n)); their mean is exact.
        let e = s.eigenvalues();
        let mean: f64 = e.iter().map(|x| x.0).sum::<f64>() / n as f64;
        assert!((mean - lambda).abs() < 1e-10 * n as f64, "mean {mean}");
        for &(re, im) in &e {
            assert!((re - lambda).hypot(im) < 10.0 * EPS.powf(1.0 / n as f64));
        }
        // Jordan form itself (already upper triangular).
        let s = RealSchur::new(&j).unwrap();
        check(&j, &s, 10.0);
    }
}

#[test]
fn huge_tiny_and_graded_entries() {
    let mut rng = Rng::new(5);
    for &scale in &[1e150, 1e-150, 1e300, 1e-300, 1e-310] {
        for &n in &[2usize, 5, 20] {
            let b = rng.matrix(n, n);
            let a = &b * scale;
            let s = RealSchur::new(&a).unwrap();
            if scale >= 1e-300 {
                check(&a, &s, 10.0);
                // The eigenvalues scale exactly with the matrix.
                let sb = RealSchur::new(&b).unwrap();
                let eb: Vec<(f64, f64)> = sb
                    .eigenvalues()
                    .iter()
                    .map(|&(r, i)| (r * scale, i * scale))
                    .collect();
                let d = eig_distance(&s.eigenvalues(), &eb);
                assert!(d <= 1e-10 * scale * b.norm(), "n={n} scale={scale}: {d}");
            } else {
                // Subnormal entries: only finiteness and structure can be asked for.
                assert_standardised(&s.t);
                assert!(s.t.iter().chain(s.z.iter()).all(|v| v.is_finite()));
            }
        }
    }
    // Graded matrices a_ij · 10^(−(i+j)) in both directions.
    for &n in &[6usize, 12] {
        let b = rng.matrix(n, n);
        for dir in [1.0f64, -1.0] {
            let a = DMatrix::from_fn(n, n, |i, j| b[(i, j)] * 10f64.powf(dir * -((i + j) as f64)));
            let s = RealSchur::new(&a).unwrap();
            check(&a, &s, 10.0);
        }
    }
    // Wildly different scales within one matrix.
    let mut a = rng.matrix(8, 8);
    a[(0, 7)] = 1e200;
    a[(7, 0)] = 1e-200;
    a[(3, 3)] = -1e100;
    let s = RealSchur::new(&a).unwrap();
    check(&a, &s, 10.0);
}

#[test]
fn special_matrices() {
    // Zero matrix.
    for &n in &[1usize, 2, 3, 10] {
        let a = DMatrix::<f64>::zeros(n, n);
        let s = RealSchur::new(&a).unwrap();
        assert!(s.t.iter().all(|&v| v == 0.0));
        check(&a, &s, 1.0);
    }
    // Identity and already upper triangular matrices: T equals A up to signs, Z is a signed identity.
    let mut rng = Rng::new(6);
    for &n in &[1usize, 2, 5, 17] {
        let mut a = rng.matrix(n, n);
        for j in 0..n {
            for i in j + 1..n {
                a[(i, j)] = 0.0;
            }
        }
        let s = RealSchur::new(&a).unwrap();
        check(&a, &s, 2.0);
        for i in 0..n {
            assert_eq!(s.t[(i, i)], a[(i, i)]);
        }
        let i_n = DMatrix::<f64>::identity(n, n);
        let s = RealSchur::new(&i_n).unwrap();
        assert_eq!(s.t, i_n);
    }
    // 1×1.
    let a = DMatrix::from_element(1, 1, -3.5);
    let s = RealSchur::new(&a).unwrap();
    assert_eq!(s.t[(0, 0)], -3.5);
    assert_eq!(s.z[(0, 0)], 1.0);
    assert_eq!(s.blocks(), vec![(0, 1)]);
    assert_eq!(s.eigenvalues(), vec![(-3.5, 0.0)]);
    // A rotation generator (purely imaginary eigenvalues) and a permutation (roots of unity).
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, 0.0]);
    let s = RealSchur::new(&a).unwrap();
    check(&a, &s, 1.0);
    assert_eq!(s.eigenvalues(), vec![(0.0, 1.0), (0.0, -1.0)]);
    let n = 7;
    let p = DMatrix::from_fn(n, n, |i, j| if (i + 1) % n == j { 1.0 } else { 0.0 });
    let s = RealSchur::new(&p).unwrap();
    check(&p, &s, 10.0);
    let mut expect = Vec::new();
    for k in 0..n {
        let th = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        expect.push((th.cos(), th.sin()));
    }
    assert!(eig_distance(&s.eigenvalues(), &expect) < 1e-12);
    // Companion-like matrix with a zero subdiagonal in the middle (already deflated).
    let mut a = rng.matrix(6, 6);
    for j in 0..6 {
        for i in j + 2..6 {
            a[(i, j)] = 0.0;
        }
    }
    a[(3, 2)] = 0.0;
    let s = RealSchur::new(&a).unwrap();
    check(&a, &s, 10.0);
}

#[test]
fn two_by_two_cases_cover_every_lanv2_branch() {
    let cases: &[[f64; 4]] = &[
        [1.0, 2.0, 0.0, 3.0],    // c = 0: already triangular
        [1.0, 0.0, 2.0, 3.0],    // b = 0: swap rows and columns
        [1.0, 2.0, -3.0, 1.0],   // a = d, sign(b) ≠ sign(c): already standard
        [4.0, 1.0, 2.0, -1.0],   // distinct real eigenvalues (z ≥ 4 eps)
        [1.0, -5.0, 2.0, 3.0],   // complex pair
        [1.0, 1.0, 1e-17, 1.0],  // nearly equal real eigenvalues: complex branch, b·c > 0 → split
        [1.0, 1.0, -1e-17, 1.0], // nearly equal, complex with tiny imaginary part
        [2.0, 1e-300, -1e-300, 2.0],
        [1e300, -1e300, 1e300, -1e300], // b + c and a − d overflow-prone
        [0.0, 0.0, 0.0, 0.0],
        [3.0, 0.0, 0.0, 3.0],
        [1.0, 1.0, -1.0, 1.0 + 1e-15], // complex branch, c becomes ... , b ≠ 0
    ];
    for &[a, b, c, d] in cases {
        let r = lanv2(a, b, c, d);
        // Reconstruct [A B; C D] = [cs −sn; sn cs]·[a b; c d]·[cs sn; −sn cs].
        let rot = DMatrix::from_row_slice(2, 2, &[r.cs, -r.sn, r.sn, r.cs]);
        let m = DMatrix::from_row_slice(2, 2, &[r.a, r.b, r.c, r.d]);
        let orig = DMatrix::from_row_slice(2, 2, &[a, b, c, d]);
        let back = &rot * m * rot.transpose();
        let scale = orig.amax().max(f64::MIN_POSITIVE);
        assert!(
            (back - &orig).amax() <= 8.0 * EPS * scale,
            "lanv2 {a} {b} {c} {d}: {r:?}"
        );
        assert!((r.cs * r.cs + r.sn * r.sn - 1.0).abs() < 4.0 * EPS);
        assert!(
            r.c == 0.0 || (r.a == r.d && r.b != 0.0 && r.b.signum() != r.c.signum()),
            "not standard: {r:?}"
        );
        // Through the public API as well.
        let s = RealSchur::new(&orig).unwrap();
        check(&orig, &s, 10.0);
    }
    // Eigenvalues of the standard forms.
    let r = lanv2(1.0, -5.0, 2.0, 3.0);
    let e = r.eigenvalues();
    assert!(
        (e[0].0 - 2.0).abs() < 1e-14 && (e[0].1 - 3.0).abs() < 1e-14,
        "{e:?}"
    );
    let r = lanv2(4.0, 1.0, 2.0, -1.0);
    let mut ev = [r.a, r.d];
    ev.sort_by(f64::total_cmp);
    let disc = (25.0f64 + 8.0).sqrt();
    assert!(
        (ev[0] - (3.0 - disc) / 2.0).abs() < 1e-14 && (ev[1] - (3.0 + disc) / 2.0).abs() < 1e-14
    );
}

#[test]
fn reflector_and_rotation_kernels() {
    let mut x = [3.0, 4.0];
    let (beta, tau) = larfg(1.0, &mut x);
    // H·(1, 3, 4) = (beta, 0, 0) with H = I − τ v vᵀ, v = (1, x).
    let v = [1.0, x[0], x[1]];
    let y = [1.0, 3.0, 4.0];
    let s: f64 = v.iter().zip(y).map(|(a, b)| a * b).sum();
    let hy: Vec<f64> = (0..3).map(|i| y[i] - tau * s * v[i]).collect();
    assert!((hy[0] - beta).abs() < 1e-14 && hy[1].abs() < 1e-14 && hy[2].abs() < 1e-14);
    assert!((beta.abs() - 26f64.sqrt()).abs() < 1e-14);
    // Tiny inputs take the rescaling path.
    let mut x = [3e-310, 0.0];
    let (beta, tau) = larfg(4e-310, &mut x);
    assert!(beta.is_finite() && tau.is_finite() && (beta.abs() - 5e-310).abs() < 1e-320);
    let mut x = [0.0];
    assert_eq!(larfg(2.0, &mut x), (2.0, 0.0));
    for &(f, g) in &[(3.0, 4.0), (0.0, -2.0), (5.0, 0.0), (-1.0, 1e-300)] {
        let (cs, sn, r) = lartg(f, g);
        assert!((cs * f + sn * g - r).abs() <= 4.0 * EPS * r.abs());
        assert!((-sn * f + cs * g).abs() <= 4.0 * EPS * r.abs());
    }
}

#[test]
fn invalid_inputs_are_rejected() {
    assert!(matches!(
        RealSchur::new(&DMatrix::zeros(2, 3)),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        RealSchur::new(&DMatrix::zeros(0, 0)),
        Err(Error::Shape(_))
    ));
    let mut a = DMatrix::<f64>::identity(3, 3);
    a[(1, 2)] = f64::NAN;
    assert!(matches!(RealSchur::new(&a), Err(Error::NonFinite(_))));
    a[(1, 2)] = f64::INFINITY;
    assert!(matches!(RealSchur::new(&a), Err(Error::NonFinite(_))));
    let mut s = RealSchur::new(&DMatrix::identity(3, 3)).unwrap();
    assert!(matches!(s.reorder_to(3, 0), Err(Error::Shape(_))));
}

/// Checks a reordering of `s0` (the Schur form of `a`) by `lhp`.
fn check_lhp_reorder(a: &DMatrix<f64>, s0: &RealSchur, c: f64) -> usize {
    let mut s = s0.clone();
    let before = s.eigenvalues();
    let expected = before.iter().filter(|e| e.0 < 0.0).count();
    let sdim = s.reorder(|re, _| re < 0.0).unwrap();
    assert_eq!(sdim, expected);
    check(a, &s, c);
    let after = s.eigenvalues();
    let tol = 1e-10 * a.norm().max(1.0);
    assert!(eig_distance(&after, &before) <= tol);
    let sel: Vec<(f64, f64)> = before.iter().copied().filter(|e| e.0 < 0.0).collect();
    assert!(
        eig_distance(&after[..sdim], &sel) <= tol,
        "selected eigenvalues moved wrong"
    );
    // sdim never splits a 2×2 block.
    assert!(sdim == a.nrows() || sdim == 0 || s.t[(sdim, sdim - 1)] == 0.0);
    sdim
}

#[test]
fn reorder_left_half_plane_random() {
    let mut rng = Rng::new(7);
    let mut worst = (0.0f64, 0.0f64);
    for &n in &[1usize, 2, 3, 4, 5, 8, 10, 31, 50, 200] {
        let reps = if n <= 10 { 15 } else { 2 };
        for _ in 0..reps {
            let a = rng.matrix(n, n);
            let s = RealSchur::new(&a).unwrap();
            check_lhp_reorder(&a, &s, 20.0);
            let mut s2 = s.clone();
            s2.reorder(|re, _| re < 0.0).unwrap();
            let (b, o) = errors(&a, &s2);
            worst = (worst.0.max(b), worst.1.max(o));
        }
    }
    eprintln!(
        "reorder: worst backward {:.3} n·eps, orthogonality {:.3} n·eps",
        worst.0, worst.1
    );
}

#[test]
fn reorder_mixed_blocks_and_clusters() {
    let mut rng = Rng::new(8);
    // Many complex pairs on both sides of the imaginary axis, interleaved with real eigenvalues.
    let real = [-3.0, 2.0, -0.5, 0.25, 1.5, -2.5];
    let pairs = [
        (-1.0, 2.0),
        (1.0, 0.5),
        (-0.2, 0.1),
        (0.3, 3.0),
        (-2.0, 1.0),
        (2.0, 2.0),
        (-0.7, 0.7),
    ];
    for _ in 0..5 {
        let a = rng.with_eigenvalues(&real, &pairs);
        let s = RealSchur::new(&a).unwrap();
        let sdim = check_lhp_reorder(&a, &s, 20.0);
        assert_eq!(sdim, 3 + 2 * 4);
    }
    // Clustered eigenvalues on both sides.
    let real: Vec<f64> = (0..10)
        .map(|k| {
            if k % 2 == 0 {
                -1.0 - 1e-8 * k as f64
            } else {
                1.0 + 1e-8 * k as f64
            }
        })
        .collect();
    let pairs: Vec<(f64, f64)> = (0..6)
        .map(|k| (if k % 2 == 0 { -0.5 } else { 0.5 }, 1.0 + 1e-9 * k as f64))
        .collect();
    let a = rng.with_eigenvalues(&real, &pairs);
    let s = RealSchur::new(&a).unwrap();
    assert_eq!(check_lhp_reorder(&a, &s, 20.0), 5 + 6);
    // A Hamiltonian matrix [[A, −G], [−Q, −Aᵀ]] as the CARE solver will use.
    let n = 30;
    let am = rng.matrix(n, n);
    let g = rng.psd(n, 3);
    let q = rng.psd(n, n);
    let mut h = DMatrix::zeros(2 * n, 2 * n);
    h.view_mut((0, 0), (n, n)).copy_from(&am);
    h.view_mut((0, n), (n, n)).copy_from(&(-&g));
    h.view_mut((n, 0), (n, n)).copy_from(&(-&q));
    h.view_mut((n, n), (n, n)).copy_from(&(-am.transpose()));
    let s = RealSchur::new(&h).unwrap();
    assert_eq!(check_lhp_reorder(&h, &s, 20.0), n);
    // Select everything / nothing: no-op.
    let mut s2 = s.clone();
    assert_eq!(s2.reorder(|_, _| true).unwrap(), 2 * n);
    assert_eq!(s2.t, s.t);
    assert_eq!(s2.reorder(|_, _| false).unwrap(), 0);
    assert_eq!(s2.t, s.t);
    // Select by imaginary part: complex pairs first.
    let mut s3 = s.clone();
    let ncplx = s.eigenvalues().iter().filter(|e| e.1 != 0.0).count();
    assert_eq!(s3.reorder(|_, im| im != 0.0).unwrap(), ncplx);
    check(&h, &s3, 20.0);
    assert!(s3.eigenvalues()[..ncplx].iter().all(|e| e.1 != 0.0));
}

#[test]
fn reorder_to_moves_blocks_both_ways() {
    let mut rng = Rng::new(9);
    let a = rng.with_eigenvalues(&[5.0, -4.0, 3.0], &[(1.0, 1.0), (-2.0, 0.5), (0.0, 2.0)]);
    let s0 = RealSchur::new(&a).unwrap();
    let n = a.nrows();
    for ifst in 0..n {
        for ilst in 0..n {
            let mut s = s0.clone();
            let before = s.eigenvalues();
            let blocks = s.blocks();
            let start = if ifst > 0 && s.t[(ifst, ifst - 1)] != 0.0 {
                ifst - 1
            } else {
                ifst
            };
            let moved = before[start];
            let pos = s.reorder_to(ifst, ilst).unwrap();
            check(&a, &s, 20.0);
            let after = s.eigenvalues();
            assert!(eig_distance(&after, &before) < 1e-10);
            let e = after[pos];
            assert!((e.0 - moved.0).abs() < 1e-10 && (e.1.abs() - moved.1.abs()).abs() < 1e-10);
            assert!(
                pos.abs_diff(ilst) <= 1,
                "{ifst}->{ilst} ended at {pos} ({blocks:?})"
            );
        }
    }
}

#[test]
fn small_sylvester_solves_all_shapes() {
    let mut rng = Rng::new(10);
    for &(n1, n2) in &[(1usize, 1usize), (1, 2), (2, 1), (2, 2)] {
        for _ in 0..20 {
            let mut t11 = [[0.0; 2]; 2];
            let mut t22 = [[0.0; 2]; 2];
            let mut b = [[0.0; 2]; 2];
            for i in 0..2 {
                for j in 0..2 {
                    t11[i][j] = rng.normal();
                    t22[i][j] = rng.normal();
                    b[i][j] = rng.normal();
                }
            }
            let (x, scale, perturbed) = small_sylvester(&t11, n1, &t22, n2, &b);
            assert!(!perturbed && scale == 1.0);
            for i in 0..n1 {
                for j in 0..n2 {
                    let mut r = -scale * b[i][j];
                    for k in 0..n1 {
                        r += t11[i][k] * x[k][j];
                    }
                    for k in 0..n2 {
                        r -= x[i][k] * t22[k][j];
                    }
                    assert!(
                        r.abs() < 1e-12 * (1.0 + x.iter().flatten().map(|v| v.abs()).sum::<f64>())
                    );
                }
            }
        }
    }
    // Common eigenvalues: the pivot is perturbed and the result stays finite.
    let t = [[1.0, 2.0], [-0.5, 1.0]];
    let (x, scale, perturbed) = small_sylvester(&t, 2, &t, 2, &[[1.0, 2.0], [3.0, 4.0]]);
    assert!(perturbed && scale > 0.0 && x.iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn rejection_predicate() {
    let dnorm = 3.0;
    let thr = rejection_threshold(dnorm);
    assert_eq!(thr, 20.0 * EPS * 3.0);
    assert!(swap_accepted(0.0, dnorm));
    assert!(swap_accepted(thr, dnorm));
    assert!(!swap_accepted(thr * 1.01, dnorm));
    assert!(!swap_accepted(f64::NAN, dnorm));
    // For a zero block the threshold is smlnum, not zero.
    assert!(swap_accepted(1e-300, 0.0));
}

/// A 4×4 quasi-triangular matrix with two strongly coupled 2×2 blocks whose complex eigenvalues
/// `2.4519 ± 1e-13·i` and `2.4519… + 5e-8 ± 1e-13·i` nearly coincide. LAPACK's dtrexc (through
/// `scipy.linalg.lapack.dtrexc`) rejects this swap too (info = 1).
pub(super) fn rejected_pair() -> DMatrix<f64> {
    DMatrix::from_row_slice(
        4,
        4,
        &[
            2.45189738922467981e0,
            1.43923049447399864e-1,
            1.12426237395638910e1,
            3.95458596388094197e0, //
            -4.01010156524999367e-24,
            2.45189738922467981e0,
            9.95507960689545257e0,
            -1.51619323311102701e1, //
            0.0,
            0.0,
            2.45189744173952029e0,
            2.04979231121078437e-1, //
            0.0,
            0.0,
            -2.81563182137051801e-24,
            2.45189744173952029e0,
        ],
    )
}

/// The milder case (residual ≈ 28× the threshold) that dtrexc rejects as well.
fn rejected_pair_mild() -> DMatrix<f64> {
    DMatrix::from_row_slice(
        4,
        4,
        &[
            -4.54034684721300097e-1,
            1.70414204539781844e0,
            -4.24725836205821938e0,
            -2.08042833535424565e0, //
            -3.52313361277669092e-12,
            -4.54034684721300097e-1,
            2.35682634107511957e0,
            3.76835987560501096e0, //
            0.0,
            0.0,
            -4.54034682454958038e-1,
            1.05943198691197133e-2, //
            0.0,
            0.0,
            -5.66711237272274677e-10,
            -4.54034682454958038e-1,
        ],
    )
}

#[test]
fn rejected_swaps_leave_the_factorisation_unchanged() {
    let t = rejected_pair();
    let n = 4;
    let mut tt = t.clone();
    let mut z = DMatrix::<f64>::identity(n, n);
    let res = swap_adjacent(tt.as_mut_slice(), z.as_mut_slice(), n, 0, 2, 2);
    let rej = res.expect_err("swap of coupled blocks with equal eigenvalues must be rejected");
    assert!(rej.residual > rej.threshold);
    assert_eq!(tt, t);
    assert_eq!(z, DMatrix::identity(n, n));
    let t2 = rejected_pair_mild();
    let mut tt = t2.clone();
    let rej =
        swap_adjacent(tt.as_mut_slice(), z.as_mut_slice(), n, 0, 2, 2).expect_err("mild case");
    assert!(rej.residual > rej.threshold && rej.residual < 100.0 * rej.threshold);
    assert_eq!(tt, t2);
    // Through the public API: embedded in a larger Schur form, reorder fails and restores T, Z.
    let mut rng = Rng::new(11);
    let m = 7;
    let mut big = rng.matrix(m, m);
    for j in 0..m {
        for i in j + 1..m {
            big[(i, j)] = 0.0;
        }
    }
    big.view_mut((2, 2), (4, 4)).copy_from(&t);
    big[(6, 6)] = -3.0;
    let q = rng.orthogonal(m);
    let mut s = RealSchur {
        t: big.clone(),
        z: q.clone(),
    };
    assert_eq!(s.blocks(), vec![(0, 1), (1, 1), (2, 2), (4, 2), (6, 1)]);
    let res = s.reorder_to(4, 2);
    assert!(matches!(res, Err(Error::Reorder(_))), "{res:?}");
    assert_eq!(s.t, big);
    assert_eq!(s.z, q);
    // reorder() selecting the second block of the pair fails the same way and restores T, Z.
    let second = s.eigenvalues()[4].0;
    let res = s.reorder(|re, _| re == second);
    assert!(matches!(res, Err(Error::Reorder(_))), "{res:?}");
    assert_eq!(s.t, big);
    assert_eq!(s.z, q);
    // Moving the trailing −3 past the pair is well conditioned: it succeeds.
    let res = s.reorder(|re, _| re < -2.0);
    assert_eq!(res, Ok(1));
    assert_standardised(&s.t);
    let a = &q * &big * q.transpose();
    check(&a, &s, 20.0);
}

#[test]
fn nearly_equal_neighbour_exercises_the_rejection_test() {
    // A 1×1 block next to a 2×2 block whose eigenvalues are a ± 1e-9·i, strongly coupled.
    for &im2 in &[1e-6f64, 1e-9, 1e-12] {
        let (b, c) = (1.0, -im2 * im2);
        let t = DMatrix::from_row_slice(
            3,
            3,
            &[
                0.5, 1.0, 1.0, //
                0.0, 0.5, b, //
                0.0, c, 0.5,
            ],
        );
        let mut s = RealSchur {
            t: t.clone(),
            z: DMatrix::identity(3, 3),
        };
        match s.reorder_to(1, 0) {
            Ok(_) => {
                // Accepted: the result must be an accurate Schur form of the same matrix.
                check(&t, &s, 20.0);
            }
            Err(Error::Reorder(_)) => {
                assert_eq!(s.t, t);
                assert_eq!(s.z, DMatrix::identity(3, 3));
            }
            Err(e) => panic!("unexpected error {e:?}"),
        }
    }
}

// ---- The multishift QR with aggressive early deflation (orders ≥ multishift::NMIN) ----

use super::multishift::{Stats, NMIN, STATS};

fn last_stats() -> Stats {
    STATS.with(|c| c.get())
}

/// Schur form, full check (in units of n·eps) and eigenvalues against nalgebra within `tol·‖A‖_F`.
fn check_large(a: &DMatrix<f64>, tol: f64) -> (RealSchur, (f64, f64)) {
    let s = RealSchur::new(a).unwrap();
    let errs = check(a, &s, 10.0);
    if tol > 0.0 {
        let d = eig_distance(&s.eigenvalues(), &reference_eigenvalues(a));
        assert!(
            d <= tol * a.norm(),
            "eigenvalues differ from nalgebra's by {d} (n = {})",
            a.nrows()
        );
    }
    (s, errs)
}

#[test]
fn multishift_random_matrices() {
    let mut rng = Rng::new(11);
    let mut worst = (0.0f64, 0.0f64);
    for &n in &[NMIN, 80, 128, 200, 301, 500] {
        let a = rng.matrix(n, n);
        let (_, (b, o)) = check_large(&a, 1e-9);
        let st = last_stats();
        assert!(st.aed_calls > 0 && st.fallbacks == 0, "{st:?}");
        worst = (worst.0.max(b), worst.1.max(o));
    }
    eprintln!(
        "multishift random: worst backward {:.3} n·eps, orthogonality {:.3} n·eps",
        worst.0, worst.1
    );
}

#[test]
fn multishift_many_complex_pairs_and_prescribed_spectra() {
    let mut rng = Rng::new(12);
    for &(nr, np) in &[(0usize, 60usize), (1, 80), (40, 60), (150, 2)] {
        let real: Vec<f64> = (0..nr).map(|k| -3.0 + 0.013 * k as f64).collect();
        let pairs: Vec<(f64, f64)> = (0..np)
            .map(|k| (0.7 - 0.021 * k as f64, 0.2 + 0.031 * k as f64))
            .collect();
        let a = rng.with_eigenvalues(&real, &pairs);
        let (s, _) = check_large(&a, 0.0);
        let got = s.eigenvalues();
        let mut expect: Vec<(f64, f64)> = real.iter().map(|&r| (r, 0.0)).collect();
        for &(re, im) in &pairs {
            expect.push((re, im));
            expect.push((re, -im));
        }
        // These spectra are somewhat ill-conditioned (non-normal upper part): compare with the
        // error of nalgebra's eigenvalues and of the double-shift path.
        let d = eig_distance(&got, &expect);
        let d_ref = eig_distance(&reference_eigenvalues(&a), &expect);
        let n = a.nrows();
        let mut h = a.clone();
        let zv = super::hqr::hessenberg_reduce(h.as_mut_slice(), n).unwrap();
        let mut z = DMatrix::from_vec(n, n, zv);
        super::hqr::francis_qr_window(h.as_mut_slice(), z.as_mut_slice(), n, 0, n - 1).unwrap();
        let d_ds = eig_distance(&RealSchur { t: h, z }.eigenvalues(), &expect);
        eprintln!(
            "{nr} real, {np} pairs: error {d:.2e}, nalgebra {d_ref:.2e}, double-shift {d_ds:.2e}"
        );
        let ncplx = |e: &[(f64, f64)]| e.iter().filter(|e| e.1 != 0.0).count();
        if nr <= 1 {
            assert_eq!(ncplx(&got), 2 * np);
        } else {
            // Dense clusters of real eigenvalues of a non-normal matrix: some pairs of close real
            // eigenvalues come out as complex pairs in every method; only compare counts loosely.
            let nref = ncplx(&reference_eigenvalues(&a));
            assert!(
                ncplx(&got).abs_diff(nref) <= 10,
                "{} vs {nref}",
                ncplx(&got)
            );
        }
        assert!(
            d <= 1e-9f64.max(10.0 * d_ref.max(d_ds)),
            "eigenvalue error {d} ({nr} real, {np} pairs; nalgebra {d_ref}, double-shift {d_ds})"
        );
    }
}

#[test]
fn multishift_clustered_and_repeated_eigenvalues() {
    let mut rng = Rng::new(13);
    // Tight clusters of real eigenvalues and of complex pairs.
    let real: Vec<f64> = (0..60).map(|k| 1.0 + 1e-10 * (k % 7) as f64).collect();
    let pairs: Vec<(f64, f64)> = (0..30).map(|k| (-1.0 + 1e-11 * k as f64, 2.0)).collect();
    let a = rng.with_eigenvalues(&real, &pairs);
    check_large(&a, 0.0);
    // Exactly repeated eigenvalues with trivial Jordan structure.
    let n = 120;
    let q = rng.orthogonal(n);
    let d = DMatrix::from_fn(
        n,
        n,
        |i, j| {
            if i == j {
                [3.0, -1.0, 0.5][i % 3]
            } else {
                0.0
            }
        },
    );
    let a = &q * d * q.transpose();
    let (s, _) = check_large(&a, 0.0);
    for &(re, im) in &s.eigenvalues() {
        assert!(
            im.abs() < 1e-12 && [3.0, -1.0, 0.5].iter().any(|&x| (x - re).abs() < 1e-12),
            "({re}, {im})"
        );
    }
    // A large Jordan-like block: eigenvalue 2 of multiplicity 100 with a nilpotent part.
    let n = 100;
    let mut b = DMatrix::<f64>::identity(n, n) * 2.0;
    for i in 0..n - 1 {
        b[(i, i + 1)] = 1.0;
    }
    let q = rng.orthogonal(n);
    let a = &q * b * q.transpose();
    check_large(&a, 0.0);
}

#[test]
fn multishift_graded_and_badly_scaled() {
    let mut rng = Rng::new(14);
    let n = 120;
    let b = rng.matrix(n, n);
    // Graded both ways: a_ij · g^(i+j) with entries spanning about 40 orders of magnitude.
    for dir in [1.0f64, -1.0] {
        let a = DMatrix::from_fn(n, n, |i, j| {
            b[(i, j)] * 10f64.powf(dir * -0.15 * (i + j) as f64)
        });
        check_large(&a, 0.0);
    }
    // Diagonal similarity with wildly different scales (eigenvalues those of b).
    let dscale: Vec<f64> = (0..n)
        .map(|i| 2f64.powi((i as i32 % 17) * 6 - 48))
        .collect();
    let a = DMatrix::from_fn(n, n, |i, j| b[(i, j)] * dscale[i] / dscale[j]);
    check_large(&a, 0.0);
    // Huge and tiny overall scale.
    for &scale in &[1e200, 1e-200] {
        let a = &b * scale;
        let s = RealSchur::new(&a).unwrap();
        check(&a, &s, 10.0);
    }
}

#[test]
fn multishift_aed_deflates_nearly_triangular_matrices_at_once() {
    let mut rng = Rng::new(15);
    let n = 200;
    // Upper triangular with distinct diagonal plus a tiny Hessenberg perturbation: every
    // eigenvalue is found by aggressive early deflation, no sweep is needed.
    let mut a = DMatrix::from_fn(n, n, |i, j| if i <= j { rng.normal() } else { 0.0 });
    for i in 0..n {
        a[(i, i)] = i as f64 + 1.0;
    }
    for i in 1..n {
        a[(i, i - 1)] = 1e-15 * rng.normal();
    }
    let (s, _) = check_large(&a, 1e-12);
    let st = last_stats();
    assert_eq!(st.sweeps, 0, "{st:?}");
    assert!(st.aed_deflated >= n - NMIN, "{st:?}");
    for (k, &(re, im)) in s.eigenvalues().iter().enumerate() {
        assert_eq!(im, 0.0);
        assert!((re.round() - re).abs() < 1e-10, "eigenvalue {k}: {re}");
    }
}

#[test]
fn multishift_without_early_deflation() {
    // The cyclic shift (all eigenvalues on the unit circle, all subdiagonals 1): the first AED
    // finds nothing to deflate and the iteration needs sweeps and exceptional shifts.
    for &n in &[NMIN, 100, 160] {
        let a = DMatrix::from_fn(n, n, |i, j| {
            if i == j + 1 || (i == 0 && j == n - 1) {
                1.0
            } else {
                0.0
            }
        });
        let (s, _) = check_large(&a, 0.0);
        let st = last_stats();
        assert_eq!(st.first_aed_deflated, Some(0), "{st:?}");
        assert!(st.sweeps > 0, "{st:?}");
        for &(re, im) in &s.eigenvalues() {
            assert!((re.hypot(im) - 1.0).abs() < 1e-10, "({re}, {im})");
        }
    }
    // A random Hessenberg matrix with subdiagonal entries of order one deflates nothing early.
    let mut rng = Rng::new(16);
    let n = 150;
    let a = DMatrix::from_fn(n, n, |i, j| {
        if i <= j + 1 {
            rng.normal() + if i == j + 1 { 3.0 } else { 0.0 }
        } else {
            0.0
        }
    });
    check_large(&a, 1e-9);
    assert_eq!(last_stats().first_aed_deflated, Some(0));
}

#[test]
fn multishift_special_structures() {
    let mut rng = Rng::new(17);
    let n = 100;
    // Zero, identity, diagonal, already triangular, reducible (zero subdiagonals) and a
    // Hamiltonian matrix as the CARE solver builds it.
    let zero = DMatrix::<f64>::zeros(n, n);
    let s = RealSchur::new(&zero).unwrap();
    assert!(s.t.iter().all(|&v| v == 0.0));
    check_large(&DMatrix::<f64>::identity(n, n), 0.0);
    let diag = DMatrix::from_fn(n, n, |i, j| if i == j { rng.normal() } else { 0.0 });
    check_large(&diag, 1e-12);
    let tri = DMatrix::from_fn(n, n, |i, j| if i <= j { rng.normal() } else { 0.0 });
    check_large(&tri, 1e-10);
    let mut red = rng.matrix(n, n);
    for j in 0..n {
        for i in j + 1..n {
            if (i / 30) != (j / 30) {
                red[(i, j)] = 0.0;
            }
        }
    }
    check_large(&red, 1e-9);
    for m in [100usize, 200] {
        let f = rng.matrix(m, m);
        let g = rng.psd(m, m);
        let q = rng.psd(m, m);
        let mut h = DMatrix::<f64>::zeros(2 * m, 2 * m);
        h.view_mut((0, 0), (m, m)).copy_from(&f);
        h.view_mut((0, m), (m, m)).copy_from(&(-&g));
        h.view_mut((m, 0), (m, m)).copy_from(&(-&q));
        h.view_mut((m, m), (m, m)).copy_from(&(-f.transpose()));
        let (s0, _) = check_large(&h, if m <= 100 { 1e-8 } else { 0.0 });
        let sdim = check_lhp_reorder(&h, &s0, 10.0);
        assert_eq!(sdim, m);
    }
}

/// Timing of `new` and `new + reorder(lhp)` (run with `--release --ignored --nocapture`). Prints
/// only; asserts nothing about time.
#[test]
#[ignore]
fn timing_report() {
    let mut rng = Rng::new(0);
    for &n in &[4usize, 16, 64, 100, 128, 200, 400, 800] {
        let a = rng.matrix(n, n);
        let reps = (2e7 / (n * n * n + 1000) as f64).clamp(3.0, 2000.0) as usize;
        let mut best = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        let mut best_cpu = f64::INFINITY;
        for _ in 0..3 {
            let t0 = std::time::Instant::now();
            let c0 = thread_cpu_seconds();
            for _ in 0..reps {
                std::hint::black_box(RealSchur::new(&a).unwrap());
            }
            let t1 = t0.elapsed().as_secs_f64() / reps as f64;
            best_cpu = best_cpu.min((thread_cpu_seconds() - c0) / reps as f64);
            let t0 = std::time::Instant::now();
            for _ in 0..reps {
                let mut s = RealSchur::new(&a).unwrap();
                std::hint::black_box(s.reorder(|re, _| re < 0.0).unwrap());
            }
            let t2 = t0.elapsed().as_secs_f64() / reps as f64;
            // The double-shift path alone (the implementation before the multishift code).
            let t0 = std::time::Instant::now();
            for _ in 0..reps {
                let mut h = a.clone();
                let zv = super::hqr::hessenberg_reduce(h.as_mut_slice(), n).unwrap();
                let mut z = DMatrix::from_vec(n, n, zv);
                super::hqr::francis_qr_window(h.as_mut_slice(), z.as_mut_slice(), n, 0, n - 1)
                    .unwrap();
                std::hint::black_box((h, z));
            }
            let t3 = t0.elapsed().as_secs_f64() / reps as f64;
            best = (best.0.min(t1), best.1.min(t2), best.2.min(t3));
        }
        eprintln!(
            "n = {n:4}: schur {:10.1} us (cpu {:10.1} us)   schur+lhp {:10.1} us   \
             double-shift only {:10.1} us",
            best.0 * 1e6,
            best_cpu * 1e6,
            best.1 * 1e6,
            best.2 * 1e6
        );
    }
}

/// CPU time of the calling thread in seconds (Linux `/proc/thread-self/schedstat`; NaN elsewhere),
/// which is less disturbed than wall time on a shared machine.
fn thread_cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

#[test]
fn multishift_falls_back_to_double_shift_at_its_iteration_bound() {
    use super::multishift::ITMAX_OVERRIDE;
    let mut rng = Rng::new(18);
    for &itmax in &[0usize, 1, 2, 10] {
        for &n in &[NMIN, 150] {
            let a = rng.matrix(n, n);
            ITMAX_OVERRIDE.with(|c| c.set(Some(itmax)));
            let s = RealSchur::new(&a);
            ITMAX_OVERRIDE.with(|c| c.set(None));
            let s = s.unwrap();
            check(&a, &s, 10.0);
            let d = eig_distance(&s.eigenvalues(), &reference_eigenvalues(&a));
            assert!(d <= 1e-9 * a.norm(), "itmax {itmax}, n {n}: {d}");
            let st = last_stats();
            // With a bound of 0 to 2 iterations the fallback is certain; with 10 it may not be
            // needed (n = 75 finishes after a few AEDs).
            if itmax <= 2 {
                assert_eq!(st.fallbacks, 1, "itmax {itmax}, n {n}: {st:?}");
            } else {
                assert!(st.fallbacks <= 1, "itmax {itmax}, n {n}: {st:?}");
            }
        }
    }
}

/// Many random matrices of assorted structure through the multishift path (run with
/// `--release --ignored`): no failure, full accuracy check on each.
#[test]
#[ignore]
fn multishift_stress() {
    let mut rng = Rng::new(1234);
    let mut worst = (0.0f64, 0.0f64);
    for trial in 0..120 {
        let n = NMIN + (rng.uniform() * 260.0) as usize;
        let a = match trial % 6 {
            0 => rng.matrix(n, n),
            1 => {
                // Random upper Hessenberg with tiny subdiagonal entries here and there.
                DMatrix::from_fn(n, n, |i, j| {
                    if i > j + 1 {
                        0.0
                    } else if i == j + 1 && (i % 7 == 0) {
                        1e-17 * rng.normal()
                    } else {
                        rng.normal()
                    }
                })
            }
            2 => {
                let b = rng.matrix(n, n);
                DMatrix::from_fn(n, n, |i, j| b[(i, j)] * 10f64.powf(-0.1 * (i + j) as f64))
            }
            3 => {
                // Integer matrix with many repeated entries.
                DMatrix::from_fn(n, n, |_, _| (rng.uniform() * 3.0).floor() - 1.0)
            }
            4 => {
                let b = rng.matrix(n, n);
                &b - b.transpose() + DMatrix::identity(n, n) * 1e-3
            }
            _ => {
                let b = rng.matrix(n, n);
                &b + b.transpose()
            }
        };
        let s = RealSchur::new(&a).unwrap_or_else(|e| panic!("trial {trial} (n = {n}): {e:?}"));
        let (b, o) = check(&a, &s, 10.0);
        worst = (worst.0.max(b), worst.1.max(o));
    }
    eprintln!(
        "multishift stress: worst backward {:.3} n·eps, orthogonality {:.3} n·eps",
        worst.0, worst.1
    );
}

/// `RealSchur::new` alone at one order, for profiling (`SCHUR_PROFILE_N`, default 400).
#[test]
#[ignore]
fn profile_new() {
    let n: usize = std::env::var("SCHUR_PROFILE_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(400);
    let a = Rng::new(0).matrix(n, n);
    let t0 = std::time::Instant::now();
    let reps = 20;
    for _ in 0..reps {
        std::hint::black_box(RealSchur::new(&a).unwrap());
    }
    eprintln!(
        "n = {n}: {:.1} us",
        t0.elapsed().as_secs_f64() / reps as f64 * 1e6
    );
}

#[test]
#[ignore]
fn scan_for_rejections() {
    let mut rng = Rng::new(99);
    let mut count = [0usize; 4];
    for trial in 0..200000 {
        let kind = trial % 3;
        let (n1, n2) = [(1usize, 2usize), (2, 1), (2, 2)][kind];
        let n = n1 + n2;
        let mut t = DMatrix::<f64>::zeros(n, n);
        let eps_gap = 10f64.powf(-4.0 - 12.0 * rng.uniform());
        let lam = rng.normal();
        let im = 10f64.powf(-3.0 - 10.0 * rng.uniform());
        let cpl = 10f64.powf(6.0 * rng.uniform());
        let set_block = |t: &mut DMatrix<f64>, k: usize, sz: usize, mu: f64, rng: &mut Rng| {
            if sz == 1 {
                t[(k, k)] = mu;
            } else {
                let b = 10f64.powf(4.0 * rng.uniform() - 2.0);
                t[(k, k)] = mu;
                t[(k + 1, k + 1)] = mu;
                t[(k, k + 1)] = b;
                t[(k + 1, k)] = -im * im / b;
            }
        };
        set_block(&mut t, 0, n1, lam, &mut rng);
        set_block(&mut t, n1, n2, lam + eps_gap, &mut rng);
        for i in 0..n1 {
            for j in n1..n {
                t[(i, j)] = cpl * rng.normal();
            }
        }
        let mut tt = t.clone();
        let mut z = DMatrix::<f64>::identity(n, n);
        if let Err(r) = swap_adjacent(tt.as_mut_slice(), z.as_mut_slice(), n, 0, n1, n2) {
            count[kind] += 1;
            if count[kind] <= 2 {
                eprintln!("kind {kind}: rejected {r:?}\n{t:.17e}");
            }
        }
        count[3] += 1;
    }
    eprintln!("rejections {count:?}");
}

/// Found by hypothesis: a matrix of subnormal entries. `new` scales it into the normal range, and
/// so must `reorder`, or rotations computed from subnormals lose orthogonality (Z off by 1e-11).
#[test]
fn reordering_a_subnormal_matrix_keeps_z_orthogonal() {
    for &v in &[-2.225_073_858_507_2e-313, 1e-310, -4e-320] {
        for n in [2usize, 3, 5] {
            let mut a = DMatrix::from_element(n, n, v);
            a[(0, n - 1)] = -v;
            let mut s = RealSchur::new(&a).unwrap();
            for select in [|re: f64, _: f64| re < 0.0, |re: f64, _: f64| re > 0.0] {
                let mut s2 = s.clone();
                let sdim = s2.reorder(select).unwrap();
                let orth = (s2.z.transpose() * &s2.z - DMatrix::<f64>::identity(n, n)).norm();
                assert!(
                    orth <= 10.0 * n as f64 * f64::EPSILON,
                    "v={v:e} n={n}: {orth:e}"
                );
                let back = &s2.z * &s2.t * s2.z.transpose();
                let err = (back - &a).amax();
                assert!(
                    // Subnormals carry an absolute granularity of 4.9e-324.
                    err <= 10.0 * n as f64 * f64::EPSILON * v.abs()
                        + (n * n) as f64 * f64::from_bits(1),
                    "v={v:e} n={n}: {err:e}"
                );
                assert!(sdim <= n);
            }
            let pos = s.reorder_to(n - 1, 0).unwrap();
            assert!(pos <= 1);
            let orth = (s.z.transpose() * &s.z - DMatrix::<f64>::identity(n, n)).norm();
            assert!(orth <= 10.0 * n as f64 * f64::EPSILON);
        }
    }
}

/// Found by hypothesis: O(1) entries mixed with subnormal ones. A swap whose Givens rotation is
/// computed from two subnormals lost orthogonality (4.5e-12) until `lartg` scaled its inputs.
#[test]
fn swaps_with_subnormal_rotation_inputs_stay_orthogonal() {
    let v = -2.225_073_86e-313;
    let mut a = DMatrix::from_element(8, 8, v);
    a[(2, 5)] = 1.0;
    a[(5, 0)] = 1.0;
    let s0 = RealSchur::new(&a).unwrap();
    for k in 1..8 {
        let mut s = s0.clone();
        s.reorder_to(k, k - 1).unwrap();
        let orth = (s.z.transpose() * &s.z - DMatrix::<f64>::identity(8, 8)).norm();
        assert!(orth <= 80.0 * f64::EPSILON, "swap {k}: {orth:e}");
        let back = (&s.z * &s.t * s.z.transpose() - &a).norm();
        assert!(back <= 80.0 * f64::EPSILON * a.norm(), "swap {k}: {back:e}");
    }
    let mut s = s0.clone();
    s.reorder(|re, _| re < 0.0).unwrap();
    let orth = (s.z.transpose() * &s.z - DMatrix::<f64>::identity(8, 8)).norm();
    assert!(orth <= 80.0 * f64::EPSILON, "{orth:e}");
}

/// Timing of the blocked Hessenberg reduction (`hessenberg.rs`, several panel widths) against
/// faer's (the path used before it) and the unblocked kernel, best wall time of several runs
/// (`cargo test --release --lib schur::tests::hessenberg_timing -- --ignored
/// --nocapture`; `HESS_NB=16,32,48` picks panel widths other than the default, `HESS_N=200,400` the orders).
#[test]
#[ignore]
fn hessenberg_timing() {
    let env_list = |name: &str, default: &[usize]| -> Vec<usize> {
        std::env::var(name)
            .ok()
            .map(|s| s.split(',').filter_map(|x| x.trim().parse().ok()).collect())
            .unwrap_or_else(|| default.to_vec())
    };
    let nbs = env_list("HESS_NB", &[]);
    let unblocked = std::env::var("HESS_UNBLOCKED").is_ok();
    let mut rng = Rng::new(5);
    for n in env_list("HESS_N", &[200, 400, 800, 1500]) {
        let a = DMatrix::from_fn(n, n, |_, _| rng.normal());
        let reps = (3e9 / (n * n * n) as f64).clamp(5.0, 50.0) as usize;
        let nbs = if nbs.is_empty() {
            vec![super::hessenberg::panel_width(n)]
        } else {
            nbs.clone()
        };
        // Methods alternate within each repetition, so that load from other processes on a
        // shared machine hits them alike; best wall time per method. Method 0 is faer's
        // reduction, 1..=nbs.len() ours, the last the unblocked kernel.
        let mut best = vec![f64::INFINITY; nbs.len() + 2];
        // The poll before the first block of Z splits our time: reduction, forming Z.
        let mut split = vec![f64::INFINITY; nbs.len()];
        for _ in 0..reps {
            for (m, b) in best.iter_mut().enumerate() {
                let mut h = a.clone();
                let hs = h.as_mut_slice();
                let t0 = std::time::Instant::now();
                if m == 0 {
                    std::hint::black_box(super::hqr::hessenberg_faer(hs, n));
                } else if m <= nbs.len() {
                    let nb = nbs[m - 1];
                    let panels = (n - 2).div_ceil(nb.min(n - 2));
                    let mut k = 0;
                    let r = super::hessenberg::reduce_blocked(hs, n, nb, &mut || {
                        k += 1;
                        if k == panels + 1 {
                            split[m - 1] = split[m - 1].min(t0.elapsed().as_secs_f64());
                        }
                        Ok::<(), ()>(())
                    });
                    std::hint::black_box(r.unwrap());
                } else if unblocked {
                    let mut z = vec![0.0; n * n];
                    for i in 0..n {
                        z[i * n + i] = 1.0;
                    }
                    super::hqr::hessenberg_small(hs, &mut z, n);
                    std::hint::black_box(z);
                } else {
                    continue;
                }
                *b = b.min(t0.elapsed().as_secs_f64());
            }
        }
        let faer = best[0];
        let mut line = format!("n = {n:4}: faer {:8.2} ms", faer * 1e3);
        for (k, &nb) in nbs.iter().enumerate() {
            line += &format!(
                "   ours nb={nb}: {:8.2} ms ({:+.1} %; reduction {:.2} ms)",
                best[k + 1] * 1e3,
                100.0 * (best[k + 1] / faer - 1.0),
                split[k] * 1e3
            );
        }
        if unblocked {
            line += &format!("   unblocked {:8.2} ms", best[nbs.len() + 1] * 1e3);
        }
        eprintln!("{line}");
    }
}

/// End-to-end effect of the blocked reduction: `RealSchur::new` at n = 400, 800 and a CARE at
/// n = 200 (Hamiltonian of order 400), with faer's reduction (before) and ours (after), best wall
/// time of several runs, alternating
/// (`cargo test --release --lib schur::tests::end_to_end_timing -- --ignored --nocapture`).
#[test]
#[ignore]
fn end_to_end_timing() {
    use crate::care::{solve_care, CareOptions};
    let mut rng = Rng::new(6);
    let time = |f: &mut dyn FnMut(), reps: usize| -> [f64; 2] {
        let mut best = [f64::INFINITY; 2];
        for _ in 0..reps {
            for (k, faer) in [true, false].into_iter().enumerate() {
                super::hqr::FAER_REDUCTION.with(|c| c.set(faer));
                let t0 = std::time::Instant::now();
                f();
                best[k] = best[k].min(t0.elapsed().as_secs_f64());
            }
        }
        super::hqr::FAER_REDUCTION.with(|c| c.set(false));
        best
    };
    for (n, reps) in [(400usize, 7usize), (800, 3)] {
        let a = rng.matrix(n, n);
        let [before, after] = time(
            &mut || {
                std::hint::black_box(RealSchur::new(&a).unwrap());
            },
            reps,
        );
        eprintln!(
            "RealSchur::new n = {n}: faer reduction {:.1} ms, ours {:.1} ms ({:+.1} %)",
            before * 1e3,
            after * 1e3,
            100.0 * (after / before - 1.0)
        );
    }
    let n = 200;
    let a = rng.matrix(n, n) * (1.0 / (n as f64).sqrt()) - DMatrix::identity(n, n) * 0.5;
    let b = rng.matrix(n, 20) * (1.0 / (n as f64).sqrt());
    let g = &b * b.transpose();
    let q = DMatrix::identity(n, n);
    let [before, after] = time(
        &mut || {
            std::hint::black_box(solve_care(&a, &g, &q, &CareOptions::default()).unwrap());
        },
        7,
    );
    eprintln!(
        "solve_care n = {n}: faer reduction {:.1} ms, ours {:.1} ms ({:+.1} %)",
        before * 1e3,
        after * 1e3,
        100.0 * (after / before - 1.0)
    );
}
