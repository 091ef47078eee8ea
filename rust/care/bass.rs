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
/// (an unstable mode that the input does not reach), in one step and in stages alike.
///
/// All unstable modes are first moved at once. When their Gramian `P` is not numerically definite
/// (many unstable modes spread over decades, few inputs: a Cauchy-like `P`), they are moved in
/// stages instead ([`stabilise_in_stages`]).
pub(super) fn stabilise(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    k: &DMatrix<f64>,
) -> Result<Option<DMatrix<f64>>> {
    match stage(a, b, k, |_| true)? {
        Stage::Stable => Ok(Some(k.clone())),
        Stage::Moved(gain) => Ok(Some(gain)),
        Stage::Failed => stabilise_in_stages(a, b, k),
    }
}

/// Bass's method applied to one unstable mode at a time (the real eigenvalue or complex pair of
/// largest modulus, moved to `−|λ|`), each stage on a fresh real Schur form of the current closed
/// loop: each `P` is `1 × 1` or `2 × 2`, definite whenever that mode is reachable. In exact
/// arithmetic a stage leaves the other eigenvalues where they are (block-triangular closed loop),
/// so at most `n` stages are needed; a stage that does not reduce the computed number of unstable
/// eigenvalues ends the attempt (`None`), as does a Gramian that is not definite.
pub(super) fn stabilise_in_stages(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    k: &DMatrix<f64>,
) -> Result<Option<DMatrix<f64>>> {
    let n = a.nrows();
    let mut gain = k.clone();
    let mut unstable = usize::MAX;
    for _ in 0..=n {
        crate::cancel::check("the staged stabilisation of the Riccati solver's start")?;
        let acl = a - matmul(b, &gain);
        let eig = RealSchur::new(&acl)?.eigenvalues();
        let now: Vec<f64> = eig
            .iter()
            .filter(|(re, _)| !(*re < 0.0))
            .map(|(re, im)| re.hypot(*im))
            .collect();
        if now.is_empty() {
            return Ok(Some(gain));
        }
        if now.len() >= unstable || now.iter().any(|v| !v.is_finite()) {
            return Ok(None);
        }
        unstable = now.len();
        let rho = now.iter().copied().fold(0.0, f64::max);
        match stage(a, b, &gain, |m| m >= rho)? {
            Stage::Moved(g) => gain = g,
            Stage::Stable => return Ok(Some(gain)),
            Stage::Failed => return Ok(None),
        }
    }
    Ok(None)
}

/// What one application of Bass's method did.
enum Stage {
    /// `A − BK` is stable by its computed spectrum: nothing to move.
    Stable,
    /// The new gain.
    Moved(DMatrix<f64>),
    /// `P` not numerically positive definite, or a non-finite gain.
    Failed,
}

/// Bass's method on the unstable eigenvalues of `A − BK` whose modulus `|λ|` passes `chosen`
/// (the others stay in `T₁₁`).
fn stage(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    k: &DMatrix<f64>,
    chosen: impl Fn(f64) -> bool,
) -> Result<Stage> {
    let n = a.nrows();
    let acl = a - matmul(b, k);
    let mut schur = RealSchur::new(&acl)?;
    let moved: Vec<(f64, f64)> = schur
        .eigenvalues()
        .into_iter()
        .filter(|(re, im)| !(*re < 0.0) && chosen(re.hypot(*im)))
        .collect();
    if moved.is_empty() {
        return Ok(Stage::Stable);
    }
    let sdim = schur.reorder(|re, im| re < 0.0 || !chosen(re.hypot(im)))?;
    let r = n - sdim;
    if r == 0 {
        return Ok(Stage::Stable);
    }
    let u2 = schur.z.columns(sdim, r).into_owned();
    let t22 = schur.t.view((sdim, sdim), (r, r)).into_owned();
    let b2 = matmul_tn(&u2, b);
    // β above every |λ(T₂₂)| keeps the closed-loop block a modest multiple of T₂₂ (β must only be
    // positive); a floor for a nilpotent T₂₂.
    let rho = moved
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
        Err(_) => return Ok(Stage::Failed),
    };
    let Some(chol) = p.cholesky() else {
        return Ok(Stage::Failed);
    };
    let k2 = chol.solve(&b2).transpose(); // B₂ᵀP⁻¹ (P symmetric)
    let gain = k + matmul_nt(&k2, &u2);
    Ok(if gain.iter().all(|v| v.is_finite()) {
        Stage::Moved(gain)
    } else {
        Stage::Failed
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    /// Many unstable modes over six decades and one input: moved one at a time, each to `−|λ|`,
    /// the stable modes kept.
    #[test]
    fn stages_stabilise_unstable_modes_spread_over_decades() {
        let mut rng = Rng::new(7);
        let unstable: Vec<f64> = (0..10)
            .map(|i| 10f64.powf(-3.0 + 6.0 * i as f64 / 9.0))
            .collect();
        let mut eig = unstable.clone();
        eig.extend([-0.5, -3.0, -40.0]);
        let a = rng.with_eigenvalues(&eig, &[]);
        let b = rng.matrix(eig.len(), 1);
        let k0 = DMatrix::zeros(1, eig.len());
        let k = stabilise_in_stages(&a, &b, &k0).unwrap().unwrap();
        let closed = RealSchur::new(&(&a - &b * &k)).unwrap().eigenvalues();
        assert!(closed.iter().all(|e| e.0 < 0.0), "{closed:?}");
        for re in [-0.5, -3.0, -40.0] {
            let near = closed
                .iter()
                .any(|(r, i)| (r - re).abs() < 1e-6 * re.abs() && i.abs() < 1e-6);
            assert!(near, "{re}: {closed:?}");
        }
        // An unstable mode the input cannot reach: B = e₁ on A = diag(2, 1, −1).
        let a = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![2.0, 1.0, -1.0]));
        let b = DMatrix::from_column_slice(3, 1, &[1.0, 0.0, 0.0]);
        assert!(stabilise_in_stages(&a, &b, &DMatrix::zeros(1, 3))
            .unwrap()
            .is_none());
        assert!(stabilise(&a, &b, &DMatrix::zeros(1, 3)).unwrap().is_none());
    }

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
