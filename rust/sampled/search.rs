//! Kernels for schedule optimisation: the exact finite-τ cost of every schedule one move away
//! from a given one, and one pass of the greedy sensor-scheduling heuristic.
//!
//! With the prefix compositions `P_l = S_{R_l} ∘ … ∘ S_{R_1}` and suffix compositions
//! `Q_l = S_{R_{r}} ∘ … ∘ S_{R_{l+1}}` of the slot triplets (computed once, `2 r_tot` star
//! products), the period triplet of a schedule that differs in one or two adjacent slots, or is a
//! rotation, costs one to three star products; its steady state then costs one doubling
//! (`≈ log₂(1/(1 − ρ))` star products) instead of `r_tot` slot compositions.

use super::doubling::{average_cost, doubling, monodromy, propagate, Doubling, DoublingOptions};
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

/// The per-sensor limits on the counts of a schedule: `min[i] ≤ k_i ≤ max[i]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CountLimits {
    /// The least number of samples of each sensor per period.
    pub min: Vec<usize>,
    /// The most samples of each sensor per period (`usize::MAX`: no cap).
    pub max: Vec<usize>,
}

impl CountLimits {
    /// `min_count` samples for every one of `n_sensors` sensors, no cap.
    pub fn common(min_count: usize, n_sensors: usize) -> Self {
        CountLimits {
            min: vec![min_count; n_sensors],
            max: vec![usize::MAX; n_sensors],
        }
    }

    /// Checks the lengths (one entry per sensor) and `min ≤ max`.
    pub fn check(&self, n_sensors: usize) -> Result<()> {
        if self.min.len() != n_sensors || self.max.len() != n_sensors {
            return Err(Error::Shape(format!(
                "the count limits must have one entry per sensor ({n_sensors}), got {} minima \
                 and {} maxima",
                self.min.len(),
                self.max.len()
            )));
        }
        if let Some(i) = (0..n_sensors).find(|&i| self.min[i] > self.max[i]) {
            return Err(Error::InvalidInput(format!(
                "sensor {i}: the least count {} exceeds the largest {}",
                self.min[i], self.max[i]
            )));
        }
        Ok(())
    }

    /// Whether slot `l`'s sensor `i` may be replaced by sensor `j`: `j ≠ i`, `i` keeps its
    /// minimum, `j` stays within its cap and the schedule (using `used` channel units) stays
    /// within the budget.
    pub fn reassign_ok(
        &self,
        disc: &Discretisation,
        counts: &[usize],
        used: f64,
        i: usize,
        j: usize,
    ) -> bool {
        if j == i || counts[i] <= self.min[i] || counts[j] >= self.max[j] {
            return false;
        }
        disc.same_length(i, j) || disc.idle(used - disc.costs[i] + disc.costs[j]).is_ok()
    }
}

/// Costs of all schedules one move away from the current one. Moves that are no-ops, that would
/// leave a sensor outside its count limits or the schedule above the budget, or whose steady
/// state fails, cost `+∞`.
#[derive(Debug, Clone)]
pub struct Neighbourhood {
    /// The cost of the current schedule.
    pub current: f64,
    /// `reassign[(l, j)]`: slot `l` given to sensor `j` (moves one slot between two sensors).
    pub reassign: DMatrix<f64>,
    /// `swap[l]`: slots `l` and `l + 1` exchanged (`l = 0, …, r_tot − 2`).
    pub swap: Vec<f64>,
    /// `rotate[k]`: the schedule started at slot `k` (`R_{k+1}, …, R_r, R_1, …, R_k`, the idle
    /// tail still last); `+∞` for the average objective without idle time, which every rotation
    /// leaves unchanged.
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
    steady_cost_of(disc, t, slots, objective, doubling(t, opts)?)
}

/// [`steady_cost`] from the doubling `d` of `t` (its monodromy, the stabilising check, the cost).
pub(crate) fn steady_cost_of(
    disc: &Discretisation,
    t: &Triplet,
    slots: &[usize],
    objective: Objective,
    d: Doubling,
) -> Result<SteadyCost> {
    let (m, rho) = monodromy(t, &d.sigma)?;
    if rho >= 1.0 {
        return Err(Error::Convergence("non-stabilising limit".into()));
    }
    let cost = match objective {
        Objective::Boundary => disc.weighted_trace(&d.sigma),
        Objective::Average => {
            let (_, posts) = propagate(disc, slots, &d.sigma)?;
            average_cost(disc, &posts)
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
    let limits = CountLimits::common(min_count, disc.n_sensors());
    neighbourhood_until(disc, slots, objective, &limits, opts, None)
}

/// The prefix compositions `P_0 = id, P_{l+1} = S_{R_l} ∘ P_l` and suffix compositions of the
/// slot triplets of a schedule.
fn prefix_suffix(disc: &Discretisation, slots: &[usize]) -> Result<(Vec<Triplet>, Vec<Triplet>)> {
    let r = slots.len();
    let n = disc.order();
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
    Ok((prefix, suffix))
}

/// As [`neighbourhood`] with per-sensor count limits (and the budget of the discretisation:
/// reassignments that exceed it cost `+∞`), but candidates whose evaluation would start after
/// `deadline` are skipped (cost `+∞`, [`Neighbourhood::complete`] `false`): a time limit for the
/// schedule search that one large neighbourhood cannot overrun by more than one candidate per
/// thread. With idle time a rotation moves the idle tail relative to the slots, so rotations are
/// costed for the average objective too.
pub fn neighbourhood_until(
    disc: &Discretisation,
    slots: &[usize],
    objective: Objective,
    limits: &CountLimits,
    opts: &DoublingOptions,
    deadline: Option<Instant>,
) -> Result<Neighbourhood> {
    disc.check_schedule(slots)?;
    limits.check(disc.n_sensors())?;
    let r = slots.len();
    let nsens = disc.n_sensors();
    let mut counts = vec![0usize; nsens];
    for &i in slots {
        counts[i] += 1;
    }
    let used = disc.used(slots);
    let tail = disc.tail(slots)?;
    let tr = &disc.slots;
    let (prefix, suffix) = prefix_suffix(disc, slots)?;
    let close = |t: Result<Triplet>| t.and_then(|t| disc.close(t, tail.as_ref()));
    let current = cost_of(
        disc,
        &disc.close(prefix[r].clone(), tail.as_ref())?,
        slots,
        objective,
        opts,
    )?;
    // Candidates run on rayon's threads: hand them this thread's cancellation token. A cancelled
    // candidate costs +∞; the cancellation is reported once all of them have returned.
    let token = crate::cancel::current();
    let timed_out = AtomicBool::new(false);
    let evaluated = AtomicUsize::new(0);
    let eval = |t: &dyn Fn() -> Result<Triplet>, cand: &dyn Fn() -> Vec<usize>| -> f64 {
        if deadline.is_some_and(|d| Instant::now() >= d) {
            timed_out.store(true, Ordering::Relaxed);
            return f64::INFINITY;
        }
        evaluated.fetch_add(1, Ordering::Relaxed);
        crate::cancel::with_token(token.as_ref(), || {
            eval_candidate(disc, objective, opts, t(), cand)
        })
    };
    let rows: Vec<Vec<f64>> = (0..r)
        .into_par_iter()
        .map(|l| {
            (0..nsens)
                .map(|j| {
                    let i = slots[l];
                    if !limits.reassign_ok(disc, &counts, used, i, j) {
                        return f64::INFINITY;
                    }
                    let cand = || {
                        let mut s = slots.to_vec();
                        s[l] = j;
                        s
                    };
                    let compose = || {
                        let t = prefix[l]
                            .then(&tr[j])
                            .and_then(|t| t.then(&suffix[l + 1]))?;
                        if disc.same_length(i, j) {
                            disc.close(t, tail.as_ref())
                        } else {
                            disc.close(t, disc.tail(&cand())?.as_ref())
                        }
                    };
                    eval(&compose, &cand)
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
            let compose = || {
                close(
                    prefix[l]
                        .then(&tr[slots[l + 1]])
                        .and_then(|t| t.then(&tr[slots[l]]))
                        .and_then(|t| t.then(&suffix[l + 2])),
                )
            };
            eval(&compose, &|| {
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
            if objective == Objective::Average && tail.is_none() {
                return f64::INFINITY;
            }
            let compose = || close(suffix[k].then(&prefix[k]));
            if objective == Objective::Average {
                eval(&compose, &|| [&slots[k..], &slots[..k]].concat())
            } else {
                eval(&compose, &Vec::new)
            }
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

/// One pass of the greedy heuristic over a period of `B` channel units (the discretisation's
/// budget), from the posterior `s0`, with at least `min_count` samples of every sensor (see
/// [`greedy_pass_limits`]).
pub fn greedy_pass(
    disc: &Discretisation,
    s0: &DMatrix<f64>,
    min_count: usize,
) -> Result<(Vec<usize>, DMatrix<f64>)> {
    greedy_pass_limits(disc, s0, &CountLimits::common(min_count, disc.n_sensors()))
}

/// The trace reduction `tr(M P c̄ (I + c̄ᵀPc̄)⁻¹ c̄ᵀ P) = ‖L⁻¹ c̄ᵀ P‖²_M` of an update with `c̄` at the
/// prior `P` (`L Lᵀ = I + c̄ᵀPc̄`).
fn update_gain(disc: &Discretisation, p: &DMatrix<f64>, c: &DMatrix<f64>) -> Result<f64> {
    let cp = c.tr_mul(p);
    let mut sm = &cp * c;
    for k in 0..sm.nrows() {
        sm[(k, k)] += 1.0;
    }
    let chol = crate::linalg::dense::symmetrize(&sm)
        .cholesky()
        .ok_or_else(|| Error::SingularProblem("I + c̄ᵀPc̄ is not positive definite".into()))?;
    let v = chol
        .l()
        .solve_lower_triangular(&cp)
        .ok_or_else(|| Error::SingularProblem("singular Cholesky factor".into()))?;
    Ok(match &disc.weight {
        None => v.norm_squared(),
        Some(m) => (&v * m).dot(&v),
    })
}

/// One pass of the greedy heuristic over a period of `B` channel units, from the posterior `s0`:
/// each slot takes, among the sensors whose sample still fits in the budget left and below
/// their cap, the one whose update most reduces the (weighted) trace of the posterior per
/// channel unit, `‖L_i⁻¹ c̄_iᵀ P_i‖²_M / b_i` (`P_i` the prior over sensor `i`'s slot,
/// `L_iL_iᵀ = I + c̄_iᵀP_ic̄_i`; ties go to the lower index) — except that a sensor not owed
/// samples under its minimum may only be chosen if the budget left afterwards still pays for
/// every sample owed. The pass ends when no sample fits (the rest of the period is idle).
/// Returns the slots and the final posterior (before the idle tail). With unit costs and
/// `B = r_tot` this is the pass over `r_tot` slots of the paper's case.
pub fn greedy_pass_limits(
    disc: &Discretisation,
    s0: &DMatrix<f64>,
    limits: &CountLimits,
) -> Result<(Vec<usize>, DMatrix<f64>)> {
    let nsens = disc.n_sensors();
    limits.check(nsens)?;
    let b = &disc.costs;
    let tol = super::discretisation::BUDGET_RTOL * disc.budget;
    let owed_units = |counts: &[usize]| -> f64 {
        (0..nsens)
            .map(|i| limits.min[i].saturating_sub(counts[i]) as f64 * b[i])
            .sum()
    };
    let mut counts = vec![0usize; nsens];
    if owed_units(&counts) > disc.budget + tol {
        return Err(Error::InvalidInput(format!(
            "the sensors' least counts need {} channel units, but the period has a budget of {}",
            owed_units(&counts),
            disc.budget
        )));
    }
    let min_cost = b.iter().copied().fold(f64::INFINITY, f64::min);
    let most = (disc.budget / min_cost + 1.0).min(super::MAX_SLOTS_PER_PERIOD as f64) as usize;
    let mut out = Vec::new();
    let mut s = s0.clone();
    let mut left = disc.budget;
    for _ in 0..most {
        crate::cancel::check("the greedy scheduling pass")?;
        let owed = owed_units(&counts);
        let mut best = (f64::NEG_INFINITY, usize::MAX);
        let mut prior: Vec<Option<DMatrix<f64>>> = vec![None; nsens];
        for i in 0..nsens {
            let spare = if counts[i] < limits.min[i] {
                owed
            } else {
                owed + b[i]
            };
            if counts[i] >= limits.max[i] || left - spare < -tol {
                continue;
            }
            let p = match (0..i).find(|&k| disc.same_length(k, i) && prior[k].is_some()) {
                Some(k) => prior[k].clone().expect("checked"),
                None => disc.predict_for(i, &s),
            };
            let gain = update_gain(disc, &p, &disc.cbar[i])?;
            let gain = if disc.unit_costs() { gain } else { gain / b[i] };
            if gain > best.0 {
                best = (gain, i);
            }
            prior[i] = Some(p);
        }
        let i = best.1;
        if i == usize::MAX {
            break;
        }
        counts[i] += 1;
        out.push(i);
        left -= b[i];
        let p = prior[i].take().expect("the chosen sensor's prior");
        s = disc.update(i, &p)?;
    }
    if out.is_empty() {
        return Err(Error::InvalidInput(format!(
            "no sample fits in the budget of {} channel units",
            disc.budget
        )));
    }
    Ok((out, s))
}
