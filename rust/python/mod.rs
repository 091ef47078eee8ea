//! The extension module `capalloc_rs._core`: the only place that knows pyo3.
//!
//! Conventions: every function takes float64 numpy arrays of any memory layout and returns
//! Fortran-ordered float64 arrays (no copy of the Rust result). Errors are raised as the package's
//! own exception classes (defined in Python in `capalloc_rs.errors`, looked up by name), never as a
//! Rust panic. Heavy work runs with the GIL released, through [`run`], which keeps Ctrl-C working.

mod cost;
mod linalg;
mod sampled;

use crate::cancel::{with_token, Token};
use crate::Error;
use nalgebra::DMatrix;
use numpy::ndarray::{Array2, ShapeBuilder};
use numpy::{IntoPyArray, PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

/// Converts a core error into the package's Python exception of the same name;
/// [`Error::Interrupted`] becomes the built-in `KeyboardInterrupt`.
pub(crate) fn to_pyerr(py: Python<'_>, err: Error) -> PyErr {
    if let Error::Interrupted(message) = err {
        return pyo3::exceptions::PyKeyboardInterrupt::new_err(message);
    }
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

/// How often the calling thread looks for a pending signal while [`run`] works.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Runs `work` without the GIL on a scoped worker thread while the calling thread checks for
/// signals (`Python::check_signals`) every [`SIGNAL_POLL`]. When a signal handler raises (Ctrl-C:
/// `KeyboardInterrupt`), the work's cancellation token is set, the worker stops at its next poll
/// (see [`crate::cancel`]) and is joined, and the handler's exception is returned. The worker is
/// always joined before `run` returns (no thread outlives the call). Python runs signal handlers
/// only in the main thread, so elsewhere `check_signals` does nothing and the call runs to the end.
pub(crate) fn run<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> crate::Result<T> + Send,
) -> PyResult<T> {
    let token = Token::new();
    let mut raised: Option<PyErr> = None;
    let result = py.detach(|| {
        std::thread::scope(|scope| {
            let (tx, rx) = mpsc::channel();
            let worker_token = token.clone();
            let worker = scope.spawn(move || {
                let out = with_token(Some(&worker_token), work);
                // The receiver only goes away after the join below.
                let _ = tx.send(());
                out
            });
            loop {
                match rx.recv_timeout(SIGNAL_POLL) {
                    Err(RecvTimeoutError::Timeout) => {
                        if raised.is_none() {
                            if let Err(e) = Python::attach(|py| py.check_signals()) {
                                raised = Some(e);
                                token.cancel();
                            }
                        }
                    }
                    // Finished (or the worker panicked and dropped the sender).
                    Ok(()) | Err(RecvTimeoutError::Disconnected) => break,
                }
            }
            worker.join()
        })
    });
    let result = match result {
        Ok(r) => r,
        Err(panic) => std::panic::resume_unwind(panic),
    };
    match (raised, result) {
        (Some(e), _) => Err(e),
        (None, r) => r.map_err(|e| to_pyerr(py, e)),
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
