//! Real Schur form `A = Z T Zᵀ` with standardised 2×2 blocks, and its reordering.
//!
//! * [`RealSchur::new`]: Householder reduction to Hessenberg form (unblocked, as LAPACK's dgehd2,
//!   up to order 80; above, the blocked dgehrd/dlahr2/dorghr-style reduction of `hessenberg.rs`,
//!   which polls the cancellation token between panels), then
//!   the Francis double-shift QR iteration in the style of LAPACK's dlahqr (Ahues–Tisseur
//!   deflation, exceptional shifts every 10 iterations, at most `30·max(10, n)` iterations per
//!   deflation), accumulating `Z`. From order 75 on (LAPACK's NMIN), the small-bulge multishift QR
//!   with aggressive early deflation (LAPACK's dlaqr0/dlaqr3/dlaqr5, see `multishift.rs`) is used
//!   instead; it hands small active blocks, its deflation windows and anything it cannot finish
//!   within `30·max(10, n)` iterations to the double-shift code. Every 2×2 block is standardised
//!   as LAPACK's dlanv2 does: a real pair is split into two 1×1 blocks with an exact zero
//!   subdiagonal, a complex pair has the form `[[a, b], [c, a]]` with `b·c < 0`; all entries below
//!   the subdiagonal are exactly zero.
//! * [`RealSchur::reorder`] / [`RealSchur::reorder_to`]: adjacent block swaps as LAPACK's
//!   dtrsen/dtrexc/dlaexc, including dlaexc's swap-rejection test.

mod hessenberg;
mod hqr;
mod kernels;
mod multishift;
mod reorder;
mod reorder_blocked;
mod selection;
#[cfg(test)]
mod tests;

use crate::{Error, Result};
use nalgebra::DMatrix;
use reorder_blocked::Interrupt;

/// A real Schur decomposition `A = Z T Zᵀ`: `T` upper quasi-triangular with standardised 2×2
/// blocks (equal diagonal, off-diagonals of opposite sign), `Z` orthogonal.
#[derive(Debug, Clone)]
pub struct RealSchur {
    /// Quasi-upper-triangular factor.
    pub t: DMatrix<f64>,
    /// Orthogonal Schur vectors.
    pub z: DMatrix<f64>,
}

/// Entries with max-norm outside `[SCALE_LO, SCALE_HI]` are scaled by a power of two before the
/// QR iteration (as LAPACK's dgees does with `sqrt(safmin)/eps` and its reciprocal).
fn scale_bounds() -> (f64, f64) {
    let lo = f64::MIN_POSITIVE.sqrt() / f64::EPSILON;
    (lo, 1.0 / lo)
}

/// The exponent `e` such that `2^e·T` has max-norm inside the scaling bounds (0 if already inside).
fn scaling_exponent(t: &DMatrix<f64>) -> i32 {
    let anrm = t.amax();
    let (lo, hi) = scale_bounds();
    if anrm > 0.0 && (anrm < lo || anrm > hi) {
        -(anrm.log2().round() as i32)
    } else {
        0
    }
}

/// `v·2^exp` in two power-of-two steps (2^exp itself may overflow when entries are subnormal).
fn scale_pow2(v: f64, exp: i32) -> f64 {
    (v * 2f64.powi(exp / 2)) * 2f64.powi(exp - exp / 2)
}

fn scale_matrix(t: &mut DMatrix<f64>, exp: i32) {
    if exp != 0 {
        t.iter_mut().for_each(|v| *v = scale_pow2(*v, exp));
    }
}

impl RealSchur {
    /// Computes the real Schur form of a square finite matrix.
    ///
    /// Errors: [`Error::Shape`] if `a` is empty or not square, [`Error::NonFinite`] if it has a
    /// NaN or infinite entry, [`Error::Convergence`] if the QR iteration exceeds its bound.
    pub fn new(a: &DMatrix<f64>) -> Result<Self> {
        let n = crate::linalg::dense::check_square("A", a)?;
        crate::linalg::dense::check_finite("A", a)?;
        let mut t = a.clone();
        // Scale by an exact power of two if the entries are very large or very small.
        let exp = scaling_exponent(a);
        scale_matrix(&mut t, exp);
        let ts = t.as_mut_slice();
        let zv = hqr::hessenberg_reduce(ts, n)?;
        crate::cancel::check("the Hessenberg reduction of the real Schur form")?;
        let mut z = DMatrix::from_vec(n, n, zv);
        hqr::francis_qr(t.as_mut_slice(), z.as_mut_slice(), n).map_err(|i| {
            if crate::cancel::is_cancelled() {
                return crate::cancel::interrupted("the QR iteration of the real Schur form");
            }
            Error::Convergence(format!(
                "real Schur QR iteration did not converge within its bound of 30·max(10, n) \
                 iterations per eigenvalue (eigenvalue at row {i} of {n})"
            ))
        })?;
        scale_matrix(&mut t, -exp);
        Ok(RealSchur { t, z })
    }

    /// Order of the matrix.
    pub fn order(&self) -> usize {
        self.t.nrows()
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

    /// Eigenvalues `(re, im)` in the order they appear on the diagonal of `T`; a complex pair is
    /// listed with the positive imaginary part first.
    pub fn eigenvalues(&self) -> Vec<(f64, f64)> {
        let mut ev = Vec::with_capacity(self.t.nrows());
        for (k, size) in self.blocks() {
            if size == 1 {
                ev.push((self.t[(k, k)], 0.0));
            } else {
                let [e1, e2] = block_eigenvalues(&self.t, k);
                ev.push(e1);
                ev.push(e2);
            }
        }
        ev
    }

    /// Moves every eigenvalue `(re, im)` for which `select(re, im)` holds to the leading block of
    /// `T`, updating `Z`, and returns how many eigenvalues were selected (`sdim`). A complex pair is
    /// selected as a whole when `select` holds for its eigenvalue with positive imaginary part.
    ///
    /// This is LAPACK's dtrsen ordering loop over dtrexc/dlaexc swaps. If a swap is rejected
    /// (the swapped blocks would be too ill-conditioned to separate accurately),
    /// [`Error::Reorder`] is returned and `T`, `Z` are restored to their values on entry.
    ///
    /// Like [`RealSchur::new`], the swaps work on `T` scaled by a power of two into the normal
    /// range: rotations computed from subnormal entries would not be orthogonal.
    pub fn reorder(&mut self, select: impl Fn(f64, f64) -> bool) -> Result<usize> {
        let exp = scaling_exponent(&self.t);
        scale_matrix(&mut self.t, exp);
        let res = self
            .reorder_scaled(&|re: f64, im: f64| select(scale_pow2(re, -exp), scale_pow2(im, -exp)));
        scale_matrix(&mut self.t, -exp);
        res
    }

    fn reorder_scaled(&mut self, select: &dyn Fn(f64, f64) -> bool) -> Result<usize> {
        let n = self.t.nrows();
        // The selection, per row (both rows of a 2×2 block carry its flag), decided once on the
        // form on entry: the moves never change a block below the one being moved.
        let mut sel = vec![false; n];
        let mut in_place = true; // every selected block already at the top
        let mut ks = 0usize;
        for (k, size) in self.blocks() {
            let (re, im) = if size == 1 {
                (self.t[(k, k)], 0.0)
            } else {
                block_eigenvalues(&self.t, k)[0]
            };
            if select(re, im) {
                sel[k..k + size].iter_mut().for_each(|s| *s = true);
                in_place &= k == ks;
                ks += size;
            }
        }
        if in_place {
            return Ok(ks);
        }
        let (t0, z0) = (self.t.clone(), self.z.clone());
        let res = reorder_blocked::reorder_selected(
            self.t.as_mut_slice(),
            self.z.as_mut_slice(),
            n,
            &sel,
            &crate::cancel::is_cancelled,
        );
        match res {
            Ok(sdim) => Ok(sdim),
            Err(stop) => {
                self.t = t0;
                self.z = z0;
                Err(match stop {
                    Interrupt::Cancelled => crate::cancel::interrupted("the Schur reordering"),
                    Interrupt::Rejected(rej, at) => Error::Reorder(format!(
                        "Schur reordering failed: swapping the eigenvalue block at row {} \
                         past its neighbour would leave an entry of size {:.3e} above the \
                         tolerance {:.3e} (eigenvalues too close to be separated accurately)",
                        at, rej.residual, rej.threshold
                    )),
                })
            }
        }
    }

    /// Moves the diagonal block starting at row `ifst` so that it starts at row `ilst`, by
    /// adjacent swaps (LAPACK's dtrexc, both directions). Rows in the middle of a 2×2 block are
    /// adjusted to the block's first row. Returns the row where the block finally starts (which
    /// may differ from `ilst` by one when 2×2 blocks are involved).
    ///
    /// Errors: [`Error::Shape`] if an index is out of range, [`Error::Reorder`] if a swap is
    /// rejected; `T` and `Z` are then restored to their values on entry.
    pub fn reorder_to(&mut self, ifst: usize, ilst: usize) -> Result<usize> {
        let n = self.t.nrows();
        if ifst >= n || ilst >= n {
            return Err(Error::Shape(format!(
                "block indices ({ifst}, {ilst}) out of range for order {n}"
            )));
        }
        let (t0, z0) = (self.t.clone(), self.z.clone());
        let exp = scaling_exponent(&self.t);
        scale_matrix(&mut self.t, exp);
        let moved =
            reorder::move_block(self.t.as_mut_slice(), self.z.as_mut_slice(), n, ifst, ilst);
        scale_matrix(&mut self.t, -exp);
        match moved {
            Ok(pos) => Ok(pos),
            Err((rej, at)) => {
                self.t = t0;
                self.z = z0;
                Err(Error::Reorder(format!(
                    "Schur reordering failed at row {at}: swap residual {:.3e} exceeds {:.3e}",
                    rej.residual, rej.threshold
                )))
            }
        }
    }
}

/// Eigenvalues of the 2×2 block at `(k, k)`, positive imaginary part first.
fn block_eigenvalues(t: &DMatrix<f64>, k: usize) -> [(f64, f64); 2] {
    let (a, b, c, d) = (t[(k, k)], t[(k, k + 1)], t[(k + 1, k)], t[(k + 1, k + 1)]);
    if a == d && b != 0.0 && c != 0.0 && b.signum() != c.signum() {
        let im = b.abs().sqrt() * c.abs().sqrt();
        [(a, im), (a, -im)]
    } else {
        // Not standardised (T was modified by the caller): standardise a copy.
        let r = kernels::lanv2(a, b, c, d);
        let e = r.eigenvalues();
        if e[0].1 < 0.0 {
            [e[1], e[0]]
        } else {
            e
        }
    }
}
