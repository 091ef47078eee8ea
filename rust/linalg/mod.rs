//! Dense linear algebra the crates we depend on do not provide at LAPACK grade.
//!
//! * [`schur`]: real Schur form with standardised 2×2 blocks and reordering (dtrexc/dlaexc).
//! * [`sylvester`]: Bartels–Stewart Sylvester and Lyapunov solvers on the quasi-triangular form.
//! * [`qz`]: the real generalised Schur form of a pencil (faer's QZ, checked).
//! * [`expm`]: matrix exponential (Padé scaling and squaring) and Van Loan's integral.
//! * [`dense`]: validation, norms, products and LU solves shared by the others.

/// Runs `$body(args…)` through a copy compiled with the target features `[$feat, …]` enabled
/// when the CPU has all of them, else through the baseline copy. `$body` should be
/// `#[inline(always)]` so that it is compiled into the fast copy.
macro_rules! dispatch_features {
    ([$($feat:tt),+], $fast:ident, $body:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {{
        #[cfg(target_arch = "x86_64")]
        {
            $(#[target_feature(enable = $feat)])+
            #[allow(clippy::too_many_arguments)]
            fn $fast($($arg: $ty),*) -> $ret {
                $body($($arg),*)
            }
            if true $(&& std::arch::is_x86_feature_detected!($feat))+ {
                // SAFETY: the CPU supports every enabled feature (checked just above).
                return unsafe { $fast($($arg),*) };
            }
        }
        $body($($arg),*)
    }};
}
pub(crate) use dispatch_features;

/// [`dispatch_features`] with AVX2 (the kernels are loops of short `axpy`s and reflector passes
/// that the baseline x86-64 target only vectorises two-wide). No FMA contraction either way, so
/// both copies give bitwise identical results.
macro_rules! dispatch_avx2 {
    ($fast:ident, $body:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {
        $crate::linalg::dispatch_features!(["avx2"], $fast, $body, ($($arg: $ty),*) -> $ret)
    };
}
pub(crate) use dispatch_avx2;

/// [`dispatch_features`] with AVX2 and FMA: `f64::mul_add` becomes one instruction (without the
/// feature it is a correct but slow library call; the results are the same either way).
macro_rules! dispatch_fma {
    ($fast:ident, $body:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {
        $crate::linalg::dispatch_features!(["avx2", "fma"], $fast, $body, ($($arg: $ty),*) -> $ret)
    };
}
pub(crate) use dispatch_fma;

pub mod dense;
pub mod expm;
pub mod qz;
pub mod schur;
pub mod sylvester;
pub mod van_loan;

#[doc(hidden)]
pub mod testing;
