//! The Riccati residual `R(X) = AᵀX + XA − XGX + Q` in working precision and compensated, with the
//! rounding bound of the working-precision evaluation, for `G` given densely or as a factor `B Bᵀ`
//! (and such a factor of a dense semidefinite `G` from its eigenvalues).

use super::compensated;
use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, norm_fro};
use nalgebra::DMatrix;

/// The quadratic term `X G X` of the residual: from `G`, or from a factor `G = B Bᵀ` as
/// `(XB)(XB)ᵀ`. The factored form matters when `G` has low rank and large entries (a network at
/// high rates): rounding `B Bᵀ` puts `eps·‖G‖` into the null directions of `G` — information the
/// model does not have — which a residual computed from that `G` cannot see.
#[derive(Clone, Copy)]
pub(super) enum Quadratic<'a> {
    Dense(&'a DMatrix<f64>),
    Factor(&'a DMatrix<f64>),
}

impl Quadratic<'_> {
    /// The inner dimension of the products `XGX`: the order of `G`, or the columns of `B`.
    pub(super) fn inner(&self) -> usize {
        match self {
            Quadratic::Dense(g) => g.nrows(),
            Quadratic::Factor(b) => b.ncols(),
        }
    }

    /// `X G X`.
    pub(super) fn xgx(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        match self {
            Quadratic::Dense(g) => matmul_tn(x, &matmul(g, x)), // X symmetric: XᵀGX = XGX
            Quadratic::Factor(b) => {
                let xb = matmul(x, b);
                matmul_nt(&xb, &xb)
            }
        }
    }

    /// A bound (up to the factor `γ`) on the rounding error of [`Self::xgx`]: `|X||GX| + |X||G||X|`
    /// for `Xᵀ(GX)`; for `(XB)(XB)ᵀ` the error of `XB` (`|X||B|`) enters once per factor, next to
    /// the computed `|XB|` — not squared, which would overstate it by the cancellation in `XB`.
    pub(super) fn xgx_abs(&self, x: &DMatrix<f64>, ax: &DMatrix<f64>) -> DMatrix<f64> {
        match self {
            Quadratic::Dense(g) => {
                let gx = matmul(g, x).abs();
                matmul(ax, &gx) + matmul(ax, &matmul(&g.abs(), ax))
            }
            Quadratic::Factor(b) => {
                let xb = matmul(x, b).abs();
                let m = matmul(ax, &b.abs());
                let cross = matmul_nt(&m, &xb);
                &cross + cross.transpose() + matmul_nt(&xb, &xb)
            }
        }
    }

    /// A bound on the rounding error of the computed `A − GX`: `(k + 2)·eps·‖G‖‖X‖` in its
    /// factored form (`k` the inner dimension).
    pub(super) fn formation(&self, x: &DMatrix<f64>) -> f64 {
        let eps = f64::EPSILON;
        match self {
            Quadratic::Factor(b) => {
                (b.ncols() as f64 + 2.0) * eps * norm_fro(b) * norm_fro(&matmul_tn(b, x))
            }
            Quadratic::Dense(g) => (x.nrows() as f64 + 2.0) * eps * norm_fro(g) * norm_fro(x),
        }
    }

    /// `AᵀX + XA − XGX + Q`.
    pub(super) fn residual(
        &self,
        a: &DMatrix<f64>,
        q: &DMatrix<f64>,
        x: &DMatrix<f64>,
    ) -> DMatrix<f64> {
        let xa = matmul(x, a);
        &xa + xa.transpose() - self.xgx(x) + q
    }

    /// `AᵀX + XA − XGX + Q` accumulated in double-double and rounded once ([`compensated`]).
    pub(super) fn residual_compensated(
        &self,
        a: &DMatrix<f64>,
        q: &DMatrix<f64>,
        x: &DMatrix<f64>,
    ) -> DMatrix<f64> {
        match self {
            Quadratic::Dense(g) => compensated::residual(a, Some(g), None, q, x),
            Quadratic::Factor(b) => compensated::residual(a, None, Some(b), q, x),
        }
    }

    /// The entrywise rounding bound of a computed residual,
    /// `γ (|Aᵀ||X| + |X||A| + [rounding of XGX] + |Q|)` with `γ = (2n + 4)·eps`, in the Frobenius
    /// norm.
    pub(super) fn rounding(&self, a: &DMatrix<f64>, q: &DMatrix<f64>, x: &DMatrix<f64>) -> f64 {
        let n = a.nrows() as f64;
        let ax = x.abs();
        let xa = matmul(&ax, &a.abs());
        let w = &xa + xa.transpose() + self.xgx_abs(x, &ax) + q.abs();
        (2.0 * n + 4.0) * f64::EPSILON * norm_fro(&w)
    }
}

/// `B` with `G = BBᵀ` from the eigenvalues of `G` above its rounding level.
pub(super) fn psd_factor(g: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let n = g.nrows();
    let eig = g.clone().symmetric_eigen();
    let top = eig.eigenvalues.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let keep: Vec<usize> = (0..n)
        .filter(|&i| eig.eigenvalues[i] > n as f64 * f64::EPSILON * top)
        .collect();
    if keep.is_empty() {
        return None;
    }
    Some(DMatrix::from_fn(n, keep.len(), |i, j| {
        eig.eigenvectors[(i, keep[j])] * eig.eigenvalues[keep[j]].sqrt()
    }))
}
