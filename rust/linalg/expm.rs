//! Matrix exponential and Van Loan's integral.
//!
//! PLACEHOLDER: being written (Higham's Padé 13 scaling and squaring). Interface is the contract.

use crate::Result;
use nalgebra::DMatrix;

/// `e^A` for a square finite matrix.
pub fn expm(a: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    crate::linalg::dense::check_square("A", a)?;
    crate::linalg::dense::check_finite("A", a)?;
    Ok(a.clone().exp())
}

/// Van Loan's discretisation over a step `t`: `E = e^{At}` and `H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`.
#[derive(Debug, Clone)]
pub struct VanLoan {
    /// The transition matrix `e^{At}`.
    pub e: DMatrix<f64>,
    /// The process-noise integral `∫₀ᵗ e^{As} Q e^{Aᵀs} ds` (symmetric).
    pub h: DMatrix<f64>,
}

/// Computes [`VanLoan`] from `expm([[−A, Q],[0, Aᵀ]] t) = [[·, F₁₂],[0, Eᵀ]]`, `H = E F₁₂`.
pub fn van_loan(a: &DMatrix<f64>, q: &DMatrix<f64>, t: f64) -> Result<VanLoan> {
    let n = a.nrows();
    let mut m = DMatrix::zeros(2 * n, 2 * n);
    m.view_mut((0, 0), (n, n)).copy_from(&(-a * t));
    m.view_mut((0, n), (n, n)).copy_from(&(q * t));
    m.view_mut((n, n), (n, n)).copy_from(&(a.transpose() * t));
    let f = expm(&m)?;
    let e = f.view((n, n), (n, n)).transpose();
    let h = &e * f.view((0, n), (n, n));
    let h = (&h + h.transpose()) * 0.5;
    Ok(VanLoan { e, h })
}
