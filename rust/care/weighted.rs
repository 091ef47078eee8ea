//! The weighted CARE `AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0` (scipy's form): `G = F Fᵀ` with the factor
//! `F = B L⁻ᵀ` from the Cholesky factor `L` of `R`, and a bound on how far the computed factor's
//! `F Fᵀ` is from the intended `B R⁻¹ Bᵀ` (what the closed-loop route adds to its certificate).

use super::{solve_factored, CareOptions, CareSolution, DataError};
use crate::linalg::dense::{
    check_finite, check_shape, check_square, check_symmetric, matmul, norm_fro, symmetrize,
};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// A bound on `‖E‖₂` in `B R⁻¹ Bᵀ = F(I + E)Fᵀ`, `F = B L⁻ᵀ` computed from the computed Cholesky
/// factor `L` of `R` (first order in eps): the Cholesky and triangular-solve backward errors
/// make `F` exact for `R + Δ`, `|Δ| ≤ (3m + 4)·eps·|L||Lᵀ|`, so `E = (I − E₀)⁻¹ − I` with
/// `‖E₀‖ ≤ (3m + 4)·eps·‖|L⁻¹||L|‖²`. ∞ when that is not below 1; 0 when `L` is diagonal with
/// powers of two on its diagonal (exact Cholesky and solves).
pub(super) fn cholesky_factor_error(l: &DMatrix<f64>) -> f64 {
    let m = l.nrows();
    // A diagonal L of powers of two (R = I, or diagonal R of powers of four): F = BL⁻ᵀ is exact.
    let exact = (0..m).all(|j| {
        (0..m).all(|i| i == j || l[(i, j)] == 0.0) && {
            let d = l[(j, j)];
            d > 0.0 && d == 2f64.powi(d.log2().round() as i32) && d * d == d.powi(2)
        }
    });
    if exact {
        return 0.0;
    }
    let mut linv = DMatrix::identity(m, m);
    if !l.solve_lower_triangular_mut(&mut linv) {
        return f64::INFINITY;
    }
    let skeel = norm_fro(&matmul(&linv.abs(), &l.abs()));
    let e0 = (3.0 * m as f64 + 4.0) * f64::EPSILON * skeel * skeel;
    if e0 < 1.0 {
        e0 / (1.0 - e0)
    } else {
        f64::INFINITY
    }
}

/// Solves scipy's form `AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0` (`r = None` means `R = I`).
/// `R` must be symmetric positive definite.
pub fn solve_care_weighted(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: Option<&DMatrix<f64>>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    let n = check_square("A", a)?;
    if b.nrows() != n || b.ncols() == 0 {
        return Err(Error::Shape(format!(
            "B must have {n} rows and at least one column, got {}×{}",
            b.nrows(),
            b.ncols()
        )));
    }
    check_finite("B", b)?;
    let m = b.ncols();
    // The factor of G = B R⁻¹ Bᵀ.
    let (g, chol) = match r {
        None => return solve_factored(a, b, q, opts, DataError::Exact),
        Some(r) => {
            check_shape("R", r, m, m)?;
            check_finite("R", r)?;
            check_symmetric("R", r, 1e-10)?;
            let chol = symmetrize(r).cholesky().ok_or_else(|| {
                Error::InvalidInput(
                    "R must be symmetric positive definite (Cholesky failed)".into(),
                )
            })?;
            // G = B R⁻¹ Bᵀ = Mᵀ M with M = L⁻¹ Bᵀ.
            let mut m_t = b.transpose();
            if !chol.l().solve_lower_triangular_mut(&mut m_t) {
                return Err(Error::InvalidInput("R is singular".into()));
            }
            (m_t.transpose(), chol)
        }
    };
    let l = chol.l();
    solve_factored(a, &g, q, opts, DataError::Cholesky(&l))
}
