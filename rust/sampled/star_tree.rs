//! The period triplet of a schedule as a balanced binary tree of star products, kept between
//! the moves of a schedule search, and the exact costs of schedules near the kept one.
//!
//! The period triplet is `S_{R_r} ⋆ … ⋆ S_{R_1}` (slot triplets composed first to last). Split
//! the slots at `m/2` recursively — exactly the association of [`compose_all`] — and keep the
//! triplet of every segment of three slots or more. A schedule that differs from the kept one in
//! `k` slots then reuses every segment that contains none of them: its period triplet costs about
//! `k · log₂ r_tot` star products instead of `r_tot`, and since the association is the same the
//! result is bit-for-bit the triplet [`compose_all`] would give (so the cost equals
//! [`super::search::schedule_cost`]'s exactly). A rotation changes every slot and costs a full
//! composition.

use super::pruned::{steady_cost_below, Bounded};
use super::search::{Objective, SteadyCost};
use super::triplet::compose_all;
use super::{Discretisation, Triplet};
use crate::sampled::doubling::DoublingOptions;
use crate::{Error, Result};
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// Kept segments recomposed for a candidate: `(node, triplet)`.
pub type Delta = Vec<(usize, Triplet)>;

/// Segments of at most this many slots are not kept (recomposed on demand: one star product).
const UNKEPT: usize = 2;

/// A candidate's segments of at least `PARALLEL_SLOTS` slots, of systems of at least
/// `PARALLEL_ORDER` states, compose their two halves in parallel (`rayon::join`): the one
/// candidate of a screen (N = 100, n = 200: ~1.2 s of star products when most slots changed)
/// then uses both cores.
const PARALLEL_SLOTS: usize = 16;
const PARALLEL_ORDER: usize = 32;

/// The kept segment triplets of one schedule (node `k` has children `2k + 1`, `2k + 2`).
#[derive(Debug, Clone)]
pub struct StarTree {
    slots: Vec<usize>,
    nodes: Vec<Option<Triplet>>,
}

fn mid(lo: usize, hi: usize) -> usize {
    lo + (hi - lo) / 2
}

impl StarTree {
    /// The tree of `slots` (`r_tot − 1` star products, as [`Discretisation::period_triplet`]).
    pub fn new(disc: &Discretisation, slots: &[usize]) -> Result<Self> {
        disc.check_schedule(slots)?;
        let mut tree = StarTree {
            slots: slots.to_vec(),
            nodes: vec![None; 4 * slots.len()],
        };
        let all: Vec<bool> = vec![true; slots.len()];
        tree.rebuild(disc, 0, 0, slots.len(), &all, None)?;
        Ok(tree)
    }

    /// As [`Self::new`], but `Ok(None)` once `deadline` has passed (checked before every star
    /// product).
    pub fn new_until(
        disc: &Discretisation,
        slots: &[usize],
        deadline: Option<Instant>,
    ) -> Result<Option<Self>> {
        disc.check_schedule(slots)?;
        let mut tree = StarTree {
            slots: slots.to_vec(),
            nodes: vec![None; 4 * slots.len()],
        };
        let all: Vec<bool> = vec![true; slots.len()];
        Ok(past(tree.rebuild(disc, 0, 0, slots.len(), &all, deadline))?.map(|()| tree))
    }

    /// The schedule the tree holds.
    pub fn slots(&self) -> &[usize] {
        &self.slots
    }

    /// The period triplet of the schedule held (its slots, then its idle tail if any).
    pub fn root(&self, disc: &Discretisation) -> Result<Triplet> {
        let t = self.compose(disc, &self.slots)?.into_owned();
        disc.close(t, disc.tail(&self.slots)?.as_ref())
    }

    /// Moves the tree to `slots` (same length), recomposing only the segments that changed.
    pub fn update(&mut self, disc: &Discretisation, slots: &[usize]) -> Result<()> {
        self.update_until(disc, slots, None)
    }

    /// As [`Self::update`], but stops with [`Error::Interrupted`] once `deadline` has passed
    /// (checked before every star product; the tree is then half-updated: drop it).
    pub fn update_until(
        &mut self,
        disc: &Discretisation,
        slots: &[usize],
        deadline: Option<Instant>,
    ) -> Result<()> {
        disc.check_schedule(slots)?;
        if slots.len() != self.slots.len() {
            return Err(Error::InvalidInput(format!(
                "the schedule has {} slots, the tree {}",
                slots.len(),
                self.slots.len()
            )));
        }
        let changed: Vec<bool> = slots.iter().zip(&self.slots).map(|(a, b)| a != b).collect();
        self.slots = slots.to_vec();
        self.rebuild(disc, 0, 0, slots.len(), &changed, deadline)
    }

    fn rebuild(
        &mut self,
        disc: &Discretisation,
        node: usize,
        lo: usize,
        hi: usize,
        changed: &[bool],
        deadline: Option<Instant>,
    ) -> Result<()> {
        if hi - lo <= UNKEPT || !changed[lo..hi].iter().any(|&c| c) {
            return Ok(());
        }
        crate::cancel::check("the star-product tree of a schedule")?;
        check_deadline(deadline)?;
        let m = mid(lo, hi);
        self.rebuild(disc, 2 * node + 1, lo, m, changed, deadline)?;
        self.rebuild(disc, 2 * node + 2, m, hi, changed, deadline)?;
        let left = self.segment(disc, 2 * node + 1, lo, m, &self.slots, None, None)?;
        let right = self.segment(disc, 2 * node + 2, m, hi, &self.slots, None, None)?;
        let t = left.then(&right)?;
        self.nodes[node] = Some(t);
        Ok(())
    }

    /// The triplet of `cand[lo..hi]`: the kept one when the segment is unchanged. Every kept
    /// segment recomposed is recorded in `delta` (when given). Past `deadline` (checked before
    /// every kept segment recomposed): [`Error::Interrupted`] (see [`check_deadline`]).
    #[allow(clippy::too_many_arguments)]
    fn segment<'a>(
        &'a self,
        disc: &Discretisation,
        node: usize,
        lo: usize,
        hi: usize,
        cand: &[usize],
        mut delta: Option<&mut Delta>,
        deadline: Option<Instant>,
    ) -> Result<Cow<'a, Triplet>> {
        if hi - lo <= UNKEPT {
            let items: Vec<&Triplet> = cand[lo..hi].iter().map(|&i| &disc.slots[i]).collect();
            return Ok(Cow::Owned(compose_all(&items, disc.order())?));
        }
        if cand[lo..hi] == self.slots[lo..hi] {
            if let Some(t) = &self.nodes[node] {
                return Ok(Cow::Borrowed(t));
            }
        }
        crate::cancel::check("the star-product tree of a schedule")?;
        check_deadline(deadline)?;
        let m = mid(lo, hi);
        let (left, right) = if hi - lo >= PARALLEL_SLOTS && disc.order() >= PARALLEL_ORDER {
            // The two halves on two threads (the same association: the same bits).
            let token = crate::cancel::current();
            let mut parts = delta.as_ref().map(|_| (Delta::new(), Delta::new()));
            let (dl, dr) = match parts.as_mut() {
                Some((a, b)) => (Some(a), Some(b)),
                None => (None, None),
            };
            let (left, right) = rayon::join(
                || {
                    crate::cancel::with_token(token.as_ref(), || {
                        self.segment(disc, 2 * node + 1, lo, m, cand, dl, deadline)
                    })
                },
                || {
                    crate::cancel::with_token(token.as_ref(), || {
                        self.segment(disc, 2 * node + 2, m, hi, cand, dr, deadline)
                    })
                },
            );
            if let (Some(d), Some((a, b))) = (delta.as_deref_mut(), parts) {
                d.extend(a);
                d.extend(b);
            }
            (left?, right?)
        } else {
            let d = delta.as_deref_mut();
            let left = self.segment(disc, 2 * node + 1, lo, m, cand, d, deadline)?;
            let d = delta.as_deref_mut();
            let right = self.segment(disc, 2 * node + 2, m, hi, cand, d, deadline)?;
            (left, right)
        };
        let t = left.then(&right)?;
        if let Some(d) = delta {
            d.push((node, t.clone()));
        }
        Ok(Cow::Owned(t))
    }

    /// The period triplet of `cand` and the kept segments it recomposed: [`Self::adopt`] moves
    /// the tree to `cand` without composing them again.
    pub fn compose_delta(&self, disc: &Discretisation, cand: &[usize]) -> Result<(Triplet, Delta)> {
        self.compose_delta_until(disc, cand, None)
    }

    /// As [`Self::compose_delta`], but [`Error::Interrupted`] once `deadline` has passed
    /// (checked before every kept segment recomposed).
    pub fn compose_delta_until(
        &self,
        disc: &Discretisation,
        cand: &[usize],
        deadline: Option<Instant>,
    ) -> Result<(Triplet, Delta)> {
        self.check_candidate(disc, cand)?;
        let mut delta = Delta::new();
        let t = self
            .segment(disc, 0, 0, cand.len(), cand, Some(&mut delta), deadline)?
            .into_owned();
        Ok((t, delta))
    }

    /// Moves the tree to `slots` given the `delta` that [`Self::compose_delta`] returned for
    /// them on this tree (unchanged since).
    pub fn adopt(&mut self, slots: &[usize], delta: Delta) {
        self.slots = slots.to_vec();
        for (node, t) in delta {
            self.nodes[node] = Some(t);
        }
    }

    fn check_candidate(&self, disc: &Discretisation, cand: &[usize]) -> Result<()> {
        disc.check_schedule(cand)?;
        if cand.len() != self.slots.len() {
            return Err(Error::InvalidInput(format!(
                "the candidate has {} slots, the tree {}",
                cand.len(),
                self.slots.len()
            )));
        }
        Ok(())
    }

    /// The period triplet of `cand` (same length as the tree's schedule), reusing every kept
    /// segment on which `cand` agrees with it.
    pub fn compose<'a>(
        &'a self,
        disc: &Discretisation,
        cand: &[usize],
    ) -> Result<Cow<'a, Triplet>> {
        self.check_candidate(disc, cand)?;
        self.segment(disc, 0, 0, cand.len(), cand, None, None)
    }
}

/// `Err(Error::Interrupted)` once `deadline` has passed: the time limit of a search stops a
/// composition as a cancellation would (the callers turn it into a skipped candidate or an
/// unfinished screen, never into an error of the search).
pub(crate) fn check_deadline(deadline: Option<Instant>) -> Result<()> {
    if deadline.is_some_and(|d| Instant::now() >= d) {
        Err(Error::Interrupted(
            "the time limit of the schedule search".into(),
        ))
    } else {
        Ok(())
    }
}

/// `Ok(None)` for a result stopped by [`check_deadline`] (its deadline passed, no cancellation
/// pending), the result otherwise.
pub(crate) fn past<T>(r: Result<T>) -> Result<Option<T>> {
    match r {
        Err(Error::Interrupted(_)) if !crate::cancel::is_cancelled() => Ok(None),
        r => r.map(Some),
    }
}

/// The exact costs of some schedules near the tree's one.
#[derive(Debug, Clone)]
pub struct CandidateCosts {
    /// The cost of each candidate (`+∞` when its steady state does not exist or it was skipped).
    pub costs: Vec<f64>,
    /// `false` if the deadline passed before every candidate was evaluated.
    pub complete: bool,
    /// How many candidates were costed.
    pub evaluated: usize,
    /// The cheapest candidate with a finite cost: its index, its recomposed segments and its
    /// steady state (for [`StarTree::adopt`] and [`super::sensitivity::screen_at`]).
    pub best: Option<(usize, Delta, SteadyCost)>,
}

type Kept = Mutex<Option<(usize, Delta, SteadyCost)>>;

/// The exact cost of each candidate (doubling of its period triplet composed on `tree`), in
/// parallel; candidates that would start after `deadline` are skipped (`+∞`), and one whose
/// composition reaches the deadline is stopped there (`+∞`, within one star product). With
/// `incumbent = Some(c)` (boundary objective) a candidate whose doubling proves its cost above
/// `c` is cut short and reported `+∞` ([`super::pruned`]): every candidate that could improve on
/// `c` is still costed exactly.
pub fn candidate_costs(
    disc: &Discretisation,
    tree: &StarTree,
    cands: &[Vec<usize>],
    objective: Objective,
    opts: &DoublingOptions,
    deadline: Option<Instant>,
    incumbent: Option<f64>,
) -> Result<CandidateCosts> {
    for c in cands {
        tree.check_candidate(disc, c)?;
    }
    let token = crate::cancel::current();
    let timed_out = AtomicBool::new(false);
    let evaluated = AtomicUsize::new(0);
    let best: Kept = Mutex::new(None);
    let costs: Vec<f64> = cands
        .par_iter()
        .enumerate()
        .map(|(k, c)| {
            if deadline.is_some_and(|d| Instant::now() >= d) {
                timed_out.store(true, Ordering::Relaxed);
                return f64::INFINITY;
            }
            evaluated.fetch_add(1, Ordering::Relaxed);
            let res = crate::cancel::with_token(token.as_ref(), || {
                let (t, delta) = tree.compose_delta_until(disc, c, deadline)?;
                let t = disc.close(t, disc.tail(c)?.as_ref())?;
                Ok::<_, Error>((
                    delta,
                    steady_cost_below(disc, &t, c, objective, opts, incumbent)?,
                ))
            });
            match res {
                Ok((_, Bounded::Above(_))) => f64::INFINITY,
                Ok((delta, Bounded::Costed(sc))) => {
                    let cost = sc.cost;
                    let mut b = best.lock().unwrap_or_else(|e| e.into_inner());
                    // The cheapest, ties to the lowest index (independent of the threads' order).
                    if b.as_ref().is_none_or(|(j, _, s)| (cost, k) < (s.cost, *j)) {
                        *b = Some((k, delta, sc));
                    }
                    cost
                }
                Err(e) => {
                    if matches!(e, Error::Interrupted(_)) && deadline.is_some() {
                        timed_out.store(true, Ordering::Relaxed);
                    }
                    f64::INFINITY
                }
            }
        })
        .collect();
    crate::cancel::check("the exact costs of candidate schedules")?;
    Ok(CandidateCosts {
        costs,
        complete: !timed_out.load(Ordering::Relaxed),
        evaluated: evaluated.into_inner(),
        best: best.into_inner().unwrap_or_else(|e| e.into_inner()),
    })
}
