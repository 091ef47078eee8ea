//! Solutions at the ends of the double range: a gain `B R⁻¹ Bᵀ` that overflows or underflows
//! although its factor is finite (the equation rescaled exactly by a power of four), and the
//! bound widened by what the doubles of `X` cannot hold (subnormal or underflowed entries).

use super::{routes, validate, CareOptions, CareSolution, DataError};
use crate::linalg::dense::{matmul_nt, norm_fro, symmetrize};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// `G = BBᵀ` overflows, or underflows to 0, although `B` is finite and not 0 (`B R⁻¹ Bᵀ ~
/// 1e450` while `X*` may be ~1e-225; `~1e-450` while `X* ~ 1e300`): the equivalent equation for
/// `cX`, `Aᵀ(cX) + (cX)A − (cX)(G/c)(cX) + cQ = 0`, with `c = 4^k` balancing `‖G‖/c` against
/// `c‖Q‖` (the factor `B/2^k`, exact scalings), is solved and `X` recovered; `None` when the
/// scaled data are not finite either.
pub(super) fn rescaled_gain(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    data: DataError<'_>,
) -> Option<Result<CareSolution>> {
    let (bmax, qmax) = (b.amax(), q.amax());
    if !(bmax > 0.0 && bmax.is_finite() && qmax.is_finite()) {
        return None;
    }
    let lq = if qmax > 0.0 { qmax.log2() } else { 0.0 };
    let k = ((2.0 * bmax.log2() - lq) / 4.0)
        .round()
        .clamp(-500.0, 500.0) as i32;
    let (down, up) = (2f64.powi(-k), 2f64.powi(k));
    let bs = b * down;
    let qs = q * up * up;
    let gs = symmetrize(&matmul_nt(&bs, &bs));
    // Data lost to underflow (√(‖G‖‖Q‖) below the double range) or overflow: not this way.
    let lost = |m: &DMatrix<f64>, ms: &DMatrix<f64>| {
        m.iter().zip(ms.iter()).any(|(v, w)| *v != 0.0 && *w == 0.0)
    };
    if validate(a, &gs, &qs).is_err()
        || lost(b, &bs)
        || lost(q, &qs)
        || gs.iter().all(|&v| v == 0.0)
    {
        return None;
    }
    let user_b;
    let data = match data {
        DataError::Cholesky { r, b: ub, l } => {
            user_b = ub * down;
            DataError::Cholesky { r, b: &user_b, l }
        }
        other => other,
    };
    Some(
        routes(a, gs, Some(&bs), &symmetrize(&qs), opts, data).and_then(|mut sol| {
            sol.x = &sol.x * down * down;
            if !sol.x.iter().all(|v| v.is_finite()) {
                return Err(Error::NonFinite(
                    "the solution X overflows the double range (B R⁻¹ Bᵀ is tiny against Q)".into(),
                ));
            }
            sol.trace_error *= down * down;
            sol.scaling *= up * up;
            Ok(with_representation(sol, q))
        }),
    )
}

/// The bound widened by what the doubles of `X` cannot hold: entries below the normal range
/// are multiples of `2⁻¹⁰⁷⁴` (an absolute error up to `2⁻¹⁰⁷⁵` each, and more in the products
/// that formed them: `4n·2⁻¹⁰⁷⁴` in all is taken), and an `X` that underflowed to 0 although
/// `Q ≠ 0` (then `X* ≠ 0`) has relative error exactly 1. Nothing changes for `X` in the normal
/// range (the term is below `1e-290` relative there).
pub(super) fn with_representation(mut sol: CareSolution, q: &DMatrix<f64>) -> CareSolution {
    let n = sol.x.nrows() as f64;
    let xn = norm_fro(&sol.x);
    let tiny = f64::from_bits(1);
    let floor = if xn > 0.0 {
        4.0 * n * tiny / xn
    } else if q.iter().any(|&v| v != 0.0) {
        1.0
    } else {
        0.0
    };
    if !(sol.forward_error >= floor) {
        sol.forward_error = floor;
    } else if xn > 0.0 {
        sol.forward_error += floor;
    }
    sol
}
