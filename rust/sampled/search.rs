//! Kernels for schedule optimisation: the exact finite-τ cost of every schedule one move away
//! from a given one, and one pass of the greedy sensor-scheduling heuristic.
//!
//! With the prefix compositions `P_l = S_{R_l} ∘ … ∘ S_{R_1}` and suffix compositions
//! `Q_l = S_{R_{r}} ∘ … ∘ S_{R_{l+1}}` of the slot triplets (computed once, `2 r_tot` star
//! products), the period triplet of a schedule that differs in one or two adjacent slots, or is a
//! rotation, costs one to three star products; its steady state then costs one doubling
//! (`≈ log₂(1/(1 − ρ))` star products) instead of `r_tot` slot compositions.

use super::doubling::{doubling, monodromy, propagate, DoublingOptions};
use super::{Discretisation, Triplet};
use crate::{Error, Result};
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// Which figure of the periodic steady state is minimised.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Objective {
    /// `tr Σ(∞; τ, R)` at the period boundary (the paper's `η̄`).
    Boundary,
    /// `(1/r_tot) Σ_l tr Σ_l⁺`, the average over the posteriors after each slot.
    Average,
}

/// Costs of all schedules one move away from the current one. Moves that are no-ops, that would
/// leave a sensor with fewer than `min_count` slots, or whose steady state fails, cost `+∞`.
#[derive(Debug, Clone)]
pub struct Neighbourhood {
    /// The cost of the current schedule.
    pub current: f64,
    /// `reassign[(l, j)]`: slot `l` given to sensor `j` (moves one slot between two sensors).
    pub reassign: DMatrix<f64>,
    /// `swap[l]`: slots `l` and `l + 1` exchanged (`l = 0, …, r_tot − 2`).
    pub swap: Vec<f64>,
    /// `rotate[k]`: the schedule started at slot `k` (`R_{k+1}, …, R_r, R_1, …, R_k`); `+∞` for
    /// the average objective, which every rotation leaves unchanged.
    pub rotate: Vec<f64>,
    /// `false` if the deadline of [`neighbourhood_until`] passed before every candidate was
    /// evaluated: the candidates not evaluated cost `+∞`, the others are exact.
    pub complete: bool,
    /// How many neighbours were costed (each a doubling): the no-op and starving moves (`+∞`
    /// by rule) and the candidates skipped after the deadline are not counted.
    pub evaluated: usize,
}

/// The cost of a schedule given its period triplet; `Err` when the steady state does not exist.
pub(crate) fn cost_of(
    disc: &Discretisation,
    t: &Triplet,
    slots: &[usize],
    objective: Objective,
    opts: &DoublingOptions,
) -> Result<f64> {
    Ok(steady_cost(disc, t, slots, objective, opts)?.cost)
}

/// The cost of a schedule with its boundary steady state and closed-loop monodromy.
#[derive(Debug, Clone)]
pub struct SteadyCost {
    /// The cost under the objective.
    pub cost: f64,
    /// `Σ(∞; τ, R)` at the period boundary.
    pub sigma: DMatrix<f64>,
    /// The closed-loop monodromy `M` at `sigma`.
    pub monodromy: DMatrix<f64>,
    /// Its spectral radius (`< 1`).
    pub rho: f64,
}

/// The exact cost of a schedule from its period triplet (as the private `cost_of`), keeping the
/// steady state and the monodromy.
pub fn steady_cost(
    disc: &Discretisation,
    t: &Triplet,
    slots: &[usize],
    objective: Objective,
    opts: &DoublingOptions,
) -> Result<SteadyCost> {
    let d = doubling(t, opts)?;
    let (m, rho) = monodromy(t, &d.sigma)?;
    if rho >= 1.0 {
        return Err(Error::Convergence("non-stabilising limit".into()));
    }
    let cost = match objective {
        Objective::Boundary => d.sigma.trace(),
        Objective::Average => {
            let (_, posts) = propagate(disc, slots, &d.sigma)?;
            posts.iter().map(|p| p.trace()).sum::<f64>() / posts.len() as f64
        }
    };
    Ok(SteadyCost {
        cost,
        sigma: d.sigma,
        monodromy: m,
        rho,
    })
}

/// The cost of one neighbour, `+∞` when its triplet or its steady state fails (or the search was
/// cancelled: [`neighbourhood`] reports that once every candidate has returned).
fn eval_candidate(
    disc: &Discretisation,
    objective: Objective,
    opts: &DoublingOptions,
    t: Result<Triplet>,
    cand: &dyn Fn() -> Vec<usize>,
) -> f64 {
    match t {
        Ok(t) => {
            let s = if objective == Objective::Average {
                cand()
            } else {
                Vec::new()
            };
            cost_of(disc, &t, &s, objective, opts).unwrap_or(f64::INFINITY)
        }
        Err(_) => f64::INFINITY,
    }
}

/// The exact cost of a schedule (doubling of its period triplet).
pub fn schedule_cost(
    disc: &Discretisation,
    slots: &[usize],
    objective: Objective,
    opts: &DoublingOptions,
) -> Result<f64> {
    let t = disc.period_triplet(slots)?;
    cost_of(disc, &t, slots, objective, opts)
}

/// Evaluates every reassignment of one slot, every adjacent swap and every rotation of `slots`.
/// Candidates are evaluated in parallel (rayon).
pub fn neighbourhood(
    disc: &Discretisation,
    slots: &[usize],
    objective: Objective,
    min_count: usize,
    opts: &DoublingOptions,
) -> Result<Neighbourhood> {
    neighbourhood_until(disc, slots, objective, min_count, opts, None)
}

/// As [`neighbourhood`], but candidates whose evaluation would start after `deadline` are
/// skipped (cost `+∞`, [`Neighbourhood::complete`] `false`): a time limit for the schedule
/// search that one large neighbourhood cannot overrun by more than one candidate per thread.
pub fn neighbourhood_until(
    disc: &Discretisation,
    slots: &[usize],
    objective: Objective,
    min_count: usize,
    opts: &DoublingOptions,
    deadline: Option<Instant>,
) -> Result<Neighbourhood> {
    disc.check_schedule(slots)?;
    let r = slots.len();
    let nsens = disc.n_sensors();
    let n = disc.order();
    let mut counts = vec![0usize; nsens];
    for &i in slots {
        counts[i] += 1;
    }
    let tr = &disc.slots;
    let mut prefix = Vec::with_capacity(r + 1);
    prefix.push(Triplet::identity(n));
    for l in 0..r {
        crate::cancel::check("the prefix compositions of a schedule")?;
        let next = prefix[l].then(&tr[slots[l]])?;
        prefix.push(next);
    }
    let mut suffix = vec![Triplet::identity(n); r + 1];
    for l in (0..r).rev() {
        suffix[l] = tr[slots[l]].then(&suffix[l + 1])?;
    }
    let current = cost_of(disc, &prefix[r], slots, objective, opts)?;
    // Candidates run on rayon's threads: hand them this thread's cancellation token. A cancelled
    // candidate costs +∞; the cancellation is reported once all of them have returned.
    let token = crate::cancel::current();
    let timed_out = AtomicBool::new(false);
    let evaluated = AtomicUsize::new(0);
    let eval = |t: Result<Triplet>, cand: &dyn Fn() -> Vec<usize>| -> f64 {
        if deadline.is_some_and(|d| Instant::now() >= d) {
            timed_out.store(true, Ordering::Relaxed);
            return f64::INFINITY;
        }
        evaluated.fetch_add(1, Ordering::Relaxed);
        crate::cancel::with_token(token.as_ref(), || {
            eval_candidate(disc, objective, opts, t, cand)
        })
    };
    let rows: Vec<Vec<f64>> = (0..r)
        .into_par_iter()
        .map(|l| {
            (0..nsens)
                .map(|j| {
                    let i = slots[l];
                    if j == i || counts[i] <= min_count {
                        return f64::INFINITY;
                    }
                    let t = prefix[l].then(&tr[j]).and_then(|t| t.then(&suffix[l + 1]));
                    eval(t, &|| {
                        let mut s = slots.to_vec();
                        s[l] = j;
                        s
                    })
                })
                .collect()
        })
        .collect();
    let reassign = DMatrix::from_fn(r, nsens, |l, j| rows[l][j]);
    let swap: Vec<f64> = (0..r.saturating_sub(1))
        .into_par_iter()
        .map(|l| {
            if slots[l] == slots[l + 1] {
                return f64::INFINITY;
            }
            let t = prefix[l]
                .then(&tr[slots[l + 1]])
                .and_then(|t| t.then(&tr[slots[l]]))
                .and_then(|t| t.then(&suffix[l + 2]));
            eval(t, &|| {
                let mut s = slots.to_vec();
                s.swap(l, l + 1);
                s
            })
        })
        .collect();
    let rotate: Vec<f64> = (0..r)
        .into_par_iter()
        .map(|k| {
            if k == 0 {
                return current;
            }
            if objective == Objective::Average {
                return f64::INFINITY;
            }
            eval(suffix[k].then(&prefix[k]), &Vec::new)
        })
        .collect();
    crate::cancel::check("the evaluation of a schedule neighbourhood")?;
    Ok(Neighbourhood {
        current,
        reassign,
        swap,
        rotate,
        complete: !timed_out.load(Ordering::Relaxed),
        evaluated: evaluated.into_inner(),
    })
}

/// One pass of the greedy heuristic over a period of `r_tot` slots, from the posterior `s0`: each
/// slot takes the sensor whose update most reduces the trace of the posterior,
/// `argmax_i ‖L_i⁻¹ c̄_iᵀ P‖_F²` (`P` the slot's prior, `L_iL_iᵀ = I + c̄_iᵀPc̄_i`; ties go to the
/// lower index), except that once the remaining slots are exactly those still owed to sensors
/// below `min_count`, only those sensors may be chosen. Returns the slots and the final posterior.
pub fn greedy_pass(
    disc: &Discretisation,
    s0: &DMatrix<f64>,
    min_count: usize,
) -> Result<(Vec<usize>, DMatrix<f64>)> {
    let r = disc.r_tot;
    let nsens = disc.n_sensors();
    if min_count.saturating_mul(nsens) > r {
        return Err(Error::InvalidInput(format!(
            "{nsens} sensors with at least {min_count} slots each need {} slots, but the period has \
             r_tot = {r}",
            min_count.saturating_mul(nsens)
        )));
    }
    let mut counts = vec![0usize; nsens];
    let mut out = Vec::with_capacity(r);
    let mut s = s0.clone();
    for l in 0..r {
        crate::cancel::check("the greedy scheduling pass")?;
        let p = disc.predict(&s);
        let deficit: usize = counts.iter().map(|&c| min_count.saturating_sub(c)).sum();
        let forced = r - l <= deficit;
        let mut best = (f64::NEG_INFINITY, usize::MAX);
        for i in 0..nsens {
            if forced && counts[i] >= min_count {
                continue;
            }
            let c = &disc.cbar[i];
            let cp = c.tr_mul(&p);
            let mut sm = &cp * c;
            for k in 0..sm.nrows() {
                sm[(k, k)] += 1.0;
            }
            let chol = crate::linalg::dense::symmetrize(&sm)
                .cholesky()
                .ok_or_else(|| {
                    Error::SingularProblem("I + c̄ᵀPc̄ is not positive definite".into())
                })?;
            let v = chol
                .l()
                .solve_lower_triangular(&cp)
                .ok_or_else(|| Error::SingularProblem("singular Cholesky factor".into()))?;
            let gain = v.norm_squared();
            if gain > best.0 {
                best = (gain, i);
            }
        }
        let i = best.1;
        counts[i] += 1;
        out.push(i);
        s = disc.update(i, &p)?;
    }
    Ok((out, s))
}
