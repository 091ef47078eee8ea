//! Dense linear algebra the crates we depend on do not provide at LAPACK grade.
//!
//! * [`schur`]: real Schur form with standardised 2×2 blocks and reordering (dtrexc/dlaexc).
//! * [`sylvester`]: Bartels–Stewart Sylvester and Lyapunov solvers on the quasi-triangular form.
//! * [`expm`]: matrix exponential (Padé scaling and squaring) and Van Loan's integral.
//! * [`dense`]: validation, norms, products and LU solves shared by the others.

pub mod dense;
pub mod expm;
pub mod schur;
pub mod sylvester;

#[doc(hidden)]
pub mod testing;
