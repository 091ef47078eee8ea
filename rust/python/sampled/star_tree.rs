//! The star-product tree a `SampledModel` keeps between the search kernels' calls, and the
//! pending candidate: `screen` builds (or moves) the tree of its schedule, whose segments — the
//! star products of runs of consecutive slot maps — `candidate_costs` reuses for every candidate
//! (only the segments a candidate changes are recomposed, `crate::sampled::star_tree`); the
//! cheapest candidate's recomposed segments and steady state are kept, so that the screen of the
//! accepted candidate neither recomposes nor doubles again. Results never depend on what is kept:
//! the tree of a schedule is a pure function of `(A, Q, [ĉ_i], tau, r_tot, slots)`.

use super::args::SearchArgs;
use super::model::PySampledModel;
use crate::sampled::search::{CountLimits, Objective, SteadyCost};
use crate::sampled::sensitivity::{screen_at_until, screen_with_until, Screen};
use crate::sampled::star_tree::{candidate_costs, past, CandidateCosts, Delta, StarTree};
use crate::sampled::Discretisation;
use crate::Error;
use std::time::Instant;

/// A star-product tree's key: `(tau, budget)` as bits and the schedule's length.
type TreeKey = (u64, u64, usize);

/// The star-product tree of the last schedule screened.
pub(super) type CachedTree = Option<(TreeKey, StarTree)>;

/// The cheapest candidate of the last `candidate_costs` on the kept tree: the tree's schedule
/// then (`base`), the candidate, the segments it recomposed and its steady state — so that the
/// screen of the accepted candidate neither recomposes nor doubles again.
pub(super) struct Pending {
    key: TreeKey,
    base: Vec<usize>,
    slots: Vec<usize>,
    delta: Delta,
    steady: SteadyCost,
}

impl PySampledModel {
    fn pending_lock(&self) -> std::sync::MutexGuard<'_, Option<Pending>> {
        self.pending.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The screen of `slots` when they are the pending cheapest candidate of the last
    /// `candidate_costs` on the kept tree: the tree adopts its segments and its steady state is
    /// reused. `None` otherwise (the pending candidate is dropped either way).
    fn screen_pending(
        &self,
        disc: &Discretisation,
        tau: f64,
        slots: &[usize],
        obj: Objective,
        limits: &CountLimits,
        deadline: Option<Instant>,
    ) -> Option<crate::Result<Option<Screen>>> {
        let key = (tau.to_bits(), disc.budget.to_bits(), slots.len());
        let p = self.pending_lock().take()?;
        let mut guard = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        match guard.as_mut() {
            Some((k, tree))
                if *k == key && p.key == key && p.slots == slots && tree.slots() == p.base =>
            {
                tree.adopt(slots, p.delta);
                let st = &p.steady;
                Some(screen_at_until(
                    disc,
                    slots,
                    &st.sigma,
                    &st.monodromy,
                    st.rho,
                    obj,
                    limits,
                    deadline,
                ))
            }
            _ => None,
        }
    }

    /// Runs `f` on the star-product tree of `(tau, slots)`: the kept tree moved to `slots` when
    /// it was made for the same `(tau, r_tot)`, else a new one (kept for the next call). A tree
    /// whose update failed half-way (or reached `deadline`: `Error::Interrupted`, see
    /// `star_tree::check_deadline`) is dropped, never reused.
    fn with_tree<T>(
        &self,
        disc: &Discretisation,
        tau: f64,
        slots: &[usize],
        deadline: Option<Instant>,
        f: impl FnOnce(&StarTree) -> crate::Result<T>,
    ) -> crate::Result<T> {
        let key = (tau.to_bits(), disc.budget.to_bits(), slots.len());
        let mut guard = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        let tree = match guard.take() {
            Some((k, mut t)) if k == key => {
                t.update_until(disc, slots, deadline)?;
                t
            }
            _ => StarTree::new_until(disc, slots, deadline)?.ok_or_else(|| {
                Error::Interrupted("the time limit of the schedule search".into())
            })?,
        };
        let out = f(&tree);
        *guard = Some((key, tree));
        out
    }

    /// The [`Screen`] of `slots` (the work of `SampledModel.screen`, off the GIL): from the
    /// pending candidate when `slots` are it (see [`Self::screen_pending`]), else on the kept tree
    /// moved to `slots` (see [`Self::with_tree`]). `None` once the deadline has passed.
    pub(super) fn screen_kept(
        &self,
        tau: f64,
        slots: &[usize],
        budget: Option<f64>,
        SearchArgs {
            obj,
            opts,
            deadline,
        }: SearchArgs,
        limits: &CountLimits,
    ) -> crate::Result<Option<Screen>> {
        let disc = self.disc_for(tau, slots, budget)?;
        disc.check_schedule(slots)?;
        if let Some(sc) = self.screen_pending(&disc, tau, slots, obj, limits, deadline) {
            return sc;
        }
        let sc = past(self.with_tree(&disc, tau, slots, deadline, |tree| {
            screen_with_until(
                &disc,
                slots,
                &tree.root(&disc)?,
                obj,
                limits,
                &opts,
                deadline,
            )
        }))?;
        Ok(sc.flatten())
    }

    /// The [`CandidateCosts`] of `cands` (the work of `SampledModel.candidate_costs`, off the
    /// GIL), all of the length of `first`, the first of them (whose budget is the call's without
    /// `budget`): on the kept tree when it was made for the same `(tau, budget, length)` — its
    /// cheapest candidate then becomes the pending one — else on a new tree of `first` (not
    /// kept; no candidate is pending).
    pub(super) fn candidate_costs_kept(
        &self,
        tau: f64,
        first: &[usize],
        cands: &[Vec<usize>],
        budget: Option<f64>,
        SearchArgs {
            obj,
            opts,
            deadline,
        }: SearchArgs,
        incumbent: Option<f64>,
    ) -> crate::Result<CandidateCosts> {
        let r = first.len();
        let disc = self.disc_for(tau, first, budget)?;
        let key = (tau.to_bits(), disc.budget.to_bits(), r);
        let guard = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        let mut cc = match &*guard {
            Some((k, tree)) if *k == key => {
                let mut cc = candidate_costs(&disc, tree, cands, obj, &opts, deadline, incumbent)?;
                *self.pending_lock() = cc.best.take().map(|(j, delta, steady)| Pending {
                    key,
                    base: tree.slots().to_vec(),
                    slots: cands[j].clone(),
                    delta,
                    steady,
                });
                cc
            }
            _ => {
                drop(guard);
                *self.pending_lock() = None;
                let tree = StarTree::new(&disc, first)?;
                candidate_costs(&disc, &tree, cands, obj, &opts, deadline, incumbent)?
            }
        };
        cc.best = None;
        Ok(cc)
    }
}
