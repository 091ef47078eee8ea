//! capalloc — the numerical core of capalloc-rs.
//!
//! Optimal capacity allocation for sampled networked systems (Chen, Belabbas, Başar). This crate holds
//! the heavy numerics: real Schur form with reordering, Bartels–Stewart Lyapunov/Sylvester solvers,
//! the matrix exponential and Van Loan's integral, and the Hamiltonian/Schur CARE solver. It contains
//! no Python; the extension module (`rust/python/`) sits behind the `python` cargo feature.
//!
//! Every fallible routine returns [`Result`]: user input never makes the crate panic.

// Index loops mirror the LAPACK algorithms they implement; iterator rewrites obscure them.
#![allow(clippy::needless_range_loop)]
// `!(x >= tol)` is the deliberate NaN-catching form of a threshold test (true for NaN), as in
// LAPACK's `.NOT.( x.GE.tol )`; rewriting it as `x < tol` would let NaN through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod allocation;
pub mod cancel;
pub mod care;
pub mod cost;
pub mod error;
pub mod linalg;
pub mod network;
pub mod sampled;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
