//! Which Hamiltonian eigenvalues are on the imaginary axis, judged by each eigenvalue's own
//! perturbation bound.
//!
//! A backward-stable Schur form is exact for `H + E`, `‖E‖ ≈ eps·‖H‖`, which moves a simple eigenvalue
//! by at most about `κ(λ)·eps·‖H‖` (`κ(λ) = ‖x‖‖y‖/|yᴴx|` from its right and left eigenvectors). An
//! eigenvalue whose real part exceeds that bound by [`AXIS_FACTOR`] is certainly off the axis,
//! however small it is compared with `‖H‖` (CAREX 6: 3.6e-3 from the axis with `‖H‖_F` = 1.5e8). A
//! defective pair *on* the axis (a 2×2 Jordan block, the generic case for a Hamiltonian) is split by
//! rounding into two eigenvalues `δ ≈ √(eps·‖H‖)` from it whose condition numbers are `≈ ‖H‖/δ`, so
//! `κ·eps·‖H‖ ≈ δ`: it fails the test, as it must.
//!
//! Condition numbers come from the quasi-triangular `T` (the Schur vectors are orthogonal, so they
//! are those of `H`) by one back- and one forward-substitution, `O(n²)` per eigenvalue; only the
//! eigenvalues within `√eps·‖H‖_F` of the axis (the old, scale-blind test) are examined.

use nalgebra::{Complex, DMatrix};

/// An eigenvalue is on the axis when `|Re λ| ≤ AXIS_FACTOR · κ(λ) · eps · ‖H‖_F`.
pub const AXIS_FACTOR: f64 = 10.0;

type C64 = Complex<f64>;

/// The eigenvalue closest to the imaginary axis relative to its perturbation bound.
#[derive(Debug, Clone, Copy)]
pub struct AxisReport {
    /// `(re, im)` of that eigenvalue.
    pub eigenvalue: (f64, f64),
    /// `|Re λ| / (κ(λ)·eps·‖H‖_F)`: below [`AXIS_FACTOR`] the eigenvalue counts as on the axis;
    /// `f64::INFINITY` when no eigenvalue is within `√eps·‖H‖_F` of the axis.
    pub margin: f64,
    /// How many eigenvalues count as on the axis.
    pub on_axis: usize,
}

/// Examines the eigenvalues of the quasi-triangular `t` (standardised 2×2 blocks) near the axis.
pub fn examine(t: &DMatrix<f64>, blocks: &[(usize, usize)], h_norm: f64) -> AxisReport {
    let eps = f64::EPSILON;
    let prefilter = eps.sqrt() * h_norm;
    let mut report = AxisReport {
        eigenvalue: (f64::NAN, f64::NAN),
        margin: f64::INFINITY,
        on_axis: 0,
    };
    for &(k, size) in blocks {
        let re = t[(k, k)];
        if !(re.abs() <= prefilter) {
            continue;
        }
        let im = if size == 2 {
            (t[(k, k + 1)].abs().sqrt()) * (t[(k + 1, k)].abs().sqrt())
        } else {
            0.0
        };
        let kappa = condition(t, k, size, h_norm);
        let bound = kappa * eps * h_norm;
        let margin = if bound > 0.0 {
            re.abs() / bound
        } else if re == 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
        let margin = if margin.is_nan() { 0.0 } else { margin };
        if margin < AXIS_FACTOR {
            report.on_axis += size;
        }
        if margin < report.margin || report.eigenvalue.0.is_nan() {
            report.margin = margin.min(report.margin);
            report.eigenvalue = (re, im);
        }
    }
    report
}

/// `κ(λ) = ‖x‖‖w‖/|wᵀx|` for the eigenvalue of the block at `k` (size 1 or 2), `T x = λ x`,
/// `Tᵀ w = λ w` (w is the conjugate of the left eigenvector). Infinite when `wᵀx` vanishes.
pub(super) fn condition(t: &DMatrix<f64>, k: usize, size: usize, h_norm: f64) -> f64 {
    let (x, w) = eigenvectors(t, k, size, h_norm);
    let nx = x.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
    let nw = w.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
    let dot: C64 = x.iter().zip(&w).map(|(a, b)| a * b).sum();
    let kappa = nx * nw / dot.norm();
    if kappa.is_finite() {
        kappa.max(1.0)
    } else {
        f64::INFINITY
    }
}

/// The first-order sensitivity of the eigenvalue of the block at `k` to perturbations of the
/// structured form `E = B V` of the matrix `Z T Zᵀ`, given `zb = ZᵀB` (`n × m`):
/// `|δλ| = |wᵀZᵀBVZx|/|wᵀx| ≤ κ_B(λ)·‖V‖₂` with `κ_B(λ) = ‖(ZᵀB)ᵀw‖‖x‖/|wᵀx|` (`x`, `w` as in
/// [`condition`]). It never exceeds `κ(λ)·‖B‖₂`, and is far below it for a mode the input `B`
/// barely reaches (the slow modes of a stiff closed loop). Infinite when `wᵀx` vanishes.
pub(super) fn input_condition(
    t: &DMatrix<f64>,
    k: usize,
    size: usize,
    h_norm: f64,
    zb: &DMatrix<f64>,
) -> f64 {
    let (x, w) = eigenvectors(t, k, size, h_norm);
    let nx = x.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
    let dot: C64 = x.iter().zip(&w).map(|(a, b)| a * b).sum();
    let mut bw2 = 0.0;
    for c in 0..zb.ncols() {
        let v: C64 = (0..zb.nrows()).map(|i| w[i] * zb[(i, c)]).sum();
        bw2 += v.norm_sqr();
    }
    let kappa = bw2.sqrt() * nx / dot.norm();
    if kappa.is_finite() {
        kappa
    } else {
        f64::INFINITY
    }
}

/// The right eigenvector `x` (zero below the block) and the vector `w` (`Tᵀw = λw`, zero above
/// the block) of the eigenvalue of the block at `k`, in the Schur basis.
fn eigenvectors(t: &DMatrix<f64>, k: usize, size: usize, h_norm: f64) -> (Vec<C64>, Vec<C64>) {
    let n = t.nrows();
    let smin = (f64::EPSILON * h_norm).max(f64::MIN_POSITIVE);
    let (lambda, xb, wb) = if size == 1 {
        let l = C64::new(t[(k, k)], 0.0);
        (l, [C64::new(1.0, 0.0); 2], [C64::new(1.0, 0.0); 2])
    } else {
        let (a, b, c) = (t[(k, k)], t[(k, k + 1)], t[(k + 1, k)]);
        let mu = (b.abs().sqrt()) * (c.abs().sqrt());
        let l = C64::new(a, mu);
        // (B − λ) v = 0 from B's first row; (Bᵀ − λ) u = 0 from Bᵀ's first row.
        (l, [C64::new(b, 0.0), l - a], [C64::new(c, 0.0), l - a])
    };
    let mut x = vec![C64::new(0.0, 0.0); n];
    let mut w = vec![C64::new(0.0, 0.0); n];
    x[k..k + size].copy_from_slice(&xb[..size]);
    w[k..k + size].copy_from_slice(&wb[..size]);
    let blocks = block_starts(t);
    // Back-substitution above the block: (T_II − λ) x_I = −Σ_{j > I} T_Ij x_j.
    for &(i0, bs) in blocks.iter().rev().filter(|(i0, _)| *i0 < k) {
        let mut rhs = [C64::new(0.0, 0.0); 2];
        for (s, r) in rhs.iter_mut().enumerate().take(bs) {
            let row = i0 + s;
            let mut acc = C64::new(0.0, 0.0);
            for j in (i0 + bs)..(k + size) {
                acc += x[j] * t[(row, j)];
            }
            *r = -acc;
        }
        let sol = solve_block(t, i0, bs, lambda, rhs, false, smin);
        x[i0..i0 + bs].copy_from_slice(&sol[..bs]);
    }
    // Forward substitution below the block: (T_IIᵀ − λ) w_I = −Σ_{j < I} T_jI w_j.
    for &(i0, bs) in blocks.iter().filter(|(i0, _)| *i0 >= k + size) {
        let mut rhs = [C64::new(0.0, 0.0); 2];
        for (s, r) in rhs.iter_mut().enumerate().take(bs) {
            let col = i0 + s;
            let mut acc = C64::new(0.0, 0.0);
            for j in k..i0 {
                acc += w[j] * t[(j, col)];
            }
            *r = -acc;
        }
        let sol = solve_block(t, i0, bs, lambda, rhs, true, smin);
        w[i0..i0 + bs].copy_from_slice(&sol[..bs]);
    }
    (x, w)
}

fn block_starts(t: &DMatrix<f64>) -> Vec<(usize, usize)> {
    let n = t.nrows();
    let mut out = Vec::new();
    let mut k = 0;
    while k < n {
        if k + 1 < n && t[(k + 1, k)] != 0.0 {
            out.push((k, 2));
            k += 2;
        } else {
            out.push((k, 1));
            k += 1;
        }
    }
    out
}

/// Solves `(B − λ) z = r` (or `(Bᵀ − λ) z = r`) for the diagonal block `B` of `t` at `i0`, with
/// pivots below `smin` replaced by `smin` (as LAPACK's dtrevc perturbs them).
fn solve_block(
    t: &DMatrix<f64>,
    i0: usize,
    bs: usize,
    lambda: C64,
    rhs: [C64; 2],
    transpose: bool,
    smin: f64,
) -> [C64; 2] {
    let guard = |p: C64| {
        if p.norm() < smin {
            C64::new(smin, 0.0)
        } else {
            p
        }
    };
    if bs == 1 {
        let p = guard(C64::new(t[(i0, i0)], 0.0) - lambda);
        return [rhs[0] / p, C64::new(0.0, 0.0)];
    }
    let (a, mut b, mut c, d) = (
        C64::new(t[(i0, i0)], 0.0) - lambda,
        C64::new(t[(i0, i0 + 1)], 0.0),
        C64::new(t[(i0 + 1, i0)], 0.0),
        C64::new(t[(i0 + 1, i0 + 1)], 0.0) - lambda,
    );
    if transpose {
        std::mem::swap(&mut b, &mut c);
    }
    let det = guard(a * d - b * c);
    [
        (rhs[0] * d - b * rhs[1]) / det,
        (a * rhs[1] - c * rhs[0]) / det,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::schur::RealSchur;
    use crate::linalg::testing::Rng;

    /// κ from dense complex eigenvectors of nalgebra, for comparison.
    #[test]
    fn condition_numbers_match_a_normal_and_a_nonnormal_case() {
        // Normal matrix: κ = 1 for every eigenvalue.
        let mut rng = Rng::new(3);
        let s = rng.matrix(6, 6);
        let skew = &s - s.transpose();
        let sch = RealSchur::new(&skew).unwrap();
        let hn = sch.t.norm();
        for (k, size) in sch.blocks() {
            let kappa = condition(&sch.t, k, size, hn);
            assert!((kappa - 1.0).abs() < 1e-8, "{kappa}");
        }
        // [[1, c], [0, 1 + d]]: κ = sqrt(1 + (c/d)²) for both eigenvalues.
        let (c, d): (f64, f64) = (10.0, 1e-2);
        let t = DMatrix::from_row_slice(2, 2, &[1.0, c, 0.0, 1.0 + d]);
        let expected = (1.0 + (c / d) * (c / d)).sqrt();
        for k in 0..2 {
            let kappa = condition(&t, k, 1, t.norm());
            assert!(
                (kappa / expected - 1.0).abs() < 1e-10,
                "{kappa} vs {expected}"
            );
        }
    }

    /// κ_B against a finite difference `δλ/ε` for `E = εBV` (real eigenvalues, random `V` with
    /// `‖V‖₂ = 1`), and zero for a mode whose left eigenvector is orthogonal to `B`.
    #[test]
    fn input_condition_bounds_the_motion_through_b_and_vanishes_for_an_unreached_mode() {
        let mut rng = Rng::new(5);
        let n = 6;
        let m = rng.with_eigenvalues(&[-1.0, -2.0, -4.0, -8.0, -16.0, -32.0], &[]);
        let b = rng.matrix(n, 2);
        let sch = RealSchur::new(&m).unwrap();
        let zb = sch.z.transpose() * &b;
        let tn = sch.t.norm();
        let eps = 1e-7;
        for trial in 0..4 {
            let mut v = rng.matrix(2, n);
            v /= v.clone().svd(false, false).singular_values.max();
            let moved = (&m + &b * &v * eps).complex_eigenvalues();
            for (k, size) in sch.blocks() {
                let lam = sch.t[(k, k)];
                let kb = input_condition(&sch.t, k, size, tn, &zb);
                let kappa = condition(&sch.t, k, size, tn);
                let b2 = b.clone().svd(false, false).singular_values.max();
                assert!(kb <= kappa * b2 * (1.0 + 1e-10), "{kb} {kappa} {b2}");
                let dl = moved
                    .iter()
                    .map(|z| (z.re - lam).abs() + z.im.abs())
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    dl / eps <= kb * 1.01 + 1e-6,
                    "trial {trial}: {} > {kb}",
                    dl / eps
                );
            }
        }
        // [[1, c], [0, 2]] with B = (c, 1)ᵀ: the left eigenvector of 1 is (1, −c), orthogonal to B.
        let c = 3.0;
        let t = DMatrix::from_row_slice(2, 2, &[1.0, c, 0.0, 2.0]);
        let zb = DMatrix::from_row_slice(2, 1, &[c, 1.0]);
        assert_eq!(input_condition(&t, 0, 1, t.norm(), &zb), 0.0);
        assert!(condition(&t, 0, 1, t.norm()) > 3.0);
        assert!(input_condition(&t, 1, 1, t.norm(), &zb) > 0.0);
    }

    #[test]
    fn a_well_separated_small_eigenvalue_of_a_large_matrix_is_off_the_axis() {
        // diag(−3.6e-3, 1.5e8) with a coupling: ‖H‖ is huge, the small eigenvalue well-conditioned.
        let t = DMatrix::from_row_slice(2, 2, &[-3.6e-3, 1.0, 0.0, 1.5e8]);
        let r = examine(&t, &[(0, 1), (1, 1)], t.norm());
        assert_eq!(r.on_axis, 0);
        assert!(r.margin > 1e3 * AXIS_FACTOR);
    }
}
