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
//! When this route refuses for an eigenvalue on the axis to within its bound, the wrong stable
//! count or a stable subspace that is not Lagrangian (or returns a marginal solution), the
//! closed-loop route (module `kleinman`: Newton–Kleinman on the `n × n` closed loop from a
//! stabilising start, with its own certificate) is tried; its solution replaces the refusal only
//! when certified — in place of a subspace that is not Lagrangian, only with its closed loop
//! `kleinman::NOT_LAGRANGIAN_MARGIN` (1e3) times its perturbation bounds from the axis (see
//! `routes`).
//!
//! Every solution carries its diagnostics ([`CareSolution`]). Failures say why: eigenvalues on the
//! imaginary axis, the wrong number of stable eigenvalues (not stabilisable / detectable), or an
//! ill-conditioned `U11`.

pub mod axis;
pub mod balance;
mod bass;
mod closed_loop_newton;
mod compensated;
mod double_double_point;
mod factor_error;
pub mod generalized;
mod hamiltonian;
mod intended;
mod kleinman;
mod quadratic;
mod range;
pub mod refine;
mod scaled_start;
mod weighted;

use crate::linalg::dense::{
    check_finite, check_shape, check_square, check_symmetric, matmul_nt, norm_fro, symmetrize,
};
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
use compensated::compensated_refinement;
pub(crate) use compensated::COMPENSATED_MAX_ORDER;
use factor_error::{factor_error, FactorError};
use hamiltonian::hamiltonian_route;
use kleinman::{Acceptance, Proof, CLOSED_LOOP_FACTOR, NOT_LAGRANGIAN_MARGIN};
use nalgebra::DMatrix;
use quadratic::Quadratic;
use range::{rescaled_gain, with_representation};
use refine::Operator;
pub use weighted::solve_care_weighted;

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
    /// The factor `F = B L⁻ᵀ` with `L` the computed Cholesky factor of `R` (the data are held
    /// here, and the factor's error bound, module `factor_error`, is computed only if the
    /// closed-loop route runs).
    Cholesky {
        /// The (symmetric) `R` factored.
        r: &'a DMatrix<f64>,
        /// The user's `B`.
        b: &'a DMatrix<f64>,
        /// The computed Cholesky factor of `r`.
        l: &'a DMatrix<f64>,
    },
}

impl DataError<'_> {
    /// Bounds on `E` and `δ` in the intended `G = (F + δ)(I + E)(F + δ)ᵀ` for the computed factor
    /// `F` (`factor`); `None` for transformed data.
    fn factor_error(&self, factor: Option<&DMatrix<f64>>) -> Option<FactorError> {
        match (self, factor) {
            (DataError::Exact, _) => Some(FactorError::EXACT),
            (DataError::Cholesky { r, b, l }, Some(f)) => Some(factor_error(r, b, l, f)),
            _ => None,
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
    match validate(a, &g, q) {
        Err(Error::NonFinite(m)) if g.iter().any(|v| !v.is_finite()) => {
            rescaled_gain(a, b, q, opts, data).unwrap_or(Err(Error::NonFinite(m)))
        }
        Err(e) => Err(e),
        Ok(_) if g.iter().all(|&v| v == 0.0) && b.iter().any(|&v| v != 0.0) => {
            rescaled_gain(a, b, q, opts, data)
                .unwrap_or_else(|| solve(a, g, Some(b), q, opts, data))
        }
        Ok(_) => solve(a, g, Some(b), q, opts, data),
    }
}

/// A Hamiltonian-route solution with a forward-error bound above this is tried again on the
/// closed loop from a dearer-input start (module `scaled_start`), and replaced when that route
/// reaches a smaller bound (not when refinement is off, `newton_steps = 0`: the bare Schur
/// solution was asked for). Fewer than four guaranteed digits: the tiny-`R` cases have bounds
/// 1e-3 … 1e5; ordinary problems stay below it (random `n = 200`: ~3e-8, `n = 400`: above 1e-6,
/// where a restart would cost six times the solve).
pub const RESTART_BOUND: f64 = 1e-4;

/// Up to order [`RESTART_SMALL_ORDER`] the restart is tried from this bound on (fewer than six
/// guaranteed digits), where it costs little: a two-input tiny-`R` case (audit seed 328,
/// `R = 1e-13·R₀`, n = 7) had bound 7.5e-5 with an error of 8.8e-10 (restarted: 1.6e-16, bound
/// 1.3e-12); CAREX 4.1 with `n = 21` (Hamiltonian bound 3e-5 on an answer correct to an ulp) is
/// certified at 4.1e-16 (error 7e-17 against 60 digits).
pub const RESTART_BOUND_SMALL: f64 = 1e-6;

/// See [`RESTART_BOUND_SMALL`].
pub const RESTART_SMALL_ORDER: usize = 64;

/// [`routes`], with the answer's representation error ([`with_representation`]).
fn solve(
    a: &DMatrix<f64>,
    g: DMatrix<f64>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    data: DataError<'_>,
) -> Result<CareSolution> {
    let q = symmetrize(q);
    routes(a, g, factor, &q, opts, data).map(|sol| with_representation(sol, &q))
}

/// The Hamiltonian route, then the closed-loop route (module `kleinman`) when the first refuses
/// (an eigenvalue on the axis to within its bound, the wrong stable count, a computed stable
/// subspace that is not Lagrangian, a singular or ill-conditioned `U11`, `G = 0`), returns a
/// marginal solution, or returns one whose bound is above [`RESTART_BOUND`] ([`RESTART_BOUND_SMALL`]
/// up to order [`RESTART_SMALL_ORDER`]): first (for a refusal
/// or a marginal answer) from the Schur solution completed by Bass's gain, whose answer is
/// returned when it is certified; then from the solution of the problem with a dearer input
/// (module `scaled_start`), whose answer is returned when its bound is below the first route's —
/// for a refusal or a marginal answer only with the strict proof of existence and stability that
/// the first attempt needs too. Otherwise the first route's answer stands. `q` is symmetrised.
///
/// **Not Lagrangian.** `U11ᵀU21` of the computed stable subspace should be symmetric; its
/// asymmetry (above `1.5e-8` the route refuses, or with
/// [`CareOptions::accept_marginal`] returns a marginal answer) is the subspace's rounding error
/// `~eps·‖H‖/sep`. It is large both for Hamiltonian eigenvalues within a few hundred perturbation
/// bounds of their mirror images (CAREX 14: closed-loop pair `−5e-13 ± i`) and for stiff models,
/// whose slow eigenvalues are `1e-9` of `‖H‖` though thousands of their own bounds from the axis
/// (which the axis test sees: it passes both). The closed-loop route tells them apart by its
/// certified margin `M`, the least `−Re λ/(κ(λ)·‖E‖ + moved)` over the closed-loop eigenvalues
/// (measured `asym·M = 3e-4 … 0.1`): in place of such a refusal its answer must, besides the strict
/// proof, have `M >` [`NOT_LAGRANGIAN_MARGIN`] `= 1e3` (else `1`, [`CLOSED_LOOP_FACTOR`]). The
/// stiff models have `M = 2.6e3 … 6.8e5` and are solved; CAREX 14 (`M = 137`) stays marginal.
/// (CAREX 11, a double eigenvalue `±i`, is refused by the axis test and its certificate fails:
/// `h = 1/2`.)
fn routes(
    a: &DMatrix<f64>,
    g: DMatrix<f64>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    data: DataError<'_>,
) -> Result<CareSolution> {
    let mut not_lagrangian = false;
    let first = hamiltonian_route(a, &g, factor, q, opts, &mut not_lagrangian);
    let inaccurate = match &first {
        Err(Error::NoStabilizingSolution(_) | Error::SingularProblem(_)) => true,
        Ok(sol) => {
            let bound = if a.nrows() <= RESTART_SMALL_ORDER {
                RESTART_BOUND_SMALL
            } else {
                RESTART_BOUND
            };
            sol.marginal || (sol.forward_error > bound && opts.newton_steps > 0)
        }
        Err(_) => false,
    };
    if !inaccurate {
        return first;
    }
    let Some(factor_error) = data.factor_error(factor) else {
        return first;
    };
    // A refusal or a marginal answer is replaced only by a solution proven to exist (and to be
    // stabilising); an inaccurate one by any solution with a smaller bound.
    let (proof, better) = match &first {
        Ok(f) if !f.marginal => (Proof::FirstOrder, f.forward_error),
        _ => (Proof::Strict, f64::INFINITY),
    };
    // In place of a subspace that is not Lagrangian, the closed loop must be far from the axis.
    let margin = if not_lagrangian {
        NOT_LAGRANGIAN_MARGIN
    } else {
        CLOSED_LOOP_FACTOR
    };
    // From the Schur solution (or Bass's gain), then from the problem with a dearer input.
    if first.is_err() || first.as_ref().is_ok_and(|f| f.marginal) {
        let strict = Acceptance {
            proof: Proof::Strict,
            margin,
        };
        if let Some(sol) =
            kleinman::solve(a, &g, factor, q, opts, factor_error.clone(), (None, strict))?
        {
            return Ok(sol);
        }
    }
    let Some(start) = scaled_start::dearer_input_start(a, &g, factor, q, opts)? else {
        return first;
    };
    let accept = Acceptance { proof, margin };
    match kleinman::solve(a, &g, factor, q, opts, factor_error, (Some(&start), accept))? {
        Some(sol) if sol.forward_error < better => Ok(sol),
        _ => first,
    }
}

#[cfg(test)]
mod tests;
