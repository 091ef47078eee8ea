//! Sylvester and Lyapunov equations by Bartels–Stewart on the real Schur form.
//!
//! * [`solve_quasi_triangular`]: `T X + X S = C` for upper quasi-triangular `T`, `S` (LAPACK
//!   dtrsyl with `TRANA = TRANB = 'N'`), recursive blocked so that the bulk of the work is matrix
//!   products (Jonsson–Kågström, RECSY).
//! * [`Lyapunov`]: `A X + X Aᵀ = Q` and the adjoint `Aᵀ X + X A = Q` with the Schur form of `A`
//!   computed once, for many right-hand sides. For symmetric `Q` only the upper block triangle of
//!   the transformed equation is solved (SLICOT SB03MD/SB03MY style), which halves the triangular
//!   work, and the result is exactly symmetric.
//! * [`Sylvester`]: `A X + X B = Q` and the adjoint `Aᵀ X + X Bᵀ = Q` with the Schur forms of `A`
//!   and `B` computed once.
//! * [`GeneralizedLyapunov`]: `Aᵀ X E + Eᵀ X A = C` on the generalised Schur form of `(A, E)`
//!   (SLICOT SG03AD), without `E⁻¹`.
//! * [`solve_sylvester`] and [`solve_lyapunov`]: one-shot versions (scipy's `solve_sylvester` and
//!   `solve_continuous_lyapunov`).
//!
//! ## Singular and nearly singular equations
//!
//! `A X + X B = Q` has a unique solution iff `λ_i(A) + λ_j(B) ≠ 0` for all eigenvalue pairs. The
//! triangular solve meets these sums as the pivots of its small diagonal-block systems (order 1–4,
//! or complex 1–2). LAPACK's dtrsyl replaces a pivot below `smin ≈ eps·max|t_ij|` by `smin` and
//! returns an inaccurate answer with `INFO = 1`; here a pivot below
//! `smin = rtol · max(‖T‖_F, ‖S‖_F)` (default [`DEFAULT_SINGULAR_RTOL`] = 1e-12 ≈ 4500·eps) stops
//! the solve with [`Error::SingularProblem`], whose message names the offending eigenvalues. A pivot that
//! small means the computed Schur forms are within a few thousand rounding errors of a singular
//! equation, and the relative error of `X` can be as large as `eps/rtol ≈ 1e-4`. Exactly
//! cancelling spectra (`±1`, `B = −A`, `±iω`) give pivots of about `eps·‖A‖`, far below the
//! default; generic problems stay far above it. The tolerance can be changed per factorisation
//! (`with_singular_rtol`; `0.0` only rejects zero and subnormal pivots).
//!
//! The pivots only see the eigenvalues; a badly non-normal equation can be ill-conditioned with all
//! `|λ_i + μ_j|` large. `sep_estimate` gives a Hager–Higham estimate of the separation
//! `sep = 1/‖L⁻¹‖` of the operator `L: X ↦ A X + X B` for that, at the cost of ~10 extra solves.
//!
//! No scaling against overflow is done (dtrsyl returns a `SCALE ≤ 1` with `X/SCALE` the true
//! solution): if the solution is not representable in `f64` the solve returns [`Error::SingularProblem`]
//! saying so. Results never contain NaN or infinities.
//!
//! ## Schur form requirements
//!
//! Any real Schur form `A = Z T Zᵀ` from [`RealSchur`] works: a 2×2 diagonal block is recognised by
//! `t[(k+1, k)] != 0.0`, blocks need not be standardised (a 2×2 block with real eigenvalues is fine),
//! and entries below the first subdiagonal are never read. Two consecutive nonzero subdiagonal
//! entries (a 3×3 unreduced block) are rejected with [`Error::InvalidInput`].

mod general;
mod generalized_lyapunov;
mod kernel;
mod lyapunov;
#[cfg(test)]
mod tests;

use std::sync::OnceLock;

use crate::linalg::dense::{
    all_finite, check_finite, check_shape, check_square, estimate_inverse_norm1, norm_fro,
};
use crate::linalg::schur::RealSchur;
use crate::{Error, Result};
use faer::linalg::matmul::matmul as faer_matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::{Accum, MatMut, MatRef, Par};
pub use general::{solve_sylvester, Sylvester};
pub use generalized_lyapunov::GeneralizedLyapunov;
use kernel::{Ctx, Kind, View};
pub use lyapunov::{solve_lyapunov, Lyapunov};
use nalgebra::DMatrix;

/// Default relative pivot tolerance: the equation is declared singular when a pivot of the
/// triangular solve (≈ `|λ_i(A) + λ_j(B)|`) falls below `rtol · max(‖A‖_F, ‖B‖_F)`.
pub const DEFAULT_SINGULAR_RTOL: f64 = 1e-12;

/// A solution with diagnostics.
#[derive(Debug, Clone)]
pub struct Solution {
    /// The solution `X`.
    pub x: DMatrix<f64>,
    /// Relative residual `‖A X + X B − Q‖_F / ((‖A‖_F + ‖B‖_F)·‖X‖_F + ‖Q‖_F)`, with `B = Aᵀ` for
    /// Lyapunov equations (and `A`, `B` replaced by their transposes for adjoint solves). Computed
    /// from the original coefficient matrices, so it includes the errors of the orthogonal
    /// transformations, not only those of the triangular solve.
    pub residual: f64,
    /// `min |pivot| / max(‖A‖_F, ‖B‖_F)` over the diagonal-block systems of the triangular solve: of
    /// the order of `min |λ_i(A) + λ_j(B)| / max(‖A‖_F, ‖B‖_F)`. The solve fails with
    /// [`Error::SingularProblem`] when this would fall below the singularity tolerance.
    pub pivot_ratio: f64,
}

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

fn fref(a: &DMatrix<f64>) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice(a.as_slice(), a.nrows(), a.ncols())
}

fn fmut(a: &mut DMatrix<f64>) -> MatMut<'_, f64> {
    let (r, c) = (a.nrows(), a.ncols());
    MatMut::from_column_major_slice_mut(a.as_mut_slice(), r, c)
}

/// `dst ← op(a) · op(b)` with `op` selected by the flags.
fn product_into(dst: &mut DMatrix<f64>, a: &DMatrix<f64>, ta: bool, b: &DMatrix<f64>, tb: bool) {
    let (fa, fb) = (fref(a), fref(b));
    let fa = if ta { fa.transpose() } else { fa };
    let fb = if tb { fb.transpose() } else { fb };
    faer_matmul(fmut(dst), Accum::Replace, fa, fb, 1.0, Par::Seq);
}

/// `op(a) · op(b)`.
fn product(a: &DMatrix<f64>, ta: bool, b: &DMatrix<f64>, tb: bool) -> DMatrix<f64> {
    let rows = if ta { a.ncols() } else { a.nrows() };
    let cols = if tb { b.nrows() } else { b.ncols() };
    let mut c = DMatrix::zeros(rows, cols);
    product_into(&mut c, a, ta, b, tb);
    c
}

/// Upper triangle of `dst ← op(a) · op(b)` (the strict lower triangle of `dst` is left as is).
fn product_upper_into(
    dst: &mut DMatrix<f64>,
    a: &DMatrix<f64>,
    ta: bool,
    b: &DMatrix<f64>,
    tb: bool,
) {
    let (fa, fb) = (fref(a), fref(b));
    let fa = if ta { fa.transpose() } else { fa };
    let fb = if tb { fb.transpose() } else { fb };
    triangular::matmul(
        fmut(dst),
        BlockStructure::TriangularUpper,
        Accum::Replace,
        fa,
        BlockStructure::Rectangular,
        fb,
        BlockStructure::Rectangular,
        1.0,
        Par::Seq,
    );
}

/// Upper triangle of `op(a) · op(b)` (the strict lower triangle of the result is zero).
fn product_upper(a: &DMatrix<f64>, ta: bool, b: &DMatrix<f64>, tb: bool) -> DMatrix<f64> {
    let rows = if ta { a.ncols() } else { a.nrows() };
    let mut c = DMatrix::zeros(rows, rows);
    product_upper_into(&mut c, a, ta, b, tb);
    c
}

/// Whether `q` (square) is exactly symmetric. Compares 32×32 tiles with their mirror images so
/// that both sides are read from cache.
fn is_exactly_symmetric(q: &DMatrix<f64>) -> bool {
    const B: usize = 32;
    let n = q.nrows();
    let a = q.as_slice();
    for jb in (0..n).step_by(B) {
        for ib in (jb..n).step_by(B) {
            for j in jb..(jb + B).min(n) {
                for i in ib.max(j + 1)..(ib + B).min(n) {
                    if a[i + j * n] != a[j + i * n] {
                        return false;
                    }
                }
            }
        }
    }
    true
}

/// Copies the upper triangle onto the lower one (tile by tile, as [`is_exactly_symmetric`]).
fn mirror_upper(x: &mut DMatrix<f64>) {
    const B: usize = 32;
    let n = x.nrows();
    let a = x.as_mut_slice();
    for jb in (0..n).step_by(B) {
        for ib in (jb..n).step_by(B) {
            for j in jb..(jb + B).min(n) {
                for i in ib.max(j + 1)..(ib + B).min(n) {
                    a[i + j * n] = a[j + i * n];
                }
            }
        }
    }
}

/// Checks that `t` is square, finite and upper quasi-triangular in the sense used here: no two
/// consecutive nonzero subdiagonal entries (entries below the subdiagonal are ignored).
fn check_quasi_triangular(name: &str, t: &DMatrix<f64>) -> Result<()> {
    let n = t.nrows();
    for j in 0..n {
        for i in 0..(j + 2).min(n) {
            let v = t[(i, j)];
            if !v.is_finite() {
                return Err(Error::NonFinite(format!(
                    "{name} has a non-finite entry ({v}) at ({i}, {j})"
                )));
            }
        }
    }
    for k in 0..n.saturating_sub(2) {
        if t[(k + 1, k)] != 0.0 && t[(k + 2, k + 1)] != 0.0 {
            return Err(Error::InvalidInput(format!(
                "{name} is not upper quasi-triangular: consecutive nonzero subdiagonal entries at \
                 ({}, {k}) and ({}, {}) (diagonal blocks must be 1×1 or 2×2)",
                k + 1,
                k + 2,
                k + 1
            )));
        }
    }
    Ok(())
}

/// Frobenius norm of the upper Hessenberg part of `t` (what the kernels read).
fn quasi_norm(t: &DMatrix<f64>) -> f64 {
    let n = t.nrows();
    let mut s = 0.0;
    for j in 0..n {
        for i in 0..(j + 2).min(n) {
            s += t[(i, j)] * t[(i, j)];
        }
    }
    s.sqrt()
}

fn smin(rtol: f64, scale: f64) -> f64 {
    (rtol * scale).max(f64::MIN_POSITIVE)
}

fn pivot_ratio(min_pivot: f64, scale: f64) -> f64 {
    if scale > 0.0 {
        min_pivot / scale
    } else {
        0.0
    }
}

fn check_rtol(rtol: f64) -> Result<()> {
    if !(rtol.is_finite() && rtol >= 0.0) {
        return Err(Error::InvalidInput(format!(
            "the singularity tolerance must be finite and non-negative, got {rtol}"
        )));
    }
    Ok(())
}

fn check_solution(x: &DMatrix<f64>, kind: Kind) -> Result<()> {
    if all_finite(x.as_slice()) {
        Ok(())
    } else {
        Err(Error::SingularProblem(format!(
            "{} solution overflows: the equation is too ill-conditioned for the size of its \
             right-hand side",
            if kind == Kind::Lyapunov {
                "Lyapunov equation"
            } else {
                "Sylvester equation"
            }
        )))
    }
}

/// `J Tᵀ J` (`J` the reversal permutation): upper quasi-triangular when `T` is, with the same
/// eigenvalues. With `A = Z T Zᵀ`, `Aᵀ = (Z J)(J Tᵀ J)(Z J)ᵀ` is a real Schur form of `Aᵀ`.
fn reversed_transpose(t: &DMatrix<f64>) -> DMatrix<f64> {
    let n = t.nrows();
    DMatrix::from_fn(n, n, |i, j| t[(n - 1 - j, n - 1 - i)])
}

fn reversed_columns(z: &DMatrix<f64>) -> DMatrix<f64> {
    let n = z.ncols();
    DMatrix::from_fn(z.nrows(), n, |i, j| z[(i, n - 1 - j)])
}

/// A real Schur factor `A = Z T Zᵀ` with the pieces both directions of a solve need.
#[derive(Debug, Clone)]
struct Factor {
    schur: RealSchur,
    /// `J Tᵀ J` and `Z J`: the Schur form of `Aᵀ`.
    adj_t: DMatrix<f64>,
    adj_z: DMatrix<f64>,
    /// `‖T‖_F` over the quasi-triangular part (= `‖A‖_F` up to rounding).
    norm: f64,
    /// Why the factor cannot be used, if it cannot.
    invalid: Option<Error>,
    /// `A` itself (given, or rebuilt from the factor on first use) for residuals.
    a: OnceLock<DMatrix<f64>>,
}

impl Factor {
    fn new(schur: RealSchur, a: Option<&DMatrix<f64>>) -> Self {
        let n = schur.t.nrows();
        let mut invalid = None;
        if schur.t.ncols() != n || schur.z.nrows() != n || schur.z.ncols() != n || n == 0 {
            invalid = Some(Error::Shape(format!(
                "Schur factors must be square and of equal non-zero order, got T {}×{} and Z {}×{}",
                schur.t.nrows(),
                schur.t.ncols(),
                schur.z.nrows(),
                schur.z.ncols()
            )));
        } else if let Err(e) =
            check_quasi_triangular("T", &schur.t).and_then(|_| check_finite("Z", &schur.z))
        {
            invalid = Some(e);
        }
        let (adj_t, adj_z, norm) = if invalid.is_none() {
            (
                reversed_transpose(&schur.t),
                reversed_columns(&schur.z),
                quasi_norm(&schur.t),
            )
        } else {
            (DMatrix::zeros(0, 0), DMatrix::zeros(0, 0), 0.0)
        };
        let cell = OnceLock::new();
        if let Some(a) = a {
            let _ = cell.set(a.clone());
        }
        Factor {
            schur,
            adj_t,
            adj_z,
            norm,
            invalid,
            a: cell,
        }
    }

    fn order(&self) -> usize {
        self.schur.t.nrows()
    }

    fn usable(&self) -> Result<()> {
        match &self.invalid {
            Some(e) => Err(e.clone()),
            None => Ok(()),
        }
    }

    /// `(T, Z)` for `A` or, when `adjoint`, for `Aᵀ`.
    fn tz(&self, adjoint: bool) -> (&DMatrix<f64>, &DMatrix<f64>) {
        if adjoint {
            (&self.adj_t, &self.adj_z)
        } else {
            (&self.schur.t, &self.schur.z)
        }
    }

    /// The matrix `A = Z T Zᵀ` (entries of `T` below the subdiagonal taken as zero).
    fn a(&self) -> &DMatrix<f64> {
        self.a.get_or_init(|| {
            let n = self.order();
            let mut t = self.schur.t.clone();
            for j in 0..n {
                for i in (j + 2)..n {
                    t[(i, j)] = 0.0;
                }
            }
            let zt = product(&self.schur.z, false, &t, false);
            product(&zt, false, &self.schur.z, true)
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Quasi-triangular solver
// ---------------------------------------------------------------------------------------------

/// Solves `T X + X S = C` in place (`C ← X`) for upper quasi-triangular `T` (m×m) and `S` (n×n).
///
/// `T` and `S` are read on and above their first subdiagonal; a nonzero subdiagonal entry marks a
/// 2×2 diagonal block. Fails with [`Error::SingularProblem`] when `λ_i(T) + λ_j(S) ≈ 0` (see the module
/// documentation; tolerance [`DEFAULT_SINGULAR_RTOL`]). On error `C` holds partial results.
pub fn solve_quasi_triangular(
    t: &DMatrix<f64>,
    s: &DMatrix<f64>,
    c: &mut DMatrix<f64>,
) -> Result<()> {
    solve_quasi_triangular_with_rtol(t, s, c, DEFAULT_SINGULAR_RTOL).map(|_| ())
}

/// [`solve_quasi_triangular`] with an explicit singularity tolerance `rtol`; returns the pivot
/// ratio `min |pivot| / max(‖T‖_F, ‖S‖_F)`.
pub fn solve_quasi_triangular_with_rtol(
    t: &DMatrix<f64>,
    s: &DMatrix<f64>,
    c: &mut DMatrix<f64>,
    rtol: f64,
) -> Result<f64> {
    check_rtol(rtol)?;
    let m = check_square("T", t)?;
    let n = check_square("S", s)?;
    check_shape("C", c, m, n)?;
    check_quasi_triangular("T", t)?;
    check_quasi_triangular("S", s)?;
    check_finite("C", c)?;
    let scale = quasi_norm(t).max(quasi_norm(s));
    let mut ctx = Ctx::new(smin(rtol, scale), Kind::QuasiTriangular);
    kernel::sylv(
        &mut ctx,
        View::new(t.as_slice(), m),
        View::new(s.as_slice(), n),
        false,
        c.as_mut_slice(),
        m,
        (0, m),
        (0, n),
    )?;
    check_solution(c, Kind::QuasiTriangular)?;
    Ok(pivot_ratio(ctx.min_pivot, scale))
}

/// Solves a Lyapunov equation with an upper quasi-triangular `T` in place (`C ← X`):
/// `T X + X Tᵀ = C`, or (`adjoint`) `Tᵀ X + X T = C` — the triangular stage of [`Lyapunov`] for a
/// caller that already holds a Schur-like factor (the CARE's closed loop is similar to the leading
/// block of the ordered Hamiltonian Schur form). An exactly symmetric `C` gives an exactly symmetric
/// `X` at half the work. Pivots below `rtol·‖T‖_F` fail with [`Error::SingularProblem`].
pub fn solve_lyapunov_quasi_triangular(
    t: &DMatrix<f64>,
    c: &mut DMatrix<f64>,
    adjoint: bool,
    rtol: f64,
) -> Result<()> {
    check_rtol(rtol)?;
    let n = check_square("T", t)?;
    check_shape("C", c, n, n)?;
    check_quasi_triangular("T", t)?;
    check_finite("C", c)?;
    // Tᵀ X + X T = C  ⇔  U X̂ + X̂ Uᵀ = Ĉ with U = J Tᵀ J, X̂ = J X J (vec reversed).
    let reversed;
    let tm = if adjoint {
        reversed = reversed_transpose(t);
        &reversed
    } else {
        t
    };
    let mut ctx = Ctx::new(smin(rtol, quasi_norm(tm)), Kind::Lyapunov);
    let tv = View::new(tm.as_slice(), n);
    if adjoint {
        c.as_mut_slice().reverse();
    }
    if is_exactly_symmetric(c) {
        kernel::lyap(&mut ctx, tv, c.as_mut_slice(), n, (0, n))?;
        mirror_upper(c);
    } else {
        kernel::sylv(&mut ctx, tv, tv, true, c.as_mut_slice(), n, (0, n), (0, n))?;
    }
    if adjoint {
        c.as_mut_slice().reverse();
    }
    check_solution(c, Kind::Lyapunov)
}

/// `1/‖L⁻¹‖₁` by the Hager–Higham estimator, where `solve(c, transpose)` overwrites the `m×n`
/// column-major `c` with `L⁻¹ c` or (`transpose`) `J L⁻ᵀ J c` with `J` the reversal of `vec`.
fn sep_by_estimator(m: usize, n: usize, solve: impl Fn(&mut [f64], bool) -> Result<()>) -> f64 {
    let mut failed = false;
    let est = estimate_inverse_norm1(m * n, |x, transpose| {
        if failed {
            return;
        }
        let v = x.as_mut_slice();
        if transpose {
            v.reverse();
        }
        if solve(v, transpose).is_err() || v.iter().any(|e| !e.is_finite()) {
            failed = true;
            return;
        }
        if transpose {
            v.reverse();
        }
    });
    if failed || est.is_nan() || est <= 0.0 || !est.is_finite() {
        0.0
    } else {
        1.0 / est
    }
}
