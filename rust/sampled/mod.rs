//! The sampled system at a finite period `τ` (Section II of the paper), with sample costs.
//!
//! The channel carries a budget of `B` channel units per period `τ`; one unit lasts `τ₀ = τ/B`.
//! A sample of sensor `i` costs `b_i` units (default 1): its slot lasts `b_i τ₀`, over which the
//! state `dx = A x dt + G dw` moves by Van Loan's discretisation `x ← E_i x + w`,
//! `E_i = e^{A b_i τ₀}`, `w ~ N(0, H_i)`, `H_i = ∫₀^{b_i τ₀} e^{As} Q e^{Aᵀs} ds`, `Q = G Gᵀ`,
//! then sensor `i` delivers `y = c̄_iᵀ x + v`, `v ~ N(0, I)`. A schedule `R_1 … R_L` uses
//! `Σ_l b_{R_l} ≤ B` units; the rest of the period is idle (a prediction without update, the
//! *tail*; [`discretisation`]). With unit costs and `B = L` this is the paper's channel of
//! `r_tot = L` slots, computed exactly as before costs existed. With an error weight `M` every
//! cost is `tr(M Σ)`.
//!
//! **Scaling.** `c̄_i = ĉ_i √τ` with `τ` the *period* (the paper's eq. (barc)). Then `r_i`, the
//! number of slots of sensor `i` per period, is exactly the rate of the fast-sampling problem: one
//! period moves the covariance by `τ[AΣ + ΣAᵀ − Σ(Σᵢ r_i ĉ_iĉ_iᵀ)Σ + Q] + O(τ²)`, so the periodic
//! steady state tends to the stabilising solution of `AΣ + ΣAᵀ − Σ W(r) Σ + Q = 0` with
//! `W(r) = Σᵢ r_i ĉ_iĉ_iᵀ` — the cost `η(r)` of the network model with `r = counts`.
//!
//! **Slot map.** `φ_i(S) = ((E_i S E_iᵀ + H_i)⁻¹ + c̄_ic̄_iᵀ)⁻¹` (posterior to posterior), the
//! period map `Φ_R = T ∘ φ_{R_L} ∘ … ∘ φ_{R_1}` (`T` the idle tail, the identity without idle
//! time) and its fixed point `Σ(∞; τ, R)`: the covariance at the period boundary, just after the
//! update of the last slot (and the tail).
//!
//! **Algorithm.** Each slot map is a Riccati triplet ([`triplet`]); the period is their star
//! product; doubling (`t ← t ⋆ t`, [`doubling`]) reaches `Σ(∞; τ, R)` in `O(log(periods))` steps;
//! the posteriors after every slot follow by applying the slot maps once around the period in
//! Joseph form. [`existence`] checks the hypotheses of Proposition 1; [`search`] evaluates the
//! neighbourhoods used by schedule optimisation and the greedy baseline; [`sensitivity`] screens
//! them by the first-order change of the cost (an adjoint Stein equation) and [`star_tree`]
//! costs the screened candidates exactly, reusing the unchanged segments of the period, each
//! doubling cut short once it proves the candidate dearer than the incumbent ([`pruned`]).

pub mod discretisation;
pub mod doubling;
pub mod exact_dfs;
pub mod existence;
mod gains;
mod length_change;
pub mod pruned;
pub mod search;
pub mod sensitivity;
pub mod star_tree;
pub mod triplet;

#[cfg(test)]
mod cost_tests;
#[cfg(test)]
mod exact_tests;
#[cfg(test)]
mod screen_tests;
#[cfg(test)]
mod speed_tests;
#[cfg(test)]
mod tests;

use crate::linalg::dense::{check_finite, check_shape, check_square, check_symmetric, symmetrize};
use crate::{Error, Result};
pub use discretisation::Discretisation;
use nalgebra::DMatrix;
pub use triplet::Triplet;

/// Hard ceiling on the slots per period `r_tot` (a schedule of `r_tot` slots, and `2 r_tot`
/// triplets per neighbourhood of the search). The Python layer refuses far smaller periods by
/// default (`capalloc_rs.limits.MAX_SLOTS_PER_PERIOD`); this bound protects the core whatever
/// that setting.
pub const MAX_SLOTS_PER_PERIOD: usize = 1 << 24;

/// The continuous-time network seen by a sampled channel: `A` (n×n), `Q = GGᵀ` (n×n, symmetric
/// positive semidefinite) and the sensors `ĉ_i` (n×p_i, unit measurement noise).
#[derive(Debug, Clone)]
pub struct SampledSystem {
    a: DMatrix<f64>,
    q: DMatrix<f64>,
    sensors: Vec<DMatrix<f64>>,
    costs: Vec<f64>,
    weight: Option<DMatrix<f64>>,
}

impl SampledSystem {
    /// Validates shapes and finiteness; `Q` must be symmetric.
    pub fn new(a: DMatrix<f64>, q: DMatrix<f64>, sensors: Vec<DMatrix<f64>>) -> Result<Self> {
        let n = check_square("A", &a)?;
        check_shape("Q", &q, n, n)?;
        check_finite("A", &a)?;
        check_finite("Q", &q)?;
        check_symmetric("Q", &q, 1e-10)?;
        if sensors.is_empty() {
            return Err(Error::Shape("at least one sensor is needed".into()));
        }
        for (i, c) in sensors.iter().enumerate() {
            if c.nrows() != n || c.ncols() == 0 {
                return Err(Error::Shape(format!(
                    "sensor {i} must be an n×p matrix with n = {n} and p ≥ 1, got {}×{}",
                    c.nrows(),
                    c.ncols()
                )));
            }
            check_finite(&format!("sensor {i}"), c)?;
        }
        let q = symmetrize(&q);
        let costs = vec![1.0; sensors.len()];
        Ok(SampledSystem {
            a,
            q,
            sensors,
            costs,
            weight: None,
        })
    }

    /// The same system with sample costs `b_i > 0` (channel units per sample of sensor `i`;
    /// default 1 each): a sample of sensor `i` then occupies `b_i` channel units of the period.
    pub fn with_costs(mut self, costs: Vec<f64>) -> Result<Self> {
        if costs.len() != self.n_sensors() {
            return Err(Error::Shape(format!(
                "costs must have one entry per sensor ({}), got {}",
                self.n_sensors(),
                costs.len()
            )));
        }
        if let Some((i, b)) = costs
            .iter()
            .enumerate()
            .find(|(_, b)| !(b.is_finite() && **b > 0.0))
        {
            return Err(Error::InvalidInput(format!(
                "costs[{i}] = {b}: a sample cost must be positive and finite"
            )));
        }
        self.costs = costs;
        Ok(self)
    }

    /// The same system with the error weight `M` (n×n, symmetric positive semidefinite): the
    /// costs become `tr(M Σ)`. `None`: the plain trace.
    pub fn with_weight(mut self, weight: Option<DMatrix<f64>>) -> Result<Self> {
        if let Some(m) = &weight {
            let n = self.order();
            check_shape("weight", m, n, n)?;
            check_finite("weight", m)?;
            check_symmetric("weight", m, 1e-10)?;
        }
        self.weight = weight.map(|m| symmetrize(&m));
        Ok(self)
    }

    /// The sample cost `b_i` of every sensor (channel units per sample).
    pub fn costs(&self) -> &[f64] {
        &self.costs
    }

    /// The error weight `M` (`None`: the plain trace).
    pub fn weight(&self) -> Option<&DMatrix<f64>> {
        self.weight.as_ref()
    }

    /// The channel units a schedule uses, `Σ_l b_{R_l}` (summed in slot order).
    pub fn used(&self, slots: &[usize]) -> f64 {
        slots.iter().map(|&i| self.costs[i]).sum()
    }

    /// State dimension `n`.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// Number of sensors `N`.
    pub fn n_sensors(&self) -> usize {
        self.sensors.len()
    }

    /// The drift matrix `A`.
    pub fn a(&self) -> &DMatrix<f64> {
        &self.a
    }

    /// The noise intensity `Q`.
    pub fn q(&self) -> &DMatrix<f64> {
        &self.q
    }

    /// The sensor matrices `ĉ_i`.
    pub fn sensors(&self) -> &[DMatrix<f64>] {
        &self.sensors
    }

    /// Checks a schedule (sensor index per slot): non-empty, every index below `N`.
    pub fn check_schedule(&self, slots: &[usize]) -> Result<()> {
        if slots.is_empty() {
            return Err(Error::InvalidInput(
                "the schedule must have at least one slot".into(),
            ));
        }
        if slots.len() > MAX_SLOTS_PER_PERIOD {
            return Err(Error::InvalidInput(format!(
                "the schedule has {} slots, more than the limit {MAX_SLOTS_PER_PERIOD} \
                 (capalloc::sampled::MAX_SLOTS_PER_PERIOD)",
                slots.len()
            )));
        }
        if let Some((l, &i)) = slots
            .iter()
            .enumerate()
            .find(|(_, &i)| i >= self.n_sensors())
        {
            return Err(Error::InvalidInput(format!(
                "slot {l} names sensor {i}, but the network has {} sensors (indices 0..{})",
                self.n_sensors(),
                self.n_sensors()
            )));
        }
        Ok(())
    }

    /// Van Loan's discretisation for a period `tau` of `r_tot` unit-cost slots: the budget
    /// `B = r_tot` channel units (see [`Self::discretise_budget`]).
    pub fn discretise(&self, tau: f64, r_tot: usize) -> Result<Discretisation> {
        if r_tot == 0 {
            return Err(Error::InvalidInput(
                "r_tot (slots per period) must be at least 1".into(),
            ));
        }
        if r_tot > MAX_SLOTS_PER_PERIOD {
            return Err(Error::InvalidInput(format!(
                "r_tot = {r_tot} slots per period exceeds the limit {MAX_SLOTS_PER_PERIOD} \
                 (capalloc::sampled::MAX_SLOTS_PER_PERIOD)"
            )));
        }
        Discretisation::new(self, tau, r_tot as f64)
    }

    /// Van Loan's discretisation for a period `tau` carrying `budget` channel units: one unit
    /// lasts `τ₀ = τ/B`, a sample of sensor `i` occupies `b_i τ₀` (one `(E, H)` per distinct
    /// cost), and the sensors are scaled to `c̄_i = ĉ_i √τ`.
    pub fn discretise_budget(&self, tau: f64, budget: f64) -> Result<Discretisation> {
        Discretisation::new(self, tau, budget)
    }
}
