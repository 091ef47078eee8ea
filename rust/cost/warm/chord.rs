//! Chord Newton–Kleinman: the corrections of a warm start solved with the start's own factored
//! closed loop instead of a fresh Schur form per iterate.
//!
//! **Iteration.** With `Ω_f(D) = A_f D + D A_fᵀ`, `A_f = A − Σ₀W(r₀)` the closed loop of the
//! start (its real Schur form kept by the start's [`Adjoint`](crate::cost::Adjoint)), and
//! `R(Σ) = AΣ + ΣAᵀ − (ΣB)(ΣB)ᵀ + Q` the residual at the new rates `r` (from the factor
//! `B = [√r_i ĉ_i]`, as the Newton iteration computes it):
//!
//! `Σ_{j+1} = Σ_j + Ω_f⁻¹(−R(Σ_j))`.
//!
//! This is Newton's method with the derivative frozen at the start: the exact derivative at `Σ_j`
//! is `Ω_j = Ω_f + E_j`, `E_j(D) = ΔA_j D + D ΔA_jᵀ`, `ΔA_j = Σ₀W(r₀) − Σ_j W(r)`, and the error
//! contracts by the factor `θ ≈ ‖Ω_f⁻¹ E_j‖ ≤ 2ℓ_f‖ΔA_j‖` per step (`ℓ_f = ‖Ω_f⁻¹‖`) — linear,
//! fast while the point is close (`Network.random(50, 2, eps=0.05)`, n = 100: 2 corrections from
//! a relative move of the rates of 1e-6 or 1e-4, 3 from 1e-3, 4 from 1e-2). Each step costs one
//! residual and one solve on the kept Schur form (≈ a third of a Schur form of the same order).
//! The first step is the tangent predictor of the Newton iteration.
//!
//! **Stopping.** The iteration stops when a correction is within 4 ulps of `Σ` (converged) or the
//! next one is predicted (from the last contraction) at the level the Newton iteration accepts
//! without a further Schur form (4 ulps; from order 64 on the rounding level of its solve), when
//! a correction does not contract by at least [`CHORD_RATIO`] against the one before (that
//! correction is not applied: the linear rate is too slow to pay, or the rounding floor is
//! reached), after the given number of steps, or on anything not finite. The first correction is
//! kept only when smaller than `‖Σ₀‖/4` (as the predictor's).
//!
//! **What follows.** The chord's iterate is handed to the Newton iteration of the parent module,
//! which factors its closed loop once: at a converged chord its first correction is at the
//! rounding level, so that one Schur form (instead of one per Newton step) gives the result, its
//! certificate ([`super::kantorovich`], with the fresh factor: the proof does not rest on the
//! frozen operator) and the factor handed to the adjoint. When the chord stopped early the Newton
//! iteration simply goes on from the chord's iterate with fresh factors (today's path), so the
//! chord never costs more than a few solves over the plain warm start.

use super::{soft, Problem};
use crate::care::{factored_residual, BLIND_STEP, BLIND_STEP_MIN_ORDER};
use crate::linalg::dense::{norm_fro, symmetrize};
use crate::linalg::sylvester::Lyapunov;
use crate::Result;
use nalgebra::DMatrix;

/// A chord correction is applied only when at most this fraction of the one before.
pub(super) const CHORD_RATIO: f64 = 0.25;

/// The chord's result: its last iterate and the corrections applied.
pub(super) struct Chord {
    pub(super) x: DMatrix<f64>,
    pub(super) steps: usize,
}

/// At most `max_steps` chord corrections from `x0` with the factored closed loop `factor`;
/// `None` when not even the first one is kept.
pub(super) fn chord(
    p: &Problem<'_>,
    at: &DMatrix<f64>,
    x0: &DMatrix<f64>,
    factor: &Lyapunov,
    max_steps: usize,
) -> Result<Option<Chord>> {
    if factor.order() != x0.nrows() || !x0.iter().all(|v| v.is_finite()) {
        return Ok(None);
    }
    let q = p.net.q();
    let mut x = x0.clone();
    let mut previous = f64::INFINITY;
    let mut steps = 0;
    let n = x0.nrows();
    let level = if n >= BLIND_STEP_MIN_ORDER {
        BLIND_STEP * n as f64 * f64::EPSILON
    } else {
        4.0 * f64::EPSILON
    };
    for j in 0..max_steps {
        crate::cancel::check("the chord Newton–Kleinman iteration")?;
        let res = factored_residual(at, p.b, q, &x);
        if !res.iter().all(|v| v.is_finite()) {
            break;
        }
        let Ok(delta) = soft(factor.solve(&(-&res)))? else {
            break;
        };
        let (dn, xn) = (norm_fro(&delta), norm_fro(&x));
        let kept = if j == 0 {
            dn <= 0.25 * xn
        } else {
            dn <= CHORD_RATIO * previous
        };
        if !kept {
            break;
        }
        x = symmetrize(&(&x + symmetrize(&delta)));
        steps += 1;
        // The next correction is predicted at `dn·θ` (`θ` the last contraction): stop when it is
        // within 4 ulps, or — from the order where the Newton iteration applies a rounding-level
        // correction untested — within that level, which the one Schur form that follows accepts.
        let next = if j == 0 { dn } else { dn * dn / previous };
        previous = dn;
        if dn <= 4.0 * f64::EPSILON * xn || next <= level * xn {
            break;
        }
    }
    Ok((steps > 0).then_some(Chord { x, steps }))
}

#[cfg(test)]
mod tests;
