//! The generalised CARE with a cross term, scipy's `solve_continuous_are(a, b, q, r, e, s)`:
//!
//! ```text
//! Aᵀ X E + Eᵀ X A − (Eᵀ X B + S) R⁻¹ (Bᵀ X E + Sᵀ) + Q = 0,
//! ```
//!
//! `E = I` and `S = 0` when omitted. `R` must be symmetric and nonsingular (it may be indefinite);
//! `E` must be nonsingular. The stabilising solution makes the pencil `(A − B K, E)`,
//! `K = R⁻¹(Bᵀ X E + Sᵀ)`, Hurwitz.
//!
//! Route (all congruences with `E⁻¹`, never an explicit inverse):
//!
//! 1. multiplying by `E⁻ᵀ` on the left and `E⁻¹` on the right gives the standard equation with
//!    cross term in the same `X`: `Â = A E⁻¹`, `Ŝ = E⁻ᵀ S`, `Q̂ = E⁻ᵀ Q E⁻¹`;
//! 2. the cross term goes into the data: `Â − B R⁻¹ Ŝᵀ`, `Q̂ − Ŝ R⁻¹ Ŝᵀ`, `G = B R⁻¹ Bᵀ`, and
//!    [`super::solve_care`] solves `ÃᵀX + XÃ − XGX + Q̃ = 0`;
//! 3. when `E` or `S` was given, Newton's iteration on the ORIGINAL equation (the residual is
//!    computed from `A, B, Q, R, E, S`): the correction solves the generalised Lyapunov equation
//!    `A_Kᵀ Δ E + Eᵀ Δ A_K = −F(X)`, `A_K = A − BK` — for an ill-conditioned `E`
//!    (`rcond₁(E) ≤` [`WELL_CONDITIONED_E`]) on the generalised Schur form of the pencil
//!    `(A_K, E)`, never with `E⁻¹`, and with double-double residual products; otherwise by the
//!    congruence with `E⁻¹` in working precision — and the answer carries the certificate of
//!    module `newton` (a Newton–Kantorovich bound, taken at the double-double point `X + D` of
//!    module `double_double_point` where it fails at `X`; or the first-order estimate).
//!
//! Steps 1–2 lose up to a factor `κ(E)` of accuracy; step 3 wins it back, since its solves on
//! the QZ form are backward stable in `(A_K, E)`. When the transformed problem is refused and `E` is
//! ill-conditioned (its data are then off by `~eps·κ(E)`), it is solved again accepting a
//! marginal answer, and that answer is kept only when step 3 proves it is near the stabilising
//! solution. When that fails too, or step 3 cannot certify the transformed problem's answer,
//! step 3 starts instead from Kleinman's iteration on the pencil itself, from a stabilising
//! feedback (module `pencil_kleinman`), again kept only with the strict proof. An answer
//! without a certificate (its closed-loop pencil not stable, or a factorisation failed) is an
//! error, [`Error::SingularProblem`] naming `E` when `E` is
//! ill-conditioned; an answer with a large bound is returned with it (the caller warns).
//!
//! Step 2 uses every route of the standard solver ([`super::solve_care_weighted`] when `R` is
//! positive definite, else [`super::solve_care`]): its answer is only the start of step 3, whose
//! certificate is for the original data.

use super::compensated;
use super::weighted::{input_columns, input_weight};
use super::{CareOptions, CareSolution};
use crate::linalg::dense::{
    check_finite, check_shape, check_square, check_symmetric, matmul, matmul_tn, norm_1, norm_fro,
    symmetrize, Lu,
};
use crate::{Error, Result};
use nalgebra::DMatrix;
use newton::Proof;

mod double_double_point;
mod newton;
mod pencil_kleinman;

/// `rcond₁(E)` below which `E` is held responsible for a refusal, and a refused transformed
/// problem is solved again accepting a marginal answer (step 3 then decides).
pub const E_RCOND_WARN: f64 = 1e-8;

/// `rcond₁(E)` above which step 3 works with `E⁻¹` instead of the QZ form of the pencil.
pub const WELL_CONDITIONED_E: f64 = 1e-4;

/// `rcond₁(E)` above which step 3's residuals are formed in working precision.
pub const COMPENSATED_E: f64 = 1e-2;

/// The data of the generalised equation, validated.
pub(super) struct Data<'a> {
    pub(super) a: &'a DMatrix<f64>,
    pub(super) b: &'a DMatrix<f64>,
    q: DMatrix<f64>,
    pub(super) e: Option<&'a DMatrix<f64>>,
    s: Option<&'a DMatrix<f64>>,
    /// `R` (symmetrised) and its LU factors (`R` may be indefinite).
    r: DMatrix<f64>,
    pub(super) r_lu: Lu,
    /// `E` given and ill-conditioned (`rcond₁(E) ≤` [`WELL_CONDITIONED_E`]): step 3 then works on
    /// the QZ form of the pencil; otherwise with `E⁻¹` (congruence), which costs a fraction and
    /// loses `~κ(E)·eps` in the corrections.
    pub(super) ill_e: bool,
    /// `E` given with `rcond₁(E) ≤` [`COMPENSATED_E`]: the residual's products in double-double
    /// (a working-precision residual's floor `γ|E|ᵀ|X||A|` then costs digits of the bound: at
    /// `κ(E) = 1e2`, n = 6, a bound of 5e-10 instead of 1e-15).
    pub(super) compensate: bool,
}

/// Smallest singular value below `eps·‖M‖₁` (scipy's test for a numerically singular `r`/`e`).
fn numerically_singular(m: &DMatrix<f64>) -> bool {
    let sv = m.clone().singular_values();
    let min_sv = sv.iter().cloned().fold(f64::INFINITY, f64::min);
    min_sv == 0.0 || min_sv < f64::EPSILON * norm_1(m)
}

fn validate<'a>(
    a: &'a DMatrix<f64>,
    b: &'a DMatrix<f64>,
    q: &'a DMatrix<f64>,
    r: Option<&'a DMatrix<f64>>,
    e: Option<&'a DMatrix<f64>>,
    s: Option<&'a DMatrix<f64>>,
) -> Result<Data<'a>> {
    let n = check_square("A", a)?;
    let m = input_columns(n, b)?;
    check_shape("Q", q, n, n)?;
    check_finite("A", a)?;
    check_finite("B", b)?;
    check_finite("Q", q)?;
    check_symmetric("Q", q, 1e-10)?;
    let r = match r {
        Some(r) => input_weight(r, m)?,
        None => DMatrix::identity(m, m),
    };
    if numerically_singular(&r) {
        return Err(Error::InvalidInput(
            "R is numerically singular (smallest singular value below eps·‖R‖₁)".into(),
        ));
    }
    let r_lu = Lu::new(&r).map_err(|_| Error::InvalidInput("R is singular".into()))?;
    if let Some(e) = e {
        check_shape("E", e, n, n)?;
        check_finite("E", e)?;
        if numerically_singular(e) {
            return Err(Error::InvalidInput(
                "E is numerically singular (smallest singular value below eps·‖E‖₁): the \
                 descriptor system has infinite eigenvalues, which this solver does not handle"
                    .into(),
            ));
        }
    }
    if let Some(s) = s {
        check_shape("S", s, n, m)?;
        check_finite("S", s)?;
    }
    Ok(Data {
        a,
        b,
        q: symmetrize(q),
        e,
        s,
        r,
        r_lu,
        ill_e: false,
        compensate: false,
    })
}

impl Data<'_> {
    /// `G = B R⁻¹ Bᵀ`: as `MᵀM`, `M = L⁻¹Bᵀ`, when `R = LLᵀ` is positive definite (exactly
    /// symmetric and semidefinite, as [`super::solve_care_weighted`] forms it), else by the LU.
    pub(super) fn g(&self) -> DMatrix<f64> {
        if let Some(chol) = self.r.clone().cholesky() {
            let mut m_t = self.b.transpose();
            if chol.l().solve_lower_triangular_mut(&mut m_t) {
                return matmul_tn(&m_t, &m_t);
            }
        }
        symmetrize(&matmul(self.b, &self.r_solve(&self.b.transpose())))
    }

    /// `‖R⁻¹‖₂ = 1/σ_min(R)` (as computed; `∞` for a singular `R`).
    pub(super) fn r_inverse_norm(&self) -> f64 {
        let smin = self.r.clone().singular_values().min();
        if smin > 0.0 {
            1.0 / smin
        } else {
            f64::INFINITY
        }
    }

    /// `R⁻¹ M`.
    fn r_solve(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        let mut x = m.clone();
        self.r_lu.solve_in_place(&mut x);
        x
    }

    /// `Eᵀ X B + S` (the factor whose `R⁻¹`-weighted square is subtracted).
    fn coupling(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let xb = matmul(x, self.b);
        let mut c = match self.e {
            Some(e) => matmul_tn(e, &xb),
            None => xb,
        };
        if let Some(s) = self.s {
            c += s;
        }
        c
    }
}

/// A residual `F(X)` with its gain and a bound on its error.
pub(super) struct Residual {
    /// `F̂(X)`.
    pub(super) f: DMatrix<f64>,
    /// `K = R⁻¹(BᵀXE + Sᵀ)` as used in it.
    pub(super) k: DMatrix<f64>,
    /// `‖F̂‖_F / (‖Q‖_F + 2‖EᵀXA‖_F + ‖CK‖_F)`.
    pub(super) rel: f64,
    /// A bound on `‖F̂ − F(X)‖_F` (the arithmetic; the data are taken as given).
    pub(super) err: f64,
}

impl Data<'_> {
    /// `F(X)` and a bound on its rounding error. With an ill-conditioned `E`
    /// ([`Data::compensate`]), the products `EᵀXA` and `EᵀXB` are accumulated in double-double ([`super::compensated`]) and rounded once: with an
    /// ill-conditioned `E`, `X` is large (`~κ(E)`) where `EᵀX` is not, and a working-precision
    /// product's rounding `γ|E|ᵀ|X||A|` would be a floor far above `eps·‖EᵀXA‖` that Newton's
    /// iteration cannot pass and that the error bound would carry. The error is then
    /// `2eps‖EᵀXA‖ + 3γ²‖|E|ᵀ|X||A|‖` per product (Ogita–Rump–Oishi), `γ = (n + 2)eps`;
    /// `C = EᵀXB + S` is rounded to double (`eps‖C‖ + 3γ²‖|E|ᵀ|X||B|‖ + eps‖S‖`) and `CK` formed
    /// in working precision: `γ_m‖|C||K|‖ + ‖δC‖‖K‖ + ‖C‖‖δK‖`,
    /// `‖δK‖ ≤ κ(R)(γ_m‖K‖ + ‖δC‖/‖R‖)` for the LU solve with `R`. Otherwise the products are
    /// formed in working precision and `γ‖|E|ᵀ|X||M|‖` bounds their rounding.
    pub(super) fn residual_with_error(&self, x: &DMatrix<f64>) -> Residual {
        let n = x.nrows();
        let eps = f64::EPSILON;
        let kappa_r = 1.0 / self.r_lu.rcond().max(f64::MIN_POSITIVE);
        let gamma_m = (self.b.ncols() as f64 + 2.0) * eps;
        let gamma = (2.0 * n as f64 + 4.0) * eps;
        // |E|ᵀ|X||M| (|X||M| without E): what the rounding of EᵀXM is measured against.
        let abs = |m: &DMatrix<f64>| {
            let xm = matmul(&x.abs(), &m.abs());
            match self.e {
                Some(e) => matmul_tn(&e.abs(), &xm),
                None => xm,
            }
        };
        let (exa, exa_err, c, c_err) = match self.e.filter(|_| self.compensate) {
            Some(e) => {
                let g2 = ((n + 2) as f64 * eps).powi(2);
                let (exa, exb) = compensated::pencil_products(e, x, self.a, self.b);
                let c = match self.s {
                    Some(s) => &exb.hi + (&exb.lo + s),
                    None => &exb.hi + &exb.lo,
                };
                let exa_err = 2.0 * eps * norm_fro(&exa.hi) + 3.0 * g2 * norm_fro(&abs(self.a));
                let c_err = eps * norm_fro(&c)
                    + 3.0 * g2 * norm_fro(&abs(self.b))
                    + self.s.map_or(0.0, |s| eps * norm_fro(s));
                (exa, exa_err, c, c_err)
            }
            None => {
                // Working precision (no `E`, or a well-conditioned one): γ|E|ᵀ|X||M| bounds the
                // rounding of EᵀXM.
                let xa = matmul(x, self.a);
                let exa = match self.e {
                    Some(e) => matmul_tn(e, &xa),
                    None => xa,
                };
                let c = self.coupling(x);
                let exa_err = gamma * norm_fro(&abs(self.a));
                let c_err =
                    gamma * norm_fro(&abs(self.b)) + self.s.map_or(0.0, |s| eps * norm_fro(s));
                let lo = DMatrix::zeros(n, n);
                (compensated::Dd { hi: exa, lo }, exa_err, c, c_err)
            }
        };
        let k = self.r_solve(&c.transpose());
        let ck = matmul(&c, &k);
        let f = DMatrix::from_fn(n, n, |i, j| {
            let (s1, t1) = compensated::two_sum(exa.hi[(i, j)], exa.hi[(j, i)]);
            let (s2, t2) = compensated::two_sum(s1, -ck[(i, j)]);
            let (s3, t3) = compensated::two_sum(s2, self.q[(i, j)]);
            s3 + (t1 + t2 + t3 + (exa.lo[(i, j)] + exa.lo[(j, i)]))
        });
        let f = symmetrize(&f);
        let r_norm = norm_fro(&self.r).max(f64::MIN_POSITIVE);
        let dk = kappa_r * (gamma_m * norm_fro(&k) + c_err / r_norm);
        let ck_err = gamma_m * norm_fro(&matmul(&c.abs(), &k.abs()))
            + c_err * norm_fro(&k)
            + norm_fro(&c) * dk;
        let (exa_n, ck_n, q_n) = (norm_fro(&exa.hi), norm_fro(&ck), norm_fro(&self.q));
        let err = 2.0 * exa_err + ck_err + 2.0 * eps * (norm_fro(&f) + 2.0 * exa_n + ck_n + q_n);
        let denom = q_n + 2.0 * exa_n + ck_n;
        let rel = if denom > 0.0 {
            norm_fro(&f) / denom
        } else {
            norm_fro(&f)
        };
        Residual { f, k, rel, err }
    }
}

/// `(E⁻ᵀ M E⁻¹)` for symmetric `M`, symmetrised.
fn congruence_inv(lu: &Lu, m: &DMatrix<f64>) -> DMatrix<f64> {
    let mut t = m.clone();
    lu.solve_transpose_in_place(&mut t); // E⁻ᵀ M
    let mut t = t.transpose(); // M E⁻¹ (M symmetric)
    lu.solve_transpose_in_place(&mut t); // E⁻ᵀ M E⁻¹
    symmetrize(&t)
}

/// `M E⁻¹`.
fn right_solve(lu: &Lu, m: &DMatrix<f64>) -> DMatrix<f64> {
    let mut t = m.transpose();
    lu.solve_transpose_in_place(&mut t); // E⁻ᵀ Mᵀ = (M E⁻¹)ᵀ
    t.transpose()
}

/// Solves `Aᵀ X E + Eᵀ X A − (Eᵀ X B + S) R⁻¹ (Bᵀ X E + Sᵀ) + Q = 0` for the stabilising `X`.
///
/// `r = None` means `R = I`, `e = None` means `E = I`, `s = None` means `S = 0`. With neither `e`
/// nor `s` this is [`super::solve_care`] on `G = B R⁻¹ Bᵀ` (with `opts` as given); otherwise see the
/// module documentation. The returned [`CareSolution`] carries, in the generalised case, the
/// relative residual of the ORIGINAL equation
/// `‖F‖_F / (‖Q‖_F + 2‖AᵀXE‖_F + ‖(EᵀXB + S)R⁻¹(BᵀXE + Sᵀ)‖_F)`, the Newton steps taken on it,
/// and `rcond` / `closed_loop_abscissa` / `scaling` of the inner standard solve (the abscissa is
/// that of the pencil `(A − BK, E)` before refinement).
///
/// Errors: [`Error::Shape`], [`Error::NonFinite`], [`Error::InvalidInput`] (asymmetric `Q`/`R`,
/// numerically singular `R` or `E`) for bad input; the errors of [`super::solve_care`]; and
/// [`Error::SingularProblem`] naming `E` when `E` is too ill-conditioned for an accurate solution.
pub fn solve_care_generalized(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: Option<&DMatrix<f64>>,
    e: Option<&DMatrix<f64>>,
    s: Option<&DMatrix<f64>>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    let mut d = validate(a, b, q, r, e, s)?;
    if e.is_none() && s.is_none() && r.is_none_or(|r| symmetrize(r).cholesky().is_some()) {
        // The standard equation with R positive definite: the factored form keeps the residual
        // of the refinement exact in the null directions of G (see `solve_care_factored`).
        return super::solve_care_weighted(a, b, q, r, opts);
    }
    let g = d.g();

    // Step 1: the congruence with E⁻¹.
    let (e_lu, e_rcond) = match e {
        Some(e) => {
            let lu = Lu::new(e)
                .map_err(|_| Error::InvalidInput("E is singular to working precision".into()))?;
            let rc = lu.rcond();
            (Some(lu), rc)
        }
        None => (None, 1.0),
    };
    d.ill_e = e.is_some() && !(e_rcond > WELL_CONDITIONED_E);
    d.compensate = e.is_some() && !(e_rcond > COMPENSATED_E);
    let (a_hat, q_hat, s_hat) = match &e_lu {
        Some(lu) => {
            let s_hat = s.map(|s| {
                let mut t = s.clone();
                lu.solve_transpose_in_place(&mut t);
                t
            });
            (right_solve(lu, a), congruence_inv(lu, &d.q), s_hat)
        }
        None => (a.clone(), d.q.clone(), s.cloned()),
    };

    // Step 2: the cross term into the data.
    let (a_t, q_t) = match &s_hat {
        Some(sh) => {
            let rs = d.r_solve(&sh.transpose()); // R⁻¹ Ŝᵀ
            (
                &a_hat - matmul(b, &rs),
                symmetrize(&(&q_hat - matmul(sh, &rs))),
            )
        }
        None => (a_hat, q_hat),
    };
    // With an ill-conditioned E the transformed data are inaccurate: name E, not the inner
    // Hamiltonian, as the likely cause of a refusal.
    let blame_e = |err: Error| match err {
        Error::NoStabilizingSolution(m)
        | Error::SingularProblem(m)
        | Error::Reorder(m)
        | Error::Convergence(m) => Error::SingularProblem(format!(
            "E is too ill-conditioned (rcond₁(E) = {e_rcond:.1e}) for an accurate solution; \
             the problem transformed by E⁻¹ failed: {m}"
        )),
        other => other,
    };
    // The transformed equation by every route of the standard solver (the factored form when R is
    // positive definite); step 3 re-certifies whatever it returns on the original equation.
    let inner = |opts: &CareOptions| {
        if d.r.clone().cholesky().is_some() {
            super::solve_care_weighted(&a_t, d.b, &q_t, Some(&d.r), opts)
        } else {
            super::solve_care(&a_t, &g, &q_t, opts)
        }
    };
    // Kleinman's iteration on the pencil itself (module `pencil_kleinman`) where the transformed
    // problem's answer is refused or not certified: its answer, else `refusal` (an interruption
    // is passed on).
    let from_pencil = |refusal: Error| {
        pencil_kleinman::certified_from_pencil(&d, &a_t, e_rcond).map_err(|other| match other {
            Error::Interrupted(m) => Error::Interrupted(m),
            _ => refusal,
        })
    };
    let sol = match inner(opts) {
        Ok(sol) => sol,
        Err(err) if e_rcond < E_RCOND_WARN && !matches!(err, Error::Interrupted(_)) => {
            // The refusal may be the transformation's: solve again accepting a marginal answer,
            // and keep it only with step 3's strict proof.
            let lenient = CareOptions {
                accept_marginal: true,
                ..*opts
            };
            return inner(&lenient)
                .and_then(|sol| certified(&d, sol, true, e_rcond))
                .or_else(|_| from_pencil(blame_e(err)));
        }
        Err(err) => return Err(err),
    };
    if e.is_none() && s.is_none() {
        return Ok(sol);
    }

    // Step 3: Newton's iteration on the original equation, on the closed-loop pencil, and its
    // certificate (module `newton`); with an ill-conditioned E, when that fails, from the
    // pencil's own Kleinman start.
    match certified(&d, sol, false, e_rcond) {
        Err(err) if e_rcond < E_RCOND_WARN && !matches!(err, Error::Interrupted(_)) => {
            from_pencil(err)
        }
        done => done,
    }
}

/// The transformed problem's solution refined on the original equation, with the certificate's
/// bound. An answer that came from a refused transformed problem (solved again accepting a
/// marginal answer) or from the pencil's Kleinman start (`strict_only`) is kept only with the
/// strict proof; otherwise the
/// first-order estimate is returned when the strict bound cannot be shown. No certificate at all
/// (the refined closed-loop pencil is not stable, or a factorisation failed) is an error, naming
/// `E` when it is ill-conditioned.
fn certified(
    d: &Data<'_>,
    mut sol: CareSolution,
    strict_only: bool,
    e_rcond: f64,
) -> Result<CareSolution> {
    let blame = |what: String| {
        if e_rcond < E_RCOND_WARN {
            Error::SingularProblem(format!(
                "E is too ill-conditioned (rcond₁(E) = {e_rcond:.1e}) for an accurate solution: {what}"
            ))
        } else {
            Error::NoStabilizingSolution(what)
        }
    };
    let Some(c) = newton::refine(d, sol.x.clone())? else {
        return Err(blame(
            "the refined solution's closed-loop pencil (A − BK, E) is not certified stable".into(),
        ));
    };
    if strict_only && c.proof != Proof::Strict {
        return Err(blame(format!(
            "the transformed problem was refused, and the refined solution (error bound \
             {:.1e}) could not be proven to be the stabilising one",
            c.forward
        )));
    }
    sol.x = c.x;
    sol.residual = c.residual;
    sol.newton_steps += c.steps;
    sol.forward_error = c.forward;
    sol.trace_error = c.trace;
    sol.closed_loop_abscissa = c.abscissa;
    sol.marginal = sol.marginal && c.proof != Proof::Strict;
    Ok(sol)
}

#[cfg(test)]
mod tests;
