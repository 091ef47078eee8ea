//! Reordering by an explicit selection of eigenvalues (LAPACK dtrsen's `SELECT` array), for callers
//! that decide which eigenvalues to move with their own rule (e.g. a Python callable).

use super::RealSchur;
use crate::linalg::dense::{check_finite, check_shape, check_square};
use crate::{Error, Result};
use nalgebra::DMatrix;
use std::cell::Cell;

impl RealSchur {
    /// Wraps an existing real Schur form `(T, Z)`, e.g. one handed back from Python, after
    /// checking that `T` is upper quasi-triangular with standardised 2×2 blocks (as
    /// [`RealSchur::new`] produces them) and that `Z` has the same shape.
    ///
    /// Errors: [`Error::Shape`], [`Error::NonFinite`], or [`Error::InvalidInput`] if `T` is not in
    /// standardised real Schur form. (Orthogonality of `Z` is the caller's responsibility.)
    pub fn from_parts(t: DMatrix<f64>, z: DMatrix<f64>) -> Result<Self> {
        let n = check_square("T", &t)?;
        check_shape("Z", &z, n, n)?;
        check_finite("T", &t)?;
        check_finite("Z", &z)?;
        let bad = |why: &str| {
            Error::InvalidInput(format!(
                "T is not a standardised real Schur form ({why}); pass the T returned by schur"
            ))
        };
        for j in 0..n {
            for i in (j + 2)..n {
                if t[(i, j)] != 0.0 {
                    return Err(bad("nonzero entry below the subdiagonal"));
                }
            }
        }
        let mut k = 0;
        while k + 1 < n {
            if t[(k + 1, k)] != 0.0 {
                if k + 2 < n && t[(k + 2, k + 1)] != 0.0 {
                    return Err(bad("two consecutive nonzero subdiagonal entries"));
                }
                let (b, c) = (t[(k, k + 1)], t[(k + 1, k)]);
                if t[(k, k)] != t[(k + 1, k + 1)] || b.signum() == c.signum() {
                    return Err(bad("a 2×2 block is not standardised"));
                }
                k += 2;
            } else {
                k += 1;
            }
        }
        Ok(RealSchur { t, z })
    }

    /// Moves the eigenvalues with `select[j]` true to the leading block of `T`, where `j` indexes
    /// the eigenvalues in the order of [`RealSchur::eigenvalues`] on entry, and returns how many
    /// eigenvalues were moved (`sdim`). As in LAPACK's dtrsen, a complex conjugate pair (a 2×2
    /// block) is moved as a whole when either of its two entries is selected, and counts 2.
    ///
    /// Errors: [`Error::Shape`] if `select` does not have one entry per eigenvalue, and those of
    /// [`RealSchur::reorder`] (`T`, `Z` restored on a rejected swap).
    pub fn reorder_selected(&mut self, select: &[bool]) -> Result<usize> {
        let n = self.order();
        if select.len() != n {
            return Err(Error::Shape(format!(
                "the selection must have one entry per eigenvalue ({n}), got {}",
                select.len()
            )));
        }
        let per_block: Vec<bool> = self
            .blocks()
            .into_iter()
            .map(|(k, size)| select[k..k + size].iter().any(|&s| s))
            .collect();
        // `reorder` asks about each diagonal block exactly once, in order: a block is only ever
        // moved up past blocks already asked about, so the blocks still to come are untouched.
        let next = Cell::new(0usize);
        self.reorder(|_, _| {
            let i = next.get();
            next.set(i + 1);
            per_block.get(i).copied().unwrap_or(false)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A with eigenvalues 3, 1 ± 2i, −1, 0.5 (block diagonal, then an orthogonal similarity).
    fn example() -> DMatrix<f64> {
        let mut d = DMatrix::zeros(5, 5);
        d[(0, 0)] = 3.0;
        d[(1, 1)] = 1.0;
        d[(1, 2)] = 2.0;
        d[(2, 1)] = -2.0;
        d[(2, 2)] = 1.0;
        d[(3, 3)] = -1.0;
        d[(4, 4)] = 0.5;
        for j in 0..5 {
            for i in 0..j {
                d[(i, j)] += 0.1 * (i + 2 * j) as f64;
            }
        }
        let q = DMatrix::from_fn(5, 5, |i, j| ((i * 5 + j) as f64).sin())
            .qr()
            .q();
        &q * d * q.transpose()
    }

    #[test]
    fn selected_eigenvalues_lead_and_pairs_move_together() {
        let a = example();
        let s0 = RealSchur::new(&a).unwrap();
        let ev = s0.eigenvalues();
        // Select exactly one member of the complex pair and the eigenvalue −1.
        let sel: Vec<bool> = ev
            .iter()
            .map(|&(re, im)| (im < 0.0) || (re + 1.0).abs() < 1e-8)
            .collect();
        let mut s = s0.clone();
        let sdim = s.reorder_selected(&sel).unwrap();
        assert_eq!(sdim, 3);
        let lead = &s.eigenvalues()[..3];
        assert!(lead.iter().all(|&(re, _)| re < 1.0 + 1e-8));
        assert_eq!(lead.iter().filter(|(_, im)| *im != 0.0).count(), 2);
        let back = &s.z * &s.t * s.z.transpose();
        assert!((back - &a).norm() < 1e-13 * a.norm());
    }

    #[test]
    fn from_parts_accepts_schur_output_and_refuses_other_matrices() {
        let s = RealSchur::new(&example()).unwrap();
        assert!(RealSchur::from_parts(s.t.clone(), s.z.clone()).is_ok());
        let full = DMatrix::from_element(3, 3, 1.0);
        assert!(matches!(
            RealSchur::from_parts(full, DMatrix::identity(3, 3)),
            Err(Error::InvalidInput(_))
        ));
        let mut unstd = DMatrix::<f64>::zeros(2, 2);
        unstd[(0, 1)] = 1.0;
        unstd[(1, 0)] = 1.0; // real eigenvalues ±1 in an unsplit block
        assert!(matches!(
            RealSchur::from_parts(unstd, DMatrix::identity(2, 2)),
            Err(Error::InvalidInput(_))
        ));
        assert!(matches!(
            RealSchur::from_parts(DMatrix::identity(2, 2), DMatrix::identity(3, 3)),
            Err(Error::Shape(_))
        ));
    }

    #[test]
    fn a_selection_of_the_wrong_length_is_refused() {
        let mut s = RealSchur::new(&example()).unwrap();
        assert!(matches!(
            s.reorder_selected(&[true; 4]),
            Err(Error::Shape(_))
        ));
    }
}
