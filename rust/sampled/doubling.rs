//! The periodic steady state `Σ(∞; τ, R)` by doubling, the posteriors after every slot, and the
//! plain fixed-point iteration (a reference for tests and benchmarks).
//!
//! **Doubling.** Let `t₀` be the period triplet, so that `Φ_R = T_{t₀}`. Then `t_{k+1} = t_k ⋆ t_k`
//! represents `Φ_R^{2^{k+1}}` and its `H` part is `Φ_R^{2^{k+1}}(0)`, the covariance after `2^{k+1}`
//! periods started from perfect knowledge. When the steady state is stabilising (the closed-loop
//! monodromy `M = A₀ (I + Σ G₀)⁻¹` has spectral radius `ρ < 1`) the error decays like `ρ^{2^{k+1}}`:
//! quadratically once `2^k` exceeds the iteration's time scale `1/(1 − ρ)`. So `k ≈ log₂(1/(1 − ρ))
//! + 4` steps replace the `≈ 30/(1 − ρ)` periods of the fixed-point iteration.

use super::triplet::TransposedLu;
use super::{Discretisation, Triplet};
use crate::linalg::dense::{matmul, norm_fro, Lu};
use crate::linalg::schur::RealSchur;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Stopping rule of [`doubling`].
#[derive(Debug, Clone, Copy)]
pub struct DoublingOptions {
    /// Stop when `‖H_{k+1} − H_k‖_F ≤ tol · ‖H_{k+1}‖_F`. Convergence is quadratic, so the returned
    /// `H_{k+1}` is accurate far beyond `tol` (to rounding) once `tol ≤ 1e-8`.
    pub tol: f64,
    /// At most this many doubling steps (`2^max_steps` periods).
    pub max_steps: usize,
}

impl Default for DoublingOptions {
    fn default() -> Self {
        DoublingOptions {
            tol: 1e-12,
            max_steps: 64,
        }
    }
}

/// The result of [`doubling`].
#[derive(Debug, Clone)]
pub struct Doubling {
    /// `Σ(∞)`: the fixed point of the triplet's map reached from `X = 0`.
    pub sigma: DMatrix<f64>,
    /// Doubling steps taken (the last composed triplet stands for `2^steps` periods).
    pub steps: usize,
    /// The last relative change `‖H_{k+1} − H_k‖_F / ‖H_{k+1}‖_F`.
    pub rel_change: f64,
}

/// Doubles `t ← t ⋆ t` until its `H` part settles; returns `lim T^m(0)`.
///
/// Errors: [`Error::Convergence`] if the composition overflows (a mode the schedule does not
/// detect grows) or if `max_steps` steps do not reach `tol` (e.g. an undetected mode on the unit
/// circle, whose covariance grows linearly).
pub fn doubling(t: &Triplet, opts: &DoublingOptions) -> Result<Doubling> {
    match doubling_cut(t, opts, |_| None)? {
        Doubled::Converged(d) => Ok(d),
        Doubled::Cut(_) => Err(Error::Convergence(
            "the doubling was cut short without a cut".into(),
        )),
    }
}

/// How [`doubling_cut`] ended.
#[derive(Debug, Clone)]
pub enum Doubled {
    /// The iterates settled: as [`doubling`].
    Converged(Doubling),
    /// `cut` returned `Some(v)` at an iterate `H_k` (before it was doubled again).
    Cut(f64),
}

/// [`doubling`] that calls `cut(H_k)` on every iterate before doubling it (`H_0` is `t`'s `H`)
/// and stops with [`Doubled::Cut`] at the first `Some`; the steps and the result otherwise are
/// exactly [`doubling`]'s. Same errors.
pub fn doubling_cut(
    t: &Triplet,
    opts: &DoublingOptions,
    mut cut: impl FnMut(&DMatrix<f64>) -> Option<f64>,
) -> Result<Doubled> {
    if !t.is_finite() {
        return Err(Error::NonFinite(
            "the period triplet has non-finite entries".into(),
        ));
    }
    let mut cur = t.clone();
    let mut rel = f64::INFINITY;
    for step in 1..=opts.max_steps {
        crate::cancel::check("the doubling of the period triplet")?;
        if let Some(v) = cut(&cur.h) {
            return Ok(Doubled::Cut(v));
        }
        let next = cur.then(&cur).map_err(|e| match e {
            Error::Convergence(m) => {
                Error::Convergence(format!("doubling step {step} (2^{step} periods): {m}"))
            }
            other => other,
        })?;
        let nh = norm_fro(&next.h);
        let dh = norm_fro(&(&next.h - &cur.h));
        rel = if nh > 0.0 { dh / nh } else { 0.0 };
        cur = next;
        if rel <= opts.tol {
            return Ok(Doubled::Converged(Doubling {
                sigma: cur.h,
                steps: step,
                rel_change: rel,
            }));
        }
    }
    Err(Error::Convergence(format!(
        "doubling did not converge in {} steps (2^{} periods): last relative change {rel:.3e} > \
         tol {:.1e}; the covariance keeps growing — the schedule does not detect a marginally \
         stable mode, or the period map is too close to non-contracting",
        opts.max_steps, opts.max_steps, opts.tol
    )))
}

/// Spectral radius of the closed-loop monodromy `M = A (I + Σ G)⁻¹` of a period triplet at a fixed
/// point `Σ` (the Jacobian of the period map there is `δ ↦ M δ Mᵀ`).
pub fn monodromy(t: &Triplet, sigma: &DMatrix<f64>) -> Result<(DMatrix<f64>, f64)> {
    let n = t.order();
    let mut v = matmul(sigma, &t.g);
    for i in 0..n {
        v[(i, i)] += 1.0;
    }
    let lu = Lu::new(&v)?;
    // M = A V⁻¹ with V = I + ΣG  ⇔  Vᵀ Mᵀ = Aᵀ.
    let mut mt = t.a.transpose();
    TransposedLu::new(&v, &lu)?.solve_in_place(&mut mt);
    let m = mt.transpose();
    let rho = spectral_radius(&m)?;
    Ok((m, rho))
}

/// `max |λ(M)|` from the real Schur form.
pub fn spectral_radius(m: &DMatrix<f64>) -> Result<f64> {
    if m.iter().all(|v| *v == 0.0) {
        return Ok(0.0);
    }
    let s = RealSchur::new(m)?;
    Ok(s.eigenvalues()
        .iter()
        .map(|(re, im)| re.hypot(*im))
        .fold(0.0, f64::max))
}

/// A limit whose closed-loop spectral radius is within this of 1 is not a steady state: its
/// sensitivity grows like `1/(1 − ρ²)`, and a mode on the unit circle that the schedule does not
/// detect makes the doubling stall at a covariance of ~`1/eps` with `ρ = 1 − O(eps)`.
pub const MARGINAL: f64 = 1e-10;

/// The periodic steady state of a schedule.
#[derive(Debug, Clone)]
pub struct SteadyState {
    /// `Σ(∞; τ, R)`: the covariance at the period boundary (after the last slot and the idle
    /// tail, if any).
    pub boundary: DMatrix<f64>,
    /// The posterior covariance after slot `l` (`l = 0, …, L − 1`); the last one, followed by the idle tail, reproduces
    /// `boundary` up to `residual`.
    pub posteriors: Vec<DMatrix<f64>>,
    /// The prior covariance of slot `l` (after its prediction, before its update).
    pub priors: Vec<DMatrix<f64>>,
    /// Doubling steps.
    pub steps: usize,
    /// The doubling's last relative change.
    pub rel_change: f64,
    /// Spectral radius of the closed-loop monodromy (`< 1`: the steady state is stabilising and
    /// does not depend on the initial covariance).
    pub spectral_radius: f64,
    /// `‖Φ_R(Σ) − Σ‖_F / ‖Σ‖_F` with `Φ_R` evaluated slot by slot in Joseph form (then the
    /// tail).
    pub residual: f64,
}

impl SteadyState {
    /// `tr Σ(∞; τ, R)` — the paper's `η̄(τ, R)` (period-boundary convention).
    pub fn eta_boundary(&self) -> f64 {
        self.boundary.trace()
    }

    /// `(1/L) Σ_l tr Σ_l⁺` — the average over the posteriors after each slot.
    pub fn eta_average(&self) -> f64 {
        self.posteriors.iter().map(|p| p.trace()).sum::<f64>() / self.posteriors.len() as f64
    }

    /// `tr(M Σ(∞; τ, R))` with the discretisation's weight (`eta_boundary` without one).
    pub fn eta_boundary_weighted(&self, disc: &Discretisation) -> f64 {
        disc.weighted_trace(&self.boundary)
    }

    /// `(1/L) Σ_l tr(M Σ_l⁺)` with the discretisation's weight (`eta_average` without one).
    pub fn eta_average_weighted(&self, disc: &Discretisation) -> f64 {
        average_cost(disc, &self.posteriors)
    }
}

/// `(1/L) Σ_l tr(M S_l)` over the posteriors `S_l` of a period (`tr` without a weight).
pub fn average_cost(disc: &Discretisation, posteriors: &[DMatrix<f64>]) -> f64 {
    posteriors
        .iter()
        .map(|p| disc.weighted_trace(p))
        .sum::<f64>()
        / posteriors.len() as f64
}

/// The prior and posterior covariances of every slot of a period.
pub type SlotCovariances = (Vec<DMatrix<f64>>, Vec<DMatrix<f64>>);

/// Applies the slot maps of one period to `s0`, returning the priors and posteriors of each slot
/// (the idle tail, if any, comes after the last posterior: see [`Discretisation::finish`]).
pub fn propagate(
    disc: &Discretisation,
    slots: &[usize],
    s0: &DMatrix<f64>,
) -> Result<SlotCovariances> {
    let mut priors = Vec::with_capacity(slots.len());
    let mut posts = Vec::with_capacity(slots.len());
    let mut s = s0.clone();
    for &i in slots {
        crate::cancel::check("the slot-by-slot propagation of a period")?;
        let p = disc.predict_for(i, &s);
        s = disc.update(i, &p)?;
        priors.push(p);
        posts.push(s.clone());
    }
    Ok((priors, posts))
}

/// `Σ(∞; τ, R)` by doubling of the period triplet, then the per-slot covariances by one pass of the
/// slot maps. Errors: see [`doubling`]; also [`Error::Convergence`] when the limit reached from
/// `X = 0` is not stabilising (`ρ(M) ≥ 1`: a growing mode that the noise `Q` does not excite, so the
/// limit depends on the initial covariance).
pub fn steady_state(
    disc: &Discretisation,
    slots: &[usize],
    opts: &DoublingOptions,
) -> Result<SteadyState> {
    let t = disc.period_triplet(slots)?;
    steady_state_from_triplet(disc, slots, &t, opts)
}

/// As [`steady_state`] with the period triplet already composed.
pub fn steady_state_from_triplet(
    disc: &Discretisation,
    slots: &[usize],
    t: &Triplet,
    opts: &DoublingOptions,
) -> Result<SteadyState> {
    let d = doubling(t, opts)?;
    let (_, rho) = monodromy(t, &d.sigma)?;
    if rho < 1.0 && 1.0 - rho <= MARGINAL {
        return Err(Error::Convergence(format!(
            "the periodic Riccati iteration reached a covariance of norm {:.3e} whose closed loop \
             is only marginally stable (spectral radius 1 − {:.1e}): a mode on the unit circle \
             is not detected by the schedule and its variance grows without bound; the doubling \
             stopped only because the growth fell below rounding",
            norm_fro(&d.sigma),
            1.0 - rho
        )));
    }
    if rho >= 1.0 {
        return Err(Error::Convergence(format!(
            "the limit of the periodic Riccati iteration from Σ = 0 is not stabilising (closed-loop \
             spectral radius {rho:.6} ≥ 1): a growing mode is not excited by the noise Q, so the \
             steady state depends on the initial covariance"
        )));
    }
    let (priors, posteriors) = propagate(disc, slots, &d.sigma)?;
    let tail = disc.tail(slots)?;
    let last = disc.finish(
        tail.as_ref(),
        posteriors.last().expect("a schedule has a slot"),
    );
    let ns = norm_fro(&d.sigma);
    let residual = if ns > 0.0 {
        norm_fro(&(&last - &d.sigma)) / ns
    } else {
        norm_fro(&last)
    };
    Ok(SteadyState {
        boundary: d.sigma,
        posteriors,
        priors,
        steps: d.steps,
        rel_change: d.rel_change,
        spectral_radius: rho,
        residual,
    })
}

/// The result of [`fixed_point`].
#[derive(Debug, Clone)]
pub struct FixedPoint {
    /// The last iterate `Φ_R^k(Σ₀)`.
    pub sigma: DMatrix<f64>,
    /// Periods iterated.
    pub periods: usize,
    /// The last relative change between consecutive periods.
    pub rel_change: f64,
}

/// The plain iteration `Σ_{k+1} = Φ_R(Σ_k)` slot by slot (Joseph form), from `s0`, until
/// `‖Σ_{k+1} − Σ_k‖_F ≤ tol ‖Σ_{k+1}‖_F`. This is what a user would write; it needs
/// `O(1/(1 − ρ))` periods. [`Error::Convergence`] after `max_periods`.
pub fn fixed_point(
    disc: &Discretisation,
    slots: &[usize],
    s0: &DMatrix<f64>,
    tol: f64,
    max_periods: usize,
) -> Result<FixedPoint> {
    disc.check_schedule(slots)?;
    let tail = disc.tail(slots)?;
    let mut s = s0.clone();
    let mut rel = f64::INFINITY;
    for k in 1..=max_periods {
        crate::cancel::check("the fixed-point iteration of the period map")?;
        let mut next = s.clone();
        for &i in slots {
            next = disc.slot_map(i, &next)?;
        }
        if tail.is_some() {
            next = disc.finish(tail.as_ref(), &next);
        }
        let nn = norm_fro(&next);
        rel = if nn > 0.0 {
            norm_fro(&(&next - &s)) / nn
        } else {
            0.0
        };
        s = next;
        if !rel.is_finite() {
            break;
        }
        if rel <= tol {
            return Ok(FixedPoint {
                sigma: s,
                periods: k,
                rel_change: rel,
            });
        }
    }
    Err(Error::Convergence(format!(
        "the fixed-point iteration did not reach tol {tol:.1e} in {max_periods} periods (last \
         relative change {rel:.3e})"
    )))
}
