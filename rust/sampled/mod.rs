//! The sampled system at a finite period `τ` (Section II of the paper).
//!
//! The channel carries `r_tot` samples per period `τ`: slot `l = 1, …, r_tot` lasts `τ₀ = τ/r_tot`
//! and carries one sample of sensor `R_l`. Over one slot the state `dx = A x dt + G dw` moves by
//! Van Loan's discretisation `x ← E x + w`, `E = e^{Aτ₀}`, `w ~ N(0, H)`,
//! `H = ∫₀^{τ₀} e^{As} Q e^{Aᵀs} ds`, `Q = G Gᵀ`, then sensor `i = R_l` delivers
//! `y = c̄_iᵀ x + v`, `v ~ N(0, I)`.
//!
//! **Scaling.** `c̄_i = ĉ_i √τ` with `τ` the *period* (the paper's eq. (barc)). Then `r_i`, the
//! number of slots of sensor `i` per period, is exactly the rate of the fast-sampling problem: one
//! period moves the covariance by `τ[AΣ + ΣAᵀ − Σ(Σᵢ r_i ĉ_iĉ_iᵀ)Σ + Q] + O(τ²)`, so the periodic
//! steady state tends to the stabilising solution of `AΣ + ΣAᵀ − Σ W(r) Σ + Q = 0` with
//! `W(r) = Σᵢ r_i ĉ_iĉ_iᵀ` — the cost `η(r)` of the network model with `r = counts`.
//!
//! **Slot map.** `φ_i(S) = ((E S Eᵀ + H)⁻¹ + c̄_ic̄_iᵀ)⁻¹` (posterior to posterior), the period map
//! `Φ_R = φ_{R_{r_tot}} ∘ … ∘ φ_{R_1}` and its fixed point `Σ(∞; τ, R)`: the posterior covariance
//! at the period boundary, just after the update of the last slot.
//!
//! **Algorithm.** Each slot map is a Riccati triplet ([`triplet`]); the period is their star
//! product; doubling (`t ← t ⋆ t`, [`doubling`]) reaches `Σ(∞; τ, R)` in `O(log(periods))` steps;
//! the posteriors after every slot follow by applying the slot maps once around the period in
//! Joseph form. [`existence`] checks the hypotheses of Proposition 1; [`search`] evaluates the
//! neighbourhoods used by schedule optimisation and the greedy baseline; [`sensitivity`] screens
//! them by the first-order change of the cost (an adjoint Stein equation) and [`star_tree`]
//! costs the screened candidates exactly, reusing the unchanged segments of the period.

pub mod doubling;
pub mod existence;
pub mod search;
pub mod sensitivity;
pub mod star_tree;
pub mod triplet;

#[cfg(test)]
mod screen_tests;
#[cfg(test)]
mod tests;

use crate::linalg::dense::{check_finite, check_shape, check_square, check_symmetric, symmetrize};
use crate::linalg::van_loan::van_loan;
use crate::{Error, Result};
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
        Ok(SampledSystem { a, q, sensors })
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

    /// Van Loan's discretisation of one slot for a period `tau` of `r_tot` slots, and the slot
    /// triplet of every sensor.
    pub fn discretise(&self, tau: f64, r_tot: usize) -> Result<Discretisation> {
        if !tau.is_finite() || tau <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "the period tau must be positive and finite, got {tau}"
            )));
        }
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
        let tau0 = tau / r_tot as f64;
        let vl = van_loan(&self.a, &self.q, tau0)?;
        check_finite("e^{Aτ₀}", &vl.e)?;
        check_finite("H", &vl.h)?;
        let sq = tau.sqrt();
        let cbar: Vec<DMatrix<f64>> = self.sensors.iter().map(|c| c * sq).collect();
        let slots = cbar
            .iter()
            .map(|c| Triplet::slot(&vl.e, &vl.h, c))
            .collect::<Result<Vec<_>>>()?;
        Ok(Discretisation {
            tau,
            r_tot,
            e: vl.e,
            h: vl.h,
            cbar,
            slots,
        })
    }
}

/// One slot of a period `τ` with `r_tot` slots: `E = e^{Aτ₀}`, `H = ∫₀^{τ₀} e^{As}Qe^{Aᵀs}ds`,
/// `c̄_i = ĉ_i √τ`, and each sensor's slot triplet (predict over `τ₀`, then update with `c̄_i`).
#[derive(Debug, Clone)]
pub struct Discretisation {
    /// The period `τ`.
    pub tau: f64,
    /// Slots per period.
    pub r_tot: usize,
    /// `e^{Aτ₀}`.
    pub e: DMatrix<f64>,
    /// The process noise of one slot.
    pub h: DMatrix<f64>,
    /// The scaled sensors `c̄_i = ĉ_i √τ`.
    pub cbar: Vec<DMatrix<f64>>,
    /// The slot triplet of each sensor.
    pub slots: Vec<Triplet>,
}

impl Discretisation {
    /// State dimension.
    pub fn order(&self) -> usize {
        self.e.nrows()
    }

    /// Number of sensors.
    pub fn n_sensors(&self) -> usize {
        self.cbar.len()
    }

    /// Checks that `slots` has `r_tot` entries, all below `N`.
    pub fn check_schedule(&self, slots: &[usize]) -> Result<()> {
        if slots.len() != self.r_tot {
            return Err(Error::InvalidInput(format!(
                "the schedule has {} slots but the discretisation was made for r_tot = {}",
                slots.len(),
                self.r_tot
            )));
        }
        if let Some((l, &i)) = slots
            .iter()
            .enumerate()
            .find(|(_, &i)| i >= self.n_sensors())
        {
            return Err(Error::InvalidInput(format!(
                "slot {l} names sensor {i}, but the network has {} sensors",
                self.n_sensors()
            )));
        }
        Ok(())
    }

    /// The prior after the prediction of one slot: `E S Eᵀ + H`.
    pub fn predict(&self, s: &DMatrix<f64>) -> DMatrix<f64> {
        let es = &self.e * s;
        symmetrize(&(&es * self.e.transpose() + &self.h))
    }

    /// The measurement update of sensor `i` in Joseph form: with `S = I + c̄ᵀPc̄` and
    /// `K = P c̄ S⁻¹`, returns `(I − Kc̄ᵀ) P (I − Kc̄ᵀ)ᵀ + K Kᵀ` (= `(P⁻¹ + c̄c̄ᵀ)⁻¹`).
    pub fn update(&self, i: usize, p: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let c = &self.cbar[i];
        let n = p.nrows();
        let pc = p * c;
        let mut s = c.tr_mul(&pc);
        for k in 0..s.nrows() {
            s[(k, k)] += 1.0;
        }
        let chol = symmetrize(&s).cholesky().ok_or_else(|| {
            Error::SingularProblem("innovation covariance I + c̄ᵀPc̄ is not positive definite".into())
        })?;
        let k = chol.solve(&pc.transpose()).transpose();
        let mut ikc = DMatrix::identity(n, n);
        ikc.gemm(-1.0, &k, &c.transpose(), 1.0);
        let mut out = &ikc * p * ikc.transpose();
        out.gemm(1.0, &k, &k.transpose(), 1.0);
        Ok(symmetrize(&out))
    }

    /// One slot map `φ_i(S)`: predict, then update with sensor `i`.
    pub fn slot_map(&self, i: usize, s: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        self.update(i, &self.predict(s))
    }

    /// The period triplet of a schedule (slot triplets composed first to last).
    pub fn period_triplet(&self, slots: &[usize]) -> Result<Triplet> {
        self.check_schedule(slots)?;
        let items: Vec<&Triplet> = slots.iter().map(|&i| &self.slots[i]).collect();
        triplet::compose_all(&items, self.order())
    }
}
