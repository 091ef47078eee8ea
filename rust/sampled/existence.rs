//! The hypotheses of Proposition 1: `(A, [c̄_1 … c̄_N])` observable and `τ ∈ 𝒯` (no aliasing).
//!
//! Both are *sufficient* for the periodic steady state to exist and not depend on `Σ(0)`;
//! [`super::doubling`] detects the failures that actually occur (growth, non-stabilising limits)
//! independently of these checks.

use super::SampledSystem;
use crate::linalg::schur::RealSchur;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Default relative rank tolerance of [`unobservable_dimension`].
pub const OBSERVABILITY_RTOL: f64 = 1e-10;

/// Default tolerance of [`aliasing_pair`], in cycles (units of `2π`).
pub const ALIASING_TOL: f64 = 1e-8;

/// Dimension of the unobservable subspace of `(A, C)` (output `y = Cᵀx`, `C` is `n × m`), by the
/// orthogonal staircase: an orthonormal basis of `span{C, AᵀC, (Aᵀ)²C, …}` grown block by block,
/// each new block re-orthogonalised against the basis (twice) and rank-decided by an SVD with
/// threshold `rtol · ‖·‖` (`‖C‖_F` for the first block, `‖A‖_F` after). Scale-invariant in `C`.
pub fn unobservable_dimension(a: &DMatrix<f64>, c: &DMatrix<f64>, rtol: f64) -> Result<usize> {
    let n = crate::linalg::dense::check_square("A", a)?;
    crate::linalg::dense::check_shape("C", c, n, c.ncols())?;
    let cn = c.norm();
    if cn == 0.0 || c.ncols() == 0 {
        return Ok(n);
    }
    let at = a.transpose();
    let an = a.norm();
    let mut basis = DMatrix::<f64>::zeros(n, 0);
    let mut block = c / cn;
    let mut threshold = rtol;
    // Each pass adds at least one column to `basis` or stops: at most n passes.
    loop {
        crate::cancel::check("the observability test")?;
        for _ in 0..2 {
            if basis.ncols() > 0 {
                let proj = &basis * basis.tr_mul(&block);
                block -= proj;
            }
        }
        // nalgebra's `svd()` iterates without bound (forever on NaN): bound it.
        let svd = block
            .clone()
            .try_svd(true, false, f64::EPSILON, 30 * n.max(10) * n)
            .ok_or_else(|| {
                Error::Convergence(format!(
                    "the SVD of the observability block did not converge within its bound of \
                     {} sweeps (non-finite entries in A or C?)",
                    30 * n.max(10) * n
                ))
            })?;
        let u = svd.u.expect("U requested");
        let keep: Vec<usize> = (0..svd.singular_values.len())
            .filter(|&k| svd.singular_values[k] > threshold)
            .collect();
        if keep.is_empty() {
            break;
        }
        let new = DMatrix::from_fn(n, keep.len(), |i, j| u[(i, keep[j])]);
        let k0 = basis.ncols();
        basis = basis.insert_columns(k0, new.ncols(), 0.0);
        basis.view_mut((0, k0), (n, new.ncols())).copy_from(&new);
        if basis.ncols() >= n {
            break;
        }
        block = &at * &new;
        threshold = rtol * an.max(f64::MIN_POSITIVE);
    }
    Ok(n - basis.ncols().min(n))
}

/// Two eigenvalues `(re, im)` of `A` (from its real Schur form).
pub type AliasingPair = ((f64, f64), (f64, f64));

/// A pair of distinct eigenvalues `λ_i ≠ λ_j` of `A` with `e^{λ_iτ} = e^{λ_jτ}` — i.e.
/// `z = (λ_i − λ_j) τ / (2πi)` within `tol` of a nonzero integer — if there is one; `None` when
/// `τ ∈ 𝒯`. Distinct eigenvalues closer than `tol` cycles give `z ≈ 0` and never count.
pub fn aliasing_pair(a: &DMatrix<f64>, tau: f64, tol: f64) -> Result<Option<AliasingPair>> {
    if !tau.is_finite() || tau <= 0.0 {
        return Err(Error::InvalidInput(format!(
            "the period tau must be positive and finite, got {tau}"
        )));
    }
    let ev = RealSchur::new(a)?.eigenvalues();
    let two_pi = 2.0 * std::f64::consts::PI;
    for i in 0..ev.len() {
        for j in (i + 1)..ev.len() {
            let (dre, dim) = (ev[i].0 - ev[j].0, ev[i].1 - ev[j].1);
            // z = (λ_i − λ_j) τ / (2πi) = (dim − i·dre) τ / 2π.
            let (zr, zi) = (dim * tau / two_pi, -dre * tau / two_pi);
            let k = zr.round();
            if k != 0.0 && (zr - k).hypot(zi) <= tol {
                return Ok(Some((ev[i], ev[j])));
            }
        }
    }
    Ok(None)
}

impl SampledSystem {
    /// The sensor matrices of the sensors that `slots` uses, side by side (`n × Σp_i`).
    pub fn used_sensors(&self, slots: &[usize]) -> DMatrix<f64> {
        let mut used = vec![false; self.n_sensors()];
        for &i in slots {
            if i < used.len() {
                used[i] = true;
            }
        }
        let cols: Vec<&DMatrix<f64>> = self
            .sensors()
            .iter()
            .zip(&used)
            .filter(|(_, u)| **u)
            .map(|(c, _)| c)
            .collect();
        let m: usize = cols.iter().map(|c| c.ncols()).sum();
        let mut out = DMatrix::zeros(self.order(), m);
        let mut k = 0;
        for c in cols {
            out.view_mut((0, k), (self.order(), c.ncols())).copy_from(c);
            k += c.ncols();
        }
        out
    }

    /// Checks Proposition 1 for a schedule: the sensors it uses observe `A`, and `τ ∈ 𝒯`.
    /// Violations are [`Error::InvalidInput`] naming the problem.
    pub fn check_existence(&self, tau: f64, slots: &[usize]) -> Result<()> {
        self.check_schedule(slots)?;
        let d = unobservable_dimension(self.a(), &self.used_sensors(slots), OBSERVABILITY_RTOL)?;
        if d > 0 {
            return Err(Error::InvalidInput(format!(
                "(A, [c̄_i]) is not observable with the sensors this schedule uses: unobservable \
                 subspace of dimension {d} (Proposition 1 needs observability)"
            )));
        }
        if let Some((l1, l2)) = aliasing_pair(self.a(), tau, ALIASING_TOL)? {
            return Err(Error::InvalidInput(format!(
                "tau = {tau} aliases the eigenvalues {}{:+}i and {}{:+}i of A (e^{{λτ}} coincide; \
                 Proposition 1 needs τ ∈ 𝒯)",
                l1.0, l1.1, l2.0, l2.1
            )));
        }
        Ok(())
    }
}
