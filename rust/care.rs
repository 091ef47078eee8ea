//! Continuous algebraic Riccati equation by the Hamiltonian/Schur method.
//!
//! PLACEHOLDER signature; implementation in progress.

use crate::{Error, Result};
use nalgebra::DMatrix;

/// Options for [`solve_care`].
#[derive(Debug, Clone, Copy)]
pub struct CareOptions {
    /// Scale `Q` and `G` by `sqrt(‖Q‖/‖G‖)` before the Schur step (SLICOT SB02RD).
    pub scale: bool,
    /// At most this many Newton–Kleinman refinement steps after the Schur solution (0: none).
    pub newton_steps: usize,
}

impl Default for CareOptions {
    fn default() -> Self {
        CareOptions {
            scale: true,
            newton_steps: 0,
        }
    }
}

/// The stabilising solution of a CARE with its diagnostics.
#[derive(Debug, Clone)]
pub struct CareSolution {
    /// The stabilising solution `X = Xᵀ`.
    pub x: DMatrix<f64>,
    /// Relative residual `‖AᵀX + XA − XGX + Q‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)`.
    pub residual: f64,
    /// Reciprocal 1-norm condition estimate of `U11` in `X U11 = U21`.
    pub rcond: f64,
    /// Spectral abscissa `max Re λ(A − G X)` of the closed loop (negative).
    pub closed_loop_abscissa: f64,
    /// Newton–Kleinman steps taken.
    pub newton_steps: usize,
    /// The scaling factor applied to `Q` and `G` (1 when scaling is off).
    pub scaling: f64,
}

/// Solves `Aᵀ X + X A − X G X + Q = 0` for the stabilising `X` (`A − G X` Hurwitz), with `G` and
/// `Q` symmetric positive semidefinite.
pub fn solve_care(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    let _ = (a, g, q, opts);
    Err(Error::NoConvergence("not implemented yet".into()))
}
