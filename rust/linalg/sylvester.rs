//! Sylvester and Lyapunov equations by Bartels–Stewart on the real Schur form.
//!
//! PLACEHOLDER: being written. The interface below is the contract other modules program against.

use crate::linalg::schur::RealSchur;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Solves `T X + X S = C` in place (`C ← X`) for upper quasi-triangular `T` (m×m) and `S` (n×n).
pub fn solve_quasi_triangular(
    t: &DMatrix<f64>,
    s: &DMatrix<f64>,
    c: &mut DMatrix<f64>,
) -> Result<()> {
    let _ = (t, s, c);
    Err(Error::Singular("not implemented yet".into()))
}

/// A Lyapunov operator `X ↦ A X + X Aᵀ` with `A` factored once (real Schur form), for many
/// right-hand sides.
#[derive(Debug, Clone)]
pub struct Lyapunov {
    schur: RealSchur,
}

impl Lyapunov {
    /// Factors `A`.
    pub fn new(a: &DMatrix<f64>) -> Result<Self> {
        Ok(Lyapunov {
            schur: RealSchur::new(a)?,
        })
    }

    /// Uses an existing Schur form of `A`.
    pub fn from_schur(schur: RealSchur) -> Self {
        Lyapunov { schur }
    }

    /// Solves `A X + X Aᵀ = Q`.
    pub fn solve(&self, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let _ = q;
        let _ = &self.schur;
        Err(Error::Singular("not implemented yet".into()))
    }

    /// Solves the adjoint equation `Aᵀ X + X A = Q`.
    pub fn solve_adjoint(&self, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let _ = q;
        Err(Error::Singular("not implemented yet".into()))
    }
}

/// Solves `A X + X B = Q` (scipy's `solve_sylvester`).
pub fn solve_sylvester(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<DMatrix<f64>> {
    let _ = (a, b, q);
    Err(Error::Singular("not implemented yet".into()))
}

/// Solves `A X + X Aᵀ = Q` (scipy's `solve_continuous_lyapunov`).
pub fn solve_lyapunov(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    Lyapunov::new(a)?.solve(q)
}
