//! Van Loan's integral: the discretisation of `dx = A x dt + dw`, `E[dw dwᵀ] = Q dt`, over a step.
//!
//! [`van_loan`] evaluates Van Loan's block exponential `expm([[−A, Q], [0, Aᵀ]] τ) = [[·, F₁₂], [0,
//! E(τ)ᵀ]]`, `H(τ) = E(τ) F₁₂`, on a step `τ = t/2^j` with `‖Aτ‖₁ ≤ 1`, then doubles up with
//! `H(2τ) = H(τ) + E(τ) H(τ) E(τ)ᵀ`, `E(2τ) = E(τ)²`. Mathematically this is the same integral; the
//! doubling avoids forming `e^{−At}`, which overflows (or loses all accuracy of `H`) for a stable
//! `A` over a long horizon, and for positive semidefinite `Q` it only ever adds positive
//! semidefinite terms. `Q` is scaled by a power of two (exact) so that its size does not inflate the
//! number of squarings of the block exponential.

use crate::linalg::dense::{
    all_finite, check_finite, check_shape, check_square, matmul, matmul_nt, norm_1, symmetrize,
};
use crate::linalg::expm::{expm, log2_ratio, scale_pow2, too_many_squarings, MAX_SQUARINGS};
use crate::{Error, Result};
use nalgebra::DMatrix;

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
