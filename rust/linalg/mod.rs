//! Dense linear algebra the crates we depend on do not provide at LAPACK grade.
//!
//! * [`schur`]: real Schur form with standardised 2×2 blocks and reordering (dtrexc/dlaexc).
//! * [`sylvester`]: Bartels–Stewart Sylvester and Lyapunov solvers on the quasi-triangular form.
//! * [`expm`]: matrix exponential (Padé scaling and squaring) and Van Loan's integral.
//! * [`dense`]: validation, norms, products and LU solves shared by the others.

/// Runs `$body(args…)` through a copy compiled with AVX2 enabled when the CPU has it (the kernels
/// are loops of short `axpy`s and reflector passes that the baseline x86-64 target only vectorises
/// two-wide), else through the baseline copy. No FMA contraction either way, so both copies give
/// bitwise identical results. `$body` should be `#[inline(always)]` so that it is compiled into
/// the AVX2 copy.
macro_rules! dispatch_avx2 {
    ($avx2:ident, $body:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2")]
            #[allow(clippy::too_many_arguments)]
            fn $avx2($($arg: $ty),*) -> $ret {
                $body($($arg),*)
            }
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2 (checked just above).
                return unsafe { $avx2($($arg),*) };
            }
        }
        $body($($arg),*)
    }};
}
pub(crate) use dispatch_avx2;

/// Like [`dispatch_avx2`], with AVX2 and FMA: `f64::mul_add` becomes one instruction (without
/// the feature it is a correct but slow library call; the results are the same either way).
macro_rules! dispatch_fma {
    ($fast:ident, $body:ident, ($($arg:ident : $ty:ty),*) -> $ret:ty) => {{
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma")]
            #[allow(clippy::too_many_arguments)]
            fn $fast($($arg: $ty),*) -> $ret {
                $body($($arg),*)
            }
            if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
                // SAFETY: the CPU supports AVX2 and FMA (checked just above).
                return unsafe { $fast($($arg),*) };
            }
        }
        $body($($arg),*)
    }};
}
pub(crate) use dispatch_fma;

pub mod dense;
pub mod expm;
pub mod schur;
pub mod sylvester;

#[doc(hidden)]
pub mod testing;
