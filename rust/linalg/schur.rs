//! Real Schur form `A = Z T Zᵀ` with standardised 2×2 blocks, and its reordering.
//!
//! PLACEHOLDER: this file is being rewritten (Francis QR + dlanv2 standardisation + dtrexc/dlaexc
//! reordering). The interface below is the contract other modules program against.

use crate::{Error, Result};
use nalgebra::DMatrix;

/// A real Schur decomposition `A = Z T Zᵀ`: `T` upper quasi-triangular with standardised 2×2
/// blocks (equal diagonal, off-diagonals of opposite sign), `Z` orthogonal.
#[derive(Debug, Clone)]
pub struct RealSchur {
    /// Quasi-upper-triangular factor.
    pub t: DMatrix<f64>,
    /// Orthogonal Schur vectors.
    pub z: DMatrix<f64>,
}

impl RealSchur {
    /// Computes the real Schur form of a square finite matrix.
    pub fn new(a: &DMatrix<f64>) -> Result<Self> {
        crate::linalg::dense::check_square("A", a)?;
        crate::linalg::dense::check_finite("A", a)?;
        let s = nalgebra::Schur::try_new(a.clone(), f64::EPSILON, 100 * a.nrows())
            .ok_or_else(|| Error::NoConvergence("Schur QR iteration did not converge".into()))?;
        let (z, t) = s.unpack();
        Ok(RealSchur { t, z })
    }

    /// Diagonal blocks as `(start, size)` with size 1 or 2.
    pub fn blocks(&self) -> Vec<(usize, usize)> {
        let n = self.t.nrows();
        let mut out = Vec::new();
        let mut k = 0;
        while k < n {
            if k + 1 < n && self.t[(k + 1, k)] != 0.0 {
                out.push((k, 2));
                k += 2;
            } else {
                out.push((k, 1));
                k += 1;
            }
        }
        out
    }

    /// Eigenvalues `(re, im)` in the order they appear on the diagonal of `T`.
    pub fn eigenvalues(&self) -> Vec<(f64, f64)> {
        let mut ev = Vec::with_capacity(self.t.nrows());
        for (k, size) in self.blocks() {
            if size == 1 {
                ev.push((self.t[(k, k)], 0.0));
            } else {
                let (a, b, c, d) = (
                    self.t[(k, k)],
                    self.t[(k, k + 1)],
                    self.t[(k + 1, k)],
                    self.t[(k + 1, k + 1)],
                );
                let re = 0.5 * (a + d);
                let disc = 0.25 * (a - d) * (a - d) + b * c;
                let im = (-disc).max(0.0).sqrt();
                ev.push((re, im));
                ev.push((re, -im));
            }
        }
        ev
    }

    /// Moves every eigenvalue `(re, im)` for which `select(re, im)` holds to the leading block of
    /// `T`, updating `Z`, and returns how many eigenvalues were selected (`sdim`). A complex pair is
    /// selected as a whole when `select` holds for its eigenvalue with positive imaginary part.
    pub fn reorder(&mut self, select: impl Fn(f64, f64) -> bool) -> Result<usize> {
        let _ = select;
        Err(Error::ReorderFailed(
            "reordering not implemented yet".into(),
        ))
    }
}
