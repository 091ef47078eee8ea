//! The Riccati residual and the closed loop of the *intended* data `G = B R⁻¹ Bᵀ` at a computed
//! `X`, when the solver worked with the computed factor `F` (`G_F = FFᵀ`) and the a-posteriori
//! bound of module `factor_error` knows `G = (F + δ)W(F + δ)ᵀ`, `W = I + E`, with `Ê`, `δ̂` to
//! within small errors.
//!
//! With `P = XF`, `D = Xδ`: `X(G − G_F)X = PEPᵀ + DWPᵀ + PWDᵀ + DWDᵀ =: C`, so the intended residual
//! is `R(X) = R_F(X) − C`, and `A − GX = (A − FFᵀX) − F(EPᵀ + WDᵀ) − δW(P + D)ᵀ`. Both are formed
//! here from `P̂` (accumulated in double-double: `P` is a product with heavy cancellation when `F`
//! has large columns), `D̂ = fl(Xδ̂)`, `Ê` and `Ŵ = I + Ê`, with Frobenius bounds on their errors
//! (the errors of `P̂`, `D̂`, `Ê`, `δ̂` propagated term by term, and the rounding of the products,
//! `γ_{2m+4}` times the same products of absolute values).
//!
//! Why the correction is *formed* rather than bounded: for an ill-conditioned `R` the matrix `C`
//! is not small (‖C‖ ≈ 3e-4 … 4e-3 at `κ(R) = 1e14`, with `‖E‖` ≈ 3e-5 … 9e-4), but it lies in the
//! directions of the fast closed-loop modes that the cheap input creates, which the Lyapunov
//! operator damps by their speed (~1e7): the true change of `X` is ~1e-13 relative. A norm bound
//! `‖Ω⁻¹‖·‖C‖` (the a-priori model) is ~1e9 times too large; the Newton step of the corrected
//! residual, computed with the intended closed loop, sees the damping.

use super::compensated::dot2;
use super::factor_error::{FactorError, Known};
use super::kleinman::Bound;
use super::quadratic::Quadratic;
use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, norm_fro};
use nalgebra::DMatrix;

/// The intended residual and closed loop at `X`, with their error bounds.
pub(super) struct Intended {
    /// `R(X) = R_F(X) − Ĉ`.
    pub(super) r: DMatrix<f64>,
    /// A bound on `‖R(X) − r‖_F` beyond the error of the given `R_F(X)`.
    pub(super) r_err: f64,
    /// `A − GX` as formed.
    pub(super) acl: DMatrix<f64>,
    /// A bound on its error beyond that of the given `A − FFᵀX`.
    pub(super) formation: f64,
    /// `1 + e ≥ ‖W‖₂`.
    pub(super) w: f64,
    /// `d ≥ ‖δ‖₂`.
    pub(super) d: f64,
}

/// `γ_k = k·eps/(1 − k·eps)`.
fn gamma(k: usize) -> f64 {
    let ke = k as f64 * f64::EPSILON;
    ke / (1.0 - ke)
}

/// `XF` accumulated in double-double (`X` symmetric), rounded once, and a Frobenius bound on its
/// error `(eps‖P̂‖ + γ_n²‖|X||F|‖)/(1 − eps)` (Dot2).
fn product_dd(x: &DMatrix<f64>, f: &DMatrix<f64>) -> (DMatrix<f64>, f64) {
    let n = x.nrows();
    let p = DMatrix::from_fn(n, f.ncols(), |i, j| {
        // Row i of the symmetric X is its column i.
        dot2(x.column(i).as_slice(), f.column(j).as_slice(), None).0
    });
    let abs = norm_fro(&matmul(&x.abs(), &f.abs())) * (1.0 + 2.0 * gamma(n));
    let err = (f64::EPSILON * norm_fro(&p) + gamma(n) * gamma(n) * abs) / (1.0 - f64::EPSILON);
    (p, err)
}

/// The intended residual and closed loop (module documentation) from the factor's residual
/// `r_f = R_F(X)` and closed loop `acl_f = A − FFᵀX`.
pub(super) fn intended(
    acl_f: &DMatrix<f64>,
    r_f: &DMatrix<f64>,
    x: &DMatrix<f64>,
    f: &DMatrix<f64>,
    fe: &FactorError,
    known: &Known,
) -> Intended {
    let (n, m) = f.shape();
    let eps = f64::EPSILON;
    let e = fe.e;
    let w1 = 1.0 + e;
    let (p, p_err) = product_dd(x, f);
    let delta = &known.delta;
    let dm = matmul(x, delta);
    let d_err = gamma(n) * norm_fro(&matmul(&x.abs(), &delta.abs())) * (1.0 + 2.0 * gamma(n))
        + norm_fro(x) * known.delta_err;
    let wm = DMatrix::identity(m, m) + &known.e;
    // ‖W − Ŵ‖ ≤ ‖E − Ê‖ + the rounding of I + Ê (diagonal only).
    let w_err = known.e_err + eps * wm.diagonal().norm();
    let (pn, dn) = (norm_fro(&p) + p_err, norm_fro(&dm) + d_err);
    // Bounds on ‖Ŵ‖ and ‖Ê‖.
    let (w1h, eh) = (w1 + w_err, e + known.e_err);

    // C = PÊPᵀ + S + Sᵀ + DŴDᵀ, S = DŴPᵀ.
    let pe = matmul(&p, &known.e);
    let s = matmul_nt(&matmul(&dm, &wm), &p);
    let c = matmul_nt(&pe, &p) + &s + s.transpose() + matmul_nt(&matmul(&dm, &wm), &dm);
    let (pa, ea, wa, da) = (p.abs(), known.e.abs(), wm.abs(), dm.abs());
    let c_abs = matmul_nt(&matmul(&pa, &ea), &pa)
        + matmul_nt(&matmul(&da, &wa), &pa) * 2.0
        + matmul_nt(&matmul(&da, &wa), &da);
    let c_err = 2.0 * pn * p_err * e
        + pn * pn * known.e_err
        + 2.0 * (d_err * w1 * pn + dn * w_err * pn + dn * w1h * p_err)
        + d_err * w1 * dn
        + dn * w_err * dn
        + dn * w1h * d_err
        + gamma(2 * m + 4) * norm_fro(&c_abs) * (1.0 + 2.0 * gamma(m));
    let r = r_f - &c;
    let r_err = c_err + eps * (norm_fro(&r) + norm_fro(r_f) + norm_fro(&c));

    // A − GX = (A − FFᵀX) − F(ÊPᵀ + ŴDᵀ) − δ̂Ŵ(P + D)ᵀ.
    let inner = matmul_nt(&known.e, &p) + matmul_nt(&wm, &dm); // m × n
    let pd = &p + &dm;
    let acl = acl_f - matmul(f, &inner) - matmul_nt(&matmul(delta, &wm), &pd);
    let inner_abs = matmul_nt(&ea, &pa) + matmul_nt(&wa, &da);
    let acl_abs = matmul(&f.abs(), &inner_abs) + matmul_nt(&matmul(&delta.abs(), &wa), &(pa + da));
    let fnorm = norm_fro(f);
    let dl = norm_fro(delta);
    let formation = fnorm * (known.e_err * pn + eh * p_err + w_err * dn + w1h * d_err)
        + known.delta_err * w1 * (pn + dn)
        + dl * (w_err * (pn + dn) + w1h * (p_err + d_err))
        + 2.0 * gamma(m + 2) * norm_fro(&acl_abs) * (1.0 + 2.0 * gamma(m))
        + 2.0 * eps * (norm_fro(&acl) + norm_fro(acl_f));
    Intended {
        r,
        r_err,
        acl,
        formation,
        w: w1,
        d: fe.delta,
    }
}

/// The residual change `X(G − FFᵀ)X` at the computed `X` when the intended
/// `G = (F + δ)(I + E)(F + δ)ᵀ` (a Cholesky-derived factor `F`, bounds `‖E‖₂ ≤ e`, `‖δ‖₂ ≤ d` of
/// module `factor_error`):
/// `G − FFᵀ = FEFᵀ + δ(I + E)Fᵀ + F(I + E)δᵀ + δ(I + E)δᵀ`, so in Frobenius norm
/// `‖X(G − FFᵀ)X‖ ≤ e‖XF‖² + 2(1 + e)‖XF‖‖X‖d + (1 + e)(‖X‖d)²`. It is added to the arithmetic
/// error of the residual, which the certificate maps through `ℓ = ‖Ω⁻¹(I)‖₂` (and `κ_B` through the
/// factor). At `X* = X + Δ` the change differs by the terms linear and quadratic in `Δ`
/// (`Δ(G − FFᵀ)X` etc.), relatively `2‖Δ‖/‖X‖ ≤ 2·forward_error ≤ 2e-6` of it; these are not
/// included (first order, as for the rounding terms).
pub(super) fn data_residual(quad: Quadratic<'_>, x: &DMatrix<f64>, fe: &FactorError) -> f64 {
    match quad {
        Quadratic::Factor(f) if !fe.is_exact() => {
            let xf = norm_fro(&matmul(x, f));
            let xd = norm_fro(x) * fe.delta;
            fe.e * xf * xf + 2.0 * (1.0 + fe.e) * xf * xd + (1.0 + fe.e) * xd * xd
        }
        _ => 0.0,
    }
}

/// The closed loop of the intended `G = (F + δ)(I + E)(F + δ)ᵀ` (see [`data_residual`]) at `X*`:
/// `GX* = FFᵀX* + F·[EFᵀX* + (I + E)δᵀX*] + W`, `W = δ(I + E)(F + δ)ᵀX*`. With
/// `‖FᵀX*‖₂ ≤ gain = ‖FᵀX‖_F + ‖FᵀΔ̂‖_F + through_b` and `‖X*‖_F ≤ ‖X‖_F(1 + forward)`:
/// the part through the factor, `‖EFᵀX* + (I + E)δᵀX*‖₂ ≤ e·gain + (1 + e)d‖X*‖`, is added to
/// [`Bound::through_b`] (and, times `‖F‖`, to [`Bound::shift`]); `W`, which does not act through
/// `F`, has `‖W‖₂ ≤ d(1 + e)(gain + d‖X*‖)` and is added to [`Bound::unstructured`]. The
/// stability test allows for both.
pub(super) fn with_factor_error(
    bound: Bound,
    quad: Quadratic<'_>,
    x: &DMatrix<f64>,
    fe: &FactorError,
) -> Bound {
    match quad {
        Quadratic::Factor(f) if !fe.is_exact() => {
            let gain =
                norm_fro(&matmul_tn(f, x)) + norm_fro(&matmul_tn(f, &bound.d)) + bound.through_b;
            let xstar = norm_fro(x) * (1.0 + bound.forward);
            let extra = fe.e * gain + (1.0 + fe.e) * fe.delta * xstar;
            let w = fe.delta * (1.0 + fe.e) * (gain + fe.delta * xstar);
            Bound {
                shift: bound.shift + norm_fro(f) * extra,
                through_b: bound.through_b + extra,
                unstructured: bound.unstructured + w,
                ..bound
            }
        }
        _ => bound,
    }
}

/// The intended data's constants for the certificate (module `intended`): `w ≥ ‖W‖₂`,
/// `d ≥ ‖δ‖₂` in `G = (F + δ)W(F + δ)ᵀ`, and the error bound of the formed closed loop beyond
/// the factor's own formation error (module `kleinman`).
#[derive(Clone, Copy)]
pub(super) struct Extra {
    pub(super) w: f64,
    pub(super) d: f64,
    pub(super) formation: f64,
}

/// Existence for the intended data, where the quadratic term `ΔGΔ` is not seen through `F`
/// alone: `‖ΔGΔ‖₂ ≤ w(‖ΔF‖₂ + d‖Δ‖₂)² =: q(u, v)` on the set `S = {‖ΔF‖₂ ≤ u, ‖Δ‖₂ ≤ v}` (closed,
/// convex, bounded). The Newton map `Φ` (continuous) sends `S` into
/// `{‖ΔF‖ ≤ u0 + κ_B q, ‖Δ‖ ≤ v0 + ℓq}` (`u0 = ‖Δ̂F‖ + κ_B·errs`, `v0 = ‖Δ̂‖₂ + ℓ·errs`), so when
/// `u0 + κ_B q(u, v) ≤ u` and `v0 + ℓq(u, v) ≤ v`, `S` is mapped into itself and holds a solution
/// (Brouwer). The smallest such `(u, v)` is approached from `(u0, v0)` by the monotone iteration
/// `(u, v) ← (u0 + κ_B q, v0 + ℓq)`; the pair found, widened by 2⁻²⁰, is verified. Returns `q`
/// there (the certificate's `u²`), `None` when the iteration does not settle.
pub(super) fn self_map(u0: f64, v0: f64, kappa_b: f64, ell: f64, ex: Extra) -> Option<f64> {
    let q = |u: f64, v: f64| ex.w * (u + ex.d * v).powi(2);
    let (mut u, mut v) = (u0, v0);
    for _ in 0..200 {
        let (un, vn) = (u0 + kappa_b * q(u, v), v0 + ell * q(u, v));
        if !(un.is_finite() && vn.is_finite()) {
            return None;
        }
        let settled = un <= u * (1.0 + 1e-12) && vn <= v * (1.0 + 1e-12);
        (u, v) = (un, vn);
        if settled {
            break;
        }
    }
    let widen = 1.0 + 2f64.powi(-20);
    let (u, v) = (u * widen, v * widen);
    let qs = q(u, v);
    (u0 + kappa_b * qs <= u && v0 + ell * qs <= v).then_some(qs)
}

/// The closed loop of the intended `G = (F + δ)W(F + δ)ᵀ` at `X*` (module `intended`), from the
/// formed `A − GX` corrected by `FFᵀΔ̂`: the remaining distance is `(G − FFᵀ)Δ̂ + GV`,
/// `V = X* − X − Δ̂` (`‖FᵀV‖₂ ≤ through_b`, `‖V‖_F ≤ beyond`):
/// `(G − FFᵀ)Δ̂ = F[EFᵀΔ̂ + Wδᵀ Δ̂] + δW(F + δ)ᵀΔ̂` and `GV = FW(F + δ)ᵀV + δW(F + δ)ᵀV`. The parts
/// through `F` give `through_b' = w(through_b + d·beyond) + (w − 1)‖FᵀΔ̂‖ + w·d‖Δ̂‖`; the parts
/// through `δ` give [`Bound::unstructured`] `= d·w(through_b + d·beyond + ‖FᵀΔ̂‖ + d‖Δ̂‖)`.
pub(super) fn intended_bound(bound: Bound, quad: Quadratic<'_>, ex: Extra) -> Bound {
    let Quadratic::Factor(f) = quad else {
        return bound;
    };
    let (w, d) = (ex.w, ex.d);
    let fd = norm_fro(&matmul_tn(f, &bound.d));
    let dn = norm_fro(&bound.d);
    let through_v = bound.through_b + d * bound.beyond;
    let through_b = w * through_v + (w - 1.0) * fd + w * d * dn;
    let unstructured = d * w * (through_v + fd + d * dn);
    Bound {
        shift: norm_fro(f) * through_b,
        through_b,
        unstructured: bound.unstructured + unstructured,
        ..bound
    }
}
