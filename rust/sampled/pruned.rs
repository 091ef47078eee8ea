//! The exact cost of a candidate schedule, its doubling cut short once it proves the candidate
//! no cheaper than an incumbent cost (a bound, not a guess).
//!
//! From `X = 0` the doubling's iterates are `H_k = Φ^{2^k}(0)` (Φ the candidate's period map).
//! `Φ` is monotone on positive semidefinite matrices (`X ⪯ Y ⇒ Φ(X) ⪯ Φ(Y)`) and
//! `Φ(0) = H ⪰ 0`, so `0 ⪯ H_0 ⪯ H_1 ⪯ … ⪯ Σ(∞)`: with a positive semidefinite weight `M`
//! (or none) every `tr(M H_k)` is a lower bound on the boundary cost `tr(M Σ(∞))`. Once it exceeds
//! the incumbent by more than rounding (relative [`PRUNE_MARGIN`]), the candidate cannot improve
//! on the incumbent and its doubling stops. Only the boundary objective is bounded this way (the
//! average would need the posteriors of every slot at every step).
//!
//! A candidate that is not cut short is costed by exactly the arithmetic of
//! [`super::search::steady_cost`] (same doubling steps, same monodromy): its cost is bit for bit
//! the same.

use super::doubling::{doubling_cut, Doubled, DoublingOptions};
use super::search::{steady_cost, steady_cost_of, Objective, SteadyCost};
use super::{Discretisation, Triplet};
use crate::Result;

/// The lower bound must exceed the incumbent by this relative margin (the rounding of the
/// monotone iterates, far above it) before a candidate is cut short.
pub const PRUNE_MARGIN: f64 = 1e-10;

/// The outcome of [`steady_cost_below`].
#[derive(Debug, Clone)]
pub enum Bounded {
    /// The candidate's exact cost and steady state (as [`steady_cost`]).
    Costed(SteadyCost),
    /// The doubling proved the cost above the incumbent: the lower bound it reached.
    Above(f64),
}

/// As [`steady_cost`], but for the boundary objective with `incumbent = Some(c)` the doubling
/// stops as soon as `tr(M H_k) > c (1 + PRUNE_MARGIN)` ([`Bounded::Above`]).
pub fn steady_cost_below(
    disc: &Discretisation,
    t: &Triplet,
    slots: &[usize],
    objective: Objective,
    opts: &DoublingOptions,
    incumbent: Option<f64>,
) -> Result<Bounded> {
    let bound = match (objective, incumbent) {
        (Objective::Boundary, Some(c)) if c.is_finite() => c + PRUNE_MARGIN * c.abs(),
        _ => {
            return Ok(Bounded::Costed(steady_cost(
                disc, t, slots, objective, opts,
            )?))
        }
    };
    let cut = doubling_cut(t, opts, |h| {
        let lower = disc.weighted_trace(h);
        (lower > bound).then_some(lower)
    })?;
    match cut {
        Doubled::Cut(lower) => Ok(Bounded::Above(lower)),
        Doubled::Converged(d) => Ok(Bounded::Costed(steady_cost_of(
            disc, t, slots, objective, d,
        )?)),
    }
}
