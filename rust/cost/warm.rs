//! Warm-started evaluations: the CARE at `r` solved by Newton–Kleinman from a nearby solution
//! `Σ₀` (the previous point of a Newton path, a line search, a sweep over capacities), with the
//! cold Hamiltonian/Schur solve ([`crate::care`]) as the fallback.
//!
//! **Iteration** (defect-correction form). With `A_k = A − Σ_k W(r)` and the residual
//! `R(Σ) = AΣ + ΣAᵀ − (ΣB)(ΣB)ᵀ + Q` computed from the factor `B = [√r_i ĉ_i]` (as the cold
//! refinement computes it, so that high rates keep their accuracy), each step factors `A_k` once
//! (real Schur form) and solves `A_k Δ_k + Δ_k A_kᵀ = −R(Σ_k)`; then `Σ_{k+1} = Σ_k + Δ_k`. From a
//! stabilising start the iterates converge quadratically (Kleinman): 3–4 steps from a point 1 %
//! away. The iteration stops when a correction is below 4 ulps of `Σ` (it is not applied, so the
//! last factorisation is exactly that of the returned `Σ`'s closed loop), or — as the cold
//! refinement does — when a correction at the rounding floor (below `√eps·‖Σ‖`) is followed by
//! one that does not contract, in which case the step is discarded. From order
//! [`BLIND_STEP_MIN_ORDER`](crate::care::BLIND_STEP_MIN_ORDER) on, a correction at the solve's own
//! rounding level that does not increase the residual is applied without a further
//! factorisation, exactly as the cold refinement applies it untested; the factor kept is then
//! that of a closed loop within that rounding-level correction of the returned one.
//!
//! **Fallback** to the cold solve, with the reason recorded in [`WarmInfo::fallback`]: a start or
//! iterate that is not finite; a closed loop that is not Hurwitz (start not stabilising); a
//! correction that does not contract (`‖Δ_{k+1}‖ > ½‖Δ_k‖`) above the rounding floor; more than
//! [`WarmParams::max_steps`] corrections; a failed factorisation or solve; a result without a
//! Newton–Kantorovich proof ([`kantorovich`]: `h = ℓ‖W‖δ ≥ ¼`, with `δ` a rigorous bound on the
//! size of the next Newton correction and `ℓ` on `‖Ω⁻¹‖`). An accepted result is thereby proven to
//! be within `ρ ≤ 2δ` of the stabilising solution (the test the cold solve makes on the
//! Hamiltonian's spectrum has no analogue here). A stalled iteration whose residual's rounding
//! floor, mapped through `Ω⁻¹`, is above `16·eps·‖Σ‖` is refined further with residuals in double-double at the
//! orders where the cold solve does so (stiff models), on the frozen final closed loop; the
//! closed loop of the refined `Σ` is factored afresh when it moved by more than a rounding-level
//! step.
//! Interruption ([`crate::cancel`]) is not a fallback: it is returned at once.
//!
//! **Diagnostics.** The [`CareSolution`] of an accepted warm solve is filled as the cold one's:
//! `residual` (relative, of the returned `Σ`), `forward_error` and `trace_error` from
//! [`crate::care::refine::error_bounds`] with `p = Ω⁻¹(I)` of the final closed loop (one more
//! solve on its Schur form) and the residual's rounding bound — or the proven radius and trace
//! bound of the Kantorovich certificate where those are larger, so that they bound the true
//! error — `closed_loop_abscissa` from the final closed loop's Schur form, `marginal = false` (a marginal solution is never certified),
//! `newton_steps` the corrections applied. Two fields have no meaning here: `rcond` (no `U11` is
//! formed) and `axis_margin` (no Hamiltonian is formed) are NaN; `scaling` is 1.
//!
//! **Chord corrections** (opt-in, [`WarmParams::chord_steps`]): from a factored start the
//! predictor becomes a chord iteration on the start's Schur form ([`chord`]), so that the Newton
//! iteration above usually starts at the rounding level and needs one Schur form.
//!
//! **Reuse.** The real Schur form of the final closed loop is kept in the [`Evaluation`] and handed
//! to its [`Adjoint`](super::Adjoint): the gradient, Hessian and Hessian-vector products of a warm
//! evaluation cost no further factorisation.

use super::Network;
use crate::care::{
    factored_residual, factored_rounding, refine, refine_compensated_factored, relative_residual,
    CareSolution, BLIND_STEP, BLIND_STEP_MIN_ORDER, COMPENSATED_MAX_ORDER,
};
use crate::linalg::dense::{norm_fro, symmetrize};
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
use nalgebra::DMatrix;
use std::fmt;

/// Parameters of a warm-started evaluation.
#[derive(Debug, Clone, Copy)]
pub struct WarmParams {
    /// At most this many Newton–Kleinman corrections from the start (each costs one real Schur
    /// form of the `n × n` closed loop and one Lyapunov solve); beyond it the cold solve is used.
    pub max_steps: usize,
    /// With a factored start ([`Adjoint::warm_evaluation`](crate::cost::Adjoint::warm_evaluation)):
    /// at most this many chord corrections on the start's Schur form (module `warm::chord`)
    /// before the Newton iteration (which then usually needs one Schur form); 0 (the default):
    /// the tangent predictor alone (one such correction).
    pub chord_steps: usize,
    /// Whether a stalled iteration at a large rounding floor is refined further with
    /// double-double residuals (below order `COMPENSATED_MAX_ORDER`, as described in the module
    /// docs; the default). `false` (opt-in, used by the filtration's path following) ends it at
    /// the working-precision floor, reporting the error bounds of that floor (a few times the
    /// cold solve's at such points, where the refined result's are far smaller), at
    /// the cost of the Newton–Kleinman iteration alone.
    pub compensated: bool,
}

/// Default bound on the warm start's corrections (quadratic convergence needs 3–4 from 1 %).
pub const DEFAULT_WARM_STEPS: usize = 8;

impl Default for WarmParams {
    fn default() -> Self {
        WarmParams {
            max_steps: DEFAULT_WARM_STEPS,
            chord_steps: 0,
            compensated: true,
        }
    }
}

/// Why a warm start gave way to the cold solve.
#[derive(Debug, Clone, PartialEq)]
pub enum Fallback {
    /// The start, an iterate, its closed loop or its residual has a NaN or infinite entry.
    NonFinite {
        /// The step (0: the start).
        step: usize,
    },
    /// The closed loop `A − Σ_k W(r)` is not Hurwitz: the iterate is not stabilising.
    NotStabilising {
        /// The step (0: the start).
        step: usize,
        /// Its spectral abscissa (≥ 0 or NaN).
        abscissa: f64,
    },
    /// A correction did not contract (`‖Δ_k‖ > ½‖Δ_{k−1}‖`) above the rounding floor.
    NoContraction {
        /// The step whose correction did not contract.
        step: usize,
        /// `‖Δ_k‖ / ‖Δ_{k−1}‖`.
        ratio: f64,
    },
    /// [`WarmParams::max_steps`] corrections did not converge.
    StepLimit {
        /// The bound.
        steps: usize,
    },
    /// A factorisation or Lyapunov solve failed (its message).
    Failed(String),
    /// The Newton–Kantorovich quantity `h ≥ ¼`: the result cannot be certified.
    NotCertified {
        /// `h` (may be NaN or ∞).
        h: f64,
    },
}

impl fmt::Display for Fallback {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Fallback::NonFinite { step } => write!(f, "non-finite iterate at step {step}"),
            Fallback::NotStabilising { step, abscissa } => write!(
                f,
                "iterate {step} is not stabilising (closed-loop abscissa {abscissa:.3e})"
            ),
            Fallback::NoContraction { step, ratio } => write!(
                f,
                "correction {step} did not contract (ratio {ratio:.3e} > 1/2)"
            ),
            Fallback::StepLimit { steps } => write!(f, "no convergence in {steps} steps"),
            Fallback::Failed(m) => write!(f, "a solve failed: {m}"),
            Fallback::NotCertified { h } => {
                write!(f, "not certified (Newton–Kantorovich h = {h:.3e} ≥ 1/4)")
            }
        }
    }
}

/// What a warm-started evaluation did ([`super::Evaluation::warm_info`]).
#[derive(Debug, Clone, PartialEq)]
pub struct WarmInfo {
    /// `None` when the warm result was accepted; otherwise why the cold solve was used.
    pub fallback: Option<Fallback>,
    /// Newton–Kleinman corrections applied from the start (also when it fell back).
    pub steps: usize,
    /// Real Schur forms of `n × n` closed loops computed by the warm iteration.
    pub factorizations: usize,
    /// The start was first moved by the tangent predictor (one solve with the start's own
    /// factored closed loop, counted in `steps`).
    pub predicted: bool,
    /// Chord corrections applied on the start's factored closed loop ([`WarmParams::chord_steps`];
    /// counted in `steps`).
    pub chord_steps: usize,
}

/// An accepted warm solve: the CARE solution and the factored closed loop of its `Σ`.
pub(super) struct Warm {
    pub(super) sol: CareSolution,
    pub(super) factor: Lyapunov,
}

/// Everything known at one iterate.
struct Iterate {
    x: DMatrix<f64>,
    lyap: Lyapunov,
    res: DMatrix<f64>,
    dn: f64,
    xn: f64,
    abscissa: f64,
    /// `‖x − x_f‖_F` with `x_f` the iterate whose closed loop `lyap` factors (0: its own).
    offset: f64,
}

/// An interruption is returned; any other failure becomes a fallback.
fn soft<T>(r: Result<T>) -> Result<std::result::Result<T, Fallback>> {
    match r {
        Ok(v) => Ok(Ok(v)),
        Err(e @ Error::Interrupted(_)) => Err(e),
        Err(e) => Ok(Err(Fallback::Failed(e.to_string()))),
    }
}

macro_rules! fall {
    ($e:expr) => {
        match $e {
            Ok(v) => v,
            Err(f) => return Ok(Err(f)),
        }
    };
}

/// The data of the CARE in the form the iteration uses.
pub(super) struct Problem<'p> {
    pub(super) net: &'p Network,
    pub(super) r: &'p [f64],
    /// `W(r)`.
    pub(super) w: &'p DMatrix<f64>,
    /// `B = [√r_i ĉ_i]`, `W = B Bᵀ`.
    pub(super) b: &'p DMatrix<f64>,
}

impl Problem<'_> {
    /// `A − Σ W(r)`.
    fn closed_loop(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        super::closed_loop_and_u(self.net, self.r, x).0
    }
}

/// Newton–Kleinman from `start`; the counters (corrections applied, factorisations) are written
/// to `info` whatever the outcome.
pub(super) fn solve(
    p: &Problem<'_>,
    start: &DMatrix<f64>,
    start_factor: Option<&Lyapunov>,
    params: &WarmParams,
    info: &mut WarmInfo,
) -> Result<std::result::Result<Warm, Fallback>> {
    let n = p.net.order();
    let at = p.net.a().transpose(); // the control form's A
    let q = p.net.q();
    let mut x = symmetrize(start);
    if let (Some(f), true) = (start_factor, params.chord_steps > 0) {
        if let Some(c) = chord(p, &at, &x, f, params.chord_steps)? {
            x = c.x;
            info.steps += c.steps;
            info.chord_steps = c.steps;
            info.predicted = true;
        }
    } else if let Some(f) = start_factor {
        if let Some(xp) = predict(p, &at, &x, f)? {
            x = xp;
            info.steps += 1;
            info.predicted = true;
        }
    }
    let mut prev: Option<Iterate> = None;
    for k in 0..=params.max_steps {
        crate::cancel::check("the warm-started Newton–Kleinman iteration")?;
        if !x.iter().all(|v| v.is_finite()) {
            return Ok(Err(Fallback::NonFinite { step: k }));
        }
        let a_cl = p.closed_loop(&x);
        if !a_cl.iter().all(|v| v.is_finite()) {
            return Ok(Err(Fallback::NonFinite { step: k }));
        }
        let lyap = fall!(soft(Lyapunov::new(&a_cl))?);
        info.factorizations += 1;
        let abscissa = abscissa(&lyap);
        if !(abscissa < 0.0) {
            return Ok(Err(Fallback::NotStabilising { step: k, abscissa }));
        }
        let res = factored_residual(&at, p.b, q, &x);
        if !res.iter().all(|v| v.is_finite()) {
            return Ok(Err(Fallback::NonFinite { step: k }));
        }
        let delta = symmetrize(&fall!(soft(lyap.solve(&(-&res)))?));
        let (dn, xn) = (norm_fro(&delta), norm_fro(&x));
        if !dn.is_finite() {
            return Ok(Err(Fallback::NonFinite { step: k }));
        }
        let cur = Iterate {
            x,
            lyap,
            res,
            dn,
            xn,
            abscissa,
            offset: 0.0,
        };
        if dn <= 4.0 * f64::EPSILON * xn {
            // After chord corrections the first Newton correction is at the rounding level by
            // construction: treated as the stall it is (refined further with compensated
            // residuals where the rounding floor is large), as accurate as the plain start.
            return finish(
                p,
                &at,
                cur,
                params.compensated && info.chord_steps > 0,
                info,
            );
        }
        if let Some(pr) = prev.take() {
            if dn > 0.5 * pr.dn {
                // The step to `cur` is not confirmed: at the rounding floor, keep the previous
                // iterate (as the cold refinement discards such a step); above it, give up.
                if pr.dn <= f64::EPSILON.sqrt() * pr.xn {
                    info.steps = info.steps.saturating_sub(1);
                    return finish(p, &at, pr, params.compensated, info);
                }
                return Ok(Err(Fallback::NoContraction {
                    step: k,
                    ratio: dn / pr.dn,
                }));
            }
        }
        let rounding_level = dn <= BLIND_STEP * n as f64 * f64::EPSILON * xn;
        if rounding_level && n < BLIND_STEP_MIN_ORDER {
            // Stop when the correction is within the noise of the residual mapped through Ω⁻¹
            // (the next factorisation could only confirm a stall); `finish` refines further with
            // compensated residuals when that noise is large, as the cold solve does.
            let pm = fall!(soft(cur.lyap.solve(&DMatrix::identity(n, n)))?);
            let floor = (n as f64).sqrt() * norm_fro(&pm) * factored_rounding(&at, p.b, q, &cur.x);
            if dn <= floor {
                return finish(p, &at, cur, params.compensated, info);
            }
        }
        if rounding_level && n >= BLIND_STEP_MIN_ORDER {
            // A correction at the solve's own rounding level: applied untested when it does not
            // increase the residual (the cold refinement's rule); the factor stays that of `cur`,
            // whose closed loop differs by that rounding-level step.
            let cand = symmetrize(&(&cur.x + &delta));
            let cres = factored_residual(&at, p.b, q, &cand);
            if norm_fro(&cres) <= norm_fro(&cur.res) {
                info.steps += 1;
                let moved = Iterate {
                    xn: norm_fro(&cand),
                    offset: norm_fro(&(&cand - &cur.x)),
                    x: cand,
                    res: cres,
                    ..cur
                };
                return finish(p, &at, moved, params.compensated, info);
            }
            return finish(p, &at, cur, params.compensated, info);
        }
        if k == params.max_steps {
            break;
        }
        x = symmetrize(&(&cur.x + &delta));
        info.steps += 1;
        prev = Some(cur);
    }
    Ok(Err(Fallback::StepLimit {
        steps: params.max_steps,
    }))
}

/// The tangent predictor: one correction with the factored closed loop of the start at its own
/// rates, `Σ₀ + Ω₀⁻¹(−R_r(Σ₀))` (a chord step, error second order in the change of rates), kept
/// only when finite and smaller than `‖Σ₀‖/4` (a larger one means the rates moved too far for the
/// linearisation; Newton then starts from `Σ₀` itself).
fn predict(
    p: &Problem<'_>,
    at: &DMatrix<f64>,
    x: &DMatrix<f64>,
    factor: &Lyapunov,
) -> Result<Option<DMatrix<f64>>> {
    if factor.order() != x.nrows() || !x.iter().all(|v| v.is_finite()) {
        return Ok(None);
    }
    let res = factored_residual(at, p.b, p.net.q(), x);
    if !res.iter().all(|v| v.is_finite()) {
        return Ok(None);
    }
    let Ok(delta) = soft(factor.solve(&(-&res)))? else {
        return Ok(None);
    };
    let dn = norm_fro(&delta);
    if !(dn <= 0.25 * norm_fro(x)) {
        return Ok(None);
    }
    Ok(Some(symmetrize(&(x + symmetrize(&delta)))))
}

/// The spectral abscissa of the factored matrix (NaN if an eigenvalue is NaN).
fn abscissa(lyap: &Lyapunov) -> f64 {
    lyap.schur()
        .eigenvalues()
        .iter()
        .map(|e| e.0)
        .fold(
            f64::NEG_INFINITY,
            |m, v| if v.is_nan() { v } else { m.max(v) },
        )
}

/// Error bounds and certification of the final iterate; `stalled`: the iteration stalled at its
/// rounding floor and may be refined with compensated residuals ([`WarmParams::compensated`]).
fn finish(
    p: &Problem<'_>,
    at: &DMatrix<f64>,
    mut it: Iterate,
    stalled: bool,
    info: &mut WarmInfo,
) -> Result<std::result::Result<Warm, Fallback>> {
    let n = it.x.nrows();
    let q = p.net.q();
    let eye = DMatrix::identity(n, n);
    // −Ω⁻¹(I) ⪰ 0 bounds Ω⁻¹ on symmetric matrices (see `care::refine`).
    let mut pm = fall!(soft(it.lyap.solve(&eye))?);
    let mut rounding = factored_rounding(at, p.b, q, &it.x);
    // As in the cold solve: a stalled refinement whose working-precision rounding floor, mapped
    // through Ω⁻¹, is well above eps·‖Σ‖ (stiff models) is refined with compensated residuals at
    // small orders; the closed loop of the refined Σ is then factored afresh (for the bound and
    // the adjoint) unless it moved by no more than a rounding-level step.
    let floor = (n as f64).sqrt() * norm_fro(&pm) * rounding;
    if stalled && n <= COMPENSATED_MAX_ORDER && floor > 16.0 * f64::EPSILON * it.xn {
        if let Some(c) = refine_compensated_factored(at, p.b, q, &it.lyap, &it.x)? {
            let moved = norm_fro(&(&c.x - &it.x));
            if c.steps > 0 && moved <= BLIND_STEP * n as f64 * f64::EPSILON * it.xn {
                // A rounding-level move: the factor (and p) of the frozen closed loop stay, as in
                // the cold solve, which keeps its frozen operator for the bound.
                info.steps += c.steps;
                rounding = c.rounding;
                it = Iterate {
                    xn: norm_fro(&c.x),
                    offset: it.offset + moved,
                    x: c.x,
                    res: c.r,
                    dn: f64::NAN,
                    ..it
                };
            } else if c.steps > 0 {
                let a_cl = p.closed_loop(&c.x);
                if !a_cl.iter().all(|v| v.is_finite()) {
                    return Ok(Err(Fallback::NonFinite { step: info.steps }));
                }
                let lyap = fall!(soft(Lyapunov::new(&a_cl))?);
                info.factorizations += 1;
                let abscissa = abscissa(&lyap);
                if !(abscissa < 0.0) {
                    return Ok(Err(Fallback::NotStabilising {
                        step: info.steps,
                        abscissa,
                    }));
                }
                info.steps += c.steps;
                pm = fall!(soft(lyap.solve(&eye))?);
                rounding = c.rounding;
                it = Iterate {
                    xn: norm_fro(&c.x),
                    x: c.x,
                    lyap,
                    res: c.r,
                    dn: f64::NAN,
                    abscissa,
                    offset: 0.0,
                };
            }
        }
    }
    let rnorm = norm_fro(&it.res);
    let gn = norm_fro(p.w);
    let proof = fall!(kantorovich(p, &it, &pm, rounding)?);
    let (mut forward_error, mut trace_error) =
        refine::error_bounds(&pm, rnorm, rounding, gn, &it.x);
    // The first-order bounds are what the cold solve reports; the proven radius may exceed them
    // (it covers the quadratic term and the solve's own error), and then it is reported.
    let nx = norm_fro(&it.x);
    if nx > 0.0 {
        forward_error = forward_error.max((n as f64).sqrt() * proof.radius / nx + f64::EPSILON);
    }
    trace_error = trace_error.max(proof.trace + f64::EPSILON * it.x.trace().abs());
    if !(forward_error.is_finite() && trace_error.is_finite()) {
        return Ok(Err(Fallback::NotCertified { h: proof.h }));
    }
    let residual = relative_residual(at, p.w, q, &it.x, &it.res);
    Ok(Ok(Warm {
        sol: CareSolution {
            x: it.x,
            residual,
            forward_error,
            trace_error,
            rcond: f64::NAN,
            closed_loop_abscissa: it.abscissa,
            axis_margin: f64::NAN,
            marginal: false,
            newton_steps: info.steps,
            scaling: 1.0,
        },
        factor: it.lyap,
    }))
}

mod api;
mod chord;
mod kantorovich;

use chord::chord;
use kantorovich::kantorovich;

#[cfg(test)]
mod tests;
