use super::super::hqr::{francis_qr_window, hessenberg_faer, hessenberg_reduce};
use super::*;
use crate::cancel::{with_token, Token};
use crate::linalg::testing::Rng;
use crate::Error;
use nalgebra::DMatrix;
use std::convert::Infallible;

const EPS: f64 = f64::EPSILON;
/// The panel width of the blocked path at the orders of these tests.
const NB: usize = 16;

/// Reduces a copy of `a` with panel width `nb` and checks the contract by an independent
/// route (nalgebra products): exact zeros below the subdiagonal, `‖ZᵀZ − I‖_F ≤ c·n·eps`,
/// `‖A − Z H Zᵀ‖_F ≤ c·n·eps·‖A‖_F`, `Z e₁ = e₁`. Returns (H, Z, backward, orthogonality),
/// the last two in units of n·eps.
fn check_nb(a: &DMatrix<f64>, nb: usize, c: f64) -> (DMatrix<f64>, DMatrix<f64>, f64, f64) {
    let n = a.nrows();
    let mut h = a.clone();
    let Ok(zv) = reduce_blocked(h.as_mut_slice(), n, nb, &mut || Ok::<(), Infallible>(()));
    let z = DMatrix::from_vec(n, n, zv);
    let (b, o) = assess(a, &h, &z, c, &format!("n = {n}, nb = {nb}"));
    (h, z, b, o)
}

fn assess(a: &DMatrix<f64>, h: &DMatrix<f64>, z: &DMatrix<f64>, c: f64, what: &str) -> (f64, f64) {
    let n = a.nrows();
    for j in 0..n {
        for i in j + 2..n {
            assert_eq!(h[(i, j)], 0.0, "{what}: H({i},{j}) below the subdiagonal");
        }
    }
    for i in 0..n {
        assert_eq!(z[(i, 0)], if i == 0 { 1.0 } else { 0.0 }, "{what}: Z e1");
        assert_eq!(z[(0, i)], if i == 0 { 1.0 } else { 0.0 }, "{what}: e1ᵀ Z");
    }
    // Scale by a power of two so that the check itself cannot overflow or underflow.
    let amax = a.amax();
    let f = if amax > 0.0 {
        2f64.powi(-(amax.log2().round() as i32))
    } else {
        1.0
    };
    let (as_, hs) = (a * f, h * f);
    let nf = n as f64;
    let back =
        (&as_ - z * &hs * z.transpose()).norm() / (nf * EPS * as_.norm().max(f64::MIN_POSITIVE));
    let orth = (z.transpose() * z - DMatrix::<f64>::identity(n, n)).norm() / (nf * EPS);
    assert!(back <= c, "{what}: backward error {back:.3} n·eps > {c}");
    assert!(orth <= c, "{what}: orthogonality {orth:.3} n·eps > {c}");
    (back, orth)
}

/// `τ·vᵀv = 2` (the reflector is orthogonal) to a few ulps for long graded vectors (`vᵀv` by
/// the compensated sum), and `H·(alpha, x) = (beta, 0)` to the accuracy of the check.
#[test]
fn long_reflectors_are_orthogonal_to_working_precision() {
    let mut rng = Rng::new(20);
    for m in [10usize, 100, 1000, 4000] {
        let mut worst = [0.0f64; 2];
        for _ in 0..20 {
            let x0: Vec<f64> = (0..m)
                .map(|_| rng.normal() * 10f64.powf(6.0 * rng.uniform() - 3.0))
                .collect();
            let alpha = rng.normal();
            for (k, f) in [larfg, larfg_plain].into_iter().enumerate() {
                let mut x = x0.clone();
                let (beta, tau) = f(alpha, &mut x);
                let orth = (tau * norm_dd(1.0, &x).powi(2) - 2.0).abs() / EPS;
                // H (alpha, x0) = (alpha, x0) − τ v (vᵀ (alpha, x0)) with v = (1, x).
                let d = alpha + x.iter().zip(&x0).map(|(v, w)| v * w).sum::<f64>();
                let mut r = (alpha - tau * d - beta).abs();
                for (v, w) in x.iter().zip(&x0) {
                    r = r.max((w - tau * d * v).abs());
                }
                let r = r / (beta.abs() * EPS);
                if k == 0 {
                    assert!(orth <= 8.0, "m = {m}: |τ·vᵀv − 2| = {orth} eps");
                    // (The check's own plain dot product rounds like √m ulps.)
                    let bound = 4.0 * (m as f64).sqrt();
                    assert!(r <= bound, "m = {m}: H·x residual {r} eps·|beta|");
                }
                worst[k] = worst[k].max(orth);
            }
        }
        eprintln!(
            "m = {m:4}: |τ·vᵀv − 2| ≤ {:.1} eps (plain sum of squares: {:.1} eps)",
            worst[0], worst[1]
        );
    }
}

#[test]
fn random_orders_around_the_blocking_threshold_and_panel_width() {
    let mut rng = Rng::new(21);
    let mut worst = (0.0f64, 0.0f64);
    for n in [81usize, 82, 95, 96, 97, 130, 257] {
        let a = rng.matrix(n, n);
        let mut h = a.clone();
        let z = DMatrix::from_vec(n, n, hessenberg_reduce(h.as_mut_slice(), n).unwrap());
        let (b, o) = assess(&a, &h, &z, 1.0, &format!("n = {n}"));
        worst = (worst.0.max(b), worst.1.max(o));
    }
    eprintln!(
        "worst backward {:.3} n·eps, orthogonality {:.3} n·eps",
        worst.0, worst.1
    );
}

#[test]
fn awkward_panel_remainders() {
    let mut rng = Rng::new(22);
    for n in [3usize, 4, 5, 10, 33, 34, 35, 66, 100] {
        let a = rng.matrix(n, n);
        for nb in [
            1usize,
            2,
            3,
            5,
            7,
            16,
            31,
            32,
            33,
            n - 3,
            n - 2,
            n - 1,
            n + 4,
        ] {
            if nb >= 1 {
                check_nb(&a, nb, 1.0);
            }
        }
    }
}

/// Any panel width gives the same H and Z up to rounding (the reflectors are the same
/// up to rounding; nb = 1 is plain dgehd2 with a rank-1 update per column).
#[test]
fn panel_widths_agree() {
    let mut rng = Rng::new(23);
    let n = 120;
    let a = rng.matrix(n, n);
    let (h1, z1, _, _) = check_nb(&a, 1, 1.0);
    for nb in [8usize, 32, 50] {
        let (h, z, _, _) = check_nb(&a, nb, 1.0);
        let dh = (&h - &h1).amax() / a.amax();
        let dz = (&z - &z1).amax();
        assert!(
            dh <= 1e-12 && dz <= 1e-12,
            "nb = {nb}: ΔH {dh:e}, ΔZ {dz:e}"
        );
    }
}

#[test]
fn graded_and_badly_scaled_matrices() {
    let mut rng = Rng::new(24);
    for n in [90usize, 150] {
        let r = rng.matrix(n, n);
        let g = |i: usize, j: usize| -150.0 + 300.0 * (i + j) as f64 / (2 * (n - 1)) as f64;
        for (name, a) in [
            (
                "growing",
                DMatrix::from_fn(n, n, |i, j| r[(i, j)] * 10f64.powf(g(i, j))),
            ),
            (
                "shrinking",
                DMatrix::from_fn(n, n, |i, j| r[(i, j)] * 10f64.powf(-g(i, j))),
            ),
            (
                "rows",
                DMatrix::from_fn(n, n, |i, j| r[(i, j)] * 10f64.powf(g(i, i))),
            ),
            (
                "cols",
                DMatrix::from_fn(n, n, |_, j| 10f64.powf(g(j, j))).component_mul(&r),
            ),
            ("tiny", &r * 1e-300),
            ("huge", &r * 1e300),
        ] {
            let mut h = a.clone();
            let z = DMatrix::from_vec(n, n, hessenberg_reduce(h.as_mut_slice(), n).unwrap());
            assert!(
                h.iter().chain(z.iter()).all(|v| v.is_finite()),
                "{name}: non-finite"
            );
            let (b, o) = assess(&a, &h, &z, 1.0, &format!("{name}, n = {n}"));
            eprintln!("{name:9} n = {n}: backward {b:.3} n·eps, orthogonality {o:.3} n·eps");
        }
    }
}

/// Zero columns below the subdiagonal give τ = 0 reflectors (V column = unit vector, zero
/// column of T, zero column of Y) at the start, middle and end of panels.
#[test]
fn zero_columns_give_identity_reflectors() {
    let mut rng = Rng::new(25);
    let n = 130;
    // Upper triangular: every τ is 0, H = A and Z = I exactly.
    let a = DMatrix::from_fn(n, n, |i, j| if i <= j { rng.normal() } else { 0.0 });
    let (h, z, _, _) = check_nb(&a, NB, 1.0);
    assert_eq!(h, a);
    assert_eq!(z, DMatrix::<f64>::identity(n, n));
    // The zero matrix.
    let (h, z, _, _) = check_nb(&DMatrix::zeros(n, n), NB, 1.0);
    assert_eq!(h, DMatrix::<f64>::zeros(n, n));
    assert_eq!(z, DMatrix::<f64>::identity(n, n));
    // Block diagonal with blocks ending inside and at the edge of a panel: τ = 0 for the
    // last column of each block, and Z is block diagonal too.
    let ends = [0usize, 1, 40, 64, 97, 98, n];
    let mut a = DMatrix::zeros(n, n);
    for w in ends.windows(2) {
        let (s, e) = (w[0], w[1]);
        for j in s..e {
            for i in s..e {
                a[(i, j)] = rng.normal();
            }
        }
    }
    for nb in [NB, 32, 7, 1] {
        let (_, z, _, _) = check_nb(&a, nb, 1.0);
        for w in ends.windows(2) {
            for j in w[0]..w[1] {
                for i in (0..n).filter(|&i| i < w[0] || i >= w[1]) {
                    assert_eq!(z[(i, j)], 0.0, "nb = {nb}: Z({i},{j}) outside its block");
                }
            }
        }
    }
    // A zero first column (the very first reflector is the identity).
    let mut a = rng.matrix(n, n);
    a.column_mut(0).fill(0.0);
    check_nb(&a, NB, 1.0);
}

/// Eigenvalues after the QR iteration agree with those from faer's reduction (the old path).
#[test]
fn eigenvalues_agree_with_the_faer_reduction() {
    let mut rng = Rng::new(26);
    for n in [90usize, 200] {
        let a = rng.matrix(n, n);
        let eig = |h: &mut DMatrix<f64>, z: Vec<f64>| {
            let mut z = DMatrix::from_vec(n, n, z);
            francis_qr_window(h.as_mut_slice(), z.as_mut_slice(), n, 0, n - 1).unwrap();
            super::super::RealSchur { t: h.clone(), z }.eigenvalues()
        };
        let mut h1 = a.clone();
        let z1 = hessenberg_reduce(h1.as_mut_slice(), n).unwrap();
        let e1 = eig(&mut h1, z1);
        let mut h2 = a.clone();
        let z2 = hessenberg_faer(h2.as_mut_slice(), n);
        let e2 = eig(&mut h2, z2);
        // Independent reference for the size of the rounding differences.
        let e3: Vec<(f64, f64)> = a
            .complex_eigenvalues()
            .iter()
            .map(|c| (c.re, c.im))
            .collect();
        let d12 = eig_distance(&e1, &e2);
        let d13 = eig_distance(&e1, &e3);
        eprintln!("n = {n}: |new − faer| {d12:.2e}, |new − nalgebra| {d13:.2e}");
        let scale = a.norm();
        assert!(d12 <= 1e-10 * scale, "n = {n}: {d12:e}");
        assert!(d13 <= 1e-10 * scale, "n = {n}: {d13:e}");
    }
}

fn eig_distance(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut used = vec![false; b.len()];
    let mut worst = 0.0f64;
    for &(re, im) in a {
        let (d, j) = b
            .iter()
            .enumerate()
            .filter(|(j, _)| !used[*j])
            .map(|(j, &(r2, i2))| ((re - r2).hypot(im - i2), j))
            .fold(
                (f64::INFINITY, usize::MAX),
                |x, y| if y.0 < x.0 { y } else { x },
            );
        used[j] = true;
        worst = worst.max(d);
    }
    worst
}

#[test]
fn a_cancelled_token_stops_the_reduction() {
    let mut rng = Rng::new(27);
    let a = rng.matrix(150, 150);
    let t = Token::new();
    t.cancel();
    let mut h = a.clone();
    let r = with_token(Some(&t), || hessenberg_reduce(h.as_mut_slice(), 150));
    assert!(
        matches!(&r, Err(Error::Interrupted(m)) if m.contains("Hessenberg")),
        "{r:?}"
    );
    let r = with_token(Some(&t), || super::super::RealSchur::new(&a));
    assert!(matches!(&r, Err(Error::Interrupted(m)) if m.contains("Hessenberg")));
}

/// The poll runs before every panel and every block of Z: stopping at the k-th poll
/// returns that error for every k, and with no stop there are exactly 2·panels polls.
#[test]
fn every_panel_and_every_block_of_z_polls() {
    let mut rng = Rng::new(28);
    let n = 140;
    let a = rng.matrix(n, n);
    assert_eq!(panel_width(n), NB);
    let panels = (n - 2).div_ceil(NB);
    let mut calls = 0;
    let mut h = a.clone();
    reduce_blocked(h.as_mut_slice(), n, NB, &mut || {
        calls += 1;
        Ok::<(), ()>(())
    })
    .unwrap();
    assert_eq!(calls, 2 * panels);
    for stop in 1..=2 * panels {
        let mut k = 0;
        let mut h = a.clone();
        let r = reduce_blocked(h.as_mut_slice(), n, NB, &mut || {
            k += 1;
            if k == stop {
                Err(stop)
            } else {
                Ok(())
            }
        });
        assert_eq!(r, Err(stop));
        assert_eq!(k, stop, "no poll after the one that stopped");
    }
}

/// A cancellation inside the blocked reduction of an AED window (n = 700: windows of 96)
/// leaves H and Z untouched by that AED: the multishift QR returns its "not converged" row,
/// with `A = Z H Zᵀ` still holding, and `RealSchur::new` reports `Interrupted`.
#[test]
fn a_cancel_inside_an_aed_window_leaves_a_valid_similarity() {
    use super::super::hqr::CANCEL_AFTER_POLLS;
    use super::super::multishift::multishift_qr;
    let n = 700;
    let mut rng = Rng::new(30);
    let a = rng.matrix(n, n);
    let mut h = a.clone();
    let zv = hessenberg_reduce(h.as_mut_slice(), n).unwrap();
    let mut z = DMatrix::from_vec(n, n, zv);
    let t = Token::new();
    CANCEL_AFTER_POLLS.with(|c| c.set(Some(0)));
    let r = with_token(Some(&t), || {
        multishift_qr(h.as_mut_slice(), z.as_mut_slice(), n)
    });
    let reached = CANCEL_AFTER_POLLS.with(|c| c.replace(None)).is_none();
    assert!(reached, "no AED window used the blocked reduction");
    assert!(t.is_cancelled());
    assert!(r.is_err(), "the multishift QR ran on after the cancel");
    let back = (&a - &z * &h * z.transpose()).norm() / (n as f64 * EPS * a.norm());
    let orth = (z.transpose() * &z - DMatrix::<f64>::identity(n, n)).norm() / (n as f64 * EPS);
    eprintln!("after the cancel: backward {back:.3} n·eps, orthogonality {orth:.3} n·eps");
    assert!(
        back <= 1.0 && orth <= 1.0,
        "backward {back}, orthogonality {orth}"
    );
    // The same through RealSchur::new (the first poll of the full reduction is skipped).
    let t = Token::new();
    CANCEL_AFTER_POLLS.with(|c| c.set(Some(2 * (n - 2).div_ceil(panel_width(n)))));
    let r = with_token(Some(&t), || super::super::RealSchur::new(&a));
    CANCEL_AFTER_POLLS.with(|c| c.set(None));
    assert!(
        matches!(&r, Err(Error::Interrupted(_))),
        "{:?}",
        r.map(|_| ())
    );
}

/// A token cancelled from another thread while a reduction of order 1500 runs stops it
/// (`cargo test --release --lib stops_a_running -- --ignored --nocapture` prints the delay).
#[test]
#[ignore]
fn a_token_cancelled_from_another_thread_stops_a_running_reduction() {
    let n = 1500;
    let mut rng = Rng::new(29);
    let a = rng.matrix(n, n);
    let t = Token::new();
    let t2 = t.clone();
    let canceller = std::thread::spawn(move || {
        std::thread::sleep(std::time::Duration::from_millis(300));
        t2.cancel();
        std::time::Instant::now()
    });
    let mut h = a.clone();
    let r = with_token(Some(&t), || hessenberg_reduce(h.as_mut_slice(), n));
    let stopped = std::time::Instant::now();
    let cancelled_at = canceller.join().unwrap();
    assert!(
        matches!(r, Err(Error::Interrupted(_))),
        "{:?}",
        r.map(|_| ())
    );
    eprintln!(
        "stopped {:.1} ms after the cancel",
        stopped
            .saturating_duration_since(cancelled_at)
            .as_secs_f64()
            * 1e3
    );
}
