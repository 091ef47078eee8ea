//! Newton's iteration on the generalised CARE with a cross term, and its error certificate, on
//! the closed-loop pencil — never through `E⁻¹`.
//!
//! With `F(X) = AᵀXE + EᵀXA − C R⁻¹ Cᵀ + Q`, `C = EᵀXB + S`, `K = R⁻¹Cᵀ`, `A_K = A − BK` and
//! `G = BR⁻¹Bᵀ`, expanding `F` at `X + Δ` is exact at second order:
//!
//! ```text
//! F(X + Δ) = F(X) + Ω(Δ) − EᵀΔGΔE,   Ω(Δ) = A_KᵀΔE + EᵀΔA_K.
//! ```
//!
//! **Iteration.** `X ← X + Ω⁻¹(−F(X))` (Kleinman's step in residual form), `Ω` solved on the
//! generalised Schur form of the pencil `(A_K, E)` ([`GeneralizedLyapunov`], backward stable
//! whatever `κ(E)`); a step is kept while the relative residual falls, at most
//! [`MAX_STEPS`] steps. The form is reused (chord steps) while each step lowers the residual by
//! [`CHORD_GAIN`]: from the transformed problem's solution one QZ form usually serves the whole
//! iteration, and a fresh one is formed for the certificate.
//!
//! **Certificate.** When the pencil `(A_K, E)` is stable, `Ω(Δ) = Eᵀ(MᵀΔ + ΔM)E` with
//! `M = A_K E⁻¹` stable, so `−Ω⁻¹` is a positive map and (Russo–Dye) `‖Ω⁻¹‖₂ = ‖P‖₂ =: ℓ`,
//! `P = −Ω⁻¹(I)` (as computed). A solution is `X* = X + Δ` with `Δ = Φ(Δ) := Ω⁻¹(−F + EᵀΔGΔE)`.
//! With `Δ̂` the computed `Ω⁻¹(−F̂)` and `errs` a bound on `‖F − F̂‖₂` (rounding of the residual),
//! on `‖F̂ + Ω̂(Δ̂)‖₂` (the solve's residual and its rounding) and on `‖(Ω − Ω̂)(Δ̂)‖₂` (the
//! rounding of `A_K`), `η = ‖Δ̂‖₂ + ℓ·errs ≥ ‖Ω⁻¹(F)‖₂` and `‖Φ(Δ)‖₂ ≤ η + ℓγ‖Δ‖₂²`,
//! `γ = ‖E‖₂²‖G‖₂`. When `h = ℓγη < ¼`, `Φ` maps the ball `‖Δ‖₂ ≤ u = 2η/(1 + √(1 − 4h))` into
//! itself and contracts there (factor `2ℓγu < 4h < 1`): a unique solution `X*` lies in it, with
//! `‖X* − X − Δ̂‖₂ ≤ ℓ(errs + γu²)`. Its closed loop is stable: with `P ≻ 0`,
//! `(A_K − GΔE)ᵀPE + EᵀP(A_K − GΔE) = −I − (EᵀPGΔE + (…)ᵀ)`, negative definite because
//! `2ℓ‖E‖²‖G‖‖Δ‖ ≤ 2ℓγu < 1` — so `X*` is the stabilising solution ([`Proof::Strict`]).
//!
//! **Seen through `E` and `B`.** With an ill-conditioned `E`, `ℓ` is large and so is `ℓγ`, while
//! the quadratic term `EᵀΔGΔE = (EᵀΔB)R⁻¹(BᵀΔE)` only sees `v = ‖EᵀΔB‖₂`. Writing
//! `Ω⁻¹(C) = P^{1/2}ZP^{1/2}` with `‖Z‖₂ ≤ ‖C‖₂` (positivity), `‖EᵀΩ⁻¹(C)B‖₂ ≤ κ‖C‖₂` with
//! `κ = √(‖EᵀPE‖₂‖BᵀPB‖₂)`, and `Φ` maps `v ≤ u` into itself and contracts in that measure when
//! `h = κ‖R⁻¹‖₂u₀ < ¼`, `u₀ = ‖EᵀΔ̂B‖ + κ·errs`, `u = 2u₀/(1 + √(1 − 4h))`; then
//! `‖X* − X − Δ̂‖₂ ≤ ℓ(errs + ‖R⁻¹‖₂u²)`, and the closed loop of `X*` is stable since
//! `‖EᵀPB R⁻¹ BᵀΔE‖ ≤ κ‖R⁻¹‖u < ½`. The smaller of the two strict bounds is taken.
//!
//! **At the double-double point.** Where neither test passes at the final `X`, they are taken
//! at `Y = X + D` (`D` Newton corrections kept as a second double, `F(Y)` in double-double with
//! every rounding bounded; module `double_double_point`) and, when that proves the solution,
//! `fl(Y)` is returned with the bound at `Y` plus the rounding `Y − fl(Y)`. At a converged double
//! `X` with `cond(E) = 1e12` the test at `X` cannot pass: `errs` is the working-precision floor of
//! the residual (`3e-13 … 1.3e-11`) and `κ²‖R⁻¹‖·errs = 0.4 … 2.1` (`κ = 1.8e5 … 4.5e5`); at `Y`
//! the residual's error bound is `2e-16 … 5e-13` and the three problems of the audit family
//! `general` that were refused for it (scipy's errors 1.9e-3, 6.3e-6, 9.2e-5; first-order
//! bounds 2.6e-9, 6.0e-10, 1.2e-10 at errors 2.8e-14, 1.7e-14, 1.3e-15) are solved with errors
//! 3.9e-17, 4.6e-17, 3.8e-17 and strict bounds 1.8e-14, 1.6e-15, 1.6e-15.
//!
//! When neither test passes (at `X` nor at `Y`) only an estimate is returned ([`Proof::FirstOrder`], as SLICOT's
//! FERR and [`super::super::refine::error_bounds`] do when the quadratic term cannot be bounded):
//! `‖Δ̂‖ + √n·ℓ·(errs + 2q̂)`, `q̂ = ‖R⁻¹‖‖EᵀΔ̂B‖²` the quadratic term at the computed correction.
//! Without `q̂`, an iterate still far from Newton's quadratic regime was reported too accurate
//! (`cond(E) = 1e12` after ten steps: `q̂` a quarter of `‖F‖`, the first-order bound 6.7e-12
//! against an error of 7.5e-12). The bounds
//! are for the data as given in double precision; `P`, `‖EᵀPE‖` and `‖BᵀPB‖` are taken as
//! computed.

use super::super::refine::norm2_bound_symmetric;
use super::{congruence_inv, right_solve, Data, WELL_CONDITIONED_E};
use crate::linalg::dense::{matmul, matmul_tn, norm_fro, symmetrize, Lu};
use crate::linalg::sylvester::{GeneralizedLyapunov, Lyapunov};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// A chord step (on the operator of an earlier iterate) that does not lower the relative
/// residual by this factor makes the next step refresh the operator.
pub const CHORD_GAIN: f64 = 1e-3;

/// At most this many Newton steps (from a poor start, e.g. the transformed problem's solution
/// with `cond(E) = 1e12`, the iteration needs more than ten before it converges quadratically).
pub const MAX_STEPS: usize = 40;

/// What a certificate proved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Proof {
    /// Existence of the stabilising solution within the bound (Newton–Kantorovich).
    Strict,
    /// The first-order bound only.
    FirstOrder,
}

/// The refined solution and what is known about it.
pub(super) struct Certified {
    pub(super) x: DMatrix<f64>,
    /// Relative residual of the original equation.
    pub(super) residual: f64,
    pub(super) steps: usize,
    /// Bound on `‖X − X*‖_F / ‖X‖_F`.
    pub(super) forward: f64,
    /// Bound on `|tr X − tr X*|`.
    pub(super) trace: f64,
    /// Largest real part of the closed-loop pencil's eigenvalues.
    pub(super) abscissa: f64,
    pub(super) proof: Proof,
}

/// The operator `Ω(Δ) = A_KᵀΔE + EᵀΔA_K` factored once (`E = I`: the standard Lyapunov form).
pub(super) enum Operator {
    Standard(Lyapunov),
    Pencil(GeneralizedLyapunov),
    /// `Ω(Δ) = Eᵀ(MᵀΔ + ΔM)E`, `M = A_K E⁻¹`, solved as `L_M⁻ᵀ(E⁻ᵀCE⁻¹)`: for a well-conditioned
    /// `E` (accurate to `~κ(E)·eps`; the certificate checks the solves by their residuals), and
    /// when the QZ form fails its own check (faer's blocked QZ, no longer used, left a backward
    /// error of 2.3e-6 in `T` on one pencil of order 200 with `κ(E) = 1.3`; see [`crate::linalg::qz`]).
    Congruence(Lyapunov, Lu),
}

impl Operator {
    /// The operator for `(A_K, E)`: the QZ form when `ill_e`, else (or when that form fails its
    /// check and `E` is well conditioned) the congruence with `E⁻¹`.
    pub(super) fn new(a_k: &DMatrix<f64>, e: Option<&DMatrix<f64>>, ill_e: bool) -> Result<Self> {
        let Some(e) = e else {
            return Ok(Operator::Standard(
                Lyapunov::new(a_k)?.with_singular_rtol(0.0)?,
            ));
        };
        if ill_e {
            match GeneralizedLyapunov::new(a_k, e) {
                Ok(g) => return Ok(Operator::Pencil(g)),
                Err(Error::Convergence(_)) => {}
                Err(other) => return Err(other),
            }
        }
        let lu = Lu::new(e)?;
        if !(lu.rcond() > WELL_CONDITIONED_E) {
            return Err(Error::Convergence(
                "the QZ form of the closed-loop pencil failed its check".into(),
            ));
        }
        let lyap = Lyapunov::new(&right_solve(&lu, a_k))?.with_singular_rtol(0.0)?;
        Ok(Operator::Congruence(lyap, lu))
    }

    /// `Ω⁻¹(C)`.
    pub(super) fn solve(&self, c: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        match self {
            Operator::Standard(l) => l.solve_adjoint(c).map(|x| symmetrize(&x)),
            Operator::Pencil(g) => g.solve_adjoint(c),
            Operator::Congruence(l, lu) => l
                .solve_adjoint(&congruence_inv(lu, c))
                .map(|x| symmetrize(&x)),
        }
    }

    /// The largest real part of the (generalised) eigenvalues.
    pub(super) fn abscissa(&self) -> f64 {
        let parts = match self {
            Operator::Standard(l) | Operator::Congruence(l, _) => {
                l.schur().eigenvalues().iter().map(|(re, _)| *re).collect()
            }
            Operator::Pencil(g) => g.form().real_parts(),
        };
        parts.into_iter().fold(f64::NEG_INFINITY, f64::max)
    }
}

/// `Ω(Δ) = A_KᵀΔE + EᵀΔA_K` and a bound on its rounding error (Frobenius).
fn apply(
    a_k: &DMatrix<f64>,
    e: Option<&DMatrix<f64>>,
    d: &DMatrix<f64>,
    g: f64,
) -> (DMatrix<f64>, f64) {
    let t = match e {
        Some(e) => matmul_tn(a_k, &matmul(d, e)),
        None => matmul_tn(a_k, d),
    };
    let abs = match e {
        Some(e) => matmul_tn(&a_k.abs(), &matmul(&d.abs(), &e.abs())),
        None => matmul_tn(&a_k.abs(), &d.abs()),
    };
    (&t + t.transpose(), 2.0 * g * norm_fro(&abs))
}

/// Newton's iteration from `x0`, then the certificate at the final iterate (module
/// documentation). `Ok(None)` when the closed-loop pencil of the final iterate is not stable or
/// a factorisation fails (no certificate).
pub(super) fn refine(d: &Data<'_>, x0: DMatrix<f64>) -> Result<Option<Certified>> {
    let (a, b, e) = (d.a, d.b, d.e);
    let mut x = x0;
    let mut res = d.residual_with_error(&x);
    let mut steps = 0;
    // Chord steps on the operator of the last refresh; refreshed (a new QZ form) when a step
    // gains less than a factor CHORD_GAIN or fails to lower the residual, and the iteration ends
    // when even a fresh operator's step does not lower it.
    let mut op: Option<Operator> = None;
    let mut fresh = false;
    for _ in 0..MAX_STEPS {
        crate::cancel::check("the generalised Riccati refinement")?;
        if !(res.rel > f64::EPSILON && res.rel.is_finite()) {
            break;
        }
        if op.is_none() {
            op = Operator::new(&(a - matmul(b, &res.k)), e, d.ill_e).ok();
            fresh = true;
        }
        let Some(Ok(delta)) = op.as_ref().map(|o| o.solve(&(-&res.f))) else {
            break;
        };
        let cand = symmetrize(&(&x + delta));
        let next = d.residual_with_error(&cand);
        let lower = next.rel < res.rel;
        if lower {
            if !(next.rel <= CHORD_GAIN * res.rel) {
                op = None;
            }
            (x, res) = (cand, next);
            steps += 1;
            fresh = false;
        } else if fresh {
            break;
        } else {
            op = None;
        }
    }
    if !x.iter().all(|v| v.is_finite()) {
        return Ok(None);
    }
    // The certificate at the final X; where its strict test fails, at the double-double point
    // X + D (module `double_double_point`).
    let kappa_r = 1.0 / d.r_lu.rcond().max(f64::MIN_POSITIVE);
    let gamma = certificate_gamma(d);
    let k_err = gamma * kappa_r * norm_fro(&res.k); // ‖K̂ − K‖ (LU solve with R)
    let Some(at) = certify(d, &res.f, res.err, &res.k, k_err)? else {
        return Ok(None);
    };
    let (mut forward, mut trace, mut proof) = at.bounds(&x);
    if at.proof != Proof::Strict {
        if let Some(dd) = super::double_double_point::certify(d, &x, &at.op)? {
            (forward, trace, proof) = (dd.forward, dd.trace, Proof::Strict);
            x = dd.x;
            res = d.residual_with_error(&x);
        }
    }
    if !(forward.is_finite() && trace.is_finite()) {
        return Ok(None);
    }
    Ok(Some(Certified {
        x,
        residual: res.rel,
        steps,
        forward,
        trace,
        abscissa: at.abscissa,
        proof,
    }))
}

/// `γ` of the certificate's rounding terms.
pub(super) fn certificate_gamma(d: &Data<'_>) -> f64 {
    (2.0 * d.a.nrows() as f64 + 2.0 * d.b.ncols() as f64 + 8.0) * f64::EPSILON
}

/// What the certificate at a point `X` shows (module documentation): the computed correction
/// `Δ̂`, `‖X* − X − Δ̂‖_F ≤ beyond` and `|tr(X* − X − Δ̂)| ≤ trace_rest` when `proof` is strict
/// (else the first-order estimates), and the operator of the closed-loop pencil.
pub(super) struct AtPoint {
    pub(super) dh: DMatrix<f64>,
    pub(super) beyond: f64,
    pub(super) trace_rest: f64,
    pub(super) proof: Proof,
    pub(super) abscissa: f64,
    pub(super) op: Operator,
}

impl AtPoint {
    /// The relative forward bound and the trace bound for `x` itself.
    fn bounds(&self, x: &DMatrix<f64>) -> (f64, f64, Proof) {
        let xn = norm_fro(x);
        let dn = norm_fro(&self.dh);
        let forward = if xn > 0.0 {
            (dn + self.beyond) / xn + f64::EPSILON
        } else if dn + self.beyond == 0.0 {
            0.0
        } else {
            f64::INFINITY
        };
        let trace = self.dh.trace().abs() + self.trace_rest + f64::EPSILON * x.trace().abs();
        (forward, trace, self.proof)
    }
}

/// The certificate at a point whose residual is `f` (`‖f − F‖_F ≤ f_err`) and gain `k`
/// (`‖k − K‖_F ≤ k_err`). `errs` bounds the closed loop's rounding too: the product `Bk`
/// (`γ|B||k|`), `k`'s own error, and the subtraction in `A − Bk` (`eps‖A_K‖`), each times
/// `2‖E‖‖Δ̂‖`. `None` when the closed-loop pencil `(A − Bk, E)` is not stable or a
/// factorisation fails.
pub(super) fn certify(
    d: &Data<'_>,
    f: &DMatrix<f64>,
    f_err: f64,
    k: &DMatrix<f64>,
    k_err: f64,
) -> Result<Option<AtPoint>> {
    let (a, b, e) = (d.a, d.b, d.e);
    let n = a.nrows();
    let gamma = certificate_gamma(d);
    let a_k = a - matmul(b, k);
    let Ok(op) = Operator::new(&a_k, e, d.ill_e) else {
        return Ok(None);
    };
    let abscissa = op.abscissa();
    if !(abscissa < 0.0) {
        return Ok(None);
    }
    let (Ok(p), Ok(dh)) = (op.solve(&(-DMatrix::identity(n, n))), op.solve(&(-f))) else {
        return Ok(None);
    };
    let ell = norm2_bound_symmetric(&p);
    let (omega_d, omega_round) = apply(&a_k, e, &dh, gamma);
    let solve_residual = norm_fro(&(&omega_d + f));
    let e_norm = e.map_or(1.0, norm_fro);
    let errs = f_err
        + solve_residual
        + omega_round
        + gamma * norm_fro(f)
        + 2.0
            * (gamma * norm_fro(&matmul(&b.abs(), &k.abs()))
                + norm_fro(b) * k_err
                + f64::EPSILON * norm_fro(&a_k))
            * e_norm
            * norm_fro(&dh);
    // The quadratic term EᵀΔGΔE = (EᵀΔB)R⁻¹(BᵀΔE), seen through B and E (module documentation).
    let e_mat = e.cloned().unwrap_or_else(|| DMatrix::identity(n, n));
    let through = |m: &DMatrix<f64>| norm_fro(&matmul_tn(&e_mat, &matmul(m, b)));
    let kappa_eb = (norm2_bound_symmetric(&matmul_tn(&e_mat, &matmul(&p, &e_mat)))
        * norm2_bound_symmetric(&matmul_tn(b, &matmul(&p, b))))
    .sqrt();
    let r_inv = d.r_inverse_norm();
    let u0 = through(&dh) + kappa_eb * errs;
    let h_b = kappa_eb * r_inv * u0;
    // The same with norms alone: ‖EᵀΔGΔE‖ ≤ ‖E‖²‖G‖‖Δ‖².
    let quad = e_norm * e_norm * norm2_bound_symmetric(&d.g());
    let eta = norm2_bound_symmetric(&dh) + ell * errs;
    let h = ell * quad * eta;
    let smaller_root = |u0: f64, h: f64| 2.0 * u0 / (1.0 + (1.0 - 4.0 * h).sqrt());
    let bounds = [
        (h_b < 0.25).then(|| r_inv * smaller_root(u0, h_b).powi(2)),
        (h < 0.25).then(|| quad * smaller_root(eta, h).powi(2)),
    ];
    let (rest, proof) = match bounds.into_iter().flatten().reduce(f64::min) {
        Some(q) => (errs + q, Proof::Strict),
        // The quadratic term at the computed correction, `‖EᵀΔ̂GΔ̂E‖ ≤ ‖R⁻¹‖‖EᵀΔ̂B‖²`, is added
        // twice: an iterate still far from Newton's quadratic regime gets a bound that says so.
        None => {
            let q_hat = r_inv * through(&dh).powi(2);
            (errs + 2.0 * q_hat, Proof::FirstOrder)
        }
    };
    let beyond = (n as f64).sqrt() * ell * rest;
    let trace_rest = p.trace().abs() * rest;
    Ok(Some(AtPoint {
        dh,
        beyond,
        trace_rest,
        proof,
        abscissa,
        op,
    }))
}
