//! Continuous algebraic Riccati equation by the Hamiltonian/Schur method (Laub 1979), with the
//! safeguards of SLICOT SB02RD:
//!
//! 1. scale `G ← s·G`, `Q ← Q/s` with `s = sqrt(‖Q‖_F/‖G‖_F)` (the solution scales back as `X = s·X'`);
//! 2. real Schur form of the Hamiltonian `H = [[A, −G], [−Q, −Aᵀ]]`, reordered so that its `n`
//!    stable eigenvalues come first: the leading `n` Schur vectors `[U11; U21]` span the stable
//!    invariant subspace;
//! 3. `X = U21 U11⁻¹`, computed as the solution of `U11ᵀ X = U21ᵀ` with an LU of `U11ᵀ` and a
//!    condition estimate of `U11`, then symmetrised;
//! 4. optionally, Newton–Kleinman refinement `(A − GX)ᵀ Δ + Δ (A − GX) = −R(X)`, `X ← X + Δ`.
//!
//! Every solution carries its diagnostics ([`CareSolution`]). Failures say why: eigenvalues on or too
//! near the imaginary axis, the wrong number of stable eigenvalues (not stabilisable / detectable),
//! or an ill-conditioned `U11`.

use crate::linalg::dense::{
    check_finite, check_shape, check_square, check_symmetric, matmul, matmul_tn, norm_fro,
    symmetrize, Lu,
};
use crate::linalg::schur::RealSchur;
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Options for [`solve_care`].
#[derive(Debug, Clone, Copy)]
pub struct CareOptions {
    /// Scale `Q` and `G` by `sqrt(‖Q‖/‖G‖)` before the Schur step (SLICOT SB02RD).
    pub scale: bool,
    /// At most this many Newton–Kleinman refinement steps after the Schur solution (0: none).
    /// A step is kept only if it lowers the residual.
    pub newton_steps: usize,
}

impl Default for CareOptions {
    fn default() -> Self {
        CareOptions {
            scale: true,
            newton_steps: 0,
        }
    }
}

/// The stabilising solution of a CARE with its diagnostics.
#[derive(Debug, Clone)]
pub struct CareSolution {
    /// The stabilising solution `X = Xᵀ`.
    pub x: DMatrix<f64>,
    /// Relative residual `‖AᵀX + XA − XGX + Q‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)`.
    pub residual: f64,
    /// Reciprocal 1-norm condition estimate of `U11` in `X U11 = U21` (small: X is inaccurate).
    pub rcond: f64,
    /// Spectral abscissa `max Re λ(A − G X)` of the closed loop (negative). Taken from the stable
    /// Hamiltonian eigenvalues, which are the closed-loop eigenvalues.
    pub closed_loop_abscissa: f64,
    /// Newton–Kleinman steps taken (and kept).
    pub newton_steps: usize,
    /// The scaling factor applied to `Q` and `G` (1 when scaling is off or not applicable).
    pub scaling: f64,
}

/// Hamiltonian eigenvalues with `|Re λ| ≤ AXIS_TOL·‖H‖_F` count as on the imaginary axis.
/// Eigenvalues of a Hamiltonian on the axis are generically double (a 2×2 Jordan block), and
/// rounding splits such a pair by about `√eps·‖H‖` — far more than `eps·‖H‖` — so only a
/// `√eps`-scale test catches them (CAREX 2.5 at ε = 0: its ±i split by 1.6e-8 = 0.07·√eps·‖H‖_F,
/// caught with a 14× margin). The price: problems whose closed loop has a real part within
/// √eps·‖H‖_F ≈ 1.5e-8·‖H‖_F of the axis are refused; their solution would carry only about half
/// the digits anyway.
pub const AXIS_TOL: f64 = 1.490_116_119_384_765_6e-8;

/// Relative asymmetry of `U11ᵀU21` above which the computed stable subspace is declared not
/// Lagrangian, i.e. eigenvalues are too near the imaginary axis for a trustworthy solution.
/// Perturbation theory: eigenvalues at distance δ from the axis perturb the subspace by ~eps/δ, so
/// this threshold corresponds to δ ≈ √eps·‖H‖.
const LAGRANGIAN_TOL: f64 = 1.5e-8;

/// Validates the data of `AᵀX + XA − XGX + Q = 0` and returns `n`.
fn validate(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<usize> {
    let n = check_square("A", a)?;
    check_shape("G", g, n, n)?;
    check_shape("Q", q, n, n)?;
    check_finite("A", a)?;
    check_finite("G", g)?;
    check_finite("Q", q)?;
    check_symmetric("Q", q, 1e-10)?;
    check_symmetric("G", g, 1e-10)?;
    Ok(n)
}

/// The Riccati residual `AᵀX + XA − XGX + Q`.
pub fn care_residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> DMatrix<f64> {
    let xa = matmul(x, a);
    let gx = matmul(g, x);
    let xgx = matmul_tn(x, &gx); // X symmetric: XᵀGX = XGX
    &xa + xa.transpose() - xgx + q
}

fn relative_residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> (DMatrix<f64>, f64) {
    let r = care_residual(a, g, q, x);
    let nx = norm_fro(x);
    let denom = norm_fro(q) + 2.0 * norm_fro(a) * nx + norm_fro(g) * nx * nx;
    let rel = if denom > 0.0 {
        norm_fro(&r) / denom
    } else {
        norm_fro(&r)
    };
    (r, rel)
}

/// The error for data whose Hamiltonian is not representable: it names the user's `Q` and `G`
/// (not the internal matrix, whose overflow would otherwise surface as "A has a non-finite entry").
fn hamiltonian_overflow(a: &DMatrix<f64>, nq: f64, ng: f64) -> Error {
    Error::InvalidInput(format!(
        "the Hamiltonian overflowed double precision: scale Q and G = B R⁻¹ Bᵀ (‖Q‖_F = {nq:.2e}, \
         ‖G‖_F = {ng:.2e}, ‖A‖_F = {:.2e}); the solver balances ‖Q‖ against ‖G‖ by sqrt(‖Q‖/‖G‖), \
         so both norms and their ratio must stay well inside the range of doubles (~1e±308)",
        norm_fro(a)
    ))
}

/// Solves `Aᵀ X + X A − X G X + Q = 0` for the stabilising `X` (`A − G X` Hurwitz), with `G` and
/// `Q` symmetric positive semidefinite (the usual `G = B R⁻¹ Bᵀ`).
pub fn solve_care(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    let n = validate(a, g, q)?;
    let q = symmetrize(q);
    let g = symmetrize(g);

    let (nq, ng) = (norm_fro(&q), norm_fro(&g));
    if ng == 0.0 {
        return Err(Error::NoStabilizingSolution(
            "G = B R⁻¹ Bᵀ is zero: no input acts on the system, so no stabilising solution exists \
             unless A is already stable (solve the Lyapunov equation instead)"
                .into(),
        ));
    }
    let s = if opts.scale && nq > 0.0 {
        // sqrt(‖Q‖/‖G‖) without forming the quotient, which under/overflows for ‖Q‖ ~ 1e-300,
        // ‖G‖ ~ 1e300 (and the scaled Hamiltonian then has 1/s = ∞ entries).
        nq.sqrt() / ng.sqrt()
    } else {
        1.0
    };

    // Hamiltonian of the scaled problem.
    let mut h = DMatrix::zeros(2 * n, 2 * n);
    let qs = -1.0 / s;
    for j in 0..n {
        for i in 0..n {
            h[(i, j)] = a[(i, j)];
            h[(i, n + j)] = g[(i, j)] * -s;
            h[(n + i, j)] = q[(i, j)] * qs;
            h[(n + i, n + j)] = -a[(j, i)];
        }
    }
    if !(nq.is_finite() && ng.is_finite() && h.iter().all(|v| v.is_finite())) {
        return Err(hamiltonian_overflow(a, nq, ng));
    }
    let hnorm = norm_fro(&h);

    let mut schur = RealSchur::new(&h)?;
    let eig = schur.eigenvalues();
    let axis_tol = AXIS_TOL * hnorm;
    if let Some(&(re, im)) = eig.iter().find(|(re, _)| re.abs() <= axis_tol) {
        return Err(Error::NoStabilizingSolution(format!(
            "the Hamiltonian has an eigenvalue on the imaginary axis ({re:.3e} {im:+.3e}i, \
             tolerance {axis_tol:.1e}): no stabilising solution exists \
             ((A, B) not stabilisable or (Q, A) not detectable on the axis)"
        )));
    }
    let stable = eig.iter().filter(|(re, _)| *re < 0.0).count();
    if stable != n {
        return Err(Error::NoStabilizingSolution(format!(
            "the Hamiltonian has {stable} stable eigenvalues, expected {n}"
        )));
    }
    let sdim = schur.reorder(|re, _| re < 0.0)?;
    if sdim != n {
        return Err(Error::NoStabilizingSolution(format!(
            "reordering selected {sdim} stable eigenvalues, expected {n}"
        )));
    }
    let closed_loop_abscissa = schur.eigenvalues()[..n]
        .iter()
        .map(|(re, _)| *re)
        .fold(f64::NEG_INFINITY, f64::max);

    let u11 = schur.z.view((0, 0), (n, n)).into_owned();
    let u21 = schur.z.view((n, 0), (n, n)).into_owned();

    // The stable subspace of a Hamiltonian is Lagrangian: U11ᵀU21 is symmetric.
    let w = matmul_tn(&u11, &u21);
    let mut skew2 = 0.0; // ‖W − Wᵀ‖_F²
    for j in 0..n {
        for i in 0..j {
            let d = w[(i, j)] - w[(j, i)];
            skew2 += 2.0 * d * d;
        }
    }
    let asym = skew2.sqrt() / norm_fro(&w).max(1.0);
    if asym > LAGRANGIAN_TOL {
        return Err(Error::NoStabilizingSolution(format!(
            "the computed stable invariant subspace is not Lagrangian (asymmetry {asym:.1e}): \
             the Hamiltonian has eigenvalues too near the imaginary axis for a reliable solution"
        )));
    }

    // X U11 = U21  ⇔  U11ᵀ X = U21ᵀ (X symmetric).
    let lu = Lu::new(&u11.transpose()).map_err(|_| {
        Error::Singular(
            "U11 is singular: the stable invariant subspace is not the graph of a matrix \
             (no stabilising solution; is (A, B) stabilisable?)"
                .into(),
        )
    })?;
    let rcond = lu.rcond();
    if rcond < f64::EPSILON {
        return Err(Error::Singular(format!(
            "U11 is too ill-conditioned (rcond = {rcond:.1e}) for an accurate solution"
        )));
    }
    let mut x = u21.transpose();
    lu.solve_in_place(&mut x);
    let mut x = symmetrize(&x) * s;
    if x.iter().any(|v| !v.is_finite()) {
        return Err(Error::Singular(
            "the solution overflowed (U11 nearly singular)".into(),
        ));
    }

    let (_, mut residual) = relative_residual(a, &g, &q, &x);
    let mut steps = 0;
    for _ in 0..opts.newton_steps {
        let (r, _) = relative_residual(a, &g, &q, &x);
        let acl = a - matmul(&g, &x);
        // (A − GX)ᵀ Δ + Δ (A − GX) = −R(X)
        let delta = match Lyapunov::new(&acl).and_then(|l| l.solve_adjoint(&(-r))) {
            Ok(d) => d,
            Err(_) => break,
        };
        let candidate = symmetrize(&(&x + delta));
        let (_, cand_res) = relative_residual(a, &g, &q, &candidate);
        if cand_res.is_nan() || cand_res >= residual {
            break;
        }
        x = candidate;
        residual = cand_res;
        steps += 1;
    }

    Ok(CareSolution {
        x,
        residual,
        rcond,
        closed_loop_abscissa,
        newton_steps: steps,
        scaling: s,
    })
}

/// Solves scipy's form `AᵀX + XA − X B R⁻¹ Bᵀ X + Q = 0` (`r = None` means `R = I`).
/// `R` must be symmetric positive definite.
pub fn solve_care_weighted(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    r: Option<&DMatrix<f64>>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    let n = check_square("A", a)?;
    if b.nrows() != n || b.ncols() == 0 {
        return Err(Error::Shape(format!(
            "B must have {n} rows and at least one column, got {}×{}",
            b.nrows(),
            b.ncols()
        )));
    }
    check_finite("B", b)?;
    let m = b.ncols();
    let g = match r {
        None => matmul(b, &b.transpose()),
        Some(r) => {
            check_shape("R", r, m, m)?;
            check_finite("R", r)?;
            check_symmetric("R", r, 1e-10)?;
            let chol = symmetrize(r).cholesky().ok_or_else(|| {
                Error::InvalidInput(
                    "R must be symmetric positive definite (Cholesky failed)".into(),
                )
            })?;
            // G = B R⁻¹ Bᵀ = Mᵀ M with M = L⁻¹ Bᵀ.
            let mut m_t = b.transpose();
            if !chol.l().solve_lower_triangular_mut(&mut m_t) {
                return Err(Error::InvalidInput("R is singular".into()));
            }
            matmul_tn(&m_t, &m_t)
        }
    };
    solve_care(a, &g, q, opts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    fn opts() -> CareOptions {
        CareOptions::default()
    }

    #[test]
    fn scalar_closed_form() {
        // 2ax − g x² + q = 0 ⇒ x = (a + sqrt(a² + g q))/g.
        for &(a, g, q) in &[
            (1.0, 1.0, 1.0),
            (-2.0, 0.5, 3.0),
            (0.0, 1.0, 1.0),
            (5.0, 1e-3, 1e2),
        ] {
            let s = solve_care(
                &DMatrix::from_element(1, 1, a),
                &DMatrix::from_element(1, 1, g),
                &DMatrix::from_element(1, 1, q),
                &opts(),
            )
            .unwrap();
            let exact = (a + (a * a + g * q).sqrt()) / g;
            assert!(
                (s.x[(0, 0)] - exact).abs() <= 1e-13 * exact.abs().max(1.0),
                "{a} {g} {q}"
            );
            assert!(
                (s.closed_loop_abscissa + (a * a + g * q).sqrt()).abs() < 1e-12 * exact.max(1.0)
            );
        }
    }

    #[test]
    fn random_problems_have_small_residuals_and_stable_closed_loops() {
        let mut rng = Rng::new(5);
        for &n in &[1usize, 2, 3, 5, 10, 30, 80] {
            let a = rng.matrix(n, n);
            let b = rng.matrix(n, (n / 2).max(1));
            let g = &b * b.transpose();
            let q = rng.psd(n, n) + DMatrix::identity(n, n);
            let s = solve_care(&a, &g, &q, &opts()).unwrap();
            assert!(s.residual < 1e-13, "n={n}: residual {}", s.residual);
            assert!(s.closed_loop_abscissa < 0.0);
            let acl = &a - &g * &s.x;
            let ev = acl.complex_eigenvalues();
            assert!(ev.iter().all(|l| l.re < 0.0));
            assert!((&s.x - s.x.transpose()).norm() == 0.0);
            assert!(
                s.x.clone().cholesky().is_some(),
                "X should be positive definite for Q > 0"
            );
        }
    }

    #[test]
    fn newton_polish_keeps_or_lowers_the_residual() {
        let mut rng = Rng::new(9);
        let n = 20;
        let a = rng.matrix(n, n) * 3.0;
        let b = rng.matrix(n, 2);
        let g = &b * b.transpose();
        let q = rng.psd(n, 3);
        let plain = solve_care(&a, &g, &q, &opts()).unwrap();
        let polished = solve_care(
            &a,
            &g,
            &q,
            &CareOptions {
                scale: true,
                newton_steps: 3,
            },
        )
        .unwrap();
        // This problem is ill-conditioned (rcond(U11) ≈ 6e-8): the Schur solution is accurate to
        // about eps/rcond, and the polish may move X by that much while lowering the residual.
        let diff = (&polished.x - &plain.x).norm() / plain.x.norm();
        assert!(polished.residual <= plain.residual);
        assert!(
            diff <= 1e3 * f64::EPSILON / plain.rcond,
            "{diff:e} vs rcond {:e}",
            plain.rcond
        );
    }

    #[test]
    fn weighted_form_matches_explicit_g() {
        let mut rng = Rng::new(2);
        let n = 6;
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, 2);
        let r = rng.psd(2, 2) + DMatrix::identity(2, 2);
        let q = rng.psd(n, n);
        let g = &b * r.clone().try_inverse().unwrap() * b.transpose();
        let x1 = solve_care_weighted(&a, &b, &q, Some(&r), &opts())
            .unwrap()
            .x;
        let x2 = solve_care(&a, &g, &q, &opts()).unwrap().x;
        assert!((&x1 - &x2).norm() <= 1e-11 * x2.norm());
    }

    #[test]
    fn imaginary_axis_eigenvalues_are_refused() {
        // Undamped oscillator with Q = 0: its unobservable modes ±i are Hamiltonian eigenvalues.
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, 0.0]);
        let g = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1.0]);
        let q = DMatrix::zeros(2, 2);
        let err = solve_care(&a, &g, &q, &opts()).unwrap_err();
        assert!(matches!(err, Error::NoStabilizingSolution(_)), "{err:?}");
    }

    #[test]
    fn double_axis_eigenvalues_split_by_rounding_are_refused() {
        // CAREX 2.5 at ε = 0: the closed loop would be [[0, −1], [1, 0]]; the Hamiltonian has the
        // double eigenvalues ±i, which rounding splits by ~1e-8 (the √eps effect).
        let a = DMatrix::from_row_slice(2, 2, &[3.0, 1.0, 4.0, 2.0]);
        let g = DMatrix::from_element(2, 2, 1.0);
        let q = DMatrix::from_row_slice(2, 2, &[-11.0, -5.0, -5.0, -2.0]);
        let err = solve_care(&a, &g, &q, &opts()).unwrap_err();
        assert!(matches!(err, Error::NoStabilizingSolution(_)), "{err:?}");
        // Slightly damped (ε = 1e-2) it is solvable and X = [[2, 1], [1, 1]] exactly.
        let e = 1e-2;
        let a = DMatrix::from_row_slice(2, 2, &[3.0 - e, 1.0, 4.0, 2.0 - e]);
        let q = DMatrix::from_row_slice(
            2,
            2,
            &[4.0 * e - 11.0, 2.0 * e - 5.0, 2.0 * e - 5.0, 2.0 * e - 2.0],
        );
        let x = solve_care(&a, &g, &q, &opts()).unwrap().x;
        let exact = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 1.0]);
        assert!((x - exact).norm() < 1e-12);
    }

    #[test]
    fn unstabilisable_data_are_refused() {
        // Unstable mode 1 not reached by G.
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let g = DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 1.0]);
        let q = DMatrix::identity(2, 2);
        assert!(solve_care(&a, &g, &q, &opts()).is_err());
    }

    #[test]
    fn bad_input_is_refused() {
        let a = DMatrix::<f64>::identity(2, 2);
        let g = DMatrix::<f64>::identity(3, 3);
        assert!(matches!(
            solve_care(&a, &g, &a, &opts()),
            Err(Error::Shape(_))
        ));
        let mut q = DMatrix::<f64>::identity(2, 2);
        q[(0, 1)] = f64::INFINITY;
        assert!(matches!(
            solve_care(&a, &a, &q, &opts()),
            Err(Error::NonFinite(_))
        ));
        let mut q = DMatrix::<f64>::identity(2, 2);
        q[(0, 1)] = 1.0;
        assert!(matches!(
            solve_care(&a, &a, &q, &opts()),
            Err(Error::InvalidInput(_))
        ));
        let r = DMatrix::from_row_slice(1, 1, &[-1.0]);
        let b = DMatrix::from_row_slice(2, 1, &[1.0, 1.0]);
        assert!(matches!(
            solve_care_weighted(&a, &b, &a, Some(&r), &opts()),
            Err(Error::InvalidInput(_))
        ));
    }
}
