//! Bindings for the hypotheses of Proposition 1 (`crate::sampled::existence`), which take `(A, C)`
//! or `(A, tau)` rather than a model: the dimension of the unobservable subspace of `(A, C)` and
//! the pair of eigenvalues of `A` aliased by the period `tau` (`τ ∉ 𝒯`), if any.

use crate::python::results::AliasingPair;
use crate::python::{run, to_matrix};
use crate::sampled::existence::{aliasing_pair, unobservable_dimension};
use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::PyComplex;

/// Dimension of the unobservable subspace of `(A, C)`, output `y = Cᵀx`.
#[pyfunction]
#[pyo3(signature = (a, c, rtol=1e-10))]
pub(super) fn sampled_unobservable_dimension(
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
pub(super) fn sampled_aliasing_pair(
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
