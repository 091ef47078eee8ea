//! The extension module `capalloc_rs._core`: the only place that knows pyo3.
//!
//! Conventions: every function takes float64 numpy arrays of any memory layout and returns
//! Fortran-ordered float64 arrays (no copy of the Rust result). Errors are raised as the package's
//! own exception classes (defined in Python in `capalloc_rs.errors`, looked up by name), never as a
//! Rust panic. Heavy work runs with the GIL released.

mod cost;
mod linalg;
mod sampled;

use crate::Error;
use nalgebra::DMatrix;
use numpy::ndarray::{Array2, ShapeBuilder};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;

/// Converts a core error into the package's Python exception of the same name.
pub(crate) fn to_pyerr(py: Python<'_>, err: Error) -> PyErr {
    let class = err.python_class();
    let message = err.to_string();
    match py
        .import("capalloc_rs.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|cls| cls.call1((message.clone(),)))
    {
        Ok(instance) => PyErr::from_value(instance),
        Err(e) => e,
    }
}

/// Copies a 2-D float64 array of any layout into a column-major matrix.
pub(crate) fn to_matrix(a: &PyReadonlyArray2<'_, f64>) -> DMatrix<f64> {
    let v = a.as_array();
    let (r, c) = v.dim();
    DMatrix::from_fn(r, c, |i, j| v[(i, j)])
}

/// Moves a column-major matrix into a Fortran-ordered numpy array without copying.
pub(crate) fn to_numpy<'py>(py: Python<'py>, m: DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    let (r, c) = (m.nrows(), m.ncols());
    let data: Vec<f64> = m.data.into();
    Array2::from_shape_vec((r, c).f(), data)
        .expect("shape matches the data length")
        .into_pyarray(py)
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    linalg::register(m)?;
    cost::register(m)?;
    sampled::register(m)?;
    Ok(())
}
