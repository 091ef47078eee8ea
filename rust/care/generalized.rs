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
//! 3. when `E` or `S` was given, Newton–Kleinman refinement on the ORIGINAL equation (the residual
//!    is computed from `A, B, Q, R, E, S`): with `A_K = A − B K`, the correction solves the
//!    generalised Lyapunov equation `A_Kᵀ Δ E + Eᵀ Δ A_K = −F(X)` (reduced to a standard one by
//!    the same congruence); a step is kept only while the residual falls.
//!
//! Steps 1–2 lose up to a factor `κ(E)` of accuracy, which step 3 wins back when `E` is
//! reasonably conditioned. When it cannot (the refined relative residual is still large and `E`
//! is ill-conditioned), [`Error::SingularProblem`] names `E` instead of returning a poor answer.

use super::weighted::{input_columns, input_weight};
use super::{CareOptions, CareSolution};
use crate::linalg::dense::{
    check_finite, check_shape, check_square, check_symmetric, matmul, matmul_tn, norm_1, norm_fro,
    symmetrize, Lu,
};
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// At most this many Newton–Kleinman steps on the original generalised equation.
pub const MAX_REFINEMENT_STEPS: usize = 10;

/// A refined solution whose relative residual is still above this bound, with `E` worse
/// conditioned than [`E_RCOND_WARN`], is refused as inaccurate (the transformation by `E⁻¹` lost
/// the digits and the refinement could not win them back).
pub const ACCEPT_RESIDUAL: f64 = 1e-10;

/// `rcond₁(E)` below which `E` is held responsible for a large residual.
pub const E_RCOND_WARN: f64 = 1e-8;

/// The data of the generalised equation, validated.
struct Data<'a> {
    a: &'a DMatrix<f64>,
    b: &'a DMatrix<f64>,
    q: DMatrix<f64>,
    e: Option<&'a DMatrix<f64>>,
    s: Option<&'a DMatrix<f64>>,
    /// `R` (symmetrised) and its LU factors (`R` may be indefinite).
    r: DMatrix<f64>,
    r_lu: Lu,
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
    })
}

impl Data<'_> {
    /// `G = B R⁻¹ Bᵀ`: as `MᵀM`, `M = L⁻¹Bᵀ`, when `R = LLᵀ` is positive definite (exactly
    /// symmetric and semidefinite, as [`super::solve_care_weighted`] forms it), else by the LU.
    fn g(&self) -> DMatrix<f64> {
        if let Some(chol) = self.r.clone().cholesky() {
            let mut m_t = self.b.transpose();
            if chol.l().solve_lower_triangular_mut(&mut m_t) {
                return matmul_tn(&m_t, &m_t);
            }
        }
        symmetrize(&matmul(self.b, &self.r_solve(&self.b.transpose())))
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

    /// The residual `F(X)`, the gain `K = R⁻¹(Bᵀ X E + Sᵀ)` and the relative residual
    /// `‖F‖_F / (‖Q‖_F + 2‖AᵀXE‖_F + ‖(EᵀXB + S)K‖_F)`.
    fn residual(&self, x: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>, f64) {
        let c = self.coupling(x); // n×m
        let k = self.r_solve(&c.transpose()); // m×n
        let xa = matmul(x, self.a);
        let exa = match self.e {
            Some(e) => matmul_tn(e, &xa),
            None => xa,
        }; // EᵀXA
        let ck = matmul(&c, &k);
        let f = &exa + exa.transpose() - &ck + &self.q;
        let f = symmetrize(&f);
        let denom = norm_fro(&self.q) + 2.0 * norm_fro(&exa) + norm_fro(&ck);
        let rel = if denom > 0.0 {
            norm_fro(&f) / denom
        } else {
            norm_fro(&f)
        };
        (f, k, rel)
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
    let d = validate(a, b, q, r, e, s)?;
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
    let mut sol = super::solve_care_transformed(&a_t, &g, &q_t, opts).map_err(|err| match err {
        // With an ill-conditioned E the transformed data are inaccurate: name E, not the inner
        // Hamiltonian, as the likely cause.
        Error::NoStabilizingSolution(m)
        | Error::SingularProblem(m)
        | Error::Reorder(m)
        | Error::Convergence(m)
            if e_rcond < E_RCOND_WARN =>
        {
            Error::SingularProblem(format!(
                "E is too ill-conditioned (rcond₁(E) = {e_rcond:.1e}) for an accurate solution; \
                 the problem transformed by E⁻¹ failed: {m}"
            ))
        }
        other => other,
    })?;
    if e.is_none() && s.is_none() {
        return Ok(sol);
    }

    // Step 3: Newton–Kleinman on the original equation.
    let (mut f, mut k, mut rel) = d.residual(&sol.x);
    let mut steps = 0;
    for _ in 0..MAX_REFINEMENT_STEPS {
        if rel <= f64::EPSILON || !rel.is_finite() {
            break;
        }
        let a_k = a - matmul(b, &k);
        let (ak_hat, rhs) = match &e_lu {
            Some(lu) => (right_solve(lu, &a_k), congruence_inv(lu, &f)),
            None => (a_k, f.clone()),
        };
        // Â_Kᵀ Δ + Δ Â_K = −E⁻ᵀ F E⁻¹
        let delta = match Lyapunov::new(&ak_hat).and_then(|l| l.solve_adjoint(&(-rhs))) {
            Ok(dl) => dl,
            Err(_) => break,
        };
        let cand = symmetrize(&(&sol.x + delta));
        let (f2, k2, rel2) = d.residual(&cand);
        if !(rel2 < rel) {
            break;
        }
        sol.x = cand;
        (f, k, rel) = (f2, k2, rel2);
        steps += 1;
    }
    if rel > ACCEPT_RESIDUAL && e_rcond < E_RCOND_WARN {
        return Err(Error::SingularProblem(format!(
            "E is too ill-conditioned (rcond₁(E) = {e_rcond:.1e}) for an accurate solution: the \
             relative residual stays at {rel:.1e} after {steps} refinement steps"
        )));
    }
    sol.residual = rel;
    sol.newton_steps += steps;
    // The bound was computed for the transformed data; the congruence by E⁻¹ adds about
    // eps/rcond(E) relative error to them (a first-order estimate).
    if e.is_some() {
        let extra = f64::EPSILON / e_rcond.max(f64::MIN_POSITIVE);
        sol.forward_error += extra;
        sol.trace_error += extra * sol.x.trace().abs();
    }
    Ok(sol)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::care::solve_care_weighted;
    use crate::linalg::testing::Rng;

    fn opts() -> CareOptions {
        CareOptions::default()
    }

    /// The residual of the original equation, computed naively with explicit products.
    fn naive_residual(
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &DMatrix<f64>,
        e: &DMatrix<f64>,
        s: &DMatrix<f64>,
        x: &DMatrix<f64>,
    ) -> f64 {
        let c = e.transpose() * x * b + s;
        let rinv = r.clone().try_inverse().unwrap();
        let f = a.transpose() * x * e + e.transpose() * x * a - &c * rinv * c.transpose() + q;
        f.norm() / (q.norm() + 2.0 * (a.transpose() * x * e).norm() + (&c * c.transpose()).norm())
    }

    #[test]
    fn identity_e_and_zero_s_reduce_to_the_standard_equation() {
        let mut rng = Rng::new(3);
        let n = 5;
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, 2);
        let q = rng.psd(n, n) + DMatrix::identity(n, n);
        let r = rng.psd(2, 2) + DMatrix::identity(2, 2);
        let x0 = solve_care_weighted(&a, &b, &q, Some(&r), &opts())
            .unwrap()
            .x;
        let e = DMatrix::identity(n, n);
        let s = DMatrix::zeros(n, 2);
        let x1 = solve_care_generalized(&a, &b, &q, Some(&r), Some(&e), Some(&s), &opts())
            .unwrap()
            .x;
        assert!((&x1 - &x0).norm() <= 1e-12 * x0.norm());
    }

    #[test]
    fn random_generalized_problems_with_cross_terms_are_solved_to_small_residuals() {
        let mut rng = Rng::new(11);
        for &n in &[1usize, 2, 3, 6, 12] {
            let m = (n / 2).max(1);
            let a = rng.matrix(n, n);
            let b = rng.matrix(n, m);
            let e = rng.matrix(n, n) + DMatrix::identity(n, n) * 3.0;
            let r = rng.psd(m, m) + DMatrix::identity(m, m);
            let s = rng.matrix(n, m) * 0.3;
            // Q ≥ S R⁻¹ Sᵀ keeps the problem well posed.
            let q = rng.psd(n, n)
                + DMatrix::identity(n, n)
                + &s * r.clone().try_inverse().unwrap() * s.transpose();
            let sol =
                solve_care_generalized(&a, &b, &q, Some(&r), Some(&e), Some(&s), &opts()).unwrap();
            let res = naive_residual(&a, &b, &q, &r, &e, &s, &sol.x);
            assert!(res < 1e-13, "n={n}: residual {res:e}");
            assert!(sol.residual < 1e-14, "n={n}: {:e}", sol.residual);
            // The closed-loop pencil (A − BK, E) is stable.
            let k =
                r.clone().try_inverse().unwrap() * (b.transpose() * &sol.x * &e + s.transpose());
            let acl = (&a - &b * k) * e.clone().try_inverse().unwrap();
            assert!(
                acl.complex_eigenvalues().iter().all(|l| l.re < 0.0),
                "n={n}"
            );
        }
    }

    #[test]
    fn indefinite_r_is_accepted_when_a_stabilising_solution_exists() {
        // Scalar: 2ax − x²/r + q = 0 with r < 0: x = r(a − sqrt(a² + q/r))... choose a = −2,
        // q = 1, r = −1: 2(−2)x + x² + 1 = 0 ⇒ x = 2 − √3 (stabilising: a − x/r = −2 + x < 0).
        let a = DMatrix::from_element(1, 1, -2.0);
        let b = DMatrix::from_element(1, 1, 1.0);
        let q = DMatrix::from_element(1, 1, 1.0);
        let r = DMatrix::from_element(1, 1, -1.0);
        let s = DMatrix::zeros(1, 1);
        let x = solve_care_generalized(&a, &b, &q, Some(&r), None, Some(&s), &opts())
            .unwrap()
            .x;
        assert!((x[(0, 0)] - (2.0 - 3f64.sqrt())).abs() < 1e-15);
    }

    #[test]
    fn an_ill_conditioned_e_gives_an_accurate_answer_or_an_error_naming_e() {
        let mut rng = Rng::new(17);
        let n = 6;
        let u = rng.matrix(n, n).qr().q();
        let v = rng.matrix(n, n).qr().q();
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, 2);
        let q = DMatrix::identity(n, n);
        let r = DMatrix::identity(2, 2);
        let s = DMatrix::zeros(n, 2);
        for &k in &[2.0, 6.0, 10.0, 14.0] {
            // σ(E) from 1 down to 10^−k: nonsingular by scipy's test, κ(E) = 10^k.
            let d = DMatrix::from_fn(n, n, |i, j| {
                if i == j {
                    10f64.powf(-k * i as f64 / (n - 1) as f64)
                } else {
                    0.0
                }
            });
            let e = &u * d * v.transpose();
            match solve_care_generalized(&a, &b, &q, Some(&r), Some(&e), None, &opts()) {
                Ok(sol) => {
                    let res = naive_residual(&a, &b, &q, &r, &e, &s, &sol.x);
                    assert!(res <= 1e-9, "κ(E) = 1e{k}: residual {res:e}");
                    assert!(sol.residual <= ACCEPT_RESIDUAL);
                }
                Err(Error::SingularProblem(m)) => {
                    assert!(k >= 8.0, "κ(E) = 1e{k} refused: {m}");
                    assert!(m.starts_with("E is too ill-conditioned"), "{m}");
                }
                Err(other) => panic!("κ(E) = 1e{k}: unexpected {other:?}"),
            }
        }
    }

    #[test]
    fn singular_r_and_e_are_refused_as_input_errors() {
        let i2 = DMatrix::<f64>::identity(2, 2);
        let sing = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        assert!(matches!(
            solve_care_generalized(&i2, &i2, &i2, Some(&sing), None, None, &opts()),
            Err(Error::InvalidInput(m)) if m.contains('R')
        ));
        assert!(matches!(
            solve_care_generalized(&i2, &i2, &i2, None, Some(&sing), None, &opts()),
            Err(Error::InvalidInput(m)) if m.contains('E')
        ));
        let s_bad = DMatrix::<f64>::zeros(3, 2);
        assert!(matches!(
            solve_care_generalized(&i2, &i2, &i2, None, None, Some(&s_bad), &opts()),
            Err(Error::Shape(_))
        ));
    }
}
