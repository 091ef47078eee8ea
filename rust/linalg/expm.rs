//! Matrix exponential and Van Loan's integral.
//!
//! # Algorithm
//!
//! [`expm`] is the scaling-and-squaring method with diagonal Padé approximants `r_m`,
//! `m ∈ {3, 5, 7, 9, 13}`, of Higham ("The scaling and squaring method for the matrix exponential
//! revisited", SIAM J. Matrix Anal. Appl. 26(4), 2005), with the two refinements of Al-Mohy and
//! Higham ("A new scaling and squaring algorithm for the matrix exponential", SIAM J. Matrix Anal.
//! Appl. 31(3), 2009, Algorithm 5.1), as in `scipy.linalg.expm`:
//!
//! * the degree `m` and the number of squarings `s` are chosen from `d_k = ‖A^k‖₁^{1/k}` rather than
//!   from `‖A‖₁` (`d_k` is computed exactly where `A^k` is formed anyway and estimated with the
//!   Hager–Higham 1-norm estimator otherwise). For non-normal matrices `d_k ≪ ‖A‖₁` is common and
//!   this avoids the *overscaling* that ruins the squaring phase;
//! * `s` is increased by `ℓ(2^{-s}A, m) = max(0, ⌈log₂(α/u)/(2m)⌉)` with
//!   `α = |c_{2m+1}| ‖ |2^{-s}A|^{2m+1} ‖₁ / ‖2^{-s}A‖₁` (`u = 2⁻⁵³`), which bounds the leading term of
//!   the backward error of `r_m` by `u` (the `‖|A|^p‖₁` are computed exactly, in log scale).
//!
//! `r_m(X) = q_m(X)⁻¹ p_m(X)` is formed with Higham's evaluation scheme (6 products for `m = 13`)
//! and an LU solve with partial pivoting (`q_m` is well conditioned under the `θ_m` bounds).
//! Products use [`crate::linalg::dense::matmul`].
//!
//! # Accuracy
//!
//! In exact arithmetic the Padé step has relative backward error at most `u = 2⁻⁵³`: the computed
//! `X ≈ e^{A+ΔA}` with `‖ΔA‖ ≤ u‖A‖` (Higham 2005, Thm. 2.1; Al-Mohy–Higham 2009). Rounding in the
//! `s` squarings is not covered by that bound; the method is not proven forward stable, but it is
//! the de-facto standard and in practice the relative error is of order `κ_exp(A)·u`. Measured
//! (see the unit tests, which assert these with margin):
//!
//! * normal matrices with `‖A‖₂ ≤ 50` against diagonalisation: relative error ≲ 1e-14;
//! * `‖A‖ ~ 10³` (symmetric, spectrum in `[-1000, 0.5]`): ≲ 1e-13 relative to `‖e^A‖`;
//! * rotation generators `[[0, θ], [−θ, 0]]`: absolute error ≲ `θ·u` up to `θ = 10³`;
//! * non-normal `[[−1, 10³], [0, −2]]`-type matrices: entrywise relative error ≲ 1e-15 (the
//!   `d_k`-based choice keeps `s` small).
//!
//! For triangular input the diagonal and first superdiagonal are recomputed exactly after every
//! squaring (Al-Mohy–Higham 2009, §2); a diagonal input is exponentiated entrywise.
//!
//! An input whose 1-norm overflows, or whose exponential overflows (detected during squaring), gives
//! [`Error::InvalidInput`] instead of a matrix with infinities; the number of squarings is bounded
//! by [`MAX_SQUARINGS`].

//!
//! Van Loan's integral, which uses [`expm`] on a block matrix, is in [`super::van_loan`].

use crate::linalg::dense::{
    all_finite, check_finite, check_square, estimate_inverse_norm1, matmul, norm_1, Lu,
};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Upper bound on the number of squarings. No input with a finite 1-norm below `f64::MAX` needs
/// more than about 1030; past this bound [`expm`] returns an error instead of iterating.
pub const MAX_SQUARINGS: u32 = 1100;

/// `θ_m` of Higham (2005), Table 2.3: the largest `‖X‖` (here `max(d_{2k}, d_{2k+2})`, Al-Mohy–Higham
/// 2009) for which `r_m(X)` has backward error at most `u = 2⁻⁵³`.
const THETA_3: f64 = 1.495585217958292e-2;
const THETA_5: f64 = 2.539_398_330_063_23e-1;
const THETA_7: f64 = 9.504178996162932e-1;
const THETA_9: f64 = 2.097847961257068e0;
/// Al-Mohy–Higham (2009), Algorithm 5.1 use 4.25 for `m = 13` (Higham 2005 had 5.37) together with
/// the `ℓ` correction.
const THETA_13: f64 = 4.25;

/// Coefficients `b_j` of the Padé numerator `p_m(x) = Σ b_j x^j` (the denominator is `p_m(−x)`),
/// scaled to integers as in Higham (2005).
const B3: [f64; 4] = [120.0, 60.0, 12.0, 1.0];
const B5: [f64; 6] = [30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0];
const B7: [f64; 8] = [
    17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0,
];
const B9: [f64; 10] = [
    17643225600.0,
    8821612800.0,
    2075673600.0,
    302702400.0,
    30270240.0,
    2162160.0,
    110880.0,
    3960.0,
    90.0,
    1.0,
];
const B13: [f64; 14] = [
    64764752532480000.0,
    32382376266240000.0,
    7771770303897600.0,
    1187353796428800.0,
    129060195264000.0,
    10559470521600.0,
    670442572800.0,
    33522128640.0,
    1323241920.0,
    40840800.0,
    960960.0,
    16380.0,
    182.0,
    1.0,
];

/// The Padé degree and the number of squarings used for one evaluation (for tests and diagnostics).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ExpmPlan {
    pub(crate) degree: usize,
    pub(crate) squarings: u32,
}

/// `e^A` for a square finite matrix.
///
/// Errors: [`Error::Shape`] (not square, or empty), [`Error::NonFinite`] (NaN/∞ entries),
/// [`Error::InvalidInput`] when `‖A‖₁` or `e^A` is not representable in double precision.
pub fn expm(a: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    expm_with_plan(a).map(|(x, _)| x)
}

pub(crate) fn expm_with_plan(a: &DMatrix<f64>) -> Result<(DMatrix<f64>, ExpmPlan)> {
    let n = check_square("A", a)?;
    check_finite("A", a)?;
    let a1 = norm_1(a);
    if !a1.is_finite() {
        return Err(Error::InvalidInput(
            "‖A‖₁ overflows double precision; e^A cannot be computed".into(),
        ));
    }
    if a1 == 0.0 {
        return Ok((
            DMatrix::identity(n, n),
            ExpmPlan {
                degree: 0,
                squarings: 0,
            },
        ));
    }
    let upper = is_upper_triangular(a);
    let lower = is_upper_triangular(&a.transpose());
    if upper && lower {
        // Diagonal: e^A is the diagonal of scalar exponentials, to within an ulp.
        let x = DMatrix::from_diagonal(&a.diagonal().map(f64::exp));
        if !all_finite(x.as_slice()) {
            return Err(overflow_error());
        }
        return Ok((
            x,
            ExpmPlan {
                degree: 0,
                squarings: 0,
            },
        ));
    }
    if lower {
        // e^{Aᵀ} = (e^A)ᵀ: use the upper triangular refinement.
        return expm_with_plan(&a.transpose()).map(|(x, plan)| (x.transpose(), plan));
    }
    let (r, plan) = pade_step(a, a1)?;
    let x = if upper {
        square_triangular(r, a, plan.squarings)?
    } else {
        square(r, plan.squarings)?
    };
    Ok((x, plan))
}

fn is_upper_triangular(a: &DMatrix<f64>) -> bool {
    let n = a.nrows();
    (0..n).all(|j| ((j + 1)..n).all(|i| a[(i, j)] == 0.0))
}

/// Chooses `m` and `s` (Al-Mohy–Higham 2009, Algorithm 5.1) and returns `r_m(2^{-s} A)`.
fn pade_step(a: &DMatrix<f64>, a1: f64) -> Result<(DMatrix<f64>, ExpmPlan)> {
    let log2_a1 = a1.log2();
    let ell_at = |m: usize, s: u32| ell(log2_abs_power_norm(a, 2 * m + 1), log2_a1, m, s);
    let plan = |degree: usize, squarings: u32| ExpmPlan { degree, squarings };

    let a2 = matmul(a, a);
    let d4_est = est_power_norm(&[&a2, &a2]).powf(1.0 / 4.0);
    let d6_est = est_power_norm(&[&a2, &a2, &a2]).powf(1.0 / 6.0);
    let eta1 = d4_est.max(d6_est);
    if eta1 <= THETA_3 && ell_at(3, 0) == 0 {
        let r = pade_solve(a, &[&a2], &B3)?;
        return Ok((r, plan(3, 0)));
    }

    let a4 = matmul(&a2, &a2);
    let d4 = norm_1_or_inf(&a4).powf(1.0 / 4.0);
    let eta2 = d4.max(d6_est);
    if eta2 <= THETA_5 && ell_at(5, 0) == 0 {
        let r = pade_solve(a, &[&a2, &a4], &B5)?;
        return Ok((r, plan(5, 0)));
    }

    let a6 = matmul(&a4, &a2);
    let d6 = norm_1_or_inf(&a6).powf(1.0 / 6.0);
    let d8_est = est_power_norm(&[&a4, &a4]).powf(1.0 / 8.0);
    let eta3 = d6.max(d8_est);
    if eta3 <= THETA_7 && ell_at(7, 0) == 0 {
        let r = pade_solve(a, &[&a2, &a4, &a6], &B7)?;
        return Ok((r, plan(7, 0)));
    }
    if eta3 <= THETA_9 && ell_at(9, 0) == 0 {
        let a8 = matmul(&a4, &a4);
        let r = pade_solve(a, &[&a2, &a4, &a6, &a8], &B9)?;
        return Ok((r, plan(9, 0)));
    }

    let d10_est = est_power_norm(&[&a4, &a6]).powf(1.0 / 10.0);
    let eta4 = d8_est.max(d10_est);
    // d_k ≤ ‖A‖₁ always; the min also covers powers that overflowed (d = ∞).
    let eta5 = eta3.min(eta4).min(a1);
    let s0 = if eta5 > THETA_13 {
        (eta5 / THETA_13).log2().ceil()
    } else {
        0.0
    };
    if s0.is_nan() || s0 > f64::from(MAX_SQUARINGS) {
        return Err(too_many_squarings());
    }
    let s0 = s0 as u32;
    let s = s0.saturating_add(ell_at(13, s0));
    if s > MAX_SQUARINGS {
        return Err(too_many_squarings());
    }

    let powers_finite = [&a2, &a4, &a6]
        .iter()
        .all(|m| m.iter().all(|v| v.is_finite()));
    let r = if s == 0 && powers_finite {
        pade13(a, &a2, &a4, &a6)?
    } else if powers_finite {
        // Scaling by powers of two is exact (up to underflow of negligible entries).
        let si = i64::from(s);
        pade13(
            &scale_pow2(a, -si),
            &scale_pow2(&a2, -2 * si),
            &scale_pow2(&a4, -4 * si),
            &scale_pow2(&a6, -6 * si),
        )?
    } else {
        let b = scale_pow2(a, -i64::from(s));
        let b2 = matmul(&b, &b);
        let b4 = matmul(&b2, &b2);
        let b6 = matmul(&b4, &b2);
        pade13(&b, &b2, &b4, &b6)?
    };
    Ok((r, plan(13, s)))
}

pub(crate) fn too_many_squarings() -> Error {
    Error::InvalidInput(format!(
        "‖A‖ is too large for the matrix exponential: more than {MAX_SQUARINGS} squarings needed"
    ))
}

fn overflow_error() -> Error {
    Error::InvalidInput("e^A overflows double precision (an eigenvalue or ‖A‖ is too large)".into())
}

/// `r_m(A)` for `m ∈ {3, 5, 7, 9}` from the even powers `[A², A⁴, …]` and the coefficients `b`.
fn pade_solve(a: &DMatrix<f64>, even: &[&DMatrix<f64>], b: &[f64]) -> Result<DMatrix<f64>> {
    let n = a.nrows();
    // U = A (b_1 I + b_3 A² + …), V = b_0 I + b_2 A² + …
    let mut u_inner = DMatrix::identity(n, n) * b[1];
    let mut v = DMatrix::identity(n, n) * b[0];
    for (k, p) in even.iter().enumerate() {
        u_inner += *p * b[2 * k + 3];
        v += *p * b[2 * k + 2];
    }
    let u = matmul(a, &u_inner);
    solve_pade(u, v)
}

/// `r_13(A)` from `A, A², A⁴, A⁶` (Higham 2005, eq. (2.11)).
fn pade13(
    a: &DMatrix<f64>,
    a2: &DMatrix<f64>,
    a4: &DMatrix<f64>,
    a6: &DMatrix<f64>,
) -> Result<DMatrix<f64>> {
    let b = &B13;
    let n = a.nrows();
    let ident = DMatrix::<f64>::identity(n, n);
    let w1 = a6 * b[13] + a4 * b[11] + a2 * b[9];
    let w = matmul(a6, &w1) + a6 * b[7] + a4 * b[5] + a2 * b[3] + &ident * b[1];
    let u = matmul(a, &w);
    let z1 = a6 * b[12] + a4 * b[10] + a2 * b[8];
    let v = matmul(a6, &z1) + a6 * b[6] + a4 * b[4] + a2 * b[2] + &ident * b[0];
    solve_pade(u, v)
}

/// Solves `(V − U) R = V + U`.
fn solve_pade(u: DMatrix<f64>, v: DMatrix<f64>) -> Result<DMatrix<f64>> {
    let q = &v - &u;
    let mut r = v + u;
    if !all_finite(q.as_slice()) || !all_finite(r.as_slice()) {
        return Err(overflow_error());
    }
    let lu = Lu::new(&q).map_err(|_| {
        Error::SingularProblem(
            "the Padé denominator q_m(A) is singular to working precision".into(),
        )
    })?;
    lu.solve_in_place(&mut r);
    if !all_finite(r.as_slice()) {
        return Err(overflow_error());
    }
    Ok(r)
}

fn square(mut x: DMatrix<f64>, s: u32) -> Result<DMatrix<f64>> {
    for _ in 0..s {
        crate::cancel::check("the squaring phase of the matrix exponential")?;
        x = matmul(&x, &x);
        if !all_finite(x.as_slice()) {
            return Err(overflow_error());
        }
    }
    Ok(x)
}

/// Squaring phase for upper triangular `A` (Al-Mohy–Higham 2009, Code Fragment 2.1): after each
/// squaring the diagonal and the first superdiagonal of `X ≈ e^{2^{-j}A}` are replaced by their
/// exact values `e^{2^{-j}a_ii}` and `2^{-j}a_{i,i+1} · exp[2^{-j}a_ii, 2^{-j}a_{i+1,i+1}]`.
fn square_triangular(mut x: DMatrix<f64>, a: &DMatrix<f64>, s: u32) -> Result<DMatrix<f64>> {
    fix_triangular(&mut x, a, -i64::from(s));
    for j in (0..s).rev() {
        crate::cancel::check("the squaring phase of the matrix exponential")?;
        x = matmul(&x, &x);
        fix_triangular(&mut x, a, -i64::from(j));
        if !all_finite(x.as_slice()) {
            return Err(overflow_error());
        }
    }
    if !all_finite(x.as_slice()) {
        return Err(overflow_error());
    }
    Ok(x)
}

fn fix_triangular(x: &mut DMatrix<f64>, a: &DMatrix<f64>, e: i64) {
    let n = a.nrows();
    for i in 0..n {
        x[(i, i)] = ldexp(a[(i, i)], e).exp();
    }
    for i in 0..n.saturating_sub(1) {
        let (l1, l2) = (ldexp(a[(i, i)], e), ldexp(a[(i + 1, i + 1)], e));
        x[(i, i + 1)] = ldexp(a[(i, i + 1)], e) * exp_divided_difference(l1, l2);
    }
}

/// The divided difference `(e^{l1} − e^{l2})/(l1 − l2)` (`= e^{l1}` if `l1 = l2`), without
/// cancellation: `e^{(l1+l2)/2} sinh(d)/d` with `d = (l1 − l2)/2` when `l1 ≈ l2`.
fn exp_divided_difference(l1: f64, l2: f64) -> f64 {
    let d = 0.5 * l1 - 0.5 * l2;
    if d == 0.0 {
        l1.exp()
    } else if d.abs() < 0.5 {
        (0.5 * l1 + 0.5 * l2).exp() * (d.sinh() / d)
    } else {
        (l1.exp() - l2.exp()) / (l1 - l2)
    }
}

/// Exponents beyond this take every finite double to 0 or ∞ (the finite doubles span
/// `2^-1074 … 2^1024`), so [`pow2_steps`] clamps to it: at most three multiplications whatever `e`.
const MAX_POW2_EXPONENT: i64 = 2200;

/// `2^e` as at most three representable factors `2^k`, `|k| ≤ 1000`, whose product applied in
/// order scales exactly (up to underflow/overflow of the result). `e` is clamped to
/// `±MAX_POW2_EXPONENT`, so the loop is bounded for any `e` (e.g. `i64::MAX` from a `log₂` of ∞).
fn pow2_steps(e: i64) -> impl Iterator<Item = f64> {
    let mut e = e.clamp(-MAX_POW2_EXPONENT, MAX_POW2_EXPONENT);
    std::iter::from_fn(move || {
        if e == 0 {
            return None;
        }
        let step = e.clamp(-1000, 1000);
        e -= step;
        Some(2f64.powi(step as i32))
    })
}

/// `x · 2^e` in exact steps.
fn ldexp(mut x: f64, e: i64) -> f64 {
    for f in pow2_steps(e) {
        x *= f;
    }
    x
}

/// `‖m‖₁`, or `∞` if `m` has a non-finite entry (an overflowed power).
fn norm_1_or_inf(m: &DMatrix<f64>) -> f64 {
    if all_finite(m.as_slice()) {
        norm_1(m)
    } else {
        f64::INFINITY
    }
}

/// `2^e · m`, applied in exact steps so that `2^e` itself need not be representable.
pub(crate) fn scale_pow2(m: &DMatrix<f64>, e: i64) -> DMatrix<f64> {
    let mut out = m.clone();
    for f in pow2_steps(e) {
        out *= f;
    }
    out
}

/// `round(log₂(num/den))` for positive finite `num`, `den`, without forming the quotient (which
/// overflows for a subnormal `den`: `0.7/7e-311 = ∞`, whose `log₂` cast to `i64` is `i64::MAX`).
pub(crate) fn log2_ratio(num: f64, den: f64) -> i64 {
    let v = (num.log2() - den.log2()).round();
    v.clamp(-(MAX_POW2_EXPONENT as f64), MAX_POW2_EXPONENT as f64) as i64
}

/// Hager–Higham estimate of `‖P₁P₂⋯P_k‖₁` using only matrix–vector products; `∞` on overflow.
fn est_power_norm(factors: &[&DMatrix<f64>]) -> f64 {
    let n = factors[0].nrows();
    let mut overflow = false;
    let est = estimate_inverse_norm1(n, |x, transpose| {
        if transpose {
            for f in factors {
                *x = f.tr_mul(x);
            }
        } else {
            for f in factors.iter().rev() {
                *x = *f * &*x;
            }
        }
        if !all_finite(x.as_slice()) {
            overflow = true;
            x.fill(0.0);
        }
    });
    if overflow || !est.is_finite() {
        f64::INFINITY
    } else {
        est
    }
}

/// `log₂ ‖ |A|^p ‖₁`, exactly up to rounding and without overflow: `|A|^p` is nonnegative, so its
/// 1-norm is the largest entry of `1ᵀ|A|^p`, computed by `p` vector–matrix products in log scale.
fn log2_abs_power_norm(a: &DMatrix<f64>, p: usize) -> f64 {
    let amax = a.amax();
    if amax == 0.0 {
        return f64::NEG_INFINITY;
    }
    let m = a.map(|v| v.abs() / amax);
    let mut v = vec![1.0; a.nrows()];
    let mut w = vec![0.0; a.ncols()];
    let mut log2_norm = p as f64 * amax.log2();
    for _ in 0..p {
        for (j, wj) in w.iter_mut().enumerate() {
            *wj = m.column(j).iter().zip(&v).map(|(x, y)| x * y).sum();
        }
        let mx = w.iter().cloned().fold(0.0, f64::max);
        if mx == 0.0 {
            return f64::NEG_INFINITY;
        }
        log2_norm += mx.log2();
        for (vi, wi) in v.iter_mut().zip(&w) {
            *vi = wi / mx;
        }
    }
    log2_norm
}

/// `log₂ |c_{2m+1}|` with `1/|c_{2m+1}| = C(2m, m) (2m+1)!`, the leading coefficient of the
/// backward-error series of `r_m` (Higham 2005, eq. (2.6)).
fn log2_abs_c(m: usize) -> f64 {
    let mut binom = 1.0f64;
    for k in 1..=m {
        binom = binom * (m + k) as f64 / k as f64;
    }
    let fact: f64 = (1..=(2 * m + 1)).map(|k| k as f64).product();
    -(binom * fact).log2()
}

/// Al-Mohy–Higham's `ℓ(2^{-s}A, m)` from `log₂‖|A|^{2m+1}‖₁` and `log₂‖A‖₁`.
fn ell(log2_abs_pow: f64, log2_a1: f64, m: usize, s: u32) -> u32 {
    if log2_abs_pow == f64::NEG_INFINITY {
        return 0;
    }
    let p = 2 * m + 1;
    // α(2^{-s}A) = |c| 2^{-sp}‖|A|^p‖ / (2^{-s}‖A‖); u = 2⁻⁵³.
    let log2_alpha = log2_abs_c(m) + log2_abs_pow - log2_a1 - ((p - 1) as f64) * f64::from(s);
    let v = ((log2_alpha + 53.0) / (2 * m) as f64).ceil();
    if v.is_nan() || v <= 0.0 {
        0
    } else {
        v.min(f64::from(MAX_SQUARINGS) + 1.0) as u32
    }
}

#[cfg(test)]
mod tests;
