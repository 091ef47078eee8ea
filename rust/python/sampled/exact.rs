//! Bindings for the exact schedule search of equal-cost slots (`crate::sampled::exact_dfs`): the
//! branch-and-bound over the schedules of one length, each node bounded below by relaxing its free
//! slots, and its record [`ExactSchedule`].

use super::args::{deadline_of, objective};
use super::model::PySampledModel;
use crate::python::{run, to_matrix};
use crate::sampled::exact_dfs::{exact_schedule, ExactProblem};
use crate::Error;
use nalgebra::DMatrix;
use numpy::PyReadonlyArray2;
use pyo3::prelude::*;

/// The outcome of `sampled_exact_schedule`: the best schedule found below the incumbent
/// (`None`: never beaten), its exact cost, the proven lower bound over the schedules of that
/// length, the nodes bounded and whether the tree was exhausted.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct ExactSchedule {
    pub slots: Option<Vec<usize>>,
    pub eta_bar: f64,
    pub lower_bound: f64,
    pub nodes: usize,
    pub complete: bool,
}

/// The branch-and-bound over the schedules of `length` equal-cost slots of `model`
/// (`crate::sampled::exact_dfs`): `relaxed[mask − 1]` is the relaxed sensor `ĉ_𝒜` (n×k,
/// `τ ĉ_𝒜ĉ_𝒜ᵀ ⪰ c̄_ic̄_iᵀ` for every sensor `i` in the bit mask), `incumbent` the exact cost to
/// beat, `symmetric` keeps `R_l ≥ R_1` (the average figure without idle time); stops after
/// `node_limit` nodes or `time_limit` seconds.
#[pyfunction]
#[pyo3(signature = (model, tau, length, which, relaxed, min_counts, max_counts, incumbent, symmetric, node_limit, time_limit=None, budget=None))]
#[allow(clippy::too_many_arguments)]
pub(super) fn sampled_exact_schedule(
    py: Python<'_>,
    model: &Bound<'_, PySampledModel>,
    tau: f64,
    length: usize,
    which: &str,
    relaxed: Vec<PyReadonlyArray2<'_, f64>>,
    min_counts: Vec<usize>,
    max_counts: Vec<usize>,
    incumbent: f64,
    symmetric: bool,
    node_limit: usize,
    time_limit: Option<f64>,
    budget: Option<f64>,
) -> PyResult<ExactSchedule> {
    let objective = objective(which)?;
    let deadline = deadline_of(time_limit)?;
    let factors: Vec<DMatrix<f64>> = relaxed.iter().map(to_matrix).collect();
    let model = model.get();
    if model.sys.costs().iter().any(|&b| b != model.sys.costs()[0]) {
        return Err(Error::InvalidInput(
            "the exact schedule kernel needs equal sample costs".into(),
        )
        .into());
    }
    if length == 0 || length > crate::sampled::MAX_SLOTS_PER_PERIOD {
        return Err(
            Error::InvalidInput(format!("length must be in 1..=2^24, got {length}")).into(),
        );
    }
    let out = run(py, || {
        let slots = vec![0; length];
        let disc = model.disc_for(tau, &slots, budget)?;
        let sq = tau.sqrt();
        let problem = ExactProblem {
            disc: &disc,
            objective,
            len: length,
            lo: min_counts,
            hi: max_counts,
            relaxed: factors.iter().map(|c| c * sq).collect(),
            symmetric,
            incumbent,
            node_limit,
            deadline,
        };
        exact_schedule(&problem)
    })?;
    Ok(ExactSchedule {
        slots: out.slots,
        eta_bar: out.cost,
        lower_bound: out.lower_bound,
        nodes: out.nodes,
        complete: out.complete,
    })
}
