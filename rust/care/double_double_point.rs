//! The strict certificate of the closed-loop route (module `kleinman`) taken at the
//! double-double point `Y = X + D` instead of at the computed `X`, for the solutions where the
//! test at `X` fails (only there: every answer certified at `X` keeps its certificate).
//!
//! **Why.** With a cheap input (`R = 1e-14`, `‖F‖ ~ 3e7`) an ulp of `X` seen through `F` is
//! `~1e-6`, so even the correctly rounded `X*` has a Newton correction `‖Δ̂F‖ ~ 5e-7` and
//! `h = κ_B·u₀` near `¼` (`κ_B ~ 2e5`). At `Y = X + D`, `D` the computed Newton correction at
//! `X` kept as a second double, the correction through `F` is quadratically smaller.
//!
//! **The residual at `Y`.** With `Ω_X(D) = A_cᵀD + DA_c`, `A_c = A − GX`, exactly
//! `R(Y) = R(X) + Ω_X(D) − DGD`. `R(X)` is the residual of module `kleinman` (the intended data's
//! for a Cholesky-derived factor, module `intended`) with its error bound `arith`;
//! `R(X) + Ω_X(D)` is accumulated in double-double from the formed `A_c` (error
//! `2eps‖·‖ + 2γ²·W + 2·formation·‖D‖`, as for the certificate's `R_s`); `DGD` is formed as
//! `(FᵀD)ᵀ(FᵀD)` (or `D(GD)` for a dense `G`) with the rounding of both products and, for the
//! intended `G = (F + δ)W(F + δ)ᵀ`, the norm bound of `D(G − FFᵀ)D`; the difference is rounded
//! once. Every one of these bounds is added to `arith`.
//!
//! **The closed loop at `Y`.** `A − GY = A_c − GD`, formed as `A_c − F(FᵀD)`; its error is that
//! of `A_c` plus the rounding of `F(FᵀD)` and the difference, plus `‖(G − FFᵀ)D‖` for the
//! intended data. The certificate of module `kleinman` (Newton–Kantorovich through `F`, or
//! Brouwer for the intended data) is then applied unchanged at `Y`, with that residual and
//! closed loop: it proves `X*` with `‖X* − Y − Δ̂_Y‖` and `‖(X* − Y − Δ̂_Y)F‖` bounded.
//!
//! **What is reported for the double `X`.** `X* − X = D + Δ̂_Y + (X* − Y − Δ̂_Y)`, so the
//! forward bound is the one at `Y` plus `‖D‖_F/‖X‖_F`, the trace bound adds `|tr D|`, and the
//! correction kept for the stability test (a) is `fl(D + Δ̂_Y)`, its rounding `eps‖·‖_F` added to
//! the distances (in `F`'s directions times `‖F‖_F`).
//!
//! **The factor's `Ê`.** For the intended data, `‖E − Ê‖_F ≤ √m·‖E‖₂ + ‖Ê‖_F ≤ √m·e + ‖Ê‖_F`
//! too; the smaller of this and the bound of module `factor_error` is used here (`R = 1e-14·I`:
//! `e = 1.3e-16`, the inverse check's bound `3.4e-15`, which times `‖XF‖² = 3e3` dominated
//! `arith`).

use super::closed_loop_newton::soft;
use super::compensated::residual;
use super::factor_error::{FactorError, Known};
use super::intended::{intended, Extra, Intended};
use super::kleinman::{certificate, Bound, Proof};
use super::quadratic::Quadratic;
use crate::linalg::dense::{matmul, matmul_tn, norm_fro, symmetrize};
use crate::linalg::sylvester::Lyapunov;
use crate::Result;
use nalgebra::DMatrix;

/// The bound for `X` and, for the intended data, their residual and closed loop and the
/// constants of the quadratic term (what module `kleinman` certifies with).
type Certified = (Bound, Option<Intended>, Option<Extra>);

/// `γ_k = k·eps/(1 − k·eps)`.
fn gamma(k: usize) -> f64 {
    let ke = k as f64 * f64::EPSILON;
    ke / (1.0 - ke)
}

/// The certificate at the double-double point (module documentation) for `X` with the factor's
/// closed loop `acl_f`, compensated residual `r_f` (arithmetic error `arith_f`); the bound for
/// `X` and, for the intended data, their residual and closed loop with the constants of the
/// quadratic term. `None` when it fails, or for an a-priori factor bound (not handled).
pub(super) fn certify_at_double_double_point(
    quad: Quadratic<'_>,
    g: &DMatrix<f64>,
    x: &DMatrix<f64>,
    (acl_f, r_f, arith_f): (&DMatrix<f64>, &DMatrix<f64>, f64),
    fe: &FactorError,
    proof: Proof,
) -> Result<Option<Certified>> {
    let n = x.nrows();
    let eps = f64::EPSILON;
    let intended = match (quad, &fe.known) {
        (Quadratic::Factor(f), Some(known)) => {
            let m = f.ncols() as f64;
            let tight = (m.sqrt() * fe.e + norm_fro(&known.e)) * (1.0 + 4.0 * eps);
            let known = Known {
                e_err: known.e_err.min(tight),
                ..known.clone()
            };
            Some(intended(acl_f, r_f, x, f, fe, &known))
        }
        _ if fe.is_exact() => None,
        _ => return Ok(None),
    };
    let (acl, r, arith, extra) = match &intended {
        Some(it) => {
            let ex = Extra {
                w: it.w,
                d: it.d,
                formation: it.formation,
            };
            (&it.acl, &it.r, arith_f + it.r_err, Some(ex))
        }
        None => (acl_f, r_f, arith_f, None),
    };
    let (w, dl) = extra.map_or((1.0, 0.0), |ex| (ex.w, ex.d));
    let formation = quad.formation(x) + extra.map_or(0.0, |ex| ex.formation);
    // D: the Newton correction at X, its linear solve corrected once by its own residual.
    let Some(lyap) = soft(Lyapunov::new(acl).and_then(|l| l.with_singular_rtol(0.0)))? else {
        return Ok(None);
    };
    let Some(d1) = soft(lyap.solve_adjoint(&(-r)))? else {
        return Ok(None);
    };
    let d1 = symmetrize(&d1);
    let Some(d2) = soft(lyap.solve_adjoint(&(-residual(acl, None, None, r, &d1))))? else {
        return Ok(None);
    };
    let d = symmetrize(&(&d1 + &d2));
    let dn = norm_fro(&d);
    // R(X) + Ω_X(D) in double-double, rounded once.
    let rs = residual(acl, None, None, r, &d);
    let g2 = gamma(2 * n + 4) * gamma(2 * n + 4);
    let ws = norm_fro(&(matmul_tn(&acl.abs(), &d.abs()) * 2.0)) + norm_fro(r);
    let rs_err = 2.0 * eps * norm_fro(&rs) + 2.0 * g2 * ws + 2.0 * formation * dn;
    // DGD, and G·D for the closed loop at Y.
    let (dgd, dgd_err, gd, gd_err) = match quad {
        Quadratic::Factor(f) => {
            let (m, fa, da) = (f.ncols(), f.abs(), d.abs());
            let mt = matmul_tn(f, &d); // FᵀD, m × n
            let em = gamma(n) * norm_fro(&matmul_tn(&fa, &da)) * (1.0 + 2.0 * gamma(n));
            let mn = norm_fro(&mt);
            let dgd = matmul_tn(&mt, &mt);
            let mta = mt.abs();
            let round = gamma(m) * norm_fro(&matmul_tn(&mta, &mta)) * (1.0 + 2.0 * gamma(m));
            // D(G − FFᵀ)D: (w − 1)‖FᵀD‖² + 2w‖FᵀD‖‖D‖d + w(‖D‖d)².
            let (u, v) = (mn + em, dn * dl);
            let data = (w - 1.0) * u * u + 2.0 * w * u * v + w * v * v;
            let gd = matmul(f, &mt);
            let fnorm = norm_fro(f);
            let gd_round = gamma(m) * norm_fro(&matmul(&fa, &mta)) * (1.0 + 2.0 * gamma(m));
            let g_data = ((w - 1.0) * fnorm * fnorm + 2.0 * w * fnorm * dl + w * dl * dl) * dn;
            let gd_err = gd_round + fnorm * em + g_data;
            (dgd, 2.0 * mn * em + em * em + round + data, gd, gd_err)
        }
        Quadratic::Dense(gm) => {
            let gd = matmul(gm, &d);
            let (ga, da) = (gm.abs(), d.abs());
            let gda = matmul(&ga, &da) * (1.0 + 2.0 * gamma(n));
            let gd_err = gamma(n) * norm_fro(&gda);
            let dgd = matmul(&d, &gd);
            let dgd_err = 2.0 * gamma(n) * norm_fro(&matmul(&da, &gda)) * (1.0 + 2.0 * gamma(n));
            (dgd, dgd_err, gd, gd_err)
        }
    };
    let r_y = symmetrize(&(&rs - &dgd));
    let arith_y = arith + rs_err + dgd_err + 2.0 * eps * (norm_fro(&r_y) + norm_fro(&dgd));
    let acl_y = acl - &gd;
    let more = gd_err + eps * norm_fro(&acl_y);
    let Some(lyap_y) = soft(Lyapunov::new(&acl_y).and_then(|l| l.with_singular_rtol(0.0)))? else {
        return Ok(None);
    };
    let input = (&r_y, arith_y, extra.map_or(more, |_| 0.0));
    let extra_y = extra.map(|ex| Extra {
        formation: ex.formation + more,
        ..ex
    });
    let Some(at_y) = certificate(&lyap_y, &acl_y, quad, input, g, x, (extra_y, proof))? else {
        return Ok(None);
    };
    // For the double X: X* − X = D + Δ̂_Y + (X* − Y − Δ̂_Y); the kept correction fl(D + Δ̂_Y).
    let total = &d + &at_y.d;
    let rounding = eps * norm_fro(&total);
    let b_norm = match quad {
        Quadratic::Factor(f) => norm_fro(f),
        Quadratic::Dense(gm) => norm_fro(gm).sqrt(),
    };
    let xn = norm_fro(x);
    let bound = Bound {
        shift: at_y.shift + b_norm * b_norm * rounding,
        through_b: at_y.through_b + b_norm * rounding,
        unstructured: at_y.unstructured,
        beyond: at_y.beyond + rounding,
        forward: at_y.forward + (dn / xn) * (1.0 + 4.0 * eps),
        trace: at_y.trace + d.trace().abs() * (1.0 + 4.0 * eps),
        d: total,
    };
    Ok(bound
        .forward
        .is_finite()
        .then_some((bound, intended, extra)))
}
