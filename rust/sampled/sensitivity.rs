//! First-order sensitivity of the periodic steady-state cost to a change of one or two slots (an
//! adjoint, or Stein, equation), used to screen the moves of a schedule search.
//!
//! Let `F` be the period map of the current schedule, `Σ̄ = F(Σ̄)` its steady state at the period
//! boundary and `M` the closed-loop monodromy (`DF(X) = M X Mᵀ`, [`monodromy`]). Along the
//! periodic orbit slot `l` has prior `P_l = E S_{l−1} Eᵀ + H` and posterior `S_l = U_{R_l}(P_l)`,
//! `U_i(P) = P − P c̄_i (I + c̄_iᵀPc̄_i)⁻¹ c̄_iᵀ P`, and closed-loop transition
//! `A_l = (I − K_l c̄_{R_l}ᵀ) E` (`K_l` the Kalman gain): `DΦ_{slot l}(δ) = A_l δ A_lᵀ`.
//!
//! If slot `l`'s output changes by `d_l` (another sensor, or two slots exchanged), the orbit moves
//! to first order by the linear periodic response, and the cost `J` by `⟨μ_l, d_l⟩` with the
//! adjoint `μ_l = w_l + A_{l+1}ᵀ μ_{l+1} A_{l+1}` around the period (cyclically):
//!
//! * boundary `J = tr Σ̄`: `w_{r−1} = I`, other `w_l = 0`, so `μ_{r−1} = Λ` with
//!   `Λ = Mᵀ Λ M + I` (one Stein equation), and `μ_l` pulled back slot by slot;
//! * average `J = (1/r) Σ_l tr S_l`: every `w_l = I/r`; a first backward pass from `ν_{r−1} = I/r`
//!   gives `C = I/r + A_0ᵀ ν_0 A_0`, then `Λ = Mᵀ Λ M + C` and the second pass.
//!
//! Screens (local change exact, its propagation linear):
//!
//! * slot `l` from sensor `i` to `j`: `⟨μ_l, U_j(P_l) − U_i(P_l)⟩ = g_i − g_j`,
//!   `g_k = tr((I + c̄_kᵀ P_l c̄_k)⁻¹ (P_l c̄_k)ᵀ μ_l (P_l c̄_k))` — `O(n² p)` per pair;
//! * slots `l, l+1` exchanged (`a = R_l`, `b = R_{l+1}`): the new prior of slot `l + 1` is
//!   `P' = P_{l+1} + Y_a S_a⁻¹ Y_aᵀ − Y_b S_b⁻¹ Y_bᵀ` (`Y_k = E P_l c̄_k`, a low-rank change), and
//!   the screen `⟨μ_{l+1}, U_a(P') − U_b(P_{l+1})⟩` (for the average, plus
//!   `(tr U_b(P_l) − tr U_a(P_l))/r`: slot `l`'s own posterior is counted too);
//! * rotations (boundary objective): the rotated schedule has the same periodic orbit, so its
//!   boundary cost is exactly `tr S_{k−1}` — no equation at all (with idle time a rotation moves
//!   the tail relative to the slots: not screened, `+∞`).
//!
//! **Weight, slot lengths, idle tail.** With an error weight `M` the sources are `M` instead of
//! `I` (boundary: `Λ = MᵀΛM + M`; average: `w_l = M/r`) and the traces are `tr(M ·)`. Each slot's
//! transition uses its own `E_{R_l}`. With an idle tail `T = (E_T, 0, H_T)` after the last slot
//! the boundary follows the tail: `μ_{r−1} = E_Tᵀ Λ E_T` (plus `M/r` for the average, whose
//! sources are then all pulled back to the boundary through the slots). Moves between sensors of
//! different costs change slot lengths and the tail: see the private module `length_change`.

use super::doubling::{doubling, monodromy, DoublingOptions, MARGINAL};
use super::gains::slot_gains;
use super::length_change::{unequal_swap, Unequal};
use super::search::{CountLimits, Objective};
use super::star_tree::{check_deadline, past};
use super::{Discretisation, Triplet};
use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, norm_fro, symmetrize};
use crate::{Error, Result};
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::time::Instant;

/// The screened neighbourhood of a schedule.
#[derive(Debug, Clone)]
pub struct Screen {
    /// The exact cost of the schedule (as [`super::search::schedule_cost`]).
    pub current: f64,
    /// Spectral radius of the closed-loop monodromy.
    pub spectral_radius: f64,
    /// `reassign[(l, j)]`: the predicted change of the cost when slot `l` goes to sensor `j`
    /// (`+∞`: no-op, or the move would leave a sensor below `min_count` slots).
    pub reassign: DMatrix<f64>,
    /// `swap[l]`: the predicted change when slots `l`, `l + 1` are exchanged (`+∞`: same sensor).
    pub swap: Vec<f64>,
    /// `rotate[k]`: the exact cost of the schedule started at slot `k` (boundary objective;
    /// `+∞` for the average, which rotations leave unchanged; `rotate[0]` is `current`).
    pub rotate: Vec<f64>,
    /// Squared-Smith steps of the Stein solve.
    pub stein_steps: usize,
}

/// Per-slot data of the periodic orbit: prior, gain, posterior and its (weighted) trace.
pub(super) struct Orbit {
    pub(super) priors: Vec<DMatrix<f64>>,
    pub(super) gains: Vec<DMatrix<f64>>,
    pub(super) posts: Vec<DMatrix<f64>>,
    pub(super) post_traces: Vec<f64>,
}

/// The Cholesky factor of `I + c̄ᵀ P c̄` and `X = P c̄`.
fn innovation(
    p: &DMatrix<f64>,
    c: &DMatrix<f64>,
) -> Result<(DMatrix<f64>, nalgebra::Cholesky<f64, nalgebra::Dyn>)> {
    let x = p * c;
    let mut s = c.tr_mul(&x);
    for k in 0..s.nrows() {
        s[(k, k)] += 1.0;
    }
    let chol = symmetrize(&s).cholesky().ok_or_else(|| {
        Error::SingularProblem("innovation covariance I + c̄ᵀPc̄ is not positive definite".into())
    })?;
    Ok((x, chol))
}

/// `g = tr(S⁻¹ Xᵀ μ X)` with `X = P c̄`, `S = I + c̄ᵀ X`: the trace reduction seen by `μ`.
fn gain(p: &DMatrix<f64>, c: &DMatrix<f64>, mu: &DMatrix<f64>) -> Result<f64> {
    let (x, chol) = innovation(p, c)?;
    let mx = mu * &x;
    let xtmx = x.tr_mul(&mx);
    Ok(chol.solve(&xtmx).trace())
}

fn forward(
    disc: &Discretisation,
    slots: &[usize],
    sigma: &DMatrix<f64>,
    joseph: bool,
) -> Result<Orbit> {
    let r = slots.len();
    let mut orbit = Orbit {
        priors: Vec::with_capacity(r),
        gains: Vec::with_capacity(r),
        posts: Vec::with_capacity(r),
        post_traces: Vec::with_capacity(r),
    };
    let mut s = sigma.clone();
    for &i in slots {
        crate::cancel::check("the periodic orbit of a schedule")?;
        // The average's cost is summed along this orbit: the same arithmetic as `propagate`.
        let p = if joseph {
            disc.predict_for(i, &s)
        } else {
            let e = disc.e_of(i);
            symmetrize(&(matmul_nt(&matmul(e, &s), e) + disc.h_of(i)))
        };
        let (x, chol) = innovation(&p, &disc.cbar[i])?;
        let k = chol.solve(&x.transpose()).transpose();
        s = if joseph {
            disc.update(i, &p)?
        } else {
            symmetrize(&(&p - &k * x.transpose()))
        };
        orbit.post_traces.push(disc.weighted_trace(&s));
        orbit.posts.push(s.clone());
        orbit.priors.push(p);
        orbit.gains.push(k);
    }
    Ok(orbit)
}

/// `A_lᵀ μ A_l` with `A_l = (I − K c̄ᵀ) E` (`E` over the slot's length).
fn pull_back(
    e: &DMatrix<f64>,
    k: &DMatrix<f64>,
    c: &DMatrix<f64>,
    mu: &DMatrix<f64>,
) -> DMatrix<f64> {
    // μJ = μ − (μK)c̄ᵀ, then Jᵀ(μJ) = μJ − c̄ (Kᵀ μJ).
    let mut mj = mu.clone();
    mj.gemm(-1.0, &(mu * k), &c.transpose(), 1.0);
    let ktmj = k.tr_mul(&mj);
    mj.gemm(-1.0, c, &ktmj, 1.0);
    symmetrize(&matmul(&matmul_tn(e, &mj), e))
}

/// `Λ = Mᵀ Λ M + C` by squared Smith iteration (`Λ ← Λ + Bᵀ Λ B`, `B ← B²`): `2^k` terms of the
/// series after `k` steps. Needs `ρ(M) < 1`; at most `max_steps` steps.
pub fn stein(
    m: &DMatrix<f64>,
    c: &DMatrix<f64>,
    max_steps: usize,
) -> Result<(DMatrix<f64>, usize)> {
    let mut x = c.clone();
    let mut b = m.clone();
    for step in 1..=max_steps {
        crate::cancel::check("the Stein equation of the schedule sensitivity")?;
        let add = matmul(&matmul_tn(&b, &x), &b);
        let (na, nx) = (norm_fro(&add), norm_fro(&x));
        x += &add;
        x = symmetrize(&x);
        if !na.is_finite() {
            break;
        }
        if na <= 1e-17 * nx {
            return Ok((x, step));
        }
        b = matmul(&b, &b);
    }
    Err(Error::Convergence(format!(
        "the Stein equation Λ = MᵀΛM + C did not converge in {max_steps} squared-Smith steps"
    )))
}

/// Screens every reassignment, adjacent swap and rotation of `slots` (see the module docs);
/// `period` is the schedule's period triplet (its idle tail included).
pub fn screen(
    disc: &Discretisation,
    slots: &[usize],
    period: &Triplet,
    objective: Objective,
    min_count: usize,
    opts: &DoublingOptions,
) -> Result<Screen> {
    let limits = CountLimits::common(min_count, disc.n_sensors());
    screen_with(disc, slots, period, objective, &limits, opts)
}

/// As [`screen`] with per-sensor count limits (and the discretisation's budget).
pub fn screen_with(
    disc: &Discretisation,
    slots: &[usize],
    period: &Triplet,
    objective: Objective,
    limits: &CountLimits,
    opts: &DoublingOptions,
) -> Result<Screen> {
    let d = doubling(period, opts)?;
    let (m, rho) = monodromy(period, &d.sigma)?;
    screen_at(disc, slots, &d.sigma, &m, rho, objective, limits)
}

/// As [`screen_with`], but `Ok(None)` once `deadline` has passed (checked between the doubling,
/// the orbit, the adjoint and the gains: each a fraction of a screen).
#[allow(clippy::too_many_arguments)]
pub fn screen_with_until(
    disc: &Discretisation,
    slots: &[usize],
    period: &Triplet,
    objective: Objective,
    limits: &CountLimits,
    opts: &DoublingOptions,
    deadline: Option<Instant>,
) -> Result<Option<Screen>> {
    if check_deadline(deadline).is_err() {
        return Ok(None);
    }
    let d = doubling(period, opts)?;
    let (m, rho) = monodromy(period, &d.sigma)?;
    screen_at_until(disc, slots, &d.sigma, &m, rho, objective, limits, deadline)
}

/// The adjoint of the cost along the orbit: `μ_l` for every slot, and `Λ_B`, the adjoint at the
/// period boundary without a direct source at the last posterior (for the change of the tail).
pub(super) struct Adjoint {
    pub(super) mus: Vec<DMatrix<f64>>,
    pub(super) lambda_b: DMatrix<f64>,
    stein_steps: usize,
}

fn adjoint(
    disc: &Discretisation,
    slots: &[usize],
    orbit: &Orbit,
    m: &DMatrix<f64>,
    average: bool,
    tail: Option<&Triplet>,
) -> Result<Adjoint> {
    let r = slots.len();
    let n = disc.order();
    let eye = DMatrix::<f64>::identity(n, n);
    let wm = disc.weight.as_ref().unwrap_or(&eye);
    let step = |l: usize, mu: &DMatrix<f64>| {
        let i = slots[l];
        pull_back(disc.e_of(i), &orbit.gains[l], &disc.cbar[i], mu)
    };
    let w = 1.0 / r as f64;
    let source = match (average, tail) {
        (false, _) => wm.clone(),
        (true, None) => {
            // ν_{r−1} = 0, ν_l = w M + A_{l+1}ᵀ ν_{l+1} A_{l+1}: the sources of slots l … r − 2.
            let mut nu = DMatrix::<f64>::zeros(n, n);
            for l in (0..r.saturating_sub(1)).rev() {
                crate::cancel::check("the adjoint of a schedule")?;
                nu = step(l + 1, &nu) + wm * w;
            }
            step(0, &nu) + wm * w
        }
        (true, Some(_)) => {
            // The boundary follows the tail: every slot's source is pulled back to it.
            let mut nu = wm * w;
            for l in (0..r.saturating_sub(1)).rev() {
                crate::cancel::check("the adjoint of a schedule")?;
                nu = step(l + 1, &nu) + wm * w;
            }
            step(0, &nu)
        }
    };
    let max_steps = 64;
    let (lambda, stein_steps) = stein(m, &source, max_steps)?;
    let lambda_b = match (average, tail) {
        (true, None) => &lambda - wm * w,
        _ => lambda.clone(),
    };
    // The adjoint at every slot, pulled back from μ_{r−1}.
    let last = match tail {
        None => lambda,
        Some(t) => {
            let pulled = symmetrize(&matmul(&matmul_tn(&t.a, &lambda), &t.a));
            if average {
                pulled + wm * w
            } else {
                pulled
            }
        }
    };
    let mut mus = vec![last];
    for l in (0..r - 1).rev() {
        crate::cancel::check("the adjoint of a schedule")?;
        let pulled = step(l + 1, mus.last().expect("μ_{r−1}"));
        mus.push(if average { pulled + wm * w } else { pulled });
    }
    mus.reverse();
    Ok(Adjoint {
        mus,
        lambda_b,
        stein_steps,
    })
}

/// As [`screen`], given the steady state `sigma` at the period boundary, the closed-loop
/// monodromy `m` there and its spectral radius `rho` (e.g. kept from the exact evaluation that
/// accepted the schedule).
pub fn screen_at(
    disc: &Discretisation,
    slots: &[usize],
    sigma: &DMatrix<f64>,
    m: &DMatrix<f64>,
    rho: f64,
    objective: Objective,
    limits: &CountLimits,
) -> Result<Screen> {
    let sc = screen_at_until(disc, slots, sigma, m, rho, objective, limits, None)?;
    Ok(sc.expect("no deadline"))
}

/// As [`screen_at`], but `Ok(None)` once `deadline` has passed (checked before the orbit, the
/// adjoint and the gains, and by every slot's gains).
#[allow(clippy::too_many_arguments)]
pub fn screen_at_until(
    disc: &Discretisation,
    slots: &[usize],
    sigma: &DMatrix<f64>,
    m: &DMatrix<f64>,
    rho: f64,
    objective: Objective,
    limits: &CountLimits,
    deadline: Option<Instant>,
) -> Result<Option<Screen>> {
    past(screened(
        disc, slots, sigma, m, rho, objective, limits, deadline,
    ))
}

#[allow(clippy::too_many_arguments)]
fn screened(
    disc: &Discretisation,
    slots: &[usize],
    sigma: &DMatrix<f64>,
    m: &DMatrix<f64>,
    rho: f64,
    objective: Objective,
    limits: &CountLimits,
    deadline: Option<Instant>,
) -> Result<Screen> {
    check_deadline(deadline)?;
    disc.check_schedule(slots)?;
    limits.check(disc.n_sensors())?;
    let r = slots.len();
    let nsens = disc.n_sensors();
    if rho >= 1.0 || 1.0 - rho <= MARGINAL {
        return Err(Error::Convergence(format!(
            "the steady state of the schedule is not stabilising (closed-loop spectral radius \
             {rho:.6})"
        )));
    }
    let average = objective == Objective::Average;
    let tail = disc.tail(slots)?;
    let orbit = forward(disc, slots, sigma, average)?;
    check_deadline(deadline)?;
    let current = if average {
        orbit.post_traces.iter().sum::<f64>() / r as f64
    } else {
        disc.weighted_trace(sigma)
    };
    let adj = adjoint(disc, slots, &orbit, m, average, tail.as_ref())?;
    check_deadline(deadline)?;
    let mus = &adj.mus;
    let mut counts = vec![0usize; nsens];
    for &i in slots {
        counts[i] += 1;
    }
    let unequal = Unequal::new(disc, slots, &orbit, sigma, &adj, tail.as_ref())?;
    // Per slot (in parallel): the gains g_k of every sensor, the reassignments and the swap.
    let token = crate::cancel::current();
    let gains: Vec<Vec<f64>> = (0..r)
        .into_par_iter()
        .map(|l| {
            crate::cancel::with_token(token.as_ref(), || {
                crate::cancel::check("the screening of a schedule neighbourhood")?;
                check_deadline(deadline)?;
                let priors: Vec<&DMatrix<f64>> =
                    (0..nsens).map(|j| unequal.prior(l, j, &orbit)).collect();
                slot_gains(&priors, &disc.cbar, &mus[l])
            })
        })
        .collect::<Result<_>>()?;
    let w = 1.0 / r as f64;
    let swap: Vec<f64> = (0..r.saturating_sub(1))
        .into_par_iter()
        .map(|l| {
            let (a, b) = (slots[l], slots[l + 1]);
            if a == b {
                return Ok(f64::INFINITY);
            }
            crate::cancel::with_token(token.as_ref(), || {
                crate::cancel::check("the screening of a schedule neighbourhood")?;
                if !disc.same_length(a, b) {
                    return unequal_swap(disc, &orbit, sigma, l, a, b, &mus[l + 1], average, w);
                }
                let p = &orbit.priors[l];
                let mut v = swap_screen(
                    disc,
                    p,
                    &orbit.priors[l + 1],
                    a,
                    b,
                    &mus[l + 1],
                    gains[l + 1][b],
                )?;
                if average {
                    // The average also counts slot l's own posterior, U_b(P_l) instead of U_a(P_l).
                    let wm = weight_or_eye(disc);
                    v += w * (gain(p, &disc.cbar[a], &wm)? - gain(p, &disc.cbar[b], &wm)?);
                }
                Ok(v)
            })
        })
        .collect::<Result<_>>()?;
    let used = disc.used(slots);
    let reassign = DMatrix::from_fn(r, nsens, |l, j| {
        let i = slots[l];
        if !limits.reassign_ok(disc, &counts, used, i, j) {
            f64::INFINITY
        } else if disc.same_length(i, j) {
            gains[l][i] - gains[l][j]
        } else {
            unequal.shift(l, i, j) + gains[l][i] - gains[l][j]
        }
    });
    let rotate = (0..r)
        .map(|k| match (k, average || tail.is_some()) {
            (0, _) => current,
            (_, true) => f64::INFINITY,
            (_, false) => orbit.post_traces[k - 1],
        })
        .collect();
    Ok(Screen {
        current,
        spectral_radius: rho,
        reassign,
        swap,
        rotate,
        stein_steps: adj.stein_steps,
    })
}

fn weight_or_eye(disc: &Discretisation) -> DMatrix<f64> {
    match &disc.weight {
        None => DMatrix::identity(disc.order(), disc.order()),
        Some(m) => m.clone(),
    }
}

/// The screen of exchanging slots `l` (sensor `a`, prior `p0`) and `l + 1` (sensor `b`, prior
/// `p1`), `mu1` the adjoint at slot `l + 1` and `gb` = `g_b` there.
fn swap_screen(
    disc: &Discretisation,
    p0: &DMatrix<f64>,
    p1: &DMatrix<f64>,
    a: usize,
    b: usize,
    mu1: &DMatrix<f64>,
    gb: f64,
) -> Result<f64> {
    let (ca, cb) = (&disc.cbar[a], &disc.cbar[b]);
    let (xa, sa) = innovation(p0, ca)?;
    let (xb, sb) = innovation(p0, cb)?;
    let e = disc.e_of(a);
    let (ya, yb) = (e * &xa, e * &xb);
    // P' − P_{l+1} = Y_a S_a⁻¹ Y_aᵀ − Y_b S_b⁻¹ Y_bᵀ.
    let mut dp = &ya * sa.solve(&ya.transpose());
    dp -= &yb * sb.solve(&yb.transpose());
    let dp = symmetrize(&dp);
    let p_new = p1 + &dp;
    let first = mu1.dot(&dp);
    Ok(first - gain(&p_new, ca, mu1)? + gb)
}
