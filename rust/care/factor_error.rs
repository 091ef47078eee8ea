//! How far the factor `F̂` of the weighted CARE's `G = B R⁻¹ Bᵀ`, computed as `F̂ᵀ = L̂⁻¹Bᵀ` from the
//! computed Cholesky factor `L̂` of `R`, is from the intended data: `B R⁻¹ Bᵀ = (F̂ + δ)(I + E)(F̂ + δ)ᵀ`
//! with bounds on `‖E‖₂` and `‖δ‖₂` (what the closed-loop route adds to its certificate).
//!
//! **A posteriori (used when it is the tighter).** With `Δ = R − L̂L̂ᵀ` and `ρ = F̂L̂ᵀ − B` (both
//! exact matrices, evaluated in double-double), `R = L̂(I + E₀)L̂ᵀ` with `E₀ = L̂⁻¹ΔL̂⁻ᵀ` and
//! `B = (F̂ + δ)L̂ᵀ` with `δ = −ρL̂⁻ᵀ`, so *exactly*
//! `B R⁻¹ Bᵀ = (F̂ + δ)(I + E₀)⁻¹(F̂ + δ)ᵀ`, i.e. `E = (I + E₀)⁻¹ − I`, `‖E‖₂ ≤ e₀/(1 − e₀)` for
//! `‖E₀‖₂ ≤ e₀ < 1`. `L̂⁻¹` is applied through its computed inverse `Ŷ` and the residual
//! `N = I − L̂Ŷ` (with the rounding of its own evaluation, `γ_{m+1}(√m + ‖|L̂||Ŷ|‖_F)`): for
//! `‖N‖₂ ≤ ν < ½`, `L̂⁻¹ = Ŷ(I − N)⁻¹ = Ŷ(I + K)`, `‖K‖₂ ≤ k = ν/(1 − ν)`. This accounts for the
//! error of the triangular solves however ill-conditioned `L̂` is (`ν ≈ γ·‖|L̂||Ŷ|‖`, the worst-case
//! relative error of a solve); the bound is refused when `ν ≥ ½`. Then
//! - `‖E₀‖₂ ≤ ‖fl(ŶΔ̂Ŷᵀ)‖_F + (2γ_m + γ_m²)‖|Ŷ||Δ̂||Ŷ|ᵀ‖_F + (2k + k²)‖Ŷ‖_F²‖Δ̂‖_F + (1 + k)²‖Ŷ‖_F²‖Δ − Δ̂‖_F`,
//! - `‖δ‖₂ ≤ ‖fl(ρ̂Ŷᵀ)‖_F + γ_m‖|ρ̂||Ŷ|ᵀ‖_F + k‖ρ̂‖_F‖Ŷ‖_F + (1 + k)‖Ŷ‖_F‖ρ − ρ̂‖_F`,
//!
//! with `Δ̂`, `ρ̂` the double-double sums rounded once, `|Δ − Δ̂| ≤ (eps|Δ̂| + γ_{m+1}²(|R| + |L̂||L̂ᵀ|))/(1 − eps)`
//! (Ogita–Rump–Oishi, Dot2) and likewise `ρ`. The products of absolute values are computed in
//! floating point and enlarged by `1 + 2γ_m` for their own rounding.
//!
//! **A priori (the fallback).** The Cholesky and triangular-solve backward errors make `F̂` exact
//! for `R + Δ`, `|Δ| ≤ (3m + 4)·eps·|L̂||L̂ᵀ|`, so `δ = 0` and `‖E₀‖ ≤ (3m + 4)·eps·‖|L̂⁻¹||L̂|‖²`
//! (first order in eps). On `R` with `κ(R) = 1e14` this is 1e-3 … 0.2, where the a-posteriori
//! bound is ~100 times smaller.

use super::compensated::dot2;
use crate::linalg::dense::{matmul, matmul_nt, norm_fro};
use nalgebra::DMatrix;

/// Bounds on the error of a computed factor `F̂` of `G = B R⁻¹ Bᵀ`:
/// `G = (F̂ + δ)(I + E)(F̂ + δ)ᵀ` with `‖E‖₂ ≤ e` and `‖δ‖₂ ≤ delta` (`e = ∞` when none).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct FactorError {
    /// A bound on `‖E‖₂`.
    pub(super) e: f64,
    /// A bound on `‖δ‖₂`.
    pub(super) delta: f64,
    /// The a-posteriori bound also knows `E` and `δ` themselves to within small errors.
    pub(super) known: Option<Known>,
}

/// `E` and `δ` as computed, with Frobenius bounds on their errors (a-posteriori bound only).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Known {
    /// `Ê ≈ E = (I + E₀)⁻¹ − I` (`m × m`).
    pub(super) e: DMatrix<f64>,
    /// `‖E − Ê‖_F ≤ e_err`.
    pub(super) e_err: f64,
    /// `δ̂ ≈ δ = −ρL̂⁻ᵀ` (`n × m`).
    pub(super) delta: DMatrix<f64>,
    /// `‖δ − δ̂‖_F ≤ delta_err`.
    pub(super) delta_err: f64,
}

impl FactorError {
    /// No error: the data are exact.
    pub(super) const EXACT: FactorError = FactorError {
        e: 0.0,
        delta: 0.0,
        known: None,
    };
    /// No bound.
    const NONE: FactorError = FactorError {
        e: f64::INFINITY,
        delta: f64::INFINITY,
        known: None,
    };

    /// Whether there is any error to account for.
    pub(super) fn is_exact(&self) -> bool {
        self.e == 0.0 && self.delta == 0.0
    }
}

/// `γ_k = k·eps/(1 − k·eps)`.
fn gamma(k: usize) -> f64 {
    let ke = k as f64 * f64::EPSILON;
    ke / (1.0 - ke)
}

/// `e₀ ↦ e₀/(1 − e₀)` (the bound on `‖(I + E₀)⁻¹ − I‖₂`), ∞ unless `e₀ < 1`.
fn inverse_perturbation(e0: f64) -> f64 {
    if e0 < 1.0 {
        e0 / (1.0 - e0)
    } else {
        f64::INFINITY
    }
}

/// The error bound of `F̂` (`f`, `n × m`) computed from `R` (`m × m`, symmetric), `B` (`n × m`) and
/// the computed Cholesky factor `L̂` of `R`: the a-posteriori bound when it is valid and its `‖E‖`
/// bound is below the a-priori one, else the a-priori bound (module documentation).
pub(super) fn factor_error(
    r: &DMatrix<f64>,
    b: &DMatrix<f64>,
    l: &DMatrix<f64>,
    f: &DMatrix<f64>,
) -> FactorError {
    if exact_factor(l) {
        return FactorError::EXACT;
    }
    let Some(y) = lower_inverse(l) else {
        return FactorError::NONE;
    };
    let prior = a_priori(l, &y);
    match a_posteriori(r, b, l, f, &y) {
        Some(post) if post.e < prior.e => post,
        _ => prior,
    }
}

/// A diagonal `L̂` of powers of two (`R = I`, or a diagonal `R` of powers of four): `F̂ = BL̂⁻ᵀ` and
/// `L̂L̂ᵀ = R` are exact.
fn exact_factor(l: &DMatrix<f64>) -> bool {
    let m = l.nrows();
    (0..m).all(|j| {
        (0..m).all(|i| i == j || l[(i, j)] == 0.0) && {
            let d = l[(j, j)];
            d > 0.0 && d == 2f64.powi(d.log2().round() as i32) && d * d == d.powi(2)
        }
    })
}

/// The computed inverse of the lower triangular `L̂` (`None` when singular or not finite).
fn lower_inverse(l: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let m = l.nrows();
    let mut y = DMatrix::identity(m, m);
    (l.solve_lower_triangular_mut(&mut y) && y.iter().all(|v| v.is_finite())).then_some(y)
}

/// The first-order a-priori bound (module documentation), `y` the computed `L̂⁻¹`.
fn a_priori(l: &DMatrix<f64>, y: &DMatrix<f64>) -> FactorError {
    let m = l.nrows();
    let skeel = norm_fro(&matmul(&y.abs(), &l.abs()));
    let e0 = (3.0 * m as f64 + 4.0) * f64::EPSILON * skeel * skeel;
    FactorError {
        e: inverse_perturbation(e0),
        delta: 0.0,
        known: None,
    }
}

/// `C − P Qᵀ` (`sign = −1`) or `P Qᵀ − C` (`sign = +1`) in double-double, rounded once, and a
/// Frobenius bound on its error: `(eps‖Ĉ‖_F + γ_{k+1}²‖|C| + |P||Q|ᵀ‖_F)/(1 − eps)` (Dot2).
fn dd_residual(
    c: &DMatrix<f64>,
    p: &DMatrix<f64>,
    q: &DMatrix<f64>,
    sign: f64,
) -> (DMatrix<f64>, f64) {
    let k = p.ncols();
    let (rows, cols) = c.shape();
    let mut x = vec![0.0; k + 1];
    let mut yv = vec![0.0; k + 1];
    let out = DMatrix::from_fn(rows, cols, |i, j| {
        for t in 0..k {
            x[t] = p[(i, t)];
            yv[t] = sign * q[(j, t)];
        }
        x[k] = c[(i, j)];
        yv[k] = -sign;
        dot2(&x, &yv, None).0
    });
    let weight = norm_fro(&(c.abs() + matmul_nt(&p.abs(), &q.abs()))) * (1.0 + 2.0 * gamma(k));
    let g2 = gamma(k + 1) * gamma(k + 1);
    let err = (f64::EPSILON * norm_fro(&out) + g2 * weight) / (1.0 - f64::EPSILON);
    (out, err)
}

/// The a-posteriori bound (module documentation), `y` the computed `L̂⁻¹`; `None` when `ν ≥ ½` or a
/// quantity is not finite.
fn a_posteriori(
    r: &DMatrix<f64>,
    b: &DMatrix<f64>,
    l: &DMatrix<f64>,
    f: &DMatrix<f64>,
    y: &DMatrix<f64>,
) -> Option<FactorError> {
    let m = l.nrows();
    let gm = gamma(m);
    // ν ≥ ‖I − L̂Ŷ‖₂ (the computed residual and its rounding).
    let ly = matmul(l, y);
    let nres = DMatrix::identity(m, m) - &ly;
    let lay = norm_fro(&matmul(&l.abs(), &y.abs())) * (1.0 + 2.0 * gm);
    let nu = norm_fro(&nres) + gamma(m + 1) * ((m as f64).sqrt() + lay);
    if !(nu < 0.5) {
        return None;
    }
    let k = nu / (1.0 - nu);
    let yn = norm_fro(y);
    // Δ = R − L̂L̂ᵀ, and E₀ = L̂⁻¹ΔL̂⁻ᵀ through Ŷ.
    let (dh, d_err) = dd_residual(r, l, l, -1.0);
    let e0_hat = matmul_nt(&matmul(y, &dh), y);
    let e0_abs = matmul_nt(&matmul(&y.abs(), &dh.abs()), &y.abs()) * (1.0 + 2.0 * gm);
    let e0_err = (2.0 * gm + gm * gm) * norm_fro(&e0_abs)
        + (2.0 * k + k * k) * yn * yn * norm_fro(&dh)
        + (1.0 + k) * (1.0 + k) * yn * yn * d_err;
    let e0 = norm_fro(&e0_hat) + e0_err;
    // ρ = F̂L̂ᵀ − B, and δ = −ρL̂⁻ᵀ through Ŷ.
    let (rho, rho_err) = dd_residual(b, f, l, 1.0);
    let d_hat = matmul_nt(&rho, y);
    let d_abs = matmul_nt(&rho.abs(), &y.abs()) * (1.0 + 2.0 * gm);
    let delta_err = gm * norm_fro(&d_abs) + k * norm_fro(&rho) * yn + (1.0 + k) * yn * rho_err;
    let delta = norm_fro(&d_hat) + delta_err;
    // The bounds' own evaluation rounds (a few operations, relatively): enlarge by 16 eps.
    let widen = 1.0 + 16.0 * f64::EPSILON;
    let (e_hat, e_err) = known_e(&e0_hat, e0 * widen, e0_err * widen)?;
    let bound = FactorError {
        e: inverse_perturbation(e0 * widen) * widen,
        delta: delta * widen,
        known: Some(Known {
            e: e_hat,
            e_err: e_err * widen,
            delta: -d_hat,
            delta_err: delta_err * widen,
        }),
    };
    (bound.e.is_finite() && bound.delta.is_finite()).then_some(bound)
}

/// `Ê = Ŵ − I` with `Ŵ` the computed inverse of `M = fl(I + Ê₀)`, and a bound on `‖E − Ê‖_F`
/// for `E = (I + E₀)⁻¹ − I`, `‖E₀‖₂ ≤ e0`, `‖E₀ − Ê₀‖_F ≤ e0_err`: with `W = (I + E₀)⁻¹`,
/// `‖W − M⁻¹‖ ≤ ‖W‖‖M − I − E₀‖‖M⁻¹‖` (`‖M − I − E₀‖ ≤ e0_err + eps·‖diag M‖`) and
/// `M⁻¹ − Ŵ = M⁻¹N`, `N = I − MŴ` (computed, with its rounding `γ_{m+1}(√m + ‖|M||Ŵ|‖)`);
/// `Ŵ − I` is exact (Sterbenz: `Ŵ` is within ½ of `I`). `None` unless `e0 < ½` and `‖N‖ < ½`.
fn known_e(e0_hat: &DMatrix<f64>, e0: f64, e0_err: f64) -> Option<(DMatrix<f64>, f64)> {
    let m = e0_hat.nrows();
    if !(e0 < 0.5) {
        return None;
    }
    let mm = DMatrix::identity(m, m) + e0_hat;
    let w = mm.clone().try_inverse()?;
    let nres = DMatrix::identity(m, m) - matmul(&mm, &w);
    let mw = norm_fro(&matmul(&mm.abs(), &w.abs())) * (1.0 + 2.0 * gamma(m));
    let nn = norm_fro(&nres) + gamma(m + 1) * ((m as f64).sqrt() + mw);
    if !(nn < 0.5) {
        return None;
    }
    let mdiff = e0_err + f64::EPSILON * mm.diagonal().norm();
    let m_inv = norm_fro(&w) / (1.0 - nn);
    let w_norm = 1.0 / (1.0 - e0);
    // (Ŵ − I rounds only if an entry of Ŵ's diagonal left [½, 2]: eps·‖diag Ŵ‖ covers it.)
    let err = w_norm * mdiff * m_inv + m_inv * nn + f64::EPSILON * w.diagonal().norm();
    let e = w - DMatrix::identity(m, m);
    (err.is_finite() && e.iter().all(|v| v.is_finite())).then_some((e, err))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `L = [[1, 0], [c, 2⁻²⁰]]` with integer `c`: `L⁻¹ = [[1, 0], [−c·2²⁰, 2²⁰]]` exactly, so
    /// `E₀ = L⁻¹ΔL⁻ᵀ` and `δ = −ρL⁻ᵀ` are computed exactly here for `Δ`, `ρ` chosen exactly
    /// representable in `R = LLᵀ + Δ` and `B = FLᵀ − ρ`.
    #[test]
    fn the_a_posteriori_bound_covers_exact_errors_tightly() {
        let s = 2f64.powi(-20);
        let c = 3.0;
        let l = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, c, s]);
        let linv = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, -c / s, 1.0 / s]);
        assert_eq!(matmul(&l, &linv), DMatrix::identity(2, 2));
        // Δ of a few ulps of R's entries (exactly representable sums).
        let u = 2f64.powi(-52);
        let delta = DMatrix::from_row_slice(2, 2, &[u, -2.0 * u, -2.0 * u, 8.0 * u]);
        let r = matmul_nt(&l, &l) + &delta;
        assert_eq!(&r - matmul_nt(&l, &l), delta);
        let f = DMatrix::from_row_slice(3, 2, &[1.0, 2.0 / s, -1.0, 1.0 / s, 0.5, -3.0 / s]);
        let rho = DMatrix::from_row_slice(3, 2, &[u, 0.0, -u, 2.0 * u, 0.0, u]) * 8.0;
        let b = matmul_nt(&f, &l) - &rho;
        assert_eq!(matmul_nt(&f, &l) - &b, rho);
        let e0_exact = norm2(&matmul_nt(&matmul(&linv, &delta), &linv));
        let d_exact = norm2(&(-matmul_nt(&rho, &linv)));
        let y = lower_inverse(&l).unwrap();
        let post = a_posteriori(&r, &b, &l, &f, &y).unwrap();
        let e_exact = e0_exact / (1.0 + e0_exact); // ‖(I + E₀)⁻¹ − I‖ ≥ e₀/(1 + e₀)
        assert!(
            post.e >= e_exact && post.e <= 2.0 * e0_exact,
            "{post:?} {e0_exact}"
        );
        assert!(
            post.delta >= d_exact && post.delta <= 2.0 * d_exact,
            "{post:?} {d_exact}"
        );
        // The a-priori bound of this L: 10·eps·‖|L⁻¹||L|‖² ≈ 0.09.
        assert!(post.e < a_priori(&l, &y).e);
        assert_eq!(factor_error(&r, &b, &l, &f), post);
    }

    fn norm2(m: &DMatrix<f64>) -> f64 {
        m.clone().svd(false, false).singular_values.max()
    }

    #[test]
    fn an_exact_factor_has_no_error_and_an_identity_factor_none() {
        let l = DMatrix::from_row_slice(2, 2, &[2.0, 0.0, 0.0, 0.5]);
        let r = matmul_nt(&l, &l);
        let b = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 3.0, 4.0]);
        let f = DMatrix::from_row_slice(2, 2, &[0.5, 4.0, 1.5, 8.0]);
        assert!(factor_error(&r, &b, &l, &f).is_exact());
    }

    #[test]
    fn a_well_conditioned_cholesky_factor_has_a_tiny_bound() {
        let r = DMatrix::from_row_slice(2, 2, &[2.0, 0.5, 0.5, 1.0]);
        let l = r.clone().cholesky().unwrap().l();
        let b = DMatrix::from_row_slice(3, 2, &[1.0, -2.0, 0.3, 4.0, 1.0, 1.0]);
        let mut ft = b.transpose();
        assert!(l.solve_lower_triangular_mut(&mut ft));
        let fe = factor_error(&r, &b, &l, &ft.transpose());
        assert!(fe.e < 1e-14 && fe.delta < 1e-14, "{fe:?}");
    }
}
