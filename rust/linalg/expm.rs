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
//! # Van Loan
//!
//! [`van_loan`] evaluates Van Loan's block exponential `expm([[−A, Q], [0, Aᵀ]] τ) = [[·, F₁₂], [0,
//! E(τ)ᵀ]]`, `H(τ) = E(τ) F₁₂`, on a step `τ = t/2^j` with `‖Aτ‖₁ ≤ 1`, then doubles up with
//! `H(2τ) = H(τ) + E(τ) H(τ) E(τ)ᵀ`, `E(2τ) = E(τ)²`. Mathematically this is the same integral; the
//! doubling avoids forming `e^{−At}`, which overflows (or loses all accuracy of `H`) for a stable
//! `A` over a long horizon, and for positive semidefinite `Q` it only ever adds positive
//! semidefinite terms. `Q` is scaled by a power of two (exact) so that its size does not inflate the
//! number of squarings of the block exponential.

use crate::linalg::dense::{
    all_finite, check_finite, check_shape, check_square, estimate_inverse_norm1, matmul, matmul_nt,
    norm_1, Lu,
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

fn too_many_squarings() -> Error {
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
        Error::Singular("the Padé denominator q_m(A) is singular to working precision".into())
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
fn scale_pow2(m: &DMatrix<f64>, e: i64) -> DMatrix<f64> {
    let mut out = m.clone();
    for f in pow2_steps(e) {
        out *= f;
    }
    out
}

/// `round(log₂(num/den))` for positive finite `num`, `den`, without forming the quotient (which
/// overflows for a subnormal `den`: `0.7/7e-311 = ∞`, whose `log₂` cast to `i64` is `i64::MAX`).
fn log2_ratio(num: f64, den: f64) -> i64 {
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

/// Van Loan's discretisation over a step `t`: `E = e^{At}` and `H = ∫₀ᵗ e^{As} Q e^{Aᵀs} ds`.
#[derive(Debug, Clone)]
pub struct VanLoan {
    /// The transition matrix `e^{At}`.
    pub e: DMatrix<f64>,
    /// The process-noise integral `∫₀ᵗ e^{As} Q e^{Aᵀs} ds` (symmetric).
    pub h: DMatrix<f64>,
}

/// Computes [`VanLoan`] from `expm([[−A, Q],[0, Aᵀ]] τ) = [[·, F₁₂],[0, E(τ)ᵀ]]`, `H(τ) = E(τ) F₁₂`
/// on a step `τ = t/2^j`, doubled up to `t` (see the module documentation).
///
/// `Q` must be symmetric (to a relative tolerance `1e-10·max|Q|`; its symmetric part is used) and
/// `t` finite and `≥ 0`. `t = 0` gives `E = I`, `H = 0` exactly. The accuracy of `E` is that of
/// [`expm`]; for positive semidefinite `Q` the computed `H` satisfies the Lyapunov identity
/// `A H + H Aᵀ = E Q Eᵀ − Q` to a relative residual of a small multiple of `u`.
pub fn van_loan(a: &DMatrix<f64>, q: &DMatrix<f64>, t: f64) -> Result<VanLoan> {
    let n = check_square("A", a)?;
    check_shape("Q", q, n, n)?;
    check_finite("A", a)?;
    check_finite("Q", q)?;
    if !t.is_finite() {
        return Err(Error::NonFinite(format!("t must be finite, got {t}")));
    }
    if t < 0.0 {
        return Err(Error::InvalidInput(format!("t must be ≥ 0, got {t}")));
    }
    let qmax = q.amax();
    for j in 0..n {
        for i in (j + 1)..n {
            if (q[(i, j)] - q[(j, i)]).abs() > 1e-10 * qmax {
                return Err(Error::InvalidInput(format!(
                    "Q must be symmetric: entries ({i}, {j}) and ({j}, {i}) differ ({} vs {})",
                    q[(i, j)],
                    q[(j, i)]
                )));
            }
        }
    }
    if t == 0.0 {
        return Ok(VanLoan {
            e: DMatrix::identity(n, n),
            h: DMatrix::zeros(n, n),
        });
    }
    let q = (q + q.transpose()) * 0.5;
    let at = a * t;
    let at1 = norm_1(&at);
    if !at1.is_finite() {
        return Err(Error::InvalidInput(
            "‖A t‖₁ overflows double precision; e^{At} cannot be computed".into(),
        ));
    }
    // Step τ = t/2^j with ‖Aτ‖₁ ≤ 1, so that e^{−Aτ} in the block exponential is harmless.
    let j = if at1 > 1.0 {
        at1.log2().ceil() as u32
    } else {
        0
    };
    if j > MAX_SQUARINGS {
        return Err(too_many_squarings());
    }
    let a_tau = scale_pow2(&at, -i64::from(j));
    let q1 = norm_1(&q);
    if !q1.is_finite() {
        return Err(Error::InvalidInput(
            "‖Q‖₁ overflows double precision; the Van Loan integral cannot be computed".into(),
        ));
    }
    if q1 == 0.0 {
        let e = expm(&at)?;
        return Ok(VanLoan {
            e,
            h: DMatrix::zeros(n, n),
        });
    }
    // Q τ scaled by an exact power of two c to ‖c Q τ‖₁ ≈ max(‖Aτ‖₁, 2⁻¹⁰): H is linear in Q, and the
    // scaling keeps a large or tiny Q from changing the number of squarings of the block matrix.
    let tau_scale =
        t * 2f64.powi(-(j.min(1000) as i32)) * 2f64.powi(-(j.saturating_sub(1000) as i32));
    let q_tau = &q * tau_scale;
    let qt1 = norm_1(&q_tau);
    // A subnormal Q τ has lost bits to underflow: scale Q itself (exactly) instead.
    let (q_tau, log2_c) = if qt1 >= f64::MIN_POSITIVE && qt1.is_finite() {
        let target = norm_1(&a_tau).max(2f64.powi(-10));
        let log2_c = log2_ratio(target, qt1);
        (scale_pow2(&q_tau, log2_c), log2_c)
    } else {
        // Q τ underflowed or overflowed: fall back to scaling Q itself before multiplying by τ.
        let log2_c = log2_ratio(1.0, q1);
        (scale_pow2(&q, log2_c) * tau_scale, log2_c)
    };
    let mut m = DMatrix::zeros(2 * n, 2 * n);
    m.view_mut((0, 0), (n, n)).copy_from(&(-&a_tau));
    m.view_mut((0, n), (n, n)).copy_from(&q_tau);
    m.view_mut((n, n), (n, n)).copy_from(&a_tau.transpose());
    let f = expm(&m)?;
    let mut e: DMatrix<f64> = f.view((n, n), (n, n)).transpose();
    let f12: DMatrix<f64> = f.view((0, n), (n, n)).into_owned();
    let mut h = scale_pow2(&symmetrize(&matmul(&e, &f12)), -log2_c);
    if !all_finite(h.as_slice()) {
        return Err(Error::InvalidInput(
            "the Van Loan integral overflows double precision".into(),
        ));
    }
    for _ in 0..j {
        crate::cancel::check("the doubling of Van Loan's integral")?;
        let eh = matmul(&e, &h);
        h += matmul_nt(&eh, &e);
        h = symmetrize(&h);
        e = matmul(&e, &e);
        if !all_finite(e.as_slice()) || !all_finite(h.as_slice()) {
            return Err(Error::InvalidInput(
                "e^{At} or the Van Loan integral overflows double precision".into(),
            ));
        }
    }
    Ok(VanLoan { e, h })
}

fn symmetrize(a: &DMatrix<f64>) -> DMatrix<f64> {
    (a + a.transpose()) * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    const U: f64 = f64::EPSILON / 2.0;

    fn rel_err(x: &DMatrix<f64>, exact: &DMatrix<f64>) -> f64 {
        (x - exact).norm() / exact.norm()
    }

    /// `e^A` through the eigendecomposition of a symmetric `A`.
    fn expm_sym_eig(a: &DMatrix<f64>) -> DMatrix<f64> {
        let eig = a.clone().symmetric_eigen();
        let v = &eig.eigenvectors;
        let d = DMatrix::from_diagonal(&eig.eigenvalues.map(f64::exp));
        v * d * v.transpose()
    }

    fn random_symmetric(rng: &mut Rng, n: usize, norm2: f64) -> DMatrix<f64> {
        let g = rng.matrix(n, n);
        let s = (&g + g.transpose()) * 0.5;
        let nrm = s.clone().symmetric_eigen().eigenvalues.amax();
        s * (norm2 / nrm)
    }

    #[test]
    fn pade_coefficients_follow_the_closed_form() {
        // p_m(x) = Σ_j (2m−j)! m! / ((2m)! j! (m−j)!) x^j, so b_j / b_{j+1} = (j+1)(2m−j)/(m−j).
        let tables: [&[f64]; 5] = [&B3, &B5, &B7, &B9, &B13];
        for b in tables {
            let m = b.len() - 1;
            assert_eq!(b[m], 1.0);
            for j in 0..m {
                let ratio = ((j + 1) * (2 * m - j)) as f64 / (m - j) as f64;
                assert!(
                    (b[j] / b[j + 1] - ratio).abs() <= 4.0 * U * ratio,
                    "m = {m}, j = {j}"
                );
            }
        }
    }

    #[test]
    fn zero_scalar_and_diagonal() {
        let z = DMatrix::<f64>::zeros(4, 4);
        assert_eq!(expm(&z).unwrap(), DMatrix::identity(4, 4));
        let mut worst = 0.0f64;
        for &x in &[-700.0, -30.0, -1.0, -1e-3, 1e-12, 0.3, 2.0, 20.0, 700.0] {
            let e = expm(&DMatrix::from_element(1, 1, x)).unwrap()[(0, 0)];
            let rel = (e - x.exp()).abs() / x.exp();
            worst = worst.max(rel);
            assert!(rel <= 2.0 * U, "x = {x}: rel {rel:e}");
        }
        eprintln!("scalar: worst rel error = {worst:.2e}");
        let mut rng = Rng::new(1);
        let d: Vec<f64> = (0..7).map(|_| 40.0 * rng.uniform() - 20.0).collect();
        let a = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(d.clone()));
        let e = expm(&a).unwrap();
        let mut worst = 0.0f64;
        for i in 0..7 {
            for j in 0..7 {
                if i != j {
                    assert_eq!(e[(i, j)], 0.0);
                }
            }
            let rel = (e[(i, i)] - d[i].exp()).abs() / d[i].exp();
            worst = worst.max(rel);
            assert!(rel <= 2.0 * U, "{i}: {rel:e}");
        }
        eprintln!("diagonal (|d| ≤ 20): worst entrywise rel error = {worst:.2e}");
    }

    #[test]
    fn nilpotent_matches_finite_series() {
        let mut rng = Rng::new(2);
        for &(n, scale) in &[(2usize, 1.0), (6, 1.0), (6, 5.0), (10, 2.0)] {
            let mut a = rng.matrix(n, n) * scale;
            for j in 0..n {
                for i in j..n {
                    a[(i, j)] = 0.0;
                }
            }
            let mut exact = DMatrix::identity(n, n);
            let mut term = DMatrix::identity(n, n);
            for k in 1..n {
                term = &term * &a / k as f64;
                exact += &term;
            }
            let rel = rel_err(&expm(&a).unwrap(), &exact);
            eprintln!("nilpotent n = {n}, scale {scale}: rel error {rel:.2e}");
            assert!(rel <= 1e-13, "n = {n}: {rel:e}");
        }
        // A² = 0 with a huge entry: r_m is exact, e^A = I + A.
        let mut a = DMatrix::zeros(2, 2);
        a[(0, 1)] = 1e150;
        let e = expm(&a).unwrap();
        assert_eq!(e, DMatrix::from_row_slice(2, 2, &[1.0, 1e150, 0.0, 1.0]));
    }

    #[test]
    fn rotation_generator_gives_cos_and_sin() {
        for &theta in &[1e-8, 0.1, 1.0, 3.0, 10.0, 100.0, 1000.0] {
            let a = DMatrix::from_row_slice(2, 2, &[0.0, theta, -theta, 0.0]);
            let e = expm(&a).unwrap();
            let (c, s) = (f64::cos(theta), f64::sin(theta));
            let exact = DMatrix::from_row_slice(2, 2, &[c, s, -s, c]);
            let err = (&e - &exact).amax();
            eprintln!(
                "rotation θ = {theta}: max abs error {err:.2e} (= {:.1} θu)",
                err / (theta.max(1.0) * U)
            );
            // cos/sin of θ are themselves only determined to ~θu by the rounding of θ.
            assert!(err <= 16.0 * U * theta.max(1.0), "θ = {theta}: {err:e}");
        }
    }

    #[test]
    fn jordan_blocks() {
        for &lambda in &[-5.0, -0.5, 0.0, 0.5, 3.0] {
            let a = DMatrix::from_row_slice(2, 2, &[lambda, 1.0, 0.0, lambda]);
            let el = f64::exp(lambda);
            let exact = DMatrix::from_row_slice(2, 2, &[el, el, 0.0, el]);
            let rel = rel_err(&expm(&a).unwrap(), &exact);
            assert!(
                rel <= 8.0 * U * f64::max(1.0, lambda.abs()),
                "λ = {lambda}: {rel:e}"
            );
            // 4×4 block: e^λ times the upper Toeplitz matrix of 1/k!.
            let n = 4;
            let a4 = DMatrix::from_fn(n, n, |i, j| {
                if i == j {
                    lambda
                } else if j == i + 1 {
                    1.0
                } else {
                    0.0
                }
            });
            let fact = [1.0, 1.0, 2.0, 6.0];
            let exact4 = DMatrix::from_fn(n, n, |i, j| if j >= i { el / fact[j - i] } else { 0.0 });
            let rel4 = rel_err(&expm(&a4).unwrap(), &exact4);
            eprintln!("Jordan λ = {lambda}: rel error 2×2 {rel:.2e}, 4×4 {rel4:.2e}");
            assert!(
                rel4 <= 16.0 * U * f64::max(1.0, lambda.abs()),
                "λ = {lambda}: {rel4:e}"
            );
        }
    }

    #[test]
    fn triangular_matches_parlett_recurrence() {
        // Parlett (from F T = T F): F_ii = e^{t_ii},
        // F_ij = (t_ij (F_jj − F_ii) − Σ_{i<k<j} (F_ik t_kj − t_ik F_kj)) / (t_jj − t_ii),
        // accurate for well separated diagonal entries.
        let mut rng = Rng::new(12);
        let n = 6;
        let diag = [-20.0, -13.0, -6.5, 0.5, 3.0, 7.0];
        let t = DMatrix::from_fn(n, n, |i, j| {
            if i == j {
                diag[i]
            } else if j > i {
                3.0 * rng.normal()
            } else {
                0.0
            }
        });
        let mut f = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            f[(i, i)] = t[(i, i)].exp();
        }
        for d in 1..n {
            for i in 0..(n - d) {
                let j = i + d;
                let mut num = t[(i, j)] * (f[(j, j)] - f[(i, i)]);
                for k in (i + 1)..j {
                    num -= f[(i, k)] * t[(k, j)] - t[(i, k)] * f[(k, j)];
                }
                f[(i, j)] = num / (t[(j, j)] - t[(i, i)]);
            }
        }
        let (e, plan) = expm_with_plan(&t).unwrap();
        let rel = rel_err(&e, &f);
        eprintln!(
            "upper triangular n = 6 vs Parlett: s = {}, rel error {rel:.2e}",
            plan.squarings
        );
        assert!(rel <= 1e-13, "{rel:e}");
        for i in 0..n {
            assert!(((e[(i, i)] - f[(i, i)]) / f[(i, i)]).abs() <= 2.0 * U);
        }
        let el = expm(&t.transpose()).unwrap();
        assert_eq!(el, e.transpose());
    }

    #[test]
    fn moler_van_loan_example() {
        // A = [[−49, 24], [−64, 31]] = V diag(−1, −17) V⁻¹, V = [[1, 3], [2, 4]]: the Taylor series
        // suffers catastrophic cancellation here (Moler & Van Loan 1978).
        let a = DMatrix::from_row_slice(2, 2, &[-49.0, 24.0, -64.0, 31.0]);
        let (x, y) = (f64::exp(-1.0), f64::exp(-17.0));
        let exact = DMatrix::from_row_slice(
            2,
            2,
            &[
                -2.0 * x + 3.0 * y,
                1.5 * x - 1.5 * y,
                -4.0 * x + 4.0 * y,
                3.0 * x - 2.0 * y,
            ],
        );
        let (e, plan) = expm_with_plan(&a).unwrap();
        let rel = rel_err(&e, &exact);
        eprintln!(
            "Moler–Van Loan example: m = {}, s = {}, rel error {rel:.2e}",
            plan.degree, plan.squarings
        );
        // κ_exp(A) ≈ ‖A‖ ≈ 10², so ~1e-14 is the best one can expect.
        assert!(rel <= 1e-13, "{rel:e}");
    }

    #[test]
    fn commuting_sum_inverse_and_doubling() {
        let mut rng = Rng::new(3);
        for &(n, scale) in &[(3usize, 0.5), (6, 1.0), (12, 2.0), (60, 3.0)] {
            let m = rng.matrix(n, n) * (scale / (n as f64).sqrt());
            let ident = DMatrix::<f64>::identity(n, n);
            // Polynomials in M commute.
            let a = &m + &m * &m * 0.3;
            let b = &ident * 0.7 - &m * 2.0;
            let ea = expm(&a).unwrap();
            let eb = expm(&b).unwrap();
            let eab = expm(&(&a + &b)).unwrap();
            let rel_sum = rel_err(&(&ea * &eb), &eab);
            let ema = expm(&(-&a)).unwrap();
            let inv = (&ea * &ema - &ident).norm() / (ea.norm() * ema.norm());
            let e2a = expm(&(&a * 2.0)).unwrap();
            let rel_dbl = rel_err(&(&ea * &ea), &e2a);
            eprintln!(
                "n = {n}: e^(A+B) vs e^A e^B {rel_sum:.2e}, e^A e^-A − I {inv:.2e}, e^2A vs (e^A)² {rel_dbl:.2e}"
            );
            let tol = 200.0 * n as f64 * U;
            assert!(rel_sum <= tol, "{rel_sum:e}");
            assert!(inv <= tol, "{inv:e}");
            assert!(rel_dbl <= tol, "{rel_dbl:e}");
        }
    }

    #[test]
    fn agrees_with_diagonalisation_for_symmetric_matrices() {
        let mut rng = Rng::new(4);
        for &n in &[2usize, 5, 20, 64] {
            for &norm2 in &[1e-3, 0.2, 1.0, 5.0, 20.0, 50.0] {
                let a = random_symmetric(&mut rng, n, norm2);
                let rel = rel_err(&expm(&a).unwrap(), &expm_sym_eig(&a));
                eprintln!("symmetric n = {n}, ‖A‖₂ = {norm2}: rel error vs eig {rel:.2e}");
                // Both routes err by O(n u ‖A‖) relative to ‖e^A‖.
                assert!(
                    rel <= 20.0 * n as f64 * U * norm2.max(1.0),
                    "n = {n}, ‖A‖ = {norm2}: {rel:e}"
                );
            }
        }
    }

    #[test]
    fn large_norm_is_stable() {
        let mut rng = Rng::new(5);
        // Symmetric, spectrum in [−1000, 0.5]: 8 or more squarings, no blow-up.
        for &n in &[4usize, 16] {
            let q = rng.orthogonal(n);
            let mut d: Vec<f64> = (0..n).map(|_| -1000.0 * rng.uniform()).collect();
            d[0] = 0.5;
            d[1] = -1000.0;
            let a = &q
                * DMatrix::from_diagonal(&nalgebra::DVector::from_vec(d.clone()))
                * q.transpose();
            let (e, plan) = expm_with_plan(&a).unwrap();
            let rel = rel_err(&e, &expm_sym_eig(&a));
            eprintln!(
                "‖A‖ ≈ 1e3 symmetric n = {n}: s = {}, rel error {rel:.2e}",
                plan.squarings
            );
            assert!(plan.degree == 13 && plan.squarings >= 8);
            assert!(rel <= 1e-11, "{rel:e}");
        }
        // Non-normal triangular with a large off-diagonal entry: exact divided difference formula.
        for &(a11, a22, a12) in &[
            (-1.0, -2.0, 1e3),
            (-1.0, -2.0, 1e8),
            (0.5, -3.0, -1e4),
            (-10.0, -12.0, 1e6),
        ] {
            let a = DMatrix::from_row_slice(2, 2, &[a11, a12, 0.0, a22]);
            let (e, plan) = expm_with_plan(&a).unwrap();
            let (e1, e2) = (f64::exp(a11), f64::exp(a22));
            let f12 = a12 * (e1 - e2) / (a11 - a22);
            let errs = [
                ((e[(0, 0)] - e1) / e1).abs(),
                ((e[(1, 1)] - e2) / e2).abs(),
                ((e[(0, 1)] - f12) / f12).abs(),
            ];
            let worst = errs.iter().cloned().fold(0.0, f64::max);
            eprintln!(
                "non-normal [[{a11}, {a12:e}], [0, {a22}]]: m = {}, s = {}, entrywise rel error {worst:.2e}",
                plan.degree, plan.squarings
            );
            assert_eq!(e[(1, 0)], 0.0);
            // ‖A‖₁ = |a12| would ask for log₂(|a12|/4.25) squarings; the d_k-based choice needs few.
            assert!(plan.squarings <= 6, "s = {}", plan.squarings);
            assert!(worst <= 1e-13, "{worst:e}");
        }
    }

    #[test]
    fn tiny_norm() {
        let mut rng = Rng::new(6);
        for &scale in &[1e-300, 1e-20, 1e-10, 1e-5] {
            let a = rng.matrix(5, 5) * scale;
            let (e, plan) = expm_with_plan(&a).unwrap();
            let ident = DMatrix::<f64>::identity(5, 5);
            // Taylor: the remainder after A²/2 is O(‖A‖³/6) ≤ 1e-15·(‖A‖/1e-5)³.
            let taylor = &ident + &a + &a * &a * 0.5 + &a * &a * &a / 6.0;
            let rel = rel_err(&e, &taylor);
            eprintln!("‖A‖ ~ {scale:e}: m = {}, rel error {rel:.2e}", plan.degree);
            assert!(rel <= 4.0 * U, "{rel:e}");
            assert!(plan.degree <= 5 && plan.squarings == 0);
            // The correction e^A − I carries A to full relative accuracy for these tiny norms.
            let rel_a = rel_err(&(&e - &ident), &(&taylor - &ident));
            if scale >= 1e-20 {
                assert!(rel_a <= 1e-6, "{rel_a:e}");
            }
        }
    }

    #[test]
    fn overflow_and_underflow() {
        // e^1000 overflows: a clear error, not infinities.
        let a = DMatrix::from_diagonal_element(3, 3, 1000.0);
        assert!(matches!(expm(&a), Err(Error::InvalidInput(m)) if m.contains("overflows")));
        let a = DMatrix::from_element(2, 2, 1e300);
        assert!(matches!(expm(&a), Err(Error::InvalidInput(_))));
        // ‖A‖₁ itself overflows.
        let a = DMatrix::from_element(3, 3, 1e308);
        assert!(matches!(expm(&a), Err(Error::InvalidInput(m)) if m.contains("‖A‖₁")));
        // A huge rotation: e^A is orthogonal but not computable to any accuracy; must not be ∞/NaN.
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1e300, -1e300, 0.0]);
        match expm(&a) {
            Ok(e) => assert!(e.iter().all(|v| v.is_finite())),
            Err(e) => assert!(matches!(e, Error::InvalidInput(_))),
        }
        // e^{−10³⁰⁰ I} underflows to 0, which is the correctly rounded answer.
        let a = DMatrix::from_diagonal_element(2, 2, -1e300);
        let e = expm(&a).unwrap();
        assert!(e.iter().all(|&v| v == 0.0));
        // Just below the overflow threshold.
        let a = DMatrix::from_diagonal_element(2, 2, 700.0);
        let e = expm(&a).unwrap();
        assert!(((e[(0, 0)] - 700f64.exp()) / 700f64.exp()).abs() <= 1e-12);
    }

    #[test]
    fn power_of_two_scaling_is_bounded_for_any_exponent() {
        // The subnormal-Q hang: log₂(∞) cast to i64 is i64::MAX, which the old loop walked down
        // 1000 at a time.
        assert_eq!(ldexp(1.0, i64::MAX), f64::INFINITY);
        assert_eq!(ldexp(1.0, i64::MIN), 0.0);
        assert_eq!(ldexp(3.0, -1075 - 2), 0.0);
        assert_eq!(
            ldexp(f64::MIN_POSITIVE, 1100),
            f64::MIN_POSITIVE * 2f64.powi(1000) * 2f64.powi(100)
        );
        let m = DMatrix::from_element(1, 1, 5e-324);
        assert_eq!(scale_pow2(&m, i64::MAX)[(0, 0)], f64::INFINITY);
        assert_eq!(scale_pow2(&m, 1074)[(0, 0)], 1.0);
        assert_eq!(log2_ratio(0.7, 7e-311), 1030);
        assert_eq!(log2_ratio(1.0, 5e-324), 1074);
    }

    #[test]
    fn van_loan_with_subnormal_tiny_and_huge_q() {
        // A = −I: H = q (1 − e^{−2t})/2 · I exactly; the case is q = 1e-310, t = 0.7.
        let a = -DMatrix::<f64>::identity(2, 2);
        for &q in &[5e-324, 1e-310, 6e-309, 1e-300, 1e-200, 1e200, 1e300] {
            let vl = van_loan(&a, &(DMatrix::identity(2, 2) * q), 0.7).unwrap();
            let exact = q * -f64::exp_m1(-1.4) / 2.0;
            let err = (vl.h[(0, 0)] - exact).abs();
            // Relative accuracy down to the subnormal range, where the spacing is 5e-324.
            assert!(err <= 8.0 * U * exact + 2.0 * 5e-324, "q = {q:e}: {err:e}");
            assert_eq!(vl.h[(0, 1)], 0.0);
            assert!((vl.e[(0, 0)] - (-0.7f64).exp()).abs() <= 4.0 * U);
        }
        // Non-normal A: H is linear in Q, so H(qQ) = q H(Q) (exact scaling by powers of two aside,
        // to rounding; to the subnormal spacing below 2^-1022).
        let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.3, 0.2, -2.0]);
        let q0 = DMatrix::from_row_slice(2, 2, &[1.0, 0.2, 0.2, 0.5]);
        let h0 = van_loan(&a, &q0, 0.7).unwrap().h;
        for &q in &[1e-310, 1e-300, 1e300] {
            let h = van_loan(&a, &(&q0 * q), 0.7).unwrap().h;
            let err = (&h - &h0 * q).amax();
            assert!(
                err <= 1e-14 * q * h0.amax() + 4.0 * 5e-324,
                "q = {q:e}: {err:e}"
            );
        }
    }

    #[test]
    fn bad_input_is_rejected() {
        assert!(matches!(expm(&DMatrix::zeros(2, 3)), Err(Error::Shape(_))));
        assert!(matches!(expm(&DMatrix::zeros(0, 0)), Err(Error::Shape(_))));
        let mut a = DMatrix::<f64>::zeros(2, 2);
        a[(1, 0)] = f64::NAN;
        assert!(matches!(expm(&a), Err(Error::NonFinite(_))));
        a[(1, 0)] = f64::INFINITY;
        assert!(matches!(expm(&a), Err(Error::NonFinite(_))));

        let a = DMatrix::<f64>::identity(2, 2);
        let q = DMatrix::<f64>::identity(2, 2);
        assert!(matches!(
            van_loan(&a, &DMatrix::zeros(3, 3), 1.0),
            Err(Error::Shape(_))
        ));
        assert!(matches!(
            van_loan(&DMatrix::zeros(2, 3), &q, 1.0),
            Err(Error::Shape(_))
        ));
        assert!(matches!(
            van_loan(&a, &q, -1.0),
            Err(Error::InvalidInput(_))
        ));
        assert!(matches!(
            van_loan(&a, &q, f64::NAN),
            Err(Error::NonFinite(_))
        ));
        assert!(matches!(
            van_loan(&a, &q, f64::INFINITY),
            Err(Error::NonFinite(_))
        ));
        let mut qn = q.clone();
        qn[(0, 1)] = f64::NAN;
        assert!(matches!(van_loan(&a, &qn, 1.0), Err(Error::NonFinite(_))));
        let mut qa = q.clone();
        qa[(0, 1)] = 0.5;
        assert!(
            matches!(van_loan(&a, &qa, 1.0), Err(Error::InvalidInput(m)) if m.contains("symmetric"))
        );
        let big = DMatrix::from_diagonal_element(2, 2, 1000.0);
        assert!(matches!(
            van_loan(&big, &q, 1.0),
            Err(Error::InvalidInput(_))
        ));
        // ‖Q‖₁ overflows although every entry is finite.
        let qbig = DMatrix::from_element(2, 2, 1e308);
        assert!(
            matches!(van_loan(&a, &qbig, 1.0), Err(Error::InvalidInput(m)) if m.contains("‖Q‖₁"))
        );
        // H itself overflows: Q (e^{2t} − 1)/2 with Q = 1e300, t = 10.
        let q300 = DMatrix::from_diagonal_element(2, 2, 1e300);
        assert!(matches!(
            van_loan(&a, &q300, 10.0),
            Err(Error::InvalidInput(_))
        ));
        // … while a huge but representable H is computed: A = 0 gives H = Q t exactly.
        let vl = van_loan(&DMatrix::zeros(2, 2), &q300, 10.0).unwrap();
        assert_eq!(vl.h[(0, 0)], 1e301);
    }

    /// Relative residual of the Lyapunov identity `A H + H Aᵀ = E Q Eᵀ − Q` (exact for Van Loan's H).
    fn lyapunov_residual(a: &DMatrix<f64>, q: &DMatrix<f64>, vl: &VanLoan) -> f64 {
        let (e, h) = (&vl.e, &vl.h);
        let lhs = a * h + h * a.transpose();
        let rhs = e * q * e.transpose() - q;
        let scale = 2.0 * a.norm() * h.norm() + e.norm().powi(2) * q.norm() + q.norm();
        (lhs - rhs).norm() / scale
    }

    /// `∫₀ᵗ e^{As} Q e^{Aᵀs} ds` by composite 5-point Gauss–Legendre quadrature.
    fn van_loan_quadrature(
        a: &DMatrix<f64>,
        q: &DMatrix<f64>,
        t: f64,
        panels: usize,
    ) -> DMatrix<f64> {
        let nodes = [
            0.0,
            -0.538_469_310_105_683_1,
            0.538_469_310_105_683_1,
            -0.906_179_845_938_664,
            0.906_179_845_938_664,
        ];
        let weights = [
            0.568_888_888_888_888_9,
            0.478_628_670_499_366_5,
            0.478_628_670_499_366_5,
            0.236_926_885_056_189_1,
            0.236_926_885_056_189_1,
        ];
        let n = a.nrows();
        let h = t / panels as f64;
        let mut sum = DMatrix::zeros(n, n);
        for p in 0..panels {
            let mid = (p as f64 + 0.5) * h;
            for (x, w) in nodes.iter().zip(&weights) {
                let s = mid + 0.5 * h * x;
                let e = expm(&(a * s)).unwrap();
                sum += (&e * q * e.transpose()) * (0.5 * h * w);
            }
        }
        sum
    }

    #[test]
    fn van_loan_satisfies_the_lyapunov_identity() {
        let mut rng = Rng::new(7);
        for &n in &[1usize, 3, 8, 30] {
            for &t in &[1e-6, 0.1, 1.0, 5.0] {
                let a = rng.matrix(n, n) * (1.0 / (n as f64).sqrt());
                let q = rng.psd(n, n.div_ceil(2));
                let vl = van_loan(&a, &q, t).unwrap();
                let res = lyapunov_residual(&a, &q, &vl);
                let e_ref = expm(&(&a * t)).unwrap();
                let e_rel = rel_err(&vl.e, &e_ref);
                eprintln!("van Loan n = {n}, t = {t}: Lyapunov residual {res:.2e}, E vs expm(At) {e_rel:.2e}");
                assert!(res <= 50.0 * n as f64 * U, "n = {n}, t = {t}: {res:e}");
                assert!(e_rel <= 100.0 * n as f64 * U * (1.0 + t), "{e_rel:e}");
                assert_eq!(vl.h, vl.h.transpose());
                let min_eig = vl.h.clone().symmetric_eigen().eigenvalues.min();
                assert!(min_eig >= -50.0 * n as f64 * U * vl.h.norm(), "{min_eig:e}");
            }
        }
    }

    #[test]
    fn van_loan_matches_quadrature() {
        let mut rng = Rng::new(8);
        for &(n, t) in &[(2usize, 0.5), (4, 1.0), (5, 3.0)] {
            let a = rng.matrix(n, n) * 0.7;
            let q = rng.psd(n, 2);
            let vl = van_loan(&a, &q, t).unwrap();
            let quad = van_loan_quadrature(&a, &q, t, 200);
            let rel = rel_err(&vl.h, &quad);
            eprintln!("van Loan vs Gauss–Legendre (n = {n}, t = {t}): rel {rel:.2e}");
            assert!(rel <= 1e-12, "{rel:e}");
        }
    }

    #[test]
    fn van_loan_matches_closed_form_for_symmetric_a() {
        // A = V Λ Vᵀ: H = V [ (VᵀQV)_ij (e^{(λi+λj)t} − 1)/(λi+λj) ] Vᵀ.
        let mut rng = Rng::new(9);
        for &(n, norm2, t) in &[
            (3usize, 1.0, 1.0),
            (6, 10.0, 2.0),
            (10, 100.0, 0.5),
            (8, 0.01, 100.0),
        ] {
            let g = random_symmetric(&mut rng, n, norm2);
            // Shift to make A stable: long horizons then test the doubling path.
            let a = &g - DMatrix::identity(n, n) * (1.05 * norm2);
            let q = rng.psd(n, n);
            let eig = a.clone().symmetric_eigen();
            let v = &eig.eigenvectors;
            let lam = &eig.eigenvalues;
            let qt = v.transpose() * &q * v;
            let core = DMatrix::from_fn(n, n, |i, j| {
                let s = lam[i] + lam[j];
                qt[(i, j)] * f64::exp_m1(s * t) / s
            });
            let exact = v * core * v.transpose();
            let vl = van_loan(&a, &q, t).unwrap();
            let rel = rel_err(&vl.h, &exact);
            eprintln!(
                "van Loan vs closed form (n = {n}, ‖A‖ ≈ {:.0}, t = {t}): rel {rel:.2e}",
                2.05 * norm2
            );
            assert!(rel <= 1e-12, "{rel:e}");
        }
        // A long horizon with a stable A: e^{−At} = e^{1000} would overflow in the one-shot block.
        let a = DMatrix::from_diagonal_element(2, 2, -10.0);
        let q = DMatrix::identity(2, 2);
        let vl = van_loan(&a, &q, 100.0).unwrap();
        let exact = -f64::exp_m1(-2000.0) / 20.0;
        assert!(((vl.h[(0, 0)] - exact) / exact).abs() <= 1e-14);
        assert_eq!(vl.h[(0, 1)], 0.0);
        assert!(vl.e.iter().all(|&v| v.abs() < 1e-300));
    }

    #[test]
    fn van_loan_scalar_zero_q_and_zero_t() {
        for &(a, q, t) in &[
            (-2.0, 3.0, 0.7),
            (0.5, 1e-30, 2.0),
            (1e-9, 1e20, 1.0),
            (-1e-3, 1.0, 1e4),
        ] {
            let vl = van_loan(
                &DMatrix::from_element(1, 1, a),
                &DMatrix::from_element(1, 1, q),
                t,
            )
            .unwrap();
            let exact = q * f64::exp_m1(2.0 * a * t) / (2.0 * a);
            let rel = ((vl.h[(0, 0)] - exact) / exact).abs();
            assert!(rel <= 1e-13, "a = {a}, q = {q}, t = {t}: {rel:e}");
            assert!(((vl.e[(0, 0)] - f64::exp(a * t)) / f64::exp(a * t)).abs() <= 1e-13);
        }
        let mut rng = Rng::new(10);
        let a = rng.matrix(4, 4);
        let q = rng.psd(4, 2);
        let vl = van_loan(&a, &q, 0.0).unwrap();
        assert_eq!(vl.e, DMatrix::identity(4, 4));
        assert_eq!(vl.h, DMatrix::zeros(4, 4));
        let vl = van_loan(&a, &DMatrix::zeros(4, 4), 1.5).unwrap();
        assert_eq!(vl.h, DMatrix::zeros(4, 4));
        assert!(rel_err(&vl.e, &expm(&(&a * 1.5)).unwrap()) <= 1e-15);
        // A = 0: H = Q t exactly (nilpotent block, r_m exact).
        let vl = van_loan(&DMatrix::zeros(4, 4), &q, 2.5).unwrap();
        assert!(rel_err(&vl.h, &(&q * 2.5)) <= 4.0 * U);
    }
}
