//! Shared dense helpers: input validation, norms, products, and an LU solver with a
//! condition estimate (Hager–Higham 1-norm estimator, as LAPACK's dgecon/dlacn2).

use crate::{Error, Result};
use faer::linalg::matmul::matmul as faer_matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::DMatrix;

/// Matrices at least this large are multiplied with faer's blocked kernel; smaller ones with nalgebra.
const FAER_MATMUL_MIN: usize = 48;

/// Checks that `a` is square and non-empty and returns its order.
pub fn check_square(name: &str, a: &DMatrix<f64>) -> Result<usize> {
    if a.nrows() != a.ncols() {
        return Err(Error::Shape(format!(
            "{name} must be square, got {}×{}",
            a.nrows(),
            a.ncols()
        )));
    }
    if a.nrows() == 0 {
        return Err(Error::Shape(format!("{name} must not be empty")));
    }
    Ok(a.nrows())
}

/// Checks that `a` has exactly the shape `rows × cols`.
pub fn check_shape(name: &str, a: &DMatrix<f64>, rows: usize, cols: usize) -> Result<()> {
    if a.nrows() != rows || a.ncols() != cols {
        return Err(Error::Shape(format!(
            "{name} must be {rows}×{cols}, got {}×{}",
            a.nrows(),
            a.ncols()
        )));
    }
    Ok(())
}

/// Checks that every entry of `a` is finite.
pub fn check_finite(name: &str, a: &DMatrix<f64>) -> Result<()> {
    if all_finite(a.as_slice()) {
        return Ok(());
    }
    if let Some(k) = a.iter().position(|v| !v.is_finite()) {
        let (i, j) = (k % a.nrows().max(1), k / a.nrows().max(1));
        return Err(Error::NonFinite(format!(
            "{name} has a non-finite entry ({}) at ({i}, {j})",
            a[k]
        )));
    }
    Ok(())
}

/// Whether every entry is finite. No early exit, so that it vectorises: `v·0` is NaN exactly for
/// infinite and NaN `v`, and NaN propagates through the sums.
pub fn all_finite(a: &[f64]) -> bool {
    let mut acc = [0.0f64; 8];
    let mut chunks = a.chunks_exact(8);
    for ch in &mut chunks {
        for (s, v) in acc.iter_mut().zip(ch) {
            *s += v * 0.0;
        }
    }
    let tail: f64 = chunks.remainder().iter().map(|v| v * 0.0).sum();
    !(acc.iter().sum::<f64>() + tail).is_nan()
}

/// `y ← y + alpha·x` (over the shorter of the two).
#[inline(always)]
pub fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

/// `Σ a_i b_i` with four partial sums (so that it vectorises).
#[inline(always)]
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ac, bc) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ac
        .remainder()
        .iter()
        .zip(bc.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ac.zip(bc) {
        for q in 0..4 {
            acc[q] += x[q] * y[q];
        }
    }
    (acc[0] + acc[2]) + (acc[1] + acc[3]) + tail
}

/// Checks symmetry to a relative tolerance `rtol · max(1, ‖a‖_max)`.
pub fn check_symmetric(name: &str, a: &DMatrix<f64>, rtol: f64) -> Result<()> {
    let scale = a.amax().max(1.0);
    let n = a.nrows();
    for j in 0..n {
        for i in (j + 1)..n {
            if (a[(i, j)] - a[(j, i)]).abs() > rtol * scale {
                return Err(Error::InvalidInput(format!(
                    "{name} must be symmetric: entries ({i}, {j}) and ({j}, {i}) differ ({} vs {})",
                    a[(i, j)],
                    a[(j, i)]
                )));
            }
        }
    }
    Ok(())
}

/// Returns `(a + aᵀ)/2` of a square `a`, each pair `(a_ij + a_ji)·½` computed once and written
/// to both places (the same numbers as forming `aᵀ`, adding and halving, without the copy).
pub fn symmetrize(a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    assert_eq!(n, a.ncols(), "symmetrize needs a square matrix");
    let mut out = DMatrix::<f64>::zeros(n, n);
    for j in 0..n {
        for i in 0..=j {
            let v = (a[(i, j)] + a[(j, i)]) * 0.5;
            out[(i, j)] = v;
            out[(j, i)] = v;
        }
    }
    out
}

/// The Frobenius norm, without overflow or underflow of the sum of squares: entries of
/// magnitude outside `[2⁻⁴⁵⁰, 2⁴⁵⁰]` are scaled by an exact power of two first (so `‖10³⁰⁰·I‖_F`
/// is `1.4e300`, not `∞`). In the usual range it is the plain `sqrt(Σ a_ij²)`.
pub fn norm_fro(a: &DMatrix<f64>) -> f64 {
    // One pass for the sum of squares and the largest magnitude (four lanes each, so that it
    // vectorises); the scaled second pass only when the largest entry is out of range.
    let (mut sq, mut mx) = ([0.0f64; 4], [0.0f64; 4]);
    let chunks = a.as_slice().chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for k in 0..4 {
            sq[k] += c[k] * c[k];
            mx[k] = mx[k].max(c[k].abs());
        }
    }
    for (k, &v) in rest.iter().enumerate() {
        sq[k] += v * v;
        mx[k] = mx[k].max(v.abs());
    }
    let amax = mx[0].max(mx[1]).max(mx[2].max(mx[3]));
    let (lo, hi) = (2f64.powi(-450), 2f64.powi(450));
    if !amax.is_finite() || amax == 0.0 || (lo..=hi).contains(&amax) {
        return ((sq[0] + sq[1]) + (sq[2] + sq[3])).sqrt();
    }
    // amax is normal or subnormal: 2^-e·amax ∈ [1, 2) up to rounding of e.
    let e = amax.log2().floor() as i32;
    let (down, up) = pow2_pair(-e);
    let scaled: f64 = a
        .iter()
        .map(|v| (v * down * up).powi(2))
        .sum::<f64>()
        .sqrt();
    let (d2, u2) = pow2_pair(e);
    scaled * d2 * u2
}

/// `2^e` as two representable factors (for `|e| ≤ 2000`).
fn pow2_pair(e: i32) -> (f64, f64) {
    (2f64.powi(e / 2), 2f64.powi(e - e / 2))
}

/// The 1-norm (maximum absolute column sum).
pub fn norm_1(a: &DMatrix<f64>) -> f64 {
    a.column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

fn faer_ref(a: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols())
}

fn faer_mut(a: &mut DMatrix<f64>) -> MatMut<'_, f64> {
    let (r, c) = (a.nrows(), a.ncols());
    MatMut::from_column_major_slice_mut(a.as_mut_slice(), r, c)
}

/// `c ← beta_keep·c + alpha·a·b` where `beta_keep` selects accumulate (`true`) or replace.
pub fn gemm(
    c: &mut DMatrix<f64>,
    accumulate: bool,
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    alpha: f64,
) {
    debug_assert_eq!(a.ncols(), b.nrows());
    debug_assert_eq!((c.nrows(), c.ncols()), (a.nrows(), b.ncols()));
    if a.nrows().min(a.ncols()).min(b.ncols()) >= FAER_MATMUL_MIN {
        let accum = if accumulate {
            Accum::Add
        } else {
            Accum::Replace
        };
        faer_matmul(
            faer_mut(c),
            accum,
            faer_ref(a),
            faer_ref(b),
            alpha,
            Par::Seq,
        );
    } else {
        c.gemm(alpha, a, b, if accumulate { 1.0 } else { 0.0 });
    }
}

/// The product `a·b`.
pub fn matmul(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    let mut c = DMatrix::zeros(a.nrows(), b.ncols());
    gemm(&mut c, false, a, b, 1.0);
    c
}

/// The product `aᵀ·b`.
pub fn matmul_tn(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    if a.nrows().min(a.ncols()).min(b.ncols()) >= FAER_MATMUL_MIN {
        let mut c = DMatrix::zeros(a.ncols(), b.ncols());
        faer_matmul(
            faer_mut(&mut c),
            Accum::Replace,
            faer_ref(a).transpose(),
            faer_ref(b),
            1.0,
            Par::Seq,
        );
        c
    } else {
        a.tr_mul(b)
    }
}

/// The product `a·bᵀ`.
pub fn matmul_nt(a: &DMatrix<f64>, b: &DMatrix<f64>) -> DMatrix<f64> {
    if a.nrows().min(a.ncols()).min(b.nrows()) >= FAER_MATMUL_MIN {
        let mut c = DMatrix::zeros(a.nrows(), b.nrows());
        faer_matmul(
            faer_mut(&mut c),
            Accum::Replace,
            faer_ref(a),
            faer_ref(b).transpose(),
            1.0,
            Par::Seq,
        );
        c
    } else {
        a * b.transpose()
    }
}

/// From this order on [`Lu::new`] uses the blocked factorisation.
const BLOCKED_LU_MIN: usize = 64;

/// LU factorisation with partial pivoting, `P A = L U`, kept for repeated solves.
#[derive(Debug, Clone)]
pub struct Lu {
    lu: DMatrix<f64>,
    perm: Vec<usize>,
    anorm1: f64,
}

impl Lu {
    /// Factors `a` (square, finite). A zero pivot gives [`Error::SingularProblem`].
    pub fn new(a: &DMatrix<f64>) -> Result<Self> {
        let n = check_square("matrix", a)?;
        let anorm1 = norm_1(a);
        if n >= BLOCKED_LU_MIN {
            return Self::new_blocked(a, anorm1);
        }
        let mut lu = a.clone();
        let mut perm: Vec<usize> = (0..n).collect();
        for k in 0..n {
            let (mut p, mut best) = (k, lu[(k, k)].abs());
            for i in (k + 1)..n {
                let v = lu[(i, k)].abs();
                if v > best {
                    best = v;
                    p = i;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return Err(Error::SingularProblem(format!(
                    "matrix is singular to working precision (zero pivot in column {k})"
                )));
            }
            if p != k {
                lu.swap_rows(p, k);
                perm.swap(p, k);
            }
            let piv = lu[(k, k)];
            for i in (k + 1)..n {
                lu[(i, k)] /= piv;
            }
            // Rank-one update of the trailing block, column by column on contiguous slices.
            let (left, right) = lu.as_mut_slice().split_at_mut((k + 1) * n);
            let lcol = &left[k * n + k + 1..(k + 1) * n];
            for cj in right.chunks_exact_mut(n) {
                let ukj = cj[k];
                if ukj != 0.0 {
                    for (x, l) in cj[k + 1..].iter_mut().zip(lcol) {
                        *x -= l * ukj;
                    }
                }
            }
        }
        Ok(Lu { lu, perm, anorm1 })
    }

    /// faer's blocked right-looking factorisation (same pivoting rule: the largest entry of the
    /// column), for the orders where the rank-one updates above become memory bound.
    fn new_blocked(a: &DMatrix<f64>, anorm1: f64) -> Result<Self> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::lu::partial_pivoting::factor::{lu_in_place, lu_in_place_scratch};
        let n = a.nrows();
        let mut lu = a.clone();
        let mut fwd = vec![0usize; n];
        let mut inv = vec![0usize; n];
        let mut buf = MemBuffer::new(lu_in_place_scratch::<usize, f64>(
            n,
            n,
            faer::Par::Seq,
            Default::default(),
        ));
        let m = faer::MatMut::from_column_major_slice_mut(lu.as_mut_slice(), n, n);
        lu_in_place(
            m,
            &mut fwd,
            &mut inv,
            faer::Par::Seq,
            MemStack::new(&mut buf),
            Default::default(),
        );
        if let Some(k) = (0..n).find(|&k| {
            let p = lu[(k, k)];
            p == 0.0 || !p.is_finite()
        }) {
            return Err(Error::SingularProblem(format!(
                "matrix is singular to working precision (zero pivot in column {k})"
            )));
        }
        Ok(Lu {
            lu,
            perm: fwd,
            anorm1,
        })
    }

    /// Order of the factored matrix.
    pub fn order(&self) -> usize {
        self.lu.nrows()
    }

    /// Solves `A x = b` in place for every column of `b`.
    pub fn solve_in_place(&self, b: &mut DMatrix<f64>) {
        let n = self.order();
        let lu = self.lu.as_slice();
        let mut col = vec![0.0; n];
        if b.ncols() >= 4 {
            // Many right-hand sides: row permutation, then faer's blocked triangular solves.
            for mut c in b.column_iter_mut() {
                for i in 0..n {
                    col[i] = c[self.perm[i]];
                }
                c.as_mut_slice().copy_from_slice(&col);
            }
            let m = b.ncols();
            let f = faer::MatRef::from_column_major_slice(lu, n, n);
            let mut rhs = faer::MatMut::from_column_major_slice_mut(b.as_mut_slice(), n, m);
            faer::linalg::triangular_solve::solve_unit_lower_triangular_in_place(
                f,
                rhs.as_mut(),
                faer::Par::Seq,
            );
            faer::linalg::triangular_solve::solve_upper_triangular_in_place(f, rhs, faer::Par::Seq);
            return;
        }
        for mut c in b.column_iter_mut() {
            for i in 0..n {
                col[i] = c[self.perm[i]];
            }
            // L y = P b (unit lower), column-oriented so that the inner loops vectorise.
            for j in 0..n {
                let x = col[j];
                if x != 0.0 {
                    for (ci, li) in col[j + 1..].iter_mut().zip(&lu[j * n + j + 1..(j + 1) * n]) {
                        *ci -= li * x;
                    }
                }
            }
            // U x = y.
            for j in (0..n).rev() {
                col[j] /= lu[j * n + j];
                let x = col[j];
                if x != 0.0 {
                    for (ci, ui) in col[..j].iter_mut().zip(&lu[j * n..j * n + j]) {
                        *ci -= ui * x;
                    }
                }
            }
            for i in 0..n {
                c[i] = col[i];
            }
        }
    }

    /// Solves `Aᵀ x = b` in place for every column of `b`.
    pub fn solve_transpose_in_place(&self, b: &mut DMatrix<f64>) {
        let n = self.order();
        let lu = self.lu.as_slice();
        let mut col = vec![0.0; n];
        for mut c in b.column_iter_mut() {
            col.copy_from_slice(c.as_slice());
            // Uᵀ y = b (forward), Lᵀ z = y (backward), x = Pᵀ z: dot products with columns of LU.
            for j in 0..n {
                let s = col[j] - dot(&lu[j * n..j * n + j], &col[..j]);
                col[j] = s / lu[j * n + j];
            }
            for j in (0..n).rev() {
                col[j] -= dot(&lu[j * n + j + 1..(j + 1) * n], &col[j + 1..]);
            }
            for i in 0..n {
                c[self.perm[i]] = col[i];
            }
        }
    }

    /// Estimate of the reciprocal 1-norm condition number `1/(‖A‖₁‖A⁻¹‖₁)` (Hager–Higham).
    pub fn rcond(&self) -> f64 {
        if self.anorm1 == 0.0 {
            return 0.0;
        }
        let inv_norm = estimate_inverse_norm1(self.order(), |x, transpose| {
            if transpose {
                self.solve_transpose_in_place(x)
            } else {
                self.solve_in_place(x)
            }
        });
        if inv_norm == 0.0 || !inv_norm.is_finite() {
            return 0.0;
        }
        1.0 / (self.anorm1 * inv_norm)
    }
}

/// Hager–Higham estimate of `‖B‖₁` for an operator given by `apply(x, transpose)` (x ← B x or Bᵀ x).
/// At most five iterations, as in LAPACK's dlacn2.
pub fn estimate_inverse_norm1(n: usize, mut apply: impl FnMut(&mut DMatrix<f64>, bool)) -> f64 {
    let mut x = DMatrix::from_element(n, 1, 1.0 / n as f64);
    apply(&mut x, false);
    let mut est: f64 = x.iter().map(|v| v.abs()).sum();
    let mut last_j = usize::MAX;
    for _ in 0..5 {
        let mut s = x.map(|v| if v >= 0.0 { 1.0 } else { -1.0 });
        apply(&mut s, true);
        let (j, zmax) = s.iter().enumerate().fold((0, -1.0), |(bj, bv), (j, v)| {
            if v.abs() > bv {
                (j, v.abs())
            } else {
                (bj, bv)
            }
        });
        if j == last_j {
            break;
        }
        last_j = j;
        let _ = zmax;
        let mut e = DMatrix::zeros(n, 1);
        e[j] = 1.0;
        apply(&mut e, false);
        let new_est: f64 = e.iter().map(|v| v.abs()).sum();
        if new_est <= est {
            break;
        }
        est = new_est;
        x = e;
    }
    // Higham's alternating-sign safeguard vector.
    let mut alt = DMatrix::from_fn(n, 1, |i, _| {
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        sign * (1.0 + i as f64 / (n.max(2) - 1) as f64)
    });
    apply(&mut alt, false);
    let alt_est = 2.0 * alt.iter().map(|v| v.abs()).sum::<f64>() / (3.0 * n as f64);
    est.max(alt_est)
}

#[cfg(test)]
mod tests;
