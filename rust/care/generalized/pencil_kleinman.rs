//! A start for Newton's iteration on the generalised CARE that does not depend on the problem
//! transformed by `E⁻¹`: Kleinman's iteration on the closed-loop pencil from a stabilising
//! feedback.
//!
//! **Feedback.** `K₀ = R⁻¹Sᵀ` (the gain of `X₀ = 0`) when the pencil `(A − BK₀, E)` is stable;
//! otherwise `K₀ = R⁻¹Sᵀ + K̂E`, `K̂` a Bass feedback (module `bass`) for the transformed data
//! `Ã = (A − BR⁻¹Sᵀ)E⁻¹`: `(A − BK₀)E⁻¹ = Ã − BK̂`, so the pencil has the eigenvalues of
//! `Ã − BK̂`. `Ã` is inaccurate by up to `eps·κ(E)`, but Bass's feedback moves an unstable
//! eigenvalue to real part `−β`, `β` above its modulus, a margin that rounding does not undo; in
//! any case the pencil's stability is checked on its own QZ form. Bass's method is applied one
//! mode at a time first (each moved to `−|λ|`): with an ill-conditioned `E`, `Ã` has eigenvalues
//! `~κ(E)` in the direction `E` nearly annihilates, which a gain of modest size moves (`K̂E`
//! small), while moving all unstable modes at once to `−β`, `β` above the largest, asks a gain
//! `~κ(E)` in every direction (`cond(E) = 1e9`: `‖K₀‖ = 2e10` against `‖K*‖ = 6`, and the first
//! iterate's closed loop, exact in 60 digits, lost in rounding). Then all at once.
//!
//! **Iteration (Kleinman 1968, generalised).** `X₁` solves
//! `(A − BK₀)ᵀX₁E + EᵀX₁(A − BK₀) = −(Q + K₀ᵀRK₀ − SK₀ − K₀ᵀSᵀ)`, then
//! `X_{k+1} = X_k + Ω_k⁻¹(−F(X_k))`, `Ω_k(Δ) = A_kᵀΔE + EᵀΔA_k`, `A_k = A − BK_k`,
//! `K_k = R⁻¹(BᵀX_kE + Sᵀ)` — the same step in residual form (`F(X_k)` with double-double products,
//! `Ω_k` on a fresh QZ form of `(A_k, E)` each step). From a stabilising `K₀` (and `R ≻ 0`,
//! `Q − SR⁻¹Sᵀ ⪰ 0`) every pencil `(A_k, E)` is stable and `X_k` decreases to the stabilising
//! solution, slowly at first (the residual need not fall in those steps) and quadratically at the
//! end. The steps are taken unconditionally, at most [`KLEINMAN_STEPS`]; the phase ends when a
//! correction is below [`PHASE_END`] of `X` (or after the last step), and the caller hands the iterate to
//! `newton::refine` for the quadratic phase and the certificate. A pencil that is not stable by its
//! computed spectrum, a failed factorisation or a non-finite iterate ends the attempt (`None`).
//! Nothing here is a proof: the caller keeps the answer only with `Proof::Strict`.

use super::super::bass;
use super::newton::Operator;
use super::{certified, Data};
use crate::care::CareSolution;
use crate::linalg::dense::{matmul, matmul_tn, norm_fro, symmetrize};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// At most this many Kleinman steps before the quadratic phase (from a Bass feedback that moved an
/// eigenvalue of modulus `~κ(E)`, `X₁` may be `~κ(E)` times too large, and each early step about
/// halves the excess).
pub const KLEINMAN_STEPS: usize = 80;

/// A correction below this fraction of `X` (Frobenius) ends the first phase.
pub const PHASE_END: f64 = 1e-6;

/// The answer from Kleinman's iteration on the closed-loop pencil, refined and certified by step 3
/// of the generalised route (`certified`) and kept only with the strict proof.
pub(super) fn certified_from_pencil(
    d: &Data<'_>,
    a_t: &DMatrix<f64>,
    e_rcond: f64,
) -> Result<CareSolution> {
    let Some((x, steps)) = kleinman_start(d, a_t)? else {
        return Err(Error::NoStabilizingSolution(
            "Kleinman's iteration on the closed-loop pencil found no stabilising start".into(),
        ));
    };
    let sol = CareSolution {
        x,
        residual: f64::NAN,
        forward_error: f64::INFINITY,
        trace_error: f64::INFINITY,
        rcond: f64::NAN,
        closed_loop_abscissa: f64::NAN,
        axis_margin: f64::NAN,
        marginal: false,
        newton_steps: steps,
        scaling: 1.0,
    };
    certified(d, sol, true, e_rcond)
}

/// The first phase from a stabilising feedback: the iterate handed to the quadratic phase and the
/// number of steps taken, or `None` (module documentation). The feedbacks are tried in turn:
/// `R⁻¹Sᵀ` when its pencil is stable, else Bass's feedback one mode at a time, then all at once.
pub(super) fn kleinman_start(
    d: &Data<'_>,
    a_t: &DMatrix<f64>,
) -> Result<Option<(DMatrix<f64>, usize)>> {
    let (b, e) = (d.b, d.e);
    let (n, m) = (d.a.nrows(), b.ncols());
    let k_s = match d.s {
        Some(s) => d.r_solve(&s.transpose()),
        None => DMatrix::zeros(m, n),
    };
    if let Some(op) = stable_pencil(d, &k_s) {
        return phase_one(d, &k_s, &op);
    }
    let zero = DMatrix::zeros(m, n);
    for staged in [true, false] {
        let k_hat = if staged {
            bass::stabilise_in_stages(a_t, b, &zero)?
        } else {
            bass::stabilise(a_t, b, &zero)?
        };
        let Some(k_hat) = k_hat else { continue };
        let k0 = match e {
            Some(e) => &k_s + matmul(&k_hat, e),
            None => &k_s + k_hat,
        };
        let Some(op) = stable_pencil(d, &k0) else {
            continue;
        };
        if let Some(found) = phase_one(d, &k0, &op)? {
            return Ok(Some(found));
        }
    }
    Ok(None)
}

/// The operator of the pencil `(A − BK, E)` when that pencil is stable by its computed spectrum.
fn stable_pencil(d: &Data<'_>, k: &DMatrix<f64>) -> Option<Operator> {
    let op = Operator::new(&(d.a - matmul(d.b, k)), d.e, d.ill_e).ok()?;
    (op.abscissa() < 0.0).then_some(op)
}

/// Kleinman's steps from the stabilising gain `k0` (`op` the operator of its pencil): `X₁` from
/// the gain, then steps in residual form until a correction is below [`PHASE_END`] of `X` or
/// [`KLEINMAN_STEPS`] are taken; `None` when a pencil is not stable, a solve fails or an iterate
/// is not finite.
fn phase_one(
    d: &Data<'_>,
    k0: &DMatrix<f64>,
    op: &Operator,
) -> Result<Option<(DMatrix<f64>, usize)>> {
    // X₁: Ω₀(X₁) = −(Q + K₀ᵀRK₀ − SK₀ − K₀ᵀSᵀ).
    let mut rhs = &d.q + matmul_tn(k0, &matmul(&d.r, k0));
    if let Some(s) = d.s {
        let sk = matmul(s, k0);
        rhs -= &sk + sk.transpose();
    }
    let Ok(mut x) = op.solve(&(-symmetrize(&rhs))) else {
        return Ok(None);
    };
    let finite = |x: &DMatrix<f64>| x.iter().all(|v| v.is_finite());
    for step in 1..=KLEINMAN_STEPS {
        crate::cancel::check("the Kleinman iteration on the closed-loop pencil")?;
        if !finite(&x) {
            return Ok(None);
        }
        let res = d.residual_with_error(&x);
        let Some(op) = stable_pencil(d, &res.k) else {
            return Ok(None);
        };
        let Ok(delta) = op.solve(&(-&res.f)) else {
            return Ok(None);
        };
        x = symmetrize(&(&x + &delta));
        if !(norm_fro(&delta) > PHASE_END * norm_fro(&x)) {
            return Ok(finite(&x).then_some((x, step + 1)));
        }
    }
    // Not settled within the bound: the quadratic phase and its certificate decide.
    Ok(finite(&x).then_some((x, KLEINMAN_STEPS + 1)))
}
