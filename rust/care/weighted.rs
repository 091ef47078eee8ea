//! The weighted CARE `AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0` (scipy's form): `G = F Fᵀ` with the factor
//! `F = B L⁻ᵀ` from the Cholesky factor `L` of `R`; the data are passed on so that the closed-loop
//! route can bound how far the computed `F Fᵀ` is from the intended `B R⁻¹ Bᵀ` (module
//! `factor_error`).

use super::{solve_factored, CareOptions, CareSolution, DataError};
use crate::linalg::dense::{check_finite, check_shape, check_square, check_symmetric, symmetrize};
use crate::{Error, Result};
use nalgebra::DMatrix;

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
    let m = input_columns(n, b)?;
    check_finite("B", b)?;
    // The factor of G = B R⁻¹ Bᵀ.
    let (g, chol, r) = match r {
        None => return solve_factored(a, b, q, opts, DataError::Exact),
        Some(r) => {
            let r = input_weight(r, m)?;
            let chol = r.clone().cholesky().ok_or_else(|| {
                Error::InvalidInput(
                    "R must be symmetric positive definite (Cholesky failed)".into(),
                )
            })?;
            // G = B R⁻¹ Bᵀ = Mᵀ M with M = L⁻¹ Bᵀ.
            let mut m_t = b.transpose();
            if !chol.l().solve_lower_triangular_mut(&mut m_t) {
                return Err(Error::InvalidInput("R is singular".into()));
            }
            (m_t.transpose(), chol, r)
        }
    };
    let l = chol.l();
    solve_factored(a, &g, q, opts, DataError::Cholesky { r: &r, b, l: &l })
}

/// The number of inputs `m` of `B`, which must have `n` rows and at least one column.
pub(super) fn input_columns(n: usize, b: &DMatrix<f64>) -> Result<usize> {
    if b.nrows() != n || b.ncols() == 0 {
        return Err(Error::Shape(format!(
            "B must have {n} rows and at least one column, got {}×{}",
            b.nrows(),
            b.ncols()
        )));
    }
    Ok(b.ncols())
}

/// The input weight `R` checked (`m × m`, finite, symmetric to 1e-10) and symmetrised.
pub(super) fn input_weight(r: &DMatrix<f64>, m: usize) -> Result<DMatrix<f64>> {
    check_shape("R", r, m, m)?;
    check_finite("R", r)?;
    check_symmetric("R", r, 1e-10)?;
    Ok(symmetrize(r))
}
