//! The Newton–Kantorovich certificate of a warm-started CARE solution: a proof that a stabilising
//! solution `Σ*` exists within a computed radius of the returned `Σ`, and the error bounds it
//! gives. A warm result is accepted only with this proof (there is no Hamiltonian whose spectrum
//! could be examined, as the cold solve does).
//!
//! **Setting.** `F(Σ) = AΣ + ΣAᵀ − ΣWΣ + Q`, `F'(Σ)D = Ω_Σ(D) = A_cl D + D A_clᵀ` with
//! `A_cl = A − ΣW`; `‖F'(Σ) − F'(Σ')‖ ≤ 2‖W‖‖Σ − Σ'‖` on symmetric matrices with the spectral norm.
//! `−Ω⁻¹` is a positive map, so `‖Ω⁻¹‖₂→₂ = ‖Ω⁻¹(I)‖₂ = ‖p‖₂` (Russo–Dye). Every spectral norm
//! below is replaced by an upper bound: `min(‖·‖_F, ‖·‖_∞)` for the symmetric `p`, `W` and `Δ̂`
//! (`‖m‖₂ ≤ ‖m‖_∞` for symmetric `m`), the Frobenius norm for the residuals.
//!
//! **The operator at hand** is the factored closed loop of a point `Σ_f` at distance
//! `s = ‖Σ − Σ_f‖` (0 when it is `Σ`'s own): with `q = 2‖p‖‖W‖s < ½`, the Banach lemma gives
//! `‖Ω_Σ⁻¹‖ ≤ ℓ = ‖p‖/(1 − q)` and `‖Ω_Σ⁻¹F(Σ)‖ ≤ δ = δ_f/(1 − q)`, where `δ_f` bounds
//! `‖Ω_f⁻¹F(Σ)‖`: the norm of the computed correction `Δ̂ ≈ Ω_f⁻¹(−R̂)` plus `‖p‖` times the solve's
//! residual (with its rounding, `(ρ + γ)(2‖A_cl‖‖Δ̂‖ + ‖R̂‖)`, `γ = (2n + 4)·eps`) and the
//! residual's own rounding bound `‖E‖` (`R̂` is `F(Σ)` up to `E`).
//!
//! **Kantorovich.** When `h = ℓ‖W‖δ < ¼` (the theorem's `βLη ≤ ½` with `L = 2‖W‖`), `F` has a
//! zero `Σ*` with `‖Σ* − Σ‖₂ ≤ ρ = 2δ/(1 + √(1 − 4h))`. It is the stabilising one: `A − Σ*W` is
//! `A − ΣW` perturbed by less than `ρ‖W‖ < 1/(2ℓ)`, and `A − ΣW` is Hurwitz with
//! `‖−Ω_Σ⁻¹(I)‖ ≤ ℓ`, so the Lyapunov robustness bound keeps it Hurwitz (`A − Σ_f W` is Hurwitz
//! by its computed spectrum and `q < ½` keeps `A − ΣW` so). Then
//! `Σ* − Σ = Ω_Σ⁻¹(−F(Σ) + ΔWΔ)` gives `|tr Σ* − tr Σ| ≤ |tr p_Σ| (‖R̂‖ + ‖E‖ + ‖W‖ρ²)`, with
//! `|tr p_Σ| ≤ |tr p| + n‖p‖q/(1 − q)`.

use super::{soft, Fallback, Iterate, Problem};
use crate::care::refine::norm2_bound_symmetric;
use crate::linalg::dense::norm_fro;
use crate::Result;
use nalgebra::DMatrix;

/// What the certificate proves about a returned `Σ`.
pub(super) struct Proof {
    /// The Newton–Kantorovich quantity `h < ¼`.
    pub(super) h: f64,
    /// `ρ ≥ ‖Σ* − Σ‖₂`.
    pub(super) radius: f64,
    /// A bound on `|tr Σ* − tr Σ|`.
    pub(super) trace: f64,
}

/// The certificate of the iterate `it` (its residual `it.res` accurate to `rounding`), with
/// `pm = Ω_f⁻¹(I)` of its factored closed loop; [`Fallback::NotCertified`] when `h ≥ ¼` (or the
/// factored operator is too far from the iterate's own, `q ≥ ½`). One Lyapunov solve on the kept
/// Schur form and two `n × n` products.
pub(super) fn kantorovich(
    p: &Problem<'_>,
    it: &Iterate,
    pm: &DMatrix<f64>,
    rounding: f64,
) -> Result<std::result::Result<Proof, Fallback>> {
    let n = it.x.nrows() as f64;
    let sol = match soft(it.lyap.solve_with_info(&(-&it.res)))? {
        Ok(s) => s,
        Err(f) => return Ok(Err(f)),
    };
    // Upper bounds of spectral norms of symmetric matrices: the smaller of ‖·‖_F and ‖·‖_∞ (the
    // latter much the tighter for the near-block-diagonal matrices of a network of subsystems).
    let p_norm = norm2_bound_symmetric(pm);
    let gn = norm2_bound_symmetric(p.w);
    let rn = norm_fro(&it.res);
    let dn = norm2_bound_symmetric(&sol.x);
    // ‖A − Σ_f W‖_F, Σ_f within `offset` of Σ.
    let a_cl = norm_fro(p.net.a()) + (it.xn + it.offset) * gn;
    let gamma = (2.0 * n + 4.0) * f64::EPSILON;
    let solve_error = (sol.residual + gamma) * (2.0 * a_cl * dn + rn);
    let delta_f = dn + p_norm * (solve_error + rounding);
    let q = 2.0 * p_norm * gn * it.offset;
    if !(q < 0.5) {
        return Ok(Err(Fallback::NotCertified { h: f64::INFINITY }));
    }
    let ell = p_norm / (1.0 - q);
    let delta = delta_f / (1.0 - q);
    let h = ell * gn * delta;
    if !(h < 0.25) {
        return Ok(Err(Fallback::NotCertified { h }));
    }
    let radius = 2.0 * delta / (1.0 + (1.0 - 4.0 * h).sqrt());
    let tr_p = pm.trace().abs() + n * p_norm * q / (1.0 - q);
    let trace = tr_p * (rn + rounding + gn * radius * radius);
    Ok(Ok(Proof { h, radius, trace }))
}
