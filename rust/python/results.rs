//! The records that cross the seam: every binding that returns more than one value returns one of
//! these frozen classes with named fields (never a positional tuple), declared once here and in
//! `python/capalloc_rs/_core.pyi` (checked against each other by `mypy.stubtest` in CI).
//!
//! Each class is immutable (`frozen`: setting a field raises `AttributeError`), has read-only
//! attributes for all its fields (`get_all`) and no constructor in Python. Array fields hold numpy
//! arrays (float64, Fortran order; the slots of [`GreedyPass`] int64); a field's array object is
//! the same on every read.

use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::prelude::*;
use pyo3::types::{PyComplex, PyModule};

type A1 = Py<PyArray1<f64>>;
type A2 = Py<PyArray2<f64>>;
type A3 = Py<PyArray3<f64>>;

/// The stabilising CARE solution `x` and its diagnostics (see `capalloc_rs.linalg.CareResult`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct CareSolution {
    pub x: A2,
    pub residual: f64,
    pub rcond: f64,
    pub closed_loop_abscissa: f64,
    pub newton_steps: usize,
    pub scaling: f64,
    pub forward_error: f64,
    pub trace_error: f64,
    pub axis_margin: f64,
    pub marginal: bool,
}

/// A real Schur form `a = z t zᵀ`; `sdim` eigenvalues selected by the ordering come first (0
/// without one).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct SchurForm {
    pub t: A2,
    pub z: A2,
    pub sdim: usize,
}

/// `e = e^{At}` and `h = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct VanLoan {
    pub e: A2,
    pub h: A2,
}

/// `η(r)` and `∇η(r)`.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct ValueGradient {
    pub value: f64,
    pub gradient: A1,
}

/// `η` (shape `(K,)`) and `∇η` (shape `(K, N)`) for each row of a batch of rates.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct ValueGradientBatch {
    pub values: A1,
    pub gradients: A2,
}

/// One evaluation of the cost at `r`: `η`, `Σ`, the CARE's relative residual, `max Re λ(A_cl)`,
/// and `∇η`, `∇²η` when the requested order reached them (else `None`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct CostEvaluation {
    pub value: f64,
    pub sigma: A2,
    pub care_residual: f64,
    pub closed_loop_abscissa: f64,
    pub gradient: Option<A1>,
    pub hessian: Option<A2>,
}

/// The slots of a period: one channel unit `e = e^{Aτ₀}`, `h = ∫₀^{τ₀} e^{As} Q e^{Aᵀs} ds`,
/// `cbar = [c̄_i]`, each sensor's slot `es[i] = e^{A b_i τ₀}`, `hs[i]`, and `tau0`.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct SlotDiscretisation {
    pub e: A2,
    pub h: A2,
    pub cbar: Vec<A2>,
    pub es: Vec<A2>,
    pub hs: Vec<A2>,
    pub tau0: f64,
}

/// The period map of a schedule as a triplet `(a, g, h)`.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct PeriodTriplet {
    pub a: A2,
    pub g: A2,
    pub h: A2,
}

/// The periodic steady state of a schedule: the boundary posterior, the per-slot posteriors and
/// priors (`(r_tot, n, n)`), and the doubling's steps, last relative change, spectral radius of
/// the period's closed loop and relative residual; the idle channel units at the end of the
/// period and the tail's prediction `(tail_e, tail_h)` over them (`(I, 0)` without idle time).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct SteadyState {
    pub boundary: A2,
    pub posteriors: A3,
    pub priors: A3,
    pub steps: usize,
    pub rel_change: f64,
    pub spectral_radius: f64,
    pub residual: f64,
    pub idle: f64,
    pub tail_e: A2,
    pub tail_h: A2,
}

/// The priors and posteriors (`(r_tot, n, n)` each) of one period from a given covariance.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct Propagation {
    pub priors: A3,
    pub posteriors: A3,
}

/// The plain fixed-point iteration's last iterate, periods taken and last relative change.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct FixedPoint {
    pub sigma: A2,
    pub periods: usize,
    pub rel_change: f64,
}

/// The costs of a schedule's neighbours (see `crate::sampled::search::Neighbourhood`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct Neighbourhood {
    pub current: f64,
    pub reassign: A2,
    pub swap: A1,
    pub rotate: A1,
    pub complete: bool,
    pub evaluated: usize,
}

/// The screened neighbourhood of a schedule (see `crate::sampled::sensitivity::Screen`):
/// predicted changes of the cost, exact rotation costs.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct Screen {
    pub current: f64,
    pub spectral_radius: f64,
    pub reassign: A2,
    pub swap: A1,
    pub rotate: A1,
    pub stein_steps: usize,
}

/// Exact costs of candidate schedules (see `crate::sampled::star_tree::CandidateCosts`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct CandidateCosts {
    pub costs: A1,
    pub complete: bool,
    pub evaluated: usize,
}

/// One greedy pass: the slots chosen (int64) and the posterior at the period's end.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct GreedyPass {
    pub slots: Py<PyArray1<i64>>,
    pub sigma: A2,
}

/// Two eigenvalues of `A` that a period aliases (`e^{λ₁τ} = e^{λ₂τ}`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct AliasingPair {
    pub first: Py<PyComplex>,
    pub second: Py<PyComplex>,
}

/// The separable (decoupled, ε = 0) allocation: `gamma`, its cost `value`, its Frank–Wolfe `gap`
/// and the Newton steps taken (see `crate::allocation::separable`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct SeparableAllocation {
    pub gamma: A1,
    pub value: f64,
    pub gap: f64,
    pub iterations: usize,
}

/// Newton's method with the exact Hessian run in the core: the last `gamma`, the steps taken, and
/// `value`, `gradient` and `value_error` at that point (see `crate::allocation::newton`).
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct NewtonAllocation {
    pub gamma: A1,
    pub iterations: usize,
    pub value: f64,
    pub gradient: A1,
    pub value_error: f64,
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<SeparableAllocation>()?;
    m.add_class::<NewtonAllocation>()?;
    m.add_class::<CareSolution>()?;
    m.add_class::<SchurForm>()?;
    m.add_class::<VanLoan>()?;
    m.add_class::<ValueGradient>()?;
    m.add_class::<ValueGradientBatch>()?;
    m.add_class::<CostEvaluation>()?;
    m.add_class::<SlotDiscretisation>()?;
    m.add_class::<PeriodTriplet>()?;
    m.add_class::<SteadyState>()?;
    m.add_class::<Propagation>()?;
    m.add_class::<FixedPoint>()?;
    m.add_class::<Neighbourhood>()?;
    m.add_class::<Screen>()?;
    m.add_class::<CandidateCosts>()?;
    m.add_class::<GreedyPass>()?;
    m.add_class::<AliasingPair>()?;
    Ok(())
}
