//! The one error seam: every [`crate::Error`] becomes a Python exception here, and nowhere else.
//!
//! `impl From<Error> for PyErr` lets a binding write `?` on any core result. The classes are the
//! package's own (`python/capalloc_rs/errors.py`), imported once each by
//! [`pyo3::import_exception!`]; the message is the error's text, unchanged.
//!
//! | Rust variant (`crate::Error`) | Python class                                   | kind          |
//! |-------------------------------|------------------------------------------------|---------------|
//! | `Shape`                       | `capalloc_rs.errors.ShapeError`                | `ValueError`  |
//! | `NonFinite`                   | `capalloc_rs.errors.NonFiniteError`            | `ValueError`  |
//! | `InvalidInput`                | `capalloc_rs.errors.InvalidInputError`         | `ValueError`  |
//! | `NoStabilizingSolution`       | `capalloc_rs.errors.NoStabilizingSolutionError`| `LinAlgError` |
//! | `SingularProblem`             | `capalloc_rs.errors.SingularProblemError`      | `LinAlgError` |
//! | `Reorder`                     | `capalloc_rs.errors.ReorderError`              | `LinAlgError` |
//! | `Convergence`                 | `capalloc_rs.errors.ConvergenceError`          | `LinAlgError` |
//! | `Interrupted`                 | built-in `KeyboardInterrupt`                   |               |
//!
//! One name per error: the Python class is the Rust variant's name with `Error` appended (the
//! built-in `KeyboardInterrupt` for a cancellation).
//! `tests/test_error_seam.py` checks every row through the test hook [`_raise_core_error`].

use crate::Error;
use pyo3::exceptions::{PyKeyboardInterrupt, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyModule;

/// Declares the imported exception classes, the conversion and the table the test hook reads,
/// from one list of `Variant => Class` rows (so the three cannot disagree).
macro_rules! error_seam {
    ($($variant:ident => $class:ident),* $(,)?) => {
        $(pyo3::import_exception!(capalloc_rs.errors, $class);)*

        impl From<Error> for PyErr {
            fn from(err: Error) -> PyErr {
                match err {
                    $(Error::$variant(message) => $class::new_err(message),)*
                    Error::Interrupted(message) => PyKeyboardInterrupt::new_err(message),
                }
            }
        }

        /// `(variant, Python class)` for every variant, in the order of the table above.
        const MAPPING: &[(&str, &str)] = &[
            $((stringify!($variant), stringify!($class)),)*
            ("Interrupted", "KeyboardInterrupt"),
        ];

        /// The core error of variant `name` with text `message`.
        fn error_named(name: &str, message: String) -> Option<Error> {
            match name {
                $(stringify!($variant) => Some(Error::$variant(message)),)*
                "Interrupted" => Some(Error::Interrupted(message)),
                _ => None,
            }
        }
    };
}

error_seam! {
    Shape => ShapeError,
    NonFinite => NonFiniteError,
    InvalidInput => InvalidInputError,
    NoStabilizingSolution => NoStabilizingSolutionError,
    SingularProblem => SingularProblemError,
    Reorder => ReorderError,
    Convergence => ConvergenceError,
}

/// Test hook: the `(variant, class)` rows of the error table.
#[pyfunction]
fn _core_error_mapping() -> Vec<(&'static str, &'static str)> {
    MAPPING.to_vec()
}

/// Test hook: raises the Python exception that the core error `variant` with text `message`
/// becomes (a plain `ValueError` for an unknown variant name).
#[pyfunction]
fn _raise_core_error(variant: &str, message: String) -> PyResult<()> {
    match error_named(variant, message) {
        Some(err) => Err(err.into()),
        None => Err(PyValueError::new_err(format!(
            "unknown error variant {variant:?}"
        ))),
    }
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(_core_error_mapping, m)?)?;
    m.add_function(wrap_pyfunction!(_raise_core_error, m)?)?;
    Ok(())
}
