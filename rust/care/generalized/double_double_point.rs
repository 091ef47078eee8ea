//! The strict certificate of module `newton` taken at the double-double point `Y = X + D`
//! instead of at the computed `X`, for the answers where the strict test at `X` fails (only
//! there: every answer certified at `X` keeps its certificate).
//!
//! **Why.** With `cond(E) = 1e12` the strict test `h = κ‖R⁻¹‖u₀ < ¼`, `u₀ = ‖EᵀΔ̂B‖ + κ·errs`,
//! fails even at a fully converged double `X`: `κ = 1.8e5…4.5e5`, and `errs`, dominated by the
//! working-precision floor of the residual (`eps·‖EᵀXA‖`, `eps·‖CK‖`), is `3e-13…1.3e-11`, so
//! `κ²‖R⁻¹‖·errs = 0.4…2.1`. At `Y = X + D`, `D` a Newton correction at `X` kept as a second
//! double, the residual is evaluated in double-double throughout (its floor `γ²·|E|ᵀ|Y||A|`) and
//! is itself quadratically small.
//!
//! **The residual at `Y`.** `F(Y) = Eᵀ(YA) + (Eᵀ(YA))ᵀ − C R⁻¹ Cᵀ + Q`, `C = Eᵀ(YB) + S`, with
//! `Y = X + D` never rounded (`E = I` when absent). Every bound below is elementwise, summed
//! in the Frobenius norm; `g_k = γ_{2k+2}`, `γ_k = k·eps/(1 − k·eps)`:
//!
//! * `P = YM` (`M = A, B`) by `Dot2` with the second operand `X + D`:
//!   `|P̂ − P| ≤ g_n²|X||M| + g_n|D||M|` (the error-free products and sums leave `Σ(t_k + e_k)`,
//!   `Σ|t_k| + |e_k| ≤ γ_n|x|ᵀ|m|`, and `a_k d_k`, summed in `c` with `2n` roundings);
//! * `N = EᵀP` from `P̂ = P_h + P_l` the same way: `|N̂ − N| ≤ g_n²|E|ᵀ|P_h| + g_n|E|ᵀ|P_l|
//!   + |E|ᵀ|P̂ − P|`;
//! * `Ĉ = C_h + C_l` with `(C_h, t) = TwoSum(N_h, S)`, `C_l = fl(N_l + t)`: `‖Ĉ − C‖ ≤ δ_C =
//!   ‖N̂₂ − N₂‖ + eps‖C_l‖`. Then `‖CR⁻¹Cᵀ − ĈR⁻¹Ĉᵀ‖ ≤ ‖R⁻¹‖(2δ_C‖Ĉ‖ + δ_C²)`;
//! * `K̂ = fl(R⁻¹C_hᵀ)` and `T = Ĉᵀ − RK̂` in double-double, rounded once:
//!   `‖T̂ − T‖ ≤ e_T = ‖g_m²|R||K̂| + γ₃(|c| + |t| + |C_l|) + eps|T̂|‖`; `δ̂ = fl(R⁻¹T̂)` with
//!   `‖R⁻¹T − δ̂‖ ≤ e_δ = ‖R⁻¹‖(e_T + ‖fl(T̂ − Rδ̂)‖ + γ_{m+1}(‖T̂‖ + ‖|R||δ̂|‖))`;
//! * `ĈR⁻¹Ĉᵀ = ĈK̂ + Ĉδ̂ + Ĉ(R⁻¹T − δ̂)`: `ĈK̂` by `Dot2` (`g_m²|C_h||K̂| + g_m|C_l||K̂|`),
//!   `fl(C_hδ̂)` (`γ_m|C_h||δ̂| + |C_l||δ̂|`), and `‖Ĉ‖e_δ`;
//! * the sum `N₁ + N₁ᵀ − ĈK̂ − C_hδ̂ + Q` by `TwoSum` on the high parts, its seven low parts
//!   summed (`γ₇·Σ|·|`) and the result rounded once (`eps|F̂|`); the symmetrisation does not
//!   increase the distance to the symmetric `F(Y)` and rounds once more (`eps‖F̂‖`).
//!
//! The sum of these is `‖F̂(Y) − F(Y)‖ ≤ f_err`, each norm of a nonnegative product computed in
//! floating point and the total multiplied by `1 + 2γ_{n²+4n+32}` (their own rounding: products
//! of nonnegative terms and Frobenius norms of `n²` squares). The gain
//! of `Y` is `K_Y = R⁻¹Cᵀ` and `‖K_Y − K̂‖ ≤ ‖δ̂‖ + e_δ + ‖R⁻¹‖δ_C`.
//!
//! **The certificate at `Y`.** That of module `newton`, unchanged, with `F̂(Y)`, `f_err`, the
//! closed loop `fl(A − BK̂)` and its rounding (the existing `γ‖|B||K̂|‖ + ‖B‖‖K_Y − K̂‖`, and
//! the subtraction's `eps‖A − BK̂‖`, times `2‖E‖‖Δ̂_Y‖` in `errs`). It proves the stabilising
//! `X*` with `‖X* − Y − Δ̂_Y‖_F ≤ beyond` and `|tr(X* − Y − Δ̂_Y)| ≤ trace_rest`. Only a strict
//! proof is used.
//!
//! **`D`.** Any `D` is sound (the certificate is at the exact `Y`); it is the chord step
//! `D ← D + Ω_X⁻¹(−F̂(X + D))` on the operator of the final `X`, from `D = 0`, while the
//! residual falls, at most [`DD_STEPS`] times.
//!
//! **What is reported.** The answer is `Ŷ = fl(X + D)`, and `t = Y − Ŷ` is known exactly
//! (`TwoSum`), so `X* − Ŷ = (t + Δ̂_Y) + (X* − Y − Δ̂_Y)`: with `Σ = fl(t + Δ̂_Y)`
//! (`|Σ − (t + Δ̂_Y)| ≤ eps|Σ|`), `‖X* − Ŷ‖_F ≤ (1 + eps)‖Σ‖_F + beyond` and
//! `|tr(X* − Ŷ)| ≤ |tr Σ| + eps√n‖Σ‖_F + trace_rest`, each with a factor `1 + 4eps` for the
//! norms' rounding and `eps` (relative) / `eps|tr Ŷ|` added as at `X`. (The standard route's
//! module of the same name keeps the double `X` and adds `‖D‖/‖X‖`; here `Ŷ` is the better
//! answer: at `cond(E) = 1e12` the errors fall from 1.3e-15 … 2.8e-14 to ~4e-17.)

use super::super::compensated::{dot2, two_sum};
use super::newton::{certify as certify_at, Operator, Proof};
use super::Data;
use crate::linalg::dense::{matmul, norm_fro, symmetrize};
use crate::Result;
use nalgebra::DMatrix;

/// At most this many chord steps for `D`.
pub const DD_STEPS: usize = 3;

/// The rounded double-double point and its bounds from the certificate at `Y = X + D`.
pub(super) struct FromY {
    /// `fl(X + D)`, the answer.
    pub(super) x: DMatrix<f64>,
    /// Bound on `‖X − X*‖_F / ‖X‖_F`.
    pub(super) forward: f64,
    /// Bound on `|tr X − tr X*|`.
    pub(super) trace: f64,
}

/// `γ_k = k·eps/(1 − k·eps)`.
fn gamma(k: usize) -> f64 {
    let ke = k as f64 * f64::EPSILON;
    ke / (1.0 - ke)
}

/// `|M|ᵀ|N|`.
fn abs_tn(m: &DMatrix<f64>, n: &DMatrix<f64>) -> DMatrix<f64> {
    m.abs().transpose() * n.abs()
}

/// `Mᵀ(N_h + N_l)` in double-double, column by column with `Dot2`.
fn dd_tn(m: &DMatrix<f64>, nh: &DMatrix<f64>, nl: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    crate::linalg::dispatch_fma!(
        dd_tn_fma,
        dd_tn_impl,
        (m: &DMatrix<f64>, nh: &DMatrix<f64>, nl: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>)
    )
}

#[inline(always)]
fn dd_tn_impl(
    m: &DMatrix<f64>,
    nh: &DMatrix<f64>,
    nl: &DMatrix<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let (r, c) = (m.ncols(), nh.ncols());
    let mut hi = DMatrix::zeros(r, c);
    let mut lo = DMatrix::zeros(r, c);
    for j in 0..c {
        for i in 0..r {
            let (h, l) = dot2(
                m.column(i).as_slice(),
                nh.column(j).as_slice(),
                Some(nl.column(j).as_slice()),
            );
            hi[(i, j)] = h;
            lo[(i, j)] = l;
        }
    }
    (hi, lo)
}

/// `Eᵀ(YM)`, `Y = X + D` symmetric, in double-double, and a bound on its error (Frobenius).
fn e_y_m(
    e: &DMatrix<f64>,
    x: &DMatrix<f64>,
    dx: &DMatrix<f64>,
    m: &DMatrix<f64>,
) -> (DMatrix<f64>, DMatrix<f64>, f64) {
    let n = x.nrows();
    let g = gamma(2 * n + 2);
    // (YM)ᵀ = Mᵀ(X + D): P = YM is its transpose.
    let (pt_h, pt_l) = dd_tn(m, x, dx);
    let (ph, pl) = (pt_h.transpose(), pt_l.transpose());
    let p_err = abs_tn(x, m) * (g * g) + abs_tn(dx, m) * g;
    let (nh, nl) = dd_tn(e, &ph, &pl);
    let ea = e.abs().transpose();
    let err = (&ea * ph.abs()) * (g * g) + (&ea * pl.abs()) * g + &ea * p_err;
    (nh, nl, norm_fro(&err))
}

/// `F̂(Y)` (symmetric), a bound on `‖F̂(Y) − F(Y)‖_F`, `K̂` and a bound on `‖K̂ − K_Y‖_F`
/// (module documentation).
struct Residual {
    f: DMatrix<f64>,
    err: f64,
    k: DMatrix<f64>,
    k_err: f64,
}

fn residual(d: &Data<'_>, x: &DMatrix<f64>, dx: &DMatrix<f64>) -> Residual {
    let (n, m) = (x.nrows(), d.b.ncols());
    let eps = f64::EPSILON;
    let eye = DMatrix::identity(n, n);
    let e = d.e.unwrap_or(&eye);
    let (n1h, n1l, n1_err) = e_y_m(e, x, dx, d.a);
    let (n2h, n2l, n2_err) = e_y_m(e, x, dx, d.b);
    // Ĉ = C_h + C_l.
    let (ch, cl) = match d.s {
        Some(s) => {
            let mut ch = n2h.clone();
            let mut cl = n2l.clone();
            for (idx, sv) in s.iter().enumerate() {
                let (h, t) = two_sum(n2h[idx], *sv);
                ch[idx] = h;
                cl[idx] = n2l[idx] + t;
            }
            (ch, cl)
        }
        None => (n2h, n2l),
    };
    let delta_c = n2_err + eps * norm_fro(&cl);
    let c_norm = norm_fro(&ch) + norm_fro(&cl);
    let r_inv = d.r_inverse_norm();
    // K̂ = fl(R⁻¹C_hᵀ); T = Ĉᵀ − RK̂ in double-double, rounded once.
    let k = d.r_solve(&ch.transpose());
    let gm = gamma(2 * m + 2);
    let neg_r = -&d.r;
    let mut t_hat = DMatrix::zeros(m, n);
    let mut t_bound = DMatrix::zeros(m, n);
    for j in 0..n {
        for i in 0..m {
            let (s, c) = dot2(neg_r.column(i).as_slice(), k.column(j).as_slice(), None);
            let (s2, t2) = two_sum(s, ch[(j, i)]);
            let v = s2 + ((c + t2) + cl[(j, i)]);
            t_hat[(i, j)] = v;
            t_bound[(i, j)] = gamma(3) * (c.abs() + t2.abs() + cl[(j, i)].abs()) + eps * v.abs();
        }
    }
    let e_t = norm_fro(&(t_bound + abs_tn(&d.r, &k) * (gm * gm)));
    let delta = d.r_solve(&t_hat);
    let rho = norm_fro(&(&t_hat - matmul(&d.r, &delta)))
        + gamma(m + 1) * (norm_fro(&t_hat) + norm_fro(&abs_tn(&d.r, &delta)));
    let e_delta = r_inv * (e_t + rho);
    // ĈK̂ by Dot2 (Ĉ's rows as columns of its transpose), and fl(C_h δ̂).
    // ĈK̂: entry (i, j) is Σ_l K̂_lj (C_h + C_l)_il, i.e. the transpose of K̂ᵀ(C_hᵀ + C_lᵀ).
    let (ckt_h, ckt_l) = dd_tn(&k, &ch.transpose(), &cl.transpose());
    let (ckh, ckl) = (ckt_h.transpose(), ckt_l.transpose());
    let cd = matmul(&ch, &delta);
    let ck_err = norm_fro(&((ch.abs() * k.abs()) * (gm * gm) + (cl.abs() * k.abs()) * gm))
        + norm_fro(&((ch.abs() * delta.abs()) * gamma(m) + cl.abs() * delta.abs()))
        + c_norm * e_delta
        + r_inv * (2.0 * delta_c * c_norm + delta_c * delta_c);
    // N₁ + N₁ᵀ − ĈK̂ − C_hδ̂ + Q.
    let mut chain = DMatrix::zeros(n, n);
    let f = DMatrix::from_fn(n, n, |i, j| {
        let (s1, t1) = two_sum(n1h[(i, j)], n1h[(j, i)]);
        let (s2, t2) = two_sum(s1, -ckh[(i, j)]);
        let (s3, t3) = two_sum(s2, d.q[(i, j)]);
        let lows = [
            t1,
            t2,
            t3,
            n1l[(i, j)],
            n1l[(j, i)],
            -ckl[(i, j)],
            -cd[(i, j)],
        ];
        let lo = lows.iter().fold(0.0, |acc, v| acc + v);
        let v = s3 + lo;
        chain[(i, j)] = gamma(7) * lows.iter().map(|v| v.abs()).sum::<f64>() + eps * v.abs();
        v
    });
    let f = symmetrize(&f);
    let up = 1.0 + 2.0 * gamma(n * n + 4 * n + 32);
    let err = up * (2.0 * n1_err + ck_err + norm_fro(&chain) + eps * norm_fro(&f));
    let k_err = up * (norm_fro(&delta) + e_delta + r_inv * delta_c);
    Residual { f, err, k, k_err }
}

/// The strict certificate at `Y = X + D` for the double `x`, `op` the operator of its closed
/// loop (module documentation); `None` when it does not prove the stabilising solution.
pub(super) fn certify(d: &Data<'_>, x: &DMatrix<f64>, op: &Operator) -> Result<Option<FromY>> {
    let n = x.nrows();
    let eps = f64::EPSILON;
    // The products take X's columns for its rows.
    if x != &x.transpose() {
        return Ok(None);
    }
    let mut dx = DMatrix::zeros(n, n);
    let mut at = residual(d, x, &dx);
    for _ in 0..DD_STEPS {
        crate::cancel::check("the certificate at the double-double point")?;
        let Ok(corr) = op.solve(&(-&at.f)) else {
            return Ok(None);
        };
        let cand = symmetrize(&(&dx + corr));
        let next = residual(d, x, &cand);
        if !(norm_fro(&next.f) < norm_fro(&at.f)) {
            break;
        }
        (dx, at) = (cand, next);
    }
    if !(at.err.is_finite() && dx.iter().all(|v| v.is_finite())) {
        return Ok(None);
    }
    let Some(y) = certify_at(d, &at.f, at.err, &at.k, at.k_err)? else {
        return Ok(None);
    };
    if y.proof != Proof::Strict {
        return Ok(None);
    }
    // The rounded Y and what it misses exactly: Y − fl(Y) = t (TwoSum), so X* − fl(Y) =
    // t + Δ̂_Y + (X* − Y − Δ̂_Y).
    let mut y_hat = x.clone();
    let mut miss = DMatrix::zeros(n, n);
    for idx in 0..n * n {
        let (h, t) = two_sum(x[idx], dx[idx]);
        y_hat[idx] = h;
        miss[idx] = t;
    }
    let total = &miss + &y.dh;
    let tn = norm_fro(&total);
    let yn = norm_fro(&y_hat);
    let slack = 1.0 + 4.0 * eps;
    let forward = ((1.0 + eps) * tn + y.beyond) * slack / yn + eps;
    let trace = (total.trace().abs() + eps * (n as f64).sqrt() * tn + y.trace_rest) * slack
        + eps * y_hat.trace().abs();
    Ok((forward.is_finite() && trace.is_finite()).then_some(FromY {
        x: y_hat,
        forward,
        trace,
    }))
}
