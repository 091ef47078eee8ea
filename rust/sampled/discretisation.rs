//! Van Loan's discretisation of the slots of a period with sample costs, and the idle tail.
//!
//! The period `τ` carries a budget of `B` channel units; one unit lasts `τ₀ = τ/B`. A sample of
//! sensor `i` costs `b_i` units: its slot lasts `b_i τ₀`, over which the state moves by
//! `x ← E_i x + w`, `E_i = e^{A b_i τ₀}`, `w ~ N(0, H_i)`, `H_i = ∫₀^{b_i τ₀} e^{As}Qe^{Aᵀs}ds`
//! (one pair per distinct cost), then sensor `i` delivers `y = c̄_iᵀx + v`, `v ~ N(0, I)`,
//! `c̄_i = ĉ_i √τ` (a sample's noise does not depend on its length). A schedule `R_1 … R_L`
//! uses `U = Σ_l b_{R_l} ≤ B` units; the rest `(B − U) τ₀` of the period is idle channel time at
//! its end: the prediction triplet `(E_T, 0, H_T)` over that time, no update (the *tail*).
//!
//! With unit costs and `B = L` (the paper's case) there is one `(E, H)` over `τ₀ = τ/L`, no tail,
//! and every number is computed exactly as before sample costs existed.

use super::{SampledSystem, Triplet, MAX_SLOTS_PER_PERIOD};
use crate::linalg::dense::{check_finite, matmul, matmul_nt, symmetrize};
use crate::linalg::van_loan::van_loan;
use crate::{Error, Result};
use nalgebra::DMatrix;
use std::sync::{Arc, Mutex};

/// Relative tolerance of the budget: a schedule may use up to `B (1 + BUDGET_RTOL)` units, and
/// idle time below `BUDGET_RTOL · B` units is no idle time (rounding of the sum of the costs).
pub const BUDGET_RTOL: f64 = 1e-12;

/// The discretisation of a period: the slot of every sensor and what is needed for the tail.
#[derive(Debug, Clone)]
pub struct Discretisation {
    /// The period `τ`.
    pub tau: f64,
    /// The budget `B` (channel units per period).
    pub budget: f64,
    /// One channel unit, `τ₀ = τ/B`.
    pub tau0: f64,
    /// `e^{Aτ₀}` (one channel unit).
    pub e: DMatrix<f64>,
    /// The process noise of one channel unit.
    pub h: DMatrix<f64>,
    /// The scaled sensors `c̄_i = ĉ_i √τ`.
    pub cbar: Vec<DMatrix<f64>>,
    /// The slot triplet of each sensor (predict over `b_i τ₀`, then update with `c̄_i`).
    pub slots: Vec<Triplet>,
    /// The sample cost `b_i` of each sensor.
    pub costs: Vec<f64>,
    /// The error weight `M` (`None`: the plain trace).
    pub weight: Option<DMatrix<f64>>,
    /// `(E_k, H_k)` per distinct cost.
    steps: Vec<(DMatrix<f64>, DMatrix<f64>)>,
    /// The index into `steps` of each sensor.
    step_of: Vec<usize>,
    /// Whether every cost is 1.
    unit: bool,
    a: DMatrix<f64>,
    q: DMatrix<f64>,
    /// The idle tails computed so far, by the bits of their idle time (at most `TAILS_KEPT`).
    tails: Arc<Mutex<Vec<(u64, Triplet)>>>,
}

/// Idle tails kept per discretisation (a search meets one per distinct sum of costs).
const TAILS_KEPT: usize = 64;

impl Discretisation {
    /// The discretisation of `sys` for a period `tau` of `budget` channel units.
    pub fn new(sys: &SampledSystem, tau: f64, budget: f64) -> Result<Self> {
        if !tau.is_finite() || tau <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "the period tau must be positive and finite, got {tau}"
            )));
        }
        if !budget.is_finite() || budget <= 0.0 {
            return Err(Error::InvalidInput(format!(
                "the budget (channel units per period) must be positive and finite, got {budget}"
            )));
        }
        let costs = sys.costs().to_vec();
        let min_cost = costs.iter().copied().fold(f64::INFINITY, f64::min);
        if budget / min_cost > MAX_SLOTS_PER_PERIOD as f64 {
            return Err(Error::InvalidInput(format!(
                "a budget of {budget} channel units allows more than {MAX_SLOTS_PER_PERIOD} \
                 samples of cost {min_cost} per period (capalloc::sampled::MAX_SLOTS_PER_PERIOD)"
            )));
        }
        let tau0 = tau / budget;
        let vl = van_loan(sys.a(), sys.q(), tau0)?;
        check_finite("e^{Aτ₀}", &vl.e)?;
        check_finite("H", &vl.h)?;
        let unit = costs.iter().all(|&b| b == 1.0);
        let mut lengths: Vec<f64> = Vec::new();
        let mut steps: Vec<(DMatrix<f64>, DMatrix<f64>)> = Vec::new();
        let mut step_of = Vec::with_capacity(costs.len());
        for &b in &costs {
            if let Some(k) = lengths.iter().position(|&x| x == b) {
                step_of.push(k);
                continue;
            }
            let (e, h) = if b == 1.0 {
                (vl.e.clone(), vl.h.clone())
            } else {
                let v = van_loan(sys.a(), sys.q(), b * tau0)?;
                check_finite("e^{A b τ₀}", &v.e)?;
                check_finite("H", &v.h)?;
                (v.e, v.h)
            };
            step_of.push(steps.len());
            lengths.push(b);
            steps.push((e, h));
        }
        let sq = tau.sqrt();
        let cbar: Vec<DMatrix<f64>> = sys.sensors().iter().map(|c| c * sq).collect();
        let slots = cbar
            .iter()
            .zip(&step_of)
            .map(|(c, &k)| Triplet::slot(&steps[k].0, &steps[k].1, c))
            .collect::<Result<Vec<_>>>()?;
        Ok(Discretisation {
            tau,
            budget,
            tau0,
            e: vl.e,
            h: vl.h,
            cbar,
            slots,
            costs,
            weight: sys.weight().cloned(),
            steps,
            step_of,
            unit,
            a: sys.a().clone(),
            q: sys.q().clone(),
            tails: Arc::new(Mutex::new(Vec::new())),
        })
    }

    /// State dimension.
    pub fn order(&self) -> usize {
        self.e.nrows()
    }

    /// Number of sensors.
    pub fn n_sensors(&self) -> usize {
        self.cbar.len()
    }

    /// Whether every sample costs one channel unit.
    pub fn unit_costs(&self) -> bool {
        self.unit
    }

    /// Whether sensors `i` and `j` have slots of the same length (the same `(E, H)`).
    pub fn same_length(&self, i: usize, j: usize) -> bool {
        self.step_of[i] == self.step_of[j]
    }

    /// `E_i = e^{A b_i τ₀}`, the transition over a slot of sensor `i`.
    pub fn e_of(&self, i: usize) -> &DMatrix<f64> {
        &self.steps[self.step_of[i]].0
    }

    /// `H_i`, the process noise over a slot of sensor `i`.
    pub fn h_of(&self, i: usize) -> &DMatrix<f64> {
        &self.steps[self.step_of[i]].1
    }

    /// The channel units a schedule uses, `Σ_l b_{R_l}` (summed in slot order).
    pub fn used(&self, slots: &[usize]) -> f64 {
        slots.iter().map(|&i| self.costs[i]).sum()
    }

    /// The idle channel units `B − U` of a schedule using `used` units: `0` below the
    /// tolerance `BUDGET_RTOL · B`; an error above the budget.
    pub fn idle(&self, used: f64) -> Result<f64> {
        let idle = self.budget - used;
        let tol = BUDGET_RTOL * self.budget;
        if idle < -tol {
            return Err(Error::InvalidInput(format!(
                "the schedule uses {used} channel units per period, more than the budget {}",
                self.budget
            )));
        }
        Ok(if idle <= tol { 0.0 } else { idle })
    }

    /// `tr(M S)` (`tr S` without a weight).
    pub fn weighted_trace(&self, s: &DMatrix<f64>) -> f64 {
        match &self.weight {
            None => s.trace(),
            Some(m) => m.dot(s),
        }
    }

    /// Checks a schedule: non-empty, every index below `N`, within the budget.
    pub fn check_schedule(&self, slots: &[usize]) -> Result<()> {
        if slots.is_empty() {
            return Err(Error::InvalidInput(
                "the schedule must have at least one slot".into(),
            ));
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
        self.idle(self.used(slots)).map(|_| ())
    }

    /// The prediction over `idle` channel units, `(E_T, 0, H_T)`; `None` for no idle time.
    /// Kept once computed (a pure function of `idle`: the cache never changes a result).
    pub fn idle_triplet(&self, idle: f64) -> Result<Option<Triplet>> {
        if idle == 0.0 {
            return Ok(None);
        }
        let key = idle.to_bits();
        let lock = || self.tails.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, t)) = lock().iter().find(|(k, _)| *k == key) {
            return Ok(Some(t.clone()));
        }
        let v = van_loan(&self.a, &self.q, idle * self.tau0)?;
        check_finite("e^{A T}", &v.e)?;
        check_finite("H_T", &v.h)?;
        let t = Triplet::predict(&v.e, &v.h);
        let mut kept = lock();
        if kept.len() < TAILS_KEPT {
            kept.push((key, t.clone()));
        }
        Ok(Some(t))
    }

    /// The tail of a schedule: the prediction over its idle time (`None`: no idle time).
    pub fn tail(&self, slots: &[usize]) -> Result<Option<Triplet>> {
        self.idle_triplet(self.idle(self.used(slots))?)
    }

    /// The period triplet from the composition `t` of the slot triplets: `t` followed by the
    /// tail (unchanged without idle time).
    pub fn close(&self, t: Triplet, tail: Option<&Triplet>) -> Result<Triplet> {
        match tail {
            None => Ok(t),
            Some(tl) => t.then(tl),
        }
    }

    /// The prediction over the tail: `E_T S E_Tᵀ + H_T` (`S` itself without idle time).
    pub fn finish(&self, tail: Option<&Triplet>, s: &DMatrix<f64>) -> DMatrix<f64> {
        match tail {
            None => s.clone(),
            Some(t) => symmetrize(&(matmul_nt(&matmul(&t.a, s), &t.a) + &t.h)),
        }
    }

    /// The prior after the prediction of one channel unit: `E S Eᵀ + H`.
    pub fn predict(&self, s: &DMatrix<f64>) -> DMatrix<f64> {
        symmetrize(&(matmul_nt(&matmul(&self.e, s), &self.e) + &self.h))
    }

    /// The prior of a slot of sensor `i`: `E_i S E_iᵀ + H_i`.
    pub fn predict_for(&self, i: usize, s: &DMatrix<f64>) -> DMatrix<f64> {
        let (e, h) = &self.steps[self.step_of[i]];
        symmetrize(&(matmul_nt(&matmul(e, s), e) + h))
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
        let mut out = matmul_nt(&matmul(&ikc, p), &ikc);
        out.gemm(1.0, &k, &k.transpose(), 1.0);
        Ok(symmetrize(&out))
    }

    /// One slot map `φ_i(S)`: predict over sensor `i`'s slot, then update with sensor `i`.
    pub fn slot_map(&self, i: usize, s: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        self.update(i, &self.predict_for(i, s))
    }

    /// The period triplet of a schedule: the slot triplets composed first to last, then the
    /// tail.
    pub fn period_triplet(&self, slots: &[usize]) -> Result<Triplet> {
        self.check_schedule(slots)?;
        let items: Vec<&Triplet> = slots.iter().map(|&i| &self.slots[i]).collect();
        let t = super::triplet::compose_all(&items, self.order())?;
        self.close(t, self.tail(slots)?.as_ref())
    }
}
