//! Bindings for `crate::sampled`: the sampled system at a finite period.
//!
//! Every function takes the raw model `(a, q, sensors)` — `A` (n×n), `Q = GGᵀ` (n×n) and a list
//! of the full-size sensor matrices `ĉ_i` (n×p_i) — plus the period `tau` and a schedule `slots`
//! (int64 sensor index per slot). The Python layer (`capalloc_rs.sampled`) validates schedules and
//! the hypotheses of Proposition 1 and raises the specific exceptions.

use super::results::{
    AliasingPair, FixedPoint, GreedyPass, Neighbourhood, PeriodTriplet, Propagation,
    SlotDiscretisation, SteadyState,
};
use super::{run, to_matrix, to_numpy};
use crate::sampled::doubling::{fixed_point, propagate, steady_state, DoublingOptions};
use crate::sampled::existence::{aliasing_pair, unobservable_dimension};
use crate::sampled::search::{greedy_pass, neighbourhood_until, schedule_cost, Objective};
use crate::sampled::{Discretisation, SampledSystem};
use crate::Error;
use nalgebra::DMatrix;
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyComplex, PyModule};
use std::time::{Duration, Instant};

type Arr3<'py> = Bound<'py, PyArray3<f64>>;

// Literal defaults in the signatures (shown by Python's text signatures, checked against
// `_core.pyi` by stubtest) equal to the core's constants:
const _: () = assert!(crate::sampled::existence::OBSERVABILITY_RTOL == 1e-10);
const _: () = assert!(crate::sampled::existence::ALIASING_TOL == 1e-8);

/// The model and the schedule, copied out of numpy.
struct Input {
    sys: SampledSystem,
    slots: Vec<usize>,
}

fn model(
    a: &PyReadonlyArray2<'_, f64>,
    q: &PyReadonlyArray2<'_, f64>,
    sensors: &[PyReadonlyArray2<'_, f64>],
) -> crate::Result<SampledSystem> {
    SampledSystem::new(
        to_matrix(a),
        to_matrix(q),
        sensors.iter().map(to_matrix).collect(),
    )
}

fn schedule(slots: &PyReadonlyArray1<'_, i64>) -> crate::Result<Vec<usize>> {
    slots
        .as_array()
        .iter()
        .enumerate()
        .map(|(l, &i)| {
            usize::try_from(i).map_err(|_| {
                Error::InvalidInput(format!("slot {l} names sensor {i}: indices must be ≥ 0"))
            })
        })
        .collect()
}

fn input(
    a: &PyReadonlyArray2<'_, f64>,
    q: &PyReadonlyArray2<'_, f64>,
    sensors: &[PyReadonlyArray2<'_, f64>],
    slots: &PyReadonlyArray1<'_, i64>,
) -> crate::Result<Input> {
    let sys = model(a, q, sensors)?;
    let slots = schedule(slots)?;
    sys.check_schedule(&slots)?;
    Ok(Input { sys, slots })
}

fn discretise(inp: &Input, tau: f64) -> crate::Result<Discretisation> {
    inp.sys.discretise(tau, inp.slots.len())
}

fn stack<'py>(py: Python<'py>, ms: &[DMatrix<f64>], n: usize) -> Arr3<'py> {
    Array3::from_shape_fn((ms.len(), n, n), |(l, i, j)| ms[l][(i, j)]).into_pyarray(py)
}

fn objective(which: &str) -> crate::Result<Objective> {
    match which {
        "boundary" => Ok(Objective::Boundary),
        "average" => Ok(Objective::Average),
        other => Err(Error::InvalidInput(format!(
            "which must be 'boundary' or 'average', got {other:?}"
        ))),
    }
}

/// The objective and doubling options of a schedule evaluation.
fn schedule_args(
    which: &str,
    tol: f64,
    max_steps: usize,
) -> crate::Result<(Objective, DoublingOptions)> {
    Ok((objective(which)?, options(tol, max_steps)?))
}

/// `sigma0` as a finite `n × n` matrix.
fn initial_covariance(
    sigma0: &PyReadonlyArray2<'_, f64>,
    n: usize,
) -> crate::Result<nalgebra::DMatrix<f64>> {
    let s0 = to_matrix(sigma0);
    crate::linalg::dense::check_shape("sigma0", &s0, n, n)?;
    crate::linalg::dense::check_finite("sigma0", &s0)?;
    Ok(s0)
}

fn options(tol: f64, max_steps: usize) -> crate::Result<DoublingOptions> {
    if !(tol.is_finite() && tol > 0.0) {
        return Err(Error::InvalidInput(format!(
            "tol must be positive and finite, got {tol}"
        )));
    }
    Ok(DoublingOptions { tol, max_steps })
}

/// The [`SlotDiscretisation`] `(e, h, cbar)` of one slot of a period `tau` with `r_tot` slots.
#[pyfunction]
fn sampled_discretise<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    r_tot: usize,
) -> PyResult<SlotDiscretisation> {
    let sys = model(&a, &q, &sensors)?;
    let d = run(py, || sys.discretise(tau, r_tot))?;
    let cbar = d
        .cbar
        .into_iter()
        .map(|c| to_numpy(py, c).unbind())
        .collect();
    Ok(SlotDiscretisation {
        e: to_numpy(py, d.e).unbind(),
        h: to_numpy(py, d.h).unbind(),
        cbar,
    })
}

/// The [`PeriodTriplet`] `(a, g, h)` of a schedule.
#[pyfunction]
fn sampled_period_triplet<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    slots: PyReadonlyArray1<'py, i64>,
) -> PyResult<PeriodTriplet> {
    let inp = input(&a, &q, &sensors, &slots)?;
    let t = run(py, || discretise(&inp, tau)?.period_triplet(&inp.slots))?;
    Ok(PeriodTriplet {
        a: to_numpy(py, t.a).unbind(),
        g: to_numpy(py, t.g).unbind(),
        h: to_numpy(py, t.h).unbind(),
    })
}

/// The periodic [`SteadyState`] of a schedule (structure-preserving doubling).
#[pyfunction]
#[pyo3(signature = (a, q, sensors, tau, slots, tol=1e-12, max_steps=64))]
#[allow(clippy::too_many_arguments)]
fn sampled_steady_state<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    slots: PyReadonlyArray1<'py, i64>,
    tol: f64,
    max_steps: usize,
) -> PyResult<SteadyState> {
    let inp = input(&a, &q, &sensors, &slots)?;
    let opts = options(tol, max_steps)?;
    let ss = run(py, || {
        steady_state(&discretise(&inp, tau)?, &inp.slots, &opts)
    })?;
    let n = inp.sys.order();
    Ok(SteadyState {
        boundary: to_numpy(py, ss.boundary).unbind(),
        posteriors: stack(py, &ss.posteriors, n).unbind(),
        priors: stack(py, &ss.priors, n).unbind(),
        steps: ss.steps,
        rel_change: ss.rel_change,
        spectral_radius: ss.spectral_radius,
        residual: ss.residual,
    })
}

/// The [`Propagation`] (priors, posteriors) of one period of slot maps applied to `sigma0`.
#[pyfunction]
fn sampled_propagate<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    slots: PyReadonlyArray1<'py, i64>,
    sigma0: PyReadonlyArray2<'py, f64>,
) -> PyResult<Propagation> {
    let inp = input(&a, &q, &sensors, &slots)?;
    let n = inp.sys.order();
    let s0 = initial_covariance(&sigma0, n)?;
    let (priors, posts) = run(py, || propagate(&discretise(&inp, tau)?, &inp.slots, &s0))?;
    Ok(Propagation {
        priors: stack(py, &priors, n).unbind(),
        posteriors: stack(py, &posts, n).unbind(),
    })
}

/// The [`FixedPoint`] `(sigma, periods, rel_change)` of the plain iteration `Σ ← Φ_R(Σ)` from `sigma0`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn sampled_fixed_point<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    slots: PyReadonlyArray1<'py, i64>,
    sigma0: PyReadonlyArray2<'py, f64>,
    tol: f64,
    max_periods: usize,
) -> PyResult<FixedPoint> {
    let inp = input(&a, &q, &sensors, &slots)?;
    let s0 = initial_covariance(&sigma0, inp.sys.order())?;
    let fp = run(py, || {
        fixed_point(&discretise(&inp, tau)?, &inp.slots, &s0, tol, max_periods)
    })?;
    Ok(FixedPoint {
        sigma: to_numpy(py, fp.sigma).unbind(),
        periods: fp.periods,
        rel_change: fp.rel_change,
    })
}

/// The exact cost of a schedule (`which` = "boundary" or "average").
#[pyfunction]
#[pyo3(signature = (a, q, sensors, tau, slots, which="boundary", tol=1e-12, max_steps=64))]
#[allow(clippy::too_many_arguments)]
fn sampled_cost(
    py: Python<'_>,
    a: PyReadonlyArray2<'_, f64>,
    q: PyReadonlyArray2<'_, f64>,
    sensors: Vec<PyReadonlyArray2<'_, f64>>,
    tau: f64,
    slots: PyReadonlyArray1<'_, i64>,
    which: &str,
    tol: f64,
    max_steps: usize,
) -> PyResult<f64> {
    let inp = input(&a, &q, &sensors, &slots)?;
    let (obj, opts) = schedule_args(which, tol, max_steps)?;
    run(py, || {
        schedule_cost(&discretise(&inp, tau)?, &inp.slots, obj, &opts)
    })
}

/// The [`Neighbourhood`] `(current, reassign[r_tot, N], swap[r_tot − 1], rotate[r_tot],
/// complete, evaluated)` — see
/// `crate::sampled::search::Neighbourhood`; with `time_limit` (seconds) candidates that would
/// start later are skipped (`+∞`, `complete = False`, not counted in `evaluated`).
#[pyfunction]
#[pyo3(signature = (a, q, sensors, tau, slots, which="boundary", min_count=1, tol=1e-12, max_steps=64, time_limit=None))]
#[allow(clippy::too_many_arguments)]
fn sampled_neighbourhood<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    slots: PyReadonlyArray1<'py, i64>,
    which: &str,
    min_count: usize,
    tol: f64,
    max_steps: usize,
    time_limit: Option<f64>,
) -> PyResult<Neighbourhood> {
    let inp = input(&a, &q, &sensors, &slots)?;
    let (obj, opts) = schedule_args(which, tol, max_steps)?;
    if time_limit.is_some_and(f64::is_nan) {
        return Err(
            Error::InvalidInput("time_limit must be a number of seconds, got nan".into()).into(),
        );
    }
    // A past deadline evaluates no candidate; one beyond what Instant holds is no deadline.
    let deadline = time_limit
        .map(|t| Duration::try_from_secs_f64(t.max(0.0)).unwrap_or(Duration::MAX))
        .and_then(|d| Instant::now().checked_add(d));
    let nb = run(py, || {
        let disc = discretise(&inp, tau)?;
        neighbourhood_until(&disc, &inp.slots, obj, min_count, &opts, deadline)
    })?;
    Ok(Neighbourhood {
        current: nb.current,
        reassign: to_numpy(py, nb.reassign).unbind(),
        swap: PyArray1::from_vec(py, nb.swap).unbind(),
        rotate: PyArray1::from_vec(py, nb.rotate).unbind(),
        complete: nb.complete,
        evaluated: nb.evaluated,
    })
}

/// The [`GreedyPass`] `(slots, sigma)`: one greedy pass over a period of `r_tot` slots from the
/// posterior `sigma0`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
fn sampled_greedy_pass<'py>(
    py: Python<'py>,
    a: PyReadonlyArray2<'py, f64>,
    q: PyReadonlyArray2<'py, f64>,
    sensors: Vec<PyReadonlyArray2<'py, f64>>,
    tau: f64,
    r_tot: usize,
    sigma0: PyReadonlyArray2<'py, f64>,
    min_count: usize,
) -> PyResult<GreedyPass> {
    let sys = model(&a, &q, &sensors)?;
    let s0 = initial_covariance(&sigma0, sys.order())?;
    let (slots, s) = run(py, || {
        greedy_pass(&sys.discretise(tau, r_tot)?, &s0, min_count)
    })?;
    let slots: Vec<i64> = slots.into_iter().map(|i| i as i64).collect();
    Ok(GreedyPass {
        slots: PyArray1::from_vec(py, slots).unbind(),
        sigma: to_numpy(py, s).unbind(),
    })
}

/// Dimension of the unobservable subspace of `(A, C)`, output `y = Cᵀx`.
#[pyfunction]
#[pyo3(signature = (a, c, rtol=1e-10))]
fn sampled_unobservable_dimension(
    py: Python<'_>,
    a: PyReadonlyArray2<'_, f64>,
    c: PyReadonlyArray2<'_, f64>,
    rtol: f64,
) -> PyResult<usize> {
    let (a, c) = (to_matrix(&a), to_matrix(&c));
    run(py, || {
        crate::linalg::dense::check_finite("A", &a)?;
        crate::linalg::dense::check_finite("C", &c)?;
        unobservable_dimension(&a, &c, rtol)
    })
}

/// The [`AliasingPair`] of eigenvalues of `A` aliased by the period `tau`, or `None`.
#[pyfunction]
#[pyo3(signature = (a, tau, tol=1e-8))]
fn sampled_aliasing_pair(
    py: Python<'_>,
    a: PyReadonlyArray2<'_, f64>,
    tau: f64,
    tol: f64,
) -> PyResult<Option<AliasingPair>> {
    let a = to_matrix(&a);
    let pair = run(py, || aliasing_pair(&a, tau, tol))?;
    Ok(pair.map(|((r1, i1), (r2, i2))| AliasingPair {
        first: PyComplex::from_doubles(py, r1, i1).unbind(),
        second: PyComplex::from_doubles(py, r2, i2).unbind(),
    }))
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(sampled_discretise, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_period_triplet, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_steady_state, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_propagate, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_fixed_point, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_cost, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_neighbourhood, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_greedy_pass, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_unobservable_dimension, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_aliasing_pair, m)?)?;
    Ok(())
}
