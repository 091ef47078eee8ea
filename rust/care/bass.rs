//! A stabilising feedback by Bass's method (Armstrong 1975), applied to the unstable part only.
//!
//! For `M` with every eigenvalue in the open right half-plane shifted by `β > 0` (here `M = T₂₂ + βI`,
//! `T₂₂` the block of a real Schur form of `A − BK` holding its eigenvalues with `Re λ ≥ 0`), the
//! Lyapunov equation `M P + P Mᵀ = 2 B₂ B₂ᵀ` has the solution
//! `P = ∫₀^∞ e^{−Mt} 2B₂B₂ᵀ e^{−Mᵀt} dt ⪰ 0`, positive definite exactly when `(T₂₂, B₂)` is
//! controllable. With `K₂ = B₂ᵀ P⁻¹`,
//! `(T₂₂ − B₂K₂) P + P (T₂₂ − B₂K₂)ᵀ = T₂₂P + PT₂₂ᵀ − 2B₂B₂ᵀ = −2βP`,
//! so every eigenvalue of `T₂₂ − B₂K₂` has real part `−β` (it is `−βI` plus a matrix similar to a
//! skew-symmetric one). In the Schur basis `A − BK = U [[T₁₁, T₁₂], [0, T₂₂]] Uᵀ` the extra gain
//! `K₂U₂ᵀ` leaves the stable block `T₁₁` alone and the closed loop becomes block triangular with
//! blocks `T₁₁` and `T₂₂ − B₂K₂`: stable. Rounding can spoil this only when `P` is nearly singular
//! (weakly controllable unstable modes); the caller verifies the computed closed loop's spectrum.

use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, norm_fro, symmetrize};
use crate::linalg::schur::RealSchur;
use crate::linalg::sylvester::Lyapunov;
use crate::Result;
use nalgebra::DMatrix;

/// A gain `K' = K + K₂U₂ᵀ` (`m × n`) that makes `A − BK'` stable, `K` itself when `A − BK` is
/// already stable (by its computed spectrum); `None` when `P` is not numerically positive definite
/// (an unstable mode that the input does not reach).
pub(super) fn stabilise(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    k: &DMatrix<f64>,
) -> Result<Option<DMatrix<f64>>> {
    let n = a.nrows();
    let acl = a - matmul(b, k);
    let mut schur = RealSchur::new(&acl)?;
    let unstable: Vec<(f64, f64)> = schur
        .eigenvalues()
        .into_iter()
        .filter(|(re, _)| !(*re < 0.0))
        .collect();
    if unstable.is_empty() {
        return Ok(Some(k.clone()));
    }
    let sdim = schur.reorder(|re, _| re < 0.0)?;
    let r = n - sdim;
    if r == 0 {
        return Ok(Some(k.clone()));
    }
    let u2 = schur.z.columns(sdim, r).into_owned();
    let t22 = schur.t.view((sdim, sdim), (r, r)).into_owned();
    let b2 = matmul_tn(&u2, b);
    // β above every |λ(T₂₂)| keeps the closed-loop block a modest multiple of T₂₂ (β must only be
    // positive); a floor for a nilpotent T₂₂.
    let rho = unstable
        .iter()
        .map(|(re, im)| re.hypot(*im))
        .fold(0.0, f64::max);
    let beta = rho
        .max(f64::EPSILON * norm_fro(&acl))
        .max(f64::MIN_POSITIVE.sqrt());
    let shifted = &t22 + DMatrix::identity(r, r) * beta;
    let rhs = symmetrize(&(matmul_nt(&b2, &b2) * 2.0));
    let p = match Lyapunov::new(&shifted).and_then(|l| l.solve(&rhs)) {
        Ok(p) => symmetrize(&p),
        Err(crate::Error::Interrupted(m)) => return Err(crate::Error::Interrupted(m)),
        Err(_) => return Ok(None),
    };
    let Some(chol) = p.cholesky() else {
        return Ok(None);
    };
    let k2 = chol.solve(&b2).transpose(); // B₂ᵀP⁻¹ (P symmetric)
    let gain = k + matmul_nt(&k2, &u2);
    Ok(gain.iter().all(|v| v.is_finite()).then_some(gain))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    #[test]
    fn the_unstable_part_is_moved_to_minus_beta_and_the_stable_part_kept() {
        let mut rng = Rng::new(11);
        let n = 6;
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, 2);
        let k0 = DMatrix::zeros(2, n);
        let open = RealSchur::new(&a).unwrap().eigenvalues();
        assert!(open.iter().any(|e| e.0 >= 0.0), "want an unstable A");
        let k = stabilise(&a, &b, &k0).unwrap().unwrap();
        let closed = RealSchur::new(&(&a - &b * &k)).unwrap().eigenvalues();
        assert!(closed.iter().all(|e| e.0 < 0.0), "{closed:?}");
        // Every stable eigenvalue of A is still an eigenvalue of the closed loop.
        for (re, im) in open.iter().filter(|e| e.0 < 0.0) {
            let near = closed
                .iter()
                .any(|(r, i)| (r - re).abs() + (i.abs() - im.abs()).abs() < 1e-8);
            assert!(near, "{re} {im}");
        }
        // Already stable: the gain is returned unchanged.
        assert_eq!(stabilise(&a, &b, &k).unwrap().unwrap(), k);
    }
}
