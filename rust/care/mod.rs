// Why this module is long: one pipeline (scale, balance, Schur, solve, refine, certify) whose steps share the
// scaled data and diagnostics, and the dispatch to the closed-loop route; the steps that stand alone are in
// the sibling modules.
//! Continuous algebraic Riccati equation by the Hamiltonian/Schur method (Laub 1979), with the
//! safeguards of SLICOT SB02RD and scipy, and an error bound for every solution:
//!
//! 1. norm scaling `G ← s·G`, `Q ← Q/s` with `s` the power of two nearest `sqrt(‖Q‖_F/‖G‖_F)`;
//! 2. symplectic balancing ([`balance`]): the CARE with data `(DAD⁻¹, DGD, D⁻¹QD⁻¹)`,
//!    `D = diag(2^k)` (both scalings exact, so `X = s·D X̃ D` exactly);
//! 3. real Schur form of the Hamiltonian `H = [[A, −G], [−Q, −Aᵀ]]`; eigenvalues on the imaginary
//!    axis are recognised by their own perturbation bounds ([`axis`]); the `n` stable eigenvalues are
//!    ordered first, and `[U11; U21]` spans the stable invariant subspace;
//! 4. `X = U21 U11⁻¹` from an LU of `U11ᵀ` with a condition estimate, symmetrised;
//! 5. Newton refinement ([`refine`]) in the original coordinates while the residual is above its own
//!    rounding level, with the closed-loop Lyapunov operator taken from the Schur form (no new
//!    factorisation; a fresh one only if that stalls);
//! 6. a forward-error bound from the same operator ([`refine::error_bounds`]).
//!
//! When this route refuses for an eigenvalue on the axis to within its bound or the wrong stable
//! count (or returns a marginal solution), the closed-loop route (module `kleinman`: Newton–Kleinman on
//! the `n × n` closed loop from a stabilising start, with its own certificate) is tried; its
//! solution replaces the refusal only when certified.
//!
//! Every solution carries its diagnostics ([`CareSolution`]). Failures say why: eigenvalues on the
//! imaginary axis, the wrong number of stable eigenvalues (not stabilisable / detectable), or an
//! ill-conditioned `U11`.

pub mod axis;
pub mod balance;
mod bass;
mod compensated;
pub mod generalized;
mod kleinman;
mod quadratic;
pub mod refine;

use crate::linalg::dense::{
    check_finite, check_shape, check_square, check_symmetric, matmul, matmul_nt, matmul_tn,
    norm_fro, symmetrize, Lu,
};
use crate::linalg::schur::RealSchur;
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
pub(crate) use compensated::COMPENSATED_MAX_ORDER;
use compensated::{compensated_refinement, CERTIFY_MAX_ORDER};
use nalgebra::DMatrix;
use quadratic::Quadratic;
use refine::{ClosedLoop, Operator};

/// Options for [`solve_care`].
#[derive(Debug, Clone, Copy)]
pub struct CareOptions {
    /// Scale `Q` and `G` by (the power of two nearest) `sqrt(‖Q‖/‖G‖)` before the Schur step
    /// (SLICOT SB02RD).
    pub scale: bool,
    /// Balance the Hamiltonian by a symplectic diagonal similarity (scipy's `balanced=True`).
    pub balance: bool,
    /// At most this many Newton refinement steps after the Schur solution (0: none). Corrections
    /// are computed until they fall below a few ulps of X; a step is kept only if the next
    /// correction is at most half as large (Newton is converging).
    pub newton_steps: usize,
    /// Return a solution even when Hamiltonian eigenvalues lie on the imaginary axis to within
    /// their perturbation bounds (a marginal problem: the solution, if any, is not stabilising
    /// but only semi-stabilising, and its accuracy is poor). The solution is marked `marginal`.
    pub accept_marginal: bool,
}

/// Default bound on the refinement steps (quadratic convergence needs two or three).
pub const DEFAULT_NEWTON_STEPS: usize = 8;

impl Default for CareOptions {
    fn default() -> Self {
        CareOptions {
            scale: true,
            balance: true,
            newton_steps: DEFAULT_NEWTON_STEPS,
            accept_marginal: false,
        }
    }
}

/// The stabilising solution of a CARE with its diagnostics.
#[derive(Debug, Clone)]
pub struct CareSolution {
    /// The stabilising solution `X = Xᵀ`.
    pub x: DMatrix<f64>,
    /// Relative residual `‖AᵀX + XA − XGX + Q‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)` (a backward
    /// error; it says nothing about the accuracy of `X` on its own).
    pub residual: f64,
    /// An upper bound on the relative error `‖X − X*‖_F / ‖X*‖_F` (first order in the residual,
    /// with a Newton–Kantorovich factor for the second-order term; `∞` when no bound can be
    /// established, e.g. for a marginal problem). See [`refine`].
    pub forward_error: f64,
    /// An upper bound on `|tr X − tr X*|`, from the same bound (`∞` when none).
    pub trace_error: f64,
    /// Reciprocal 1-norm condition estimate of `U11` in `X U11 = U21` (small: X is inaccurate).
    /// NaN for a warm-started solution ([`crate::cost::Evaluation::warm`]) and for one of the
    /// closed-loop route (module `kleinman`), which form no `U11`; their accuracy is stated by
    /// `forward_error` alone.
    pub rcond: f64,
    /// Spectral abscissa `max Re λ(A − G X)` of the closed loop (negative). Taken from the stable
    /// Hamiltonian eigenvalues, which are the closed-loop eigenvalues (for a warm-started solution:
    /// from the real Schur form of the final closed loop itself).
    pub closed_loop_abscissa: f64,
    /// Distance of the Hamiltonian eigenvalue nearest the imaginary axis in units of its own
    /// perturbation bound `κ(λ)·eps·‖H‖` (∞ when none is within `√eps·‖H‖`); below
    /// [`axis::AXIS_FACTOR`] it counts as on the axis. NaN for a warm-started solution, which forms
    /// no Hamiltonian: there the stabilising property is certified instead by the
    /// Newton–Kantorovich test of the error bound (a warm start that fails it falls back to this
    /// solver). NaN too for a solution of the closed-loop route (module `kleinman`), whose closed loop
    /// is judged by its own eigenvalue perturbation bounds.
    pub axis_margin: f64,
    /// The problem is marginal (eigenvalues on the axis to within their perturbation bounds, or a
    /// computed stable subspace that is not Lagrangian) and was solved because
    /// [`CareOptions::accept_marginal`] asked for it.
    pub marginal: bool,
    /// Refinement steps taken (and kept); for a warm-started solution, the Newton–Kleinman
    /// corrections applied to the starting point.
    pub newton_steps: usize,
    /// The norm-scaling factor applied to `Q` and `G` (1 when scaling is off or not applicable,
    /// and for a warm-started solution).
    pub scaling: f64,
}

/// From order [`BLIND_STEP_MIN_ORDER`] on (where the contraction test costs as much as 8 % of
/// the solve), a correction below `BLIND_STEP·n·eps·‖X‖_F` that does not increase the residual
/// is applied without the test. On random problems it is the Newton step that the test accepts
/// (error 5e-13 → 1e-15 at n = 200); on small ill-conditioned ones a rounding-level step can be
/// noise (CAREX 1.2: 9e-16 → 4e-15), hence the order limit.
pub(crate) const BLIND_STEP: f64 = 64.0;
pub(crate) const BLIND_STEP_MIN_ORDER: usize = 64;

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

/// `‖W − Wᵀ‖_F / max(‖W‖_F, 1)` for `W = U11ᵀU21` (zero for a Lagrangian subspace).
fn lagrangian_asymmetry(u11: &DMatrix<f64>, u21: &DMatrix<f64>) -> f64 {
    let n = u11.nrows();
    let w = matmul_tn(u11, u21);
    let mut skew2 = 0.0; // ‖W − Wᵀ‖_F²
    for j in 0..n {
        for i in 0..j {
            let d = w[(i, j)] - w[(j, i)];
            skew2 += 2.0 * d * d;
        }
    }
    skew2.sqrt() / norm_fro(&w).max(1.0)
}

/// The Riccati residual `AᵀX + XA − XGX + Q`.
pub fn care_residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> DMatrix<f64> {
    Quadratic::Dense(g).residual(a, q, x)
}

/// The residual `AᵀX + XA − (XB)(XB)ᵀ + Q` of the CARE with `G = B Bᵀ` given by its factor, as
/// [`solve_care_factored`]'s refinement computes it, and the Frobenius-norm bound on its rounding
/// error (`γ (|Aᵀ||X| + |X||A| + [rounding of (XB)(XB)ᵀ] + |Q|)`, `γ = (2n + 4)·eps`): what a
/// solver that refines `X` by its own route needs to report the same error bounds.
pub(crate) fn factored_residual(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> DMatrix<f64> {
    Quadratic::Factor(b).residual(a, q, x)
}

/// The rounding bound of [`factored_residual`] at `x`.
pub(crate) fn factored_rounding(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> f64 {
    Quadratic::Factor(b).rounding(a, q, x)
}

/// A solution refined with compensated residuals ([`refine_compensated_factored`]).
pub(crate) struct Refined {
    /// The refined `X`.
    pub(crate) x: DMatrix<f64>,
    /// Its residual, accurate to `rounding`.
    pub(crate) r: DMatrix<f64>,
    /// A bound on the error of `r` (Frobenius).
    pub(crate) rounding: f64,
    /// Corrections applied.
    pub(crate) steps: usize,
}

/// The cold solve's refinement of a stalled, stiff solution with residuals in double-double,
/// for a caller holding the real Schur form of the transposed closed loop `(A − B BᵀX)ᵀ`
/// (the operator is kept frozen). `None` when the compensated residual is not finite.
pub(crate) fn refine_compensated_factored(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    closed_loop_t: &Lyapunov,
    x: &DMatrix<f64>,
) -> Result<Option<Refined>> {
    let op = Operator::Transposed(closed_loop_t);
    let frozen = |_: &DMatrix<f64>| None;
    Ok(
        compensated_refinement(a, q, Quadratic::Factor(b), &op, &frozen, x)?.map(|c| Refined {
            x: c.x,
            r: c.r,
            rounding: c.rounding,
            steps: c.steps,
        }),
    )
}

/// `‖R‖_F / (‖Q‖_F + 2‖A‖_F‖X‖_F + ‖G‖_F‖X‖_F²)` ([`CareSolution::residual`]).
pub(crate) fn relative_residual(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> f64 {
    let nx = norm_fro(x);
    let denom = norm_fro(q) + 2.0 * norm_fro(a) * nx + norm_fro(g) * nx * nx;
    if denom > 0.0 {
        norm_fro(r) / denom
    } else {
        norm_fro(r)
    }
}

/// The power of two nearest `v > 0`.
fn pow2_near(v: f64) -> f64 {
    let e = v.log2().round().clamp(-1000.0, 1000.0);
    2f64.powi(e as i32)
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
    validate(a, g, q)?;
    solve(a, symmetrize(g), None, q, opts, DataError::Exact)
}

/// [`solve_care`] for data computed from the user's by a transformation whose error the
/// closed-loop route cannot bound (the generalised and cross-term forms): only the Hamiltonian
/// route is used.
pub(crate) fn solve_care_transformed(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    validate(a, g, q)?;
    solve(a, symmetrize(g), None, q, opts, DataError::Transformed)
}

/// [`solve_care`] with `G = B Bᵀ` given by its factor `B` (`n × m`): the residual of the
/// refinement is computed as `(XB)(XB)ᵀ`, which keeps the accuracy when `G` has low rank and
/// large entries (rounding `B Bᵀ` would add information in the null directions of `G`).
pub fn solve_care_factored(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<CareSolution> {
    solve_factored(a, b, q, opts, DataError::Exact)
}

/// How the data reached the solver: what the closed-loop route must add to its bound.
#[derive(Clone, Copy)]
enum DataError<'a> {
    /// The user's own `A`, `G` (or its factor) and `Q`.
    Exact,
    /// The factor `F = B L⁻ᵀ` with `L` the computed Cholesky factor of `R` (held here, and
    /// [`cholesky_factor_error`] computed only if the closed-loop route runs).
    Cholesky(&'a DMatrix<f64>),
    /// Data transformed by the caller with errors not bounded here: no closed-loop route.
    Transformed,
}

impl DataError<'_> {
    /// A bound on `‖E‖₂` in the intended `G = F(I + E)Fᵀ`; `None` for transformed data.
    fn factor_error(&self) -> Option<f64> {
        match self {
            DataError::Exact => Some(0.0),
            DataError::Cholesky(l) => Some(cholesky_factor_error(l)),
            DataError::Transformed => None,
        }
    }
}

/// [`solve_care_factored`] for a factor `B` of the intended `G`, as `data` says.
fn solve_factored(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    data: DataError<'_>,
) -> Result<CareSolution> {
    let n = check_square("A", a)?;
    if b.nrows() != n {
        return Err(Error::Shape(format!(
            "B must have {n} rows, got {}×{}",
            b.nrows(),
            b.ncols()
        )));
    }
    check_finite("B", b)?;
    let g = symmetrize(&matmul_nt(b, b));
    validate(a, &g, q)?;
    solve(a, g, Some(b), q, opts, data)
}

/// The norm-scaled, symplectically balanced data of a CARE and its Hamiltonian
/// `H = [[Ã, −G̃], [−Q̃, −Ãᵀ]]` (steps 1–2 of the module documentation).
pub(super) struct Scaled {
    /// The norm-scaling factor `s` (`G̃ ∝ s·G`, `Q̃ ∝ Q/s`).
    pub(super) s: f64,
    /// The balancing `D = diag(2^k)`.
    pub(super) d: Vec<f64>,
    pub(super) ab: DMatrix<f64>,
    pub(super) gb: DMatrix<f64>,
    /// The Hamiltonian and its Frobenius norm.
    pub(super) h: DMatrix<f64>,
    pub(super) hnorm: f64,
}

/// Scales and balances `(A, G, Q)` (`‖G‖_F = ng > 0`) and forms the Hamiltonian; an error when it
/// is not representable.
pub(super) fn scaled_hamiltonian(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<Scaled> {
    let n = a.nrows();
    let (nq, ng) = (norm_fro(q), norm_fro(g));
    let s = if opts.scale && nq > 0.0 {
        // sqrt(‖Q‖/‖G‖) without forming the quotient, which under/overflows for ‖Q‖ ~ 1e-300,
        // ‖G‖ ~ 1e300 (and the scaled Hamiltonian then has 1/s = ∞ entries).
        pow2_near(nq.sqrt() / ng.sqrt())
    } else {
        1.0
    };
    let (gs, qs) = (g * s, q / s);

    // Symplectic balancing (exact: powers of two); fall back to none if it would overflow.
    let mut k = if opts.balance {
        balance::symplectic_exponents(a, &gs, &qs)
    } else {
        vec![0; n]
    };
    let (mut ab, mut gb, mut qb) = balance::apply(&k, a, &gs, &qs);
    if ![&ab, &gb, &qb]
        .iter()
        .all(|m| m.iter().all(|v| v.is_finite()))
    {
        k = vec![0; n];
        (ab, gb, qb) = (a.clone(), gs.clone(), qs.clone());
    }
    let d: Vec<f64> = k.iter().map(|&e| 2f64.powi(e)).collect();

    // Hamiltonian of the scaled, balanced problem.
    let mut h = DMatrix::zeros(2 * n, 2 * n);
    for j in 0..n {
        for i in 0..n {
            h[(i, j)] = ab[(i, j)];
            h[(i, n + j)] = -gb[(i, j)];
            h[(n + i, j)] = -qb[(i, j)];
            h[(n + i, n + j)] = -ab[(j, i)];
        }
    }
    let hnorm = norm_fro(&h);
    if !(nq.is_finite() && ng.is_finite() && hnorm.is_finite() && h.iter().all(|v| v.is_finite())) {
        return Err(hamiltonian_overflow(a, nq, ng));
    }
    Ok(Scaled {
        s,
        d,
        ab,
        gb,
        h,
        hnorm,
    })
}

/// The Hamiltonian route, then — only when it refuses for want of a stabilising solution (an
/// eigenvalue on the axis to within its bound, the wrong stable count) or returns a marginal
/// solution — the closed-loop route (module `kleinman`), whose solution is returned when it is
/// certified; otherwise the first route's answer stands. A computed stable subspace that is not
/// Lagrangian (Hamiltonian eigenvalues clustered at the axis, as in CAREX 11 and 14: a nearly
/// uncontrollable oscillation) keeps the first route's answer: such a problem is treated as
/// marginal, refused unless [`CareOptions::accept_marginal`].
fn solve(
    a: &DMatrix<f64>,
    g: DMatrix<f64>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    data: DataError<'_>,
) -> Result<CareSolution> {
    let q = symmetrize(q);
    let mut not_lagrangian = false;
    let first = hamiltonian_route(a, &g, factor, &q, opts, &mut not_lagrangian);
    let second = !matches!(data, DataError::Transformed)
        && !not_lagrangian
        && match &first {
            Err(Error::NoStabilizingSolution(_)) => norm_fro(&g) > 0.0,
            Ok(sol) => sol.marginal,
            Err(_) => false,
        };
    if !second {
        return first;
    }
    let Some(factor_error) = data.factor_error() else {
        return first;
    };
    match kleinman::solve(a, &g, factor, &q, opts, factor_error)? {
        Some(sol) => Ok(sol),
        None => first,
    }
}

/// Steps 1–6 of the module documentation; `not_lagrangian` is set when the answer (a refusal or
/// a marginal solution) is due to a stable subspace that is not Lagrangian.
fn hamiltonian_route(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    not_lagrangian_flag: &mut bool,
) -> Result<CareSolution> {
    let n = a.nrows();
    let quad = match factor {
        Some(b) => Quadratic::Factor(b),
        None => Quadratic::Dense(g),
    };

    let ng = norm_fro(g);
    if ng == 0.0 {
        return Err(Error::NoStabilizingSolution(
            "G = B R⁻¹ Bᵀ is zero: no input acts on the system, so no stabilising solution exists \
             unless A is already stable (solve the Lyapunov equation instead)"
                .into(),
        ));
    }
    let Scaled {
        s,
        d,
        ab,
        gb,
        h,
        hnorm,
    } = scaled_hamiltonian(a, g, q, opts)?;

    let mut schur = RealSchur::new(&h)?;
    let report = axis::examine(&schur.t, &schur.blocks(), hnorm);
    // An eigenvalue within AXIS_FACTOR of its perturbation bound may be on the axis — or be the
    // slow, badly conditioned closed-loop eigenvalue of a stiff model, whose stabilising solution
    // is perfectly computable. Such a problem is solved provisionally and kept only when the
    // solution is certified below (Newton–Kantorovich); otherwise it is refused (or, asked to
    // accept marginal problems, returned marked marginal).
    let near_axis = report.on_axis > 0;
    let provisional = near_axis && !opts.accept_marginal;
    let axis_error = || {
        let (re, im) = report.eigenvalue;
        Error::NoStabilizingSolution(format!(
            "the Hamiltonian has an eigenvalue on the imaginary axis to within its perturbation \
             bound ({re:.3e} {im:+.3e}i, {:.2} times its bound κ·eps·‖H‖, threshold {}): no \
             stabilising solution exists ((A, B) not stabilisable or (Q, A) not detectable on the \
             axis)",
            report.margin,
            axis::AXIS_FACTOR
        ))
    };
    // While the answer is provisional, a failure below is reported as the axis refusal it most
    // likely is.
    let refuse = |e: Error| if provisional { axis_error() } else { e };
    let eig = schur.eigenvalues();
    let stable = eig.iter().filter(|(re, _)| *re < 0.0).count();
    if stable != n {
        return Err(refuse(Error::NoStabilizingSolution(format!(
            "the Hamiltonian has {stable} stable eigenvalues, expected {n}"
        ))));
    }
    let sdim = schur.reorder(|re, _| re < 0.0).map_err(|e| match e {
        Error::Interrupted(_) => e,
        e => refuse(e),
    })?;
    if sdim != n {
        return Err(refuse(Error::NoStabilizingSolution(format!(
            "reordering selected {sdim} stable eigenvalues, expected {n}"
        ))));
    }
    let closed_loop_abscissa = schur.eigenvalues()[..n]
        .iter()
        .map(|(re, _)| *re)
        .fold(f64::NEG_INFINITY, f64::max);

    let u11 = schur.z.view((0, 0), (n, n)).into_owned();
    let u21 = schur.z.view((n, 0), (n, n)).into_owned();

    // The stable subspace of a Hamiltonian is Lagrangian: U11ᵀU21 is symmetric. A computed
    // subspace that is not means eigenvalues too near the axis to be separated reliably: marginal.
    let asym = lagrangian_asymmetry(&u11, &u21);
    *not_lagrangian_flag = asym > LAGRANGIAN_TOL && !provisional;
    if asym > LAGRANGIAN_TOL && !opts.accept_marginal {
        return Err(refuse(Error::NoStabilizingSolution(format!(
            "the computed stable invariant subspace is not Lagrangian (asymmetry {asym:.1e}): \
             the Hamiltonian has eigenvalues too near the imaginary axis for a reliable solution"
        ))));
    }
    let not_lagrangian = asym > LAGRANGIAN_TOL;

    // X̃ U11 = U21  ⇔  U11ᵀ X̃ = U21ᵀ (X̃ symmetric).
    let lu = Lu::new(&u11.transpose()).map_err(|_| {
        refuse(Error::SingularProblem(
            "U11 is singular: the stable invariant subspace is not the graph of a matrix \
             (no stabilising solution; is (A, B) stabilisable?)"
                .into(),
        ))
    })?;
    let rcond = lu.rcond();
    if rcond < f64::EPSILON {
        return Err(refuse(Error::SingularProblem(format!(
            "U11 is too ill-conditioned (rcond = {rcond:.1e}) for an accurate solution"
        ))));
    }
    let mut xb = u21.transpose();
    lu.solve_in_place(&mut xb);
    let xb = symmetrize(&xb);
    // X = s·D X̃ D (exact).
    let mut x = balance::congruence(&xb, &d, s);
    if x.iter().any(|v| !v.is_finite()) {
        return Err(refuse(Error::SingularProblem(
            "the solution overflowed (U11 nearly singular)".into(),
        )));
    }

    let t11 = schur.t.view((0, 0), (n, n)).into_owned();
    let mut op = Operator::Frozen(ClosedLoop {
        t11: &t11,
        lu: &lu,
        u11: &u11,
        d: &d,
    });
    // The closed loop of a given X, balanced and factored afresh (when the frozen one stalls).
    let fresh = |x: &DMatrix<f64>| {
        let xb = balance::inverse_congruence(x, &d, s);
        let acl = &ab - matmul(&gb, &xb);
        Lyapunov::new(&acl)
            .and_then(|l| l.with_singular_rtol(0.0))
            .ok()
            .map(|l| Operator::Fresh(Box::new(l), &d))
    };
    let mut r = quad.residual(a, q, &x);
    let mut steps = 0;
    // Newton corrections Δ = Ω⁻¹(−R(X)) until they are below a few ulps of X. A small residual does
    // not mean a small error (it can sit at its rounding level while X is wrong in directions the
    // residual barely sees — a network at high rates), nor does a smaller residual mean a smaller
    // error (in a stiff problem the residual's norm lives in the fast modes, the error in the slow
    // ones). So a step is judged by the next correction: it is kept when the corrections contract
    // (‖Δ_next‖ ≤ ½‖Δ‖), as they do while Newton converges, and discarded when they do not —
    // except, for large n, a correction at the solve's own rounding level (below
    // BLIND_STEP·n·eps·‖X‖) that does not increase the residual, which is applied untested: the
    // test would cost a solve, and a noise step of that size cannot make X worse by more than
    // the rounding of the Schur solution. The error bound is a posteriori (from the final
    // residual) either way.
    let mut delta = if opts.newton_steps > 0 {
        op.solve(&(-&r)).ok()
    } else {
        None
    };
    let mut tries = 0;
    let mut stalled = false;
    while let Some(dl) = delta.take() {
        let (dn, xn) = (norm_fro(&dl), norm_fro(&x));
        if tries >= opts.newton_steps || !(dn > 4.0 * f64::EPSILON * xn) {
            break; // converged (or a NaN correction)
        }
        tries += 1;
        let candidate = symmetrize(&(&x + &dl));
        let cr = quad.residual(a, q, &candidate);
        if n >= BLIND_STEP_MIN_ORDER
            && dn <= BLIND_STEP * n as f64 * f64::EPSILON * xn
            && norm_fro(&cr) <= norm_fro(&r)
        {
            // A correction at the rounding level of the solve itself: applied without testing
            // the next one (which costs a solve); were it noise, X moves by no more than that.
            x = candidate;
            r = cr;
            steps += 1;
            break;
        }
        let next = op.solve(&(-&cr)).ok();
        if next.as_ref().is_some_and(|nd| norm_fro(nd) <= 0.5 * dn) {
            x = candidate;
            r = cr;
            steps += 1;
            delta = next;
            continue;
        }
        // No contraction: at the rounding floor, stop; far from it, the frozen operator no longer
        // describes the closed loop — factor the current one once and start again from X.
        if dn <= f64::EPSILON.sqrt() * xn || matches!(op, Operator::Fresh(..)) {
            stalled = true;
            break;
        }
        match fresh(&x) {
            Some(f) => op = f,
            None => break,
        }
        delta = op.solve(&(-&r)).ok();
    }
    let mut rnorm = norm_fro(&r);
    let mut rounding = quad.rounding(a, q, &x);
    // Error bound: −Ω⁻¹(I) ⪰ 0 bounds Ω⁻¹ on symmetric matrices (see `refine`).
    let p = op.solve(&DMatrix::identity(n, n)).ok();
    let mut axis_certified = false;
    let mut fresh_p = None;
    if let Some(p) = &p {
        // When the refinement above stalled (a correction did not contract), the working-
        // precision residual's rounding floor, mapped through Ω⁻¹, may be what stopped it: if
        // that floor is well above eps·‖X‖ (stiff or badly scaled problems), refine further with
        // the residual in double-double (small orders only: it costs about ten plain residuals).
        // Not for marginal problems, where the frozen operator is too far off for it to help.
        let floor = (n as f64).sqrt() * norm_fro(p) * rounding;
        let stiff = stalled
            && !near_axis
            && !not_lagrangian
            && n <= COMPENSATED_MAX_ORDER
            && floor > 16.0 * f64::EPSILON * norm_fro(&x);
        let check_axis = near_axis && !not_lagrangian && n <= CERTIFY_MAX_ORDER;
        let refined = if stiff || check_axis {
            compensated_refinement(a, q, quad, &op, &fresh, &x)?
        } else {
            None
        };
        // A near-axis solution is certified when a stabilising solution provably exists within
        // its error: Newton–Kantorovich with β = ‖p‖ (= ‖Ω⁻¹‖, Russo–Dye), Lipschitz constant
        // 2‖G‖ and the computed correction η (plus what the arithmetic may hide) gives
        // h = 2β‖G‖η < 1/4, hence a solution within 2η; and ‖G‖·2η < 1/(2β) keeps A − GX* stable
        // (the Lyapunov robustness bound for A_clᵀP + PA_cl = −I, P = −p).
        let certified = check_axis
            && refined.as_ref().is_some_and(|c| {
                let beta = norm_fro(c.p.as_ref().unwrap_or(p));
                2.0 * beta * ng * (c.eta + beta * c.arith) < 0.25
            });
        // Kept when it moved X on a stiff problem, or certified a near-axis one (otherwise the
        // working-precision figures stand, unchanged).
        if let Some(c) = refined.filter(|c| if check_axis { certified } else { c.steps > 0 }) {
            x = c.x;
            r = c.r;
            rnorm = norm_fro(&r);
            rounding = c.rounding;
            steps += c.steps;
            fresh_p = c.p;
        }
        axis_certified = certified;
    }
    // The bound uses the closed loop of the final X when it was factored afresh.
    let p = fresh_p.or(p);
    if provisional && !axis_certified {
        return Err(axis_error());
    }
    let marginal = (near_axis && !axis_certified) || not_lagrangian;
    let residual = relative_residual(a, g, q, &x, &r);
    let (forward_error, trace_error) = match &p {
        Some(p) => refine::error_bounds(p, rnorm, rounding, ng, &x),
        None => (f64::INFINITY, f64::INFINITY),
    };

    Ok(CareSolution {
        x,
        residual,
        forward_error,
        trace_error,
        rcond,
        closed_loop_abscissa,
        axis_margin: report.margin,
        marginal,
        newton_steps: steps,
        scaling: s,
    })
}

/// A bound on `‖E‖₂` in `B R⁻¹ Bᵀ = F(I + E)Fᵀ`, `F = B L⁻ᵀ` computed from the computed Cholesky
/// factor `L` of `R` (first order in eps): the Cholesky and triangular-solve backward errors
/// make `F` exact for `R + Δ`, `|Δ| ≤ (3m + 4)·eps·|L||Lᵀ|`, so `E = (I − E₀)⁻¹ − I` with
/// `‖E₀‖ ≤ (3m + 4)·eps·‖|L⁻¹||L|‖²`. ∞ when that is not below 1; 0 when `L` is diagonal with
/// powers of two on its diagonal (exact Cholesky and solves).
fn cholesky_factor_error(l: &DMatrix<f64>) -> f64 {
    let m = l.nrows();
    // A diagonal L of powers of two (R = I, or diagonal R of powers of four): F = BL⁻ᵀ is exact.
    let exact = (0..m).all(|j| {
        (0..m).all(|i| i == j || l[(i, j)] == 0.0) && {
            let d = l[(j, j)];
            d > 0.0 && d == 2f64.powi(d.log2().round() as i32) && d * d == d.powi(2)
        }
    });
    if exact {
        return 0.0;
    }
    let mut linv = DMatrix::identity(m, m);
    if !l.solve_lower_triangular_mut(&mut linv) {
        return f64::INFINITY;
    }
    let skeel = norm_fro(&matmul(&linv.abs(), &l.abs()));
    let e0 = (3.0 * m as f64 + 4.0) * f64::EPSILON * skeel * skeel;
    if e0 < 1.0 {
        e0 / (1.0 - e0)
    } else {
        f64::INFINITY
    }
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
    // The factor of G = B R⁻¹ Bᵀ.
    let (g, chol) = match r {
        None => return solve_factored(a, b, q, opts, DataError::Exact),
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
            (m_t.transpose(), chol)
        }
    };
    let l = chol.l();
    solve_factored(a, &g, q, opts, DataError::Cholesky(&l))
}

#[cfg(test)]
mod tests;
