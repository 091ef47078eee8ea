//! The closed-loop Lyapunov operator of a computed CARE solution, and what it gives: Newton
//! (defect-correction) refinement and a forward-error bound.
//!
//! With `X` the stabilising solution and `A_cl = A − G X`, an error `Δ = X* − X` satisfies
//! `Ω(Δ) − Δ G Δ = −R(X)`, `Ω(Δ) = A_clᵀ Δ + Δ A_cl`, `R(X) = AᵀX + XA − XGX + Q` (the residual).
//!
//! **The operator comes for free from the Schur step.** The ordered Schur form of the (scaled,
//! balanced) Hamiltonian gives `H̃ [U11; U21] = [U11; U21] T11`, hence `Ã_cl U11 = U11 T11`; with the
//! exact diagonal scaling `Ã_cl = D A_cl D⁻¹` this is `A_cl = V T11 V⁻¹`, `V = D⁻¹ U11`, and
//!
//! `Ω⁻¹(C) = D U11⁻ᵀ Y U11⁻¹ D`  where  `T11ᵀ Y + Y T11 = U11ᵀ (D⁻¹ C D⁻¹) U11`
//!
//! — a triangular Lyapunov solve and two solves with the LU of `U11` already computed for `X`.
//!
//! **Forward error.** `−Ω⁻¹` is a positive map (`−Ω⁻¹(C) = ∫ e^{A_clᵀt} C e^{A_cl t} dt`), so by the
//! Russo–Dye theorem its norm induced by the spectral norm is `‖Ω⁻¹(I)‖₂`, one solve. To first order
//! `‖Δ‖₂ ≤ ‖Ω⁻¹(I)‖₂ (‖R̂‖₂ + ‖E‖₂)`, with `R̂` the computed residual and `E` its rounding error,
//! bounded entrywise by `γ (|Aᵀ||X| + |X||A| + |X||G||X| + |Q|)`, `γ = (2n + 4)·eps`; the quadratic term is covered by the
//! Newton–Kantorovich factor `1/(1 − 2h)`, `h = ‖Ω⁻¹(I)‖₂ ‖G‖₂ ‖Δ‖₂` (only the first-order estimate when
//! `h ≥ 1/4`, where the first-order estimate is returned as SLICOT's FERR does). The relative
//! Frobenius error is at most `√n` times the relative spectral one.

use super::balance;
use crate::linalg::dense::{matmul, norm_fro, symmetrize, Lu};
use crate::linalg::sylvester::solve_lyapunov_quasi_triangular;
use crate::linalg::sylvester::Lyapunov;
use crate::Result;
use nalgebra::DMatrix;

/// The closed-loop Lyapunov operator `Ω` in the factored form above.
pub struct ClosedLoop<'a> {
    /// Leading `n×n` block of the ordered Schur form (quasi-triangular).
    pub t11: &'a DMatrix<f64>,
    /// LU of `U11ᵀ` (as used for `X`).
    pub lu: &'a Lu,
    /// `U11` itself.
    pub u11: &'a DMatrix<f64>,
    /// The diagonal scaling `D` from original to balanced coordinates (`Ã = D A D⁻¹`).
    pub d: &'a [f64],
}

impl ClosedLoop<'_> {
    /// `Ω⁻¹(C)` for symmetric `C` (pivots below `rtol·‖T11‖` fail).
    pub fn solve(&self, c: &DMatrix<f64>, rtol: f64) -> Result<DMatrix<f64>> {
        let n = c.nrows();
        let d = self.d;
        let cs = super::balance::inverse_congruence(c, d, 1.0);
        // W = U11ᵀ C' U11 with U11 taken as σ·V, σ a power of two near its largest entry: the
        // equation is linear, so Y/σ² solves it with VᵀC'V, and U11⁻ᵀYU11⁻¹ = σ·U11⁻ᵀ(σ·U11⁻ᵀ(Y/σ²))ᵀ
        // (exact scalings). Without σ, a badly scaled problem (‖X̃‖ ~ 1e225 in the scaled
        // coordinates, U11 ~ 1e-226) underflows W to 0 and with it every correction and bound.
        let top = self.u11.amax();
        let sigma = if top > 0.0 && top.is_finite() {
            super::hamiltonian::pow2_near(top)
        } else {
            1.0
        };
        let v = self.u11 / sigma;
        // Made exactly symmetric for the half-work triangular solve.
        let w = matmul(&v.transpose(), &matmul(&cs, &v));
        let mut y = symmetrize(&w);
        solve_lyapunov_quasi_triangular(self.t11, &mut y, true, rtol)?;
        // Z = U11⁻ᵀ Y U11⁻¹: the LU is of U11ᵀ, so `solve_in_place` applies U11⁻ᵀ.
        self.lu.solve_in_place(&mut y);
        y *= sigma;
        let mut z = y.transpose();
        self.lu.solve_in_place(&mut z);
        z *= sigma;
        Ok(DMatrix::from_fn(n, n, |i, j| {
            0.5 * (z[(i, j)] + z[(j, i)]) * d[i] * d[j]
        }))
    }
}

/// The error bounds of a computed solution `X`: `(relative Frobenius error, |tr X − tr X*|)`.
///
/// `p = Ω⁻¹(I)` (negative semidefinite; `‖p‖_F ≥ ‖p‖₂`), `residual ≥ ‖R̂‖₂`, `rounding ≥ ‖E‖₂`,
/// `g_norm ≥ ‖G‖₂` (Frobenius norms serve as these upper bounds). To first order
/// `‖Δ‖₂ ≤ ‖p‖₂ (‖R̂‖₂ + ‖E‖₂) =: ℓ` and `|tr Δ| ≤ |tr p| (‖R̂‖₂ + ‖E‖₂)`; when the
/// Newton–Kantorovich quantity `h = ‖p‖₂‖G‖₂ℓ` is below 1/4 both are multiplied by `1/(1 − 2h)`,
/// which covers the quadratic term. Above 1/4 (norm bounds of badly scaled data overestimate `h`
/// by orders of magnitude) the first-order estimate is returned, as SLICOT's FERR does. The
/// relative Frobenius error is at most `√n·‖Δ‖₂/‖X‖_F`; representing `X` adds `eps`.
pub fn error_bounds(
    p: &DMatrix<f64>,
    residual: f64,
    rounding: f64,
    g_norm: f64,
    x: &DMatrix<f64>,
) -> (f64, f64) {
    let n = x.nrows() as f64;
    let p_norm = norm_fro(p);
    let p_trace = p.trace().abs();
    let e = residual + rounding;
    let lin = p_norm * e;
    let h = p_norm * g_norm * lin;
    let factor = if h < 0.25 { 1.0 / (1.0 - 2.0 * h) } else { 1.0 };
    if !(lin.is_finite() && p_trace.is_finite()) {
        return (f64::INFINITY, f64::INFINITY);
    }
    let nx = norm_fro(x);
    let forward = if nx > 0.0 {
        n.sqrt() * lin * factor / nx + f64::EPSILON
    } else if lin == 0.0 {
        0.0
    } else {
        f64::INFINITY
    };
    let trace = p_trace * e * factor + f64::EPSILON * x.trace().abs();
    (forward, trace)
}

/// The closed-loop operator used for corrections and the error bound: the one from the Schur
/// form, or a freshly factored `Ã_cl` (balanced coordinates) when the former stalled.
pub(crate) enum Operator<'a> {
    Frozen(ClosedLoop<'a>),
    Fresh(Box<Lyapunov>, &'a [f64]),
    /// The factored transpose `(A − G X)ᵀ` in the original coordinates (a caller that works in the
    /// filter form, e.g. a warm-started cost evaluation): `Ω⁻¹(C)` is its `solve`.
    Transposed(&'a Lyapunov),
}

impl Operator<'_> {
    /// `Ω⁻¹(C)` in the original coordinates (`Ω(Δ) = A_clᵀΔ + ΔA_cl`).
    pub(crate) fn solve(&self, c: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        match self {
            Operator::Frozen(cl) => cl.solve(c, 0.0),
            Operator::Fresh(lyap, d) => {
                let y = lyap.solve_adjoint(&balance::inverse_congruence(c, d, 1.0))?;
                Ok(balance::congruence(&y, d, 1.0))
            }
            Operator::Transposed(lyap) => lyap.solve(c),
        }
    }
}

/// `min(‖m‖_F, ‖m‖_∞) ≥ ‖m‖₂` for a symmetric `m` (`‖m‖₂ ≤ √(‖m‖₁‖m‖_∞) = ‖m‖_∞`).
pub fn norm2_bound_symmetric(m: &DMatrix<f64>) -> f64 {
    let inf = m
        .row_iter()
        .map(|row| row.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    norm_fro(m).min(inf)
}
