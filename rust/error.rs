//! The crate's error type: input errors (`Shape`, `NonFinite`, `InvalidInput`), numerical failures
//! (`NoStabilizingSolution`, `SingularProblem`, `Reorder`, `Convergence`) and cancellation
//! (`Interrupted`). The core knows no binding: how each variant reaches another language is
//! decided where that binding lives.

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
    SingularProblem(String),
    /// An eigenvalue swap in Schur reordering was rejected because it would lose accuracy.
    #[error("{0}")]
    Reorder(String),
    /// An iteration did not converge within its bound.
    #[error("{0}")]
    Convergence(String),
    /// The computation was cancelled through its [`crate::cancel::Token`] (e.g. on Ctrl-C).
    #[error("{0}")]
    Interrupted(String),
}

/// Result alias used throughout the crate.
pub type Result<T> = std::result::Result<T, Error>;
