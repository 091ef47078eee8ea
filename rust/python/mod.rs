//! The extension module `capalloc_rs._core`: the only place that knows pyo3.
//!
//! Conventions: every function takes float64 numpy arrays of any memory layout and returns
//! Fortran-ordered float64 arrays (no copy of the Rust result). Errors are raised as the package's
//! own exception classes (defined in Python in `capalloc_rs.errors`) through the one conversion
//! in [`errors`] (`impl From<Error> for PyErr`, so bindings use `?`), never as a Rust panic.
//! Several values come back as one frozen record with named fields ([`results`]), never as a
//! positional tuple; the stateful classes (`CostModel`, `SampledModel`) hold a model validated
//! once. Heavy work runs with the GIL released, through [`run`], which keeps Ctrl-C working.
//! `python/capalloc_rs/_core.pyi` declares all of it and CI checks it with `mypy.stubtest`.

mod allocation;
mod cost;
mod errors;
mod linalg;
mod results;
mod sampled;

use crate::cancel::{with_token, Token};
use nalgebra::DMatrix;
use numpy::ndarray::{Array2, ShapeBuilder};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

/// How often the calling thread looks for a pending signal while [`run`] works.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Runs `work` without the GIL on a worker of the crate's shared rayon pool while the calling
/// thread checks for signals (`Python::check_signals`) every [`SIGNAL_POLL`]. When a signal
/// handler raises (Ctrl-C: `KeyboardInterrupt`), the work's cancellation token is set, the worker
/// stops at its next poll (see [`crate::cancel`]), and the handler's exception is returned.
/// `in_place_scope` returns only once the job has finished, so nothing outlives the call, and no
/// thread is created per call (a scoped `std::thread` costs ~0.35 ms per call on a loaded
/// machine, as much as a whole small cost evaluation; handing a job to a pool costs
/// microseconds). The pool is `cost::shared_pool`, rebuilt in a forked child (rayon's global
/// pool has no threads there and would hang). Python runs signal handlers only in the main
/// thread; elsewhere `check_signals` does nothing and the call runs to its end.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> crate::Result<T> + Send,
) -> PyResult<T> {
    let token = Token::new();
    let pool = crate::cost::shared_pool()?;
    let (raised, result) = py.detach(|| {
        let (tx, rx) = mpsc::channel();
        let mut raised: Option<PyErr> = None;
        let mut result = None;
        pool.in_place_scope(|scope| {
            let worker_token = token.clone();
            scope.spawn(move |_| {
                // The receiver lives until the scope has joined this job.
                let _ = tx.send(with_token(Some(&worker_token), work));
            });
            loop {
                match rx.recv_timeout(SIGNAL_POLL) {
                    Ok(r) => {
                        result = Some(r);
                        break;
                    }
                    Err(RecvTimeoutError::Timeout) => {
                        if raised.is_none() {
                            if let Err(e) = Python::attach(|py| py.check_signals()) {
                                raised = Some(e);
                                token.cancel();
                            }
                        }
                    }
                    // The job panicked: the scope re-raises the panic when it ends.
                    Err(RecvTimeoutError::Disconnected) => break,
                }
            }
        });
        (raised, result)
    });
    match (raised, result) {
        (Some(e), _) => Err(e),
        (None, Some(r)) => Ok(r?),
        (None, None) => unreachable!("the job either sent its result or panicked"),
    }
}

/// Problems of at most this order run on the calling thread (GIL released, no hand-off to a
/// worker): they finish in well under a millisecond — far inside the second within which Ctrl-C
/// must be honoured — and the hand-off of [`run`] (~18 µs) would be most of their cost (a CARE of
/// order 4 takes ~20 µs).
pub(crate) const INLINE_ORDER: usize = 32;

/// [`run`] for one problem of order `order`: inline below [`INLINE_ORDER`], else through [`run`].
pub(crate) fn run_order<T: Send>(
    py: Python<'_>,
    order: usize,
    work: impl FnOnce() -> crate::Result<T> + Send,
) -> PyResult<T> {
    if order <= INLINE_ORDER {
        Ok(py.detach(work)?)
    } else {
        run(py, work)
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

/// Loads numpy's C-API capsule and rust-numpy's borrow-checking capsule now, while the module is
/// imported, so that no later call imports them lazily: rust-numpy treats a failed lazy import as
/// a bug and panics, and a Ctrl-C arriving during that import (or any failure of it) would reach
/// the user as a `PanicException` instead of a `KeyboardInterrupt`.
fn load_numpy_api(py: Python<'_>) -> PyResult<()> {
    let probe = PyArray1::<f64>::zeros(py, 1, false);
    drop(probe.try_readonly()?);
    Ok(())
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    load_numpy_api(m.py())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    errors::register(m)?;
    results::register(m)?;
    linalg::register(m)?;
    cost::register(m)?;
    allocation::register(m)?;
    sampled::register(m)?;
    Ok(())
}
