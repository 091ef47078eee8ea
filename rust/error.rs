//! The crate's error type. Each variant maps to one Python exception class of the package
//! (see `python/capalloc_rs/errors.py`): input errors are `ValueError`s, numerical failures are
//! `numpy.linalg.LinAlgError`s; [`Error::Interrupted`] becomes the built-in `KeyboardInterrupt`.

use thiserror::Error as ThisError;

/// Everything that can go wrong in the numerical core.
#[derive(Debug, Clone, PartialEq, ThisError)]
pub enum Error {
    /// Mis-shaped input: non-square, mismatched dimensions, empty.
    #[error("{0}")]
    Shape(String),
    /// NaN or infinite entries in the input.
    #[error("{0}")]
    NonFinite(String),
    /// Other invalid input (e.g. a weight matrix that is not positive definite).
    #[error("{0}")]
    InvalidInput(String),
    /// The Riccati equation has no stabilising solution (Hamiltonian eigenvalues on or too near the
    /// imaginary axis, or the stable invariant subspace is not a graph).
    #[error("{0}")]
    NoStabilizingSolution(String),
    /// A linear system or matrix equation is singular or too ill-conditioned to solve accurately
    /// (e.g. λ_i(A) + λ_j(B) ≈ 0 in a Sylvester equation, or U11 near-singular in the CARE).
    #[error("{0}")]
    Singular(String),
    /// An eigenvalue swap in Schur reordering was rejected because it would lose accuracy.
    #[error("{0}")]
    ReorderFailed(String),
    /// An iteration did not converge within its bound.
    #[error("{0}")]
    NoConvergence(String),
    /// The computation was cancelled through its [`crate::cancel::Token`] (Ctrl-C in Python,
    /// where it becomes `KeyboardInterrupt`).
    #[error("{0}")]
    Interrupted(String),
}

impl Error {
    /// The name of the Python exception class this error maps to.
    pub fn python_class(&self) -> &'static str {
        match self {
            Error::Shape(_) => "ShapeError",
            Error::NonFinite(_) => "NonFiniteError",
            Error::InvalidInput(_) => "InvalidInputError",
            Error::NoStabilizingSolution(_) => "NoStabilizingSolutionError",
            Error::Singular(_) => "SingularProblemError",
            Error::ReorderFailed(_) => "ReorderError",
            Error::NoConvergence(_) => "ConvergenceError",
            Error::Interrupted(_) => "KeyboardInterrupt",
        }
    }
}

/// Result alias used throughout the crate.
pub type Result<T> = std::result::Result<T, Error>;
