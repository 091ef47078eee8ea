//! Bindings for `crate::sampled`: the sampled system at a finite period.
//!
//! [`model::PySampledModel`] (`_core.SampledModel`) holds the model `(A, Q = GGᵀ, [ĉ_i])`
//! validated once (shapes, finiteness, symmetry of `Q`) and the discretisation of the last
//! `(tau, r_tot)` it was asked for; its methods take the period `tau` and a schedule `slots`
//! (int64 sensor index per slot), so the schedule search converts and validates the model once,
//! not on every candidate. The Python layer (`capalloc_rs.sampled`) validates schedules and the
//! hypotheses of Proposition 1 and raises the specific exceptions. The two existence tests, which
//! take `(A, C)` rather than the model, stay free functions.
//!
//! One file per concept: [`model`] the pyclass, its discretisation cache and its methods (each
//! binds one core function); [`args`] the checks of the arguments they share (schedule, count
//! limits, objective, doubling options, deadline); [`star_tree`] the star-product tree and the
//! pending candidate kept between the search kernels `screen` and `candidate_costs`;
//! [`existence`] the existence tests; [`exact`] the exact schedule search
//! (`sampled_exact_schedule`) and its record.

mod args;
mod exact;
mod existence;
mod model;
mod star_tree;

use pyo3::prelude::*;
use pyo3::types::PyModule;

// Literal defaults in the signatures (shown by Python's text signatures, checked against
// `_core.pyi` by stubtest) equal to the core's constants:
const _: () = assert!(crate::sampled::existence::OBSERVABILITY_RTOL == 1e-10);
const _: () = assert!(crate::sampled::existence::ALIASING_TOL == 1e-8);

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<model::PySampledModel>()?;
    m.add_function(wrap_pyfunction!(
        existence::sampled_unobservable_dimension,
        m
    )?)?;
    m.add_function(wrap_pyfunction!(existence::sampled_aliasing_pair, m)?)?;
    m.add_class::<exact::ExactSchedule>()?;
    m.add_function(wrap_pyfunction!(exact::sampled_exact_schedule, m)?)?;
    Ok(())
}
