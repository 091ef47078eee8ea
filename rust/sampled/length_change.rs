//! The screen of the moves that change the length of a slot (sample costs): a reassignment
//! between sensors of different costs changes slot `l`'s prior (the prediction over the new
//! length, `P_l^{(j)} = E_j S_{l−1} E_jᵀ + H_j`) and the idle tail at the end of the period
//! (longer by `b_i − b_j` units), and an exchange of adjacent slots of different lengths changes
//! both slots. Each local change is computed exactly and propagated linearly by the adjoint of
//! [`super::sensitivity`]: `⟨μ_l, P_l^{(j)} − P_l⟩ + g_i(P_l) − g_j(P_l^{(j)}) + ⟨Λ_B, δB⟩` for a
//! reassignment (`Λ_B` the adjoint at the period boundary without a direct source at the last
//! posterior, `δB` the change of the boundary covariance by the new tail), and
//! `⟨μ_{l+1}, S'_{l+1} − S_{l+1}⟩` for an exchange (plus, for the average, the change of slot
//! `l`'s own posterior).

use super::sensitivity::{Adjoint, Orbit};
use super::{Discretisation, Triplet};
use crate::Result;
use nalgebra::DMatrix;

/// What a reassignment between sensors of different slot lengths changes besides the update:
/// slot `l`'s prior (the prediction over the new length) and the idle tail (longer or shorter
/// by the difference of the costs), both exact, their propagation linear.
pub(super) struct Unequal {
    /// `priors[l][k]`: slot `l`'s prior over the length of class `k` (`None`: its own).
    priors: Vec<Vec<Option<DMatrix<f64>>>>,
    /// `shift[l][j]`: `⟨μ_l, P_l^{(j)} − P_l⟩`.
    shift: Vec<Vec<f64>>,
    /// `tail[k][m]` (by class representatives): `⟨Λ_B, δB⟩`, the change of the boundary when
    /// the idle time grows by `b_k − b_m` units.
    tail: Vec<Vec<f64>>,
    /// The representative sensor of each sensor's length class.
    class: Vec<usize>,
}

impl Unequal {
    pub(super) fn new(
        disc: &Discretisation,
        slots: &[usize],
        orbit: &Orbit,
        sigma: &DMatrix<f64>,
        adj: &Adjoint,
        tail: Option<&Triplet>,
    ) -> Result<Self> {
        let nsens = disc.n_sensors();
        let class: Vec<usize> = (0..nsens)
            .map(|j| (0..=j).find(|&k| disc.same_length(k, j)).expect("j itself"))
            .collect();
        let r = slots.len();
        if disc.unit_costs() || class.iter().all(|&k| k == 0) {
            return Ok(Unequal {
                priors: Vec::new(),
                shift: Vec::new(),
                tail: Vec::new(),
                class,
            });
        }
        let reps: Vec<usize> = (0..nsens).filter(|&j| class[j] == j).collect();
        let mut priors = vec![vec![None; nsens]; r];
        let mut shift = vec![vec![0.0; nsens]; r];
        for l in 0..r {
            crate::cancel::check("the screening of a schedule neighbourhood")?;
            let prev = if l == 0 { sigma } else { &orbit.posts[l - 1] };
            for &k in &reps {
                if disc.same_length(k, slots[l]) {
                    continue;
                }
                let p = disc.predict_for(k, prev);
                let d = adj.mus[l].dot(&(&p - &orbit.priors[l]));
                for j in (0..nsens).filter(|&j| class[j] == k) {
                    shift[l][j] = d;
                }
                priors[l][k] = Some(p);
            }
        }
        let last = orbit.posts.last().expect("a schedule has a slot");
        let now = disc.finish(tail, last);
        let used = disc.used(slots);
        let mut tails = vec![vec![0.0; nsens]; nsens];
        for &i in &reps {
            for &j in &reps {
                if i == j {
                    continue;
                }
                tails[i][j] = match disc.idle(used - disc.costs[i] + disc.costs[j]) {
                    Ok(idle) => {
                        let t = disc.idle_triplet(idle)?;
                        adj.lambda_b.dot(&(disc.finish(t.as_ref(), last) - &now))
                    }
                    Err(_) => f64::INFINITY,
                };
            }
        }
        Ok(Unequal {
            priors,
            shift,
            tail: tails,
            class,
        })
    }

    /// Slot `l`'s prior over sensor `j`'s length.
    pub(super) fn prior<'a>(&'a self, l: usize, j: usize, orbit: &'a Orbit) -> &'a DMatrix<f64> {
        match self.priors.get(l).and_then(|p| p[self.class[j]].as_ref()) {
            Some(p) => p,
            None => &orbit.priors[l],
        }
    }

    /// The screen of slot `l` going from sensor `i` to `j` (lengths differ) besides the gains.
    pub(super) fn shift(&self, l: usize, i: usize, j: usize) -> f64 {
        self.shift[l][j] + self.tail[self.class[i]][self.class[j]]
    }
}

/// The screen of exchanging slots `l` (sensor `a`) and `l + 1` (sensor `b`) of different
/// lengths: both slots recomputed exactly (`b` first, then `a`; together they last as long as
/// before), `⟨μ_{l+1}, S'_{l+1} − S_{l+1}⟩`, plus for the average the change of slot `l`'s own
/// posterior.
#[allow(clippy::too_many_arguments)]
pub(super) fn unequal_swap(
    disc: &Discretisation,
    orbit: &Orbit,
    sigma: &DMatrix<f64>,
    l: usize,
    a: usize,
    b: usize,
    mu1: &DMatrix<f64>,
    average: bool,
    w: f64,
) -> Result<f64> {
    let prev = if l == 0 { sigma } else { &orbit.posts[l - 1] };
    let sb = disc.slot_map(b, prev)?;
    let sa = disc.slot_map(a, &sb)?;
    let mut v = mu1.dot(&(&sa - &orbit.posts[l + 1]));
    if average {
        v += w * (disc.weighted_trace(&sb) - orbit.post_traces[l]);
    }
    Ok(v)
}
