//! The trace reductions of every sensor at one slot of the screen ([`super::sensitivity`]),
//! batched.
//!
//! For sensor `k` at a slot with prior `P` and adjoint `μ`,
//! `g_k = tr(S_k⁻¹ X_kᵀ μ X_k)` with `X_k = P c̄_k`, `S_k = I + c̄_kᵀ X_k`. Sensors that share the
//! prior (all of them when their samples last equally long) are done together: with
//! `C = [c̄_k …]` the products `X = P C` and `μ X` are two blocked matrix products instead of `2N`
//! matrix–vector ones (which dominated the screen at `N = 50`); the `p × p` parts are then per
//! sensor, as before.

use crate::linalg::dense::{matmul, symmetrize};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// `g_k` for every sensor `k` (`priors[k]`: its prior at the slot, `cbar[k]`: its `c̄`).
pub(super) fn slot_gains(
    priors: &[&DMatrix<f64>],
    cbar: &[DMatrix<f64>],
    mu: &DMatrix<f64>,
) -> Result<Vec<f64>> {
    let mut out = vec![0.0; priors.len()];
    let mut done = vec![false; priors.len()];
    for k0 in 0..priors.len() {
        if done[k0] {
            continue;
        }
        let p = priors[k0];
        let group: Vec<usize> = (k0..priors.len())
            .filter(|&k| !done[k] && std::ptr::eq(priors[k], p))
            .collect();
        let n = p.nrows();
        let width: usize = group.iter().map(|&k| cbar[k].ncols()).sum();
        let mut c = DMatrix::<f64>::zeros(n, width);
        let mut off = 0;
        for &k in &group {
            let q = cbar[k].ncols();
            c.columns_mut(off, q).copy_from(&cbar[k]);
            off += q;
        }
        let x = matmul(p, &c);
        let y = matmul(mu, &x);
        let mut off = 0;
        for &k in &group {
            let q = cbar[k].ncols();
            let xk = x.columns(off, q);
            let mut s = cbar[k].tr_mul(&xk);
            for i in 0..q {
                s[(i, i)] += 1.0;
            }
            let chol = symmetrize(&s).cholesky().ok_or_else(|| {
                Error::SingularProblem(
                    "innovation covariance I + c̄ᵀPc̄ is not positive definite".into(),
                )
            })?;
            let xtmx = xk.tr_mul(&y.columns(off, q));
            out[k] = chol.solve(&xtmx).trace();
            done[k] = true;
            off += q;
        }
    }
    Ok(out)
}
