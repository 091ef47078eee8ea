//! The closed-loop route: the stabilising CARE solution by Newton–Kleinman iteration on the `n × n`
//! closed loop, for the problems the Hamiltonian route refuses although a stabilising solution may
//! exist (stiff models whose slow closed-loop eigenvalue, well conditioned in `A − GX`, is lost in
//! the `2n × 2n` Hamiltonian of norm `~‖A‖`; `G` with entries `~1e14` from an ill-conditioned `R`).
//!
//! **Start.** The graph `X₀` of the invariant subspace of the `n` leftmost Hamiltonian eigenvalues
//! (the Schur solution, whether or not its stable count or its axis test passed), else `X₀ = 0`;
//! the gain `K₀ = BᵀX₀` is completed by Bass's method on the unstable part of `A − BK₀`
//! ([`super::bass`]; one mode at a time when the Gramian of all of them is not numerically
//! definite) so that the computed `A − BK₀` is stable.
//!
//! **Iteration (Kleinman 1968).** `(A − BK_k)ᵀX_{k+1} + X_{k+1}(A − BK_k) = −Q − K_kᵀK_k`,
//! `K_{k+1} = BᵀX_{k+1}`. From a stabilising `K₀` every `A − BK_k` is stable and `X_k` decreases
//! monotonically to the stabilising solution, quadratically at the end. A stabilising feedback
//! exhibits stabilisability, and with `(Q, A)` detectable the stabilising solution exists and is
//! the limit; a problem without one shows it by a closed loop that cannot be kept stable or a limit
//! whose closed loop is not stable beyond its perturbation bounds. The limit is then refined by
//! Newton steps with the residual in double-double ([`super::compensated`]).
//!
//! **Acceptance**, both required (otherwise the caller keeps the Hamiltonian route's refusal):
//! (b) a Kantorovich-type certificate ([`certificate`]: the Newton correction checked by its own
//! double-double residual, `‖Ω⁻¹‖ = ‖Ω⁻¹(I)‖₂` (Russo–Dye) for what the arithmetic may hide, and
//! the quadratic term seen through `B`) proves a solution `X*` with
//! `‖X* − X‖_F/‖X‖_F ≤ forward_error ≤` [`FORWARD_ERROR_LIMIT`]; (a) the closed loop of `X`
//! corrected by its Newton step is stable with a margin judged by its own eigenvalue perturbation
//! bounds: every eigenvalue has `−Re λ > CLOSED_LOOP_FACTOR·(κ(λ)·‖E‖ + κ_B(λ)·‖V‖₂)`, `κ(λ)` its
//! condition in the Schur form of that closed loop, `‖E‖` the Schur backward error `eps·‖A_c‖`
//! and the rounding of `A − GX`, and `B·V = G(X* − X − Δ̂)` the proven distance to the exact
//! solution's closed loop, seen through the eigenvalue's sensitivity to the input
//! (`κ_B(λ) = ‖Bᵀy‖‖x‖/|yᴴx| ≤ κ(λ)‖B‖₂`, [`stability_margin`]) — so the closed loop of the exact
//! solution is stable too, and `X*` is the stabilising solution. An eigenvalue on the axis (an
//! uncontrollable oscillation) fails (a): its closed-loop eigenvalue stays within its bound of the
//! axis. In place of a refusal for a computed stable subspace that is not Lagrangian, (a) is asked
//! with the factor [`NOT_LAGRANGIAN_MARGIN`] instead of [`CLOSED_LOOP_FACTOR`] (see there: the
//! stiff models pass it by decades, CAREX 14 stays marginal).
//!
//! **At the double-double point.** Where the strict test (b) fails at `X` (only there), it is
//! taken at `Y = X + D`, `D` the Newton correction at `X` held as a second double (module
//! `double_double_point`): `R(Y) = R(X) + Ω_X(D) − DGD` accumulated in double-double with the
//! error bounds of each term, the closed loop `A − GY = A_c − GD` with its rounding, and the same
//! certificate at `Y`, which proves `X*` within its radius of `Y + Δ̂_Y`. For the returned `X`
//! the bound adds `‖D‖_F/‖X‖_F`, and (a) is asked at the closed loop of `Y + Δ̂_Y`.
//!
//! **A Cholesky-derived factor.** For scipy's form with a general `R` the iteration works with the
//! computed factor `F` of `G = B R⁻¹ Bᵀ`. When the a-posteriori bound of module `factor_error`
//! knows the intended `G = (F + δ)(I + E)(F + δ)ᵀ` (`Ê`, `δ̂` to within small errors), (a) and
//! (b) are taken for the intended data: residual and closed loop formed by module `intended`,
//! up to [`INTENDED_STEPS`] Newton steps on them, the quadratic term bounded with `δ`
//! (`intended::self_map`) and the closed loop's distance split into the part through `F` and the
//! part through `δ` (`intended::intended_bound`). Otherwise (the a-priori bound) the data's
//! error is bounded by norms and added to the residual's (`intended::data_residual`,
//! `intended::with_factor_error`).

use super::axis::{condition, input_condition};
use super::closed_loop_newton::{closed_loop, iterate, newton_from, soft};
use super::compensated::{arith_bound, compensated_refinement};
use super::double_double_point::certify_at_double_double_point;
use super::factor_error::FactorError;
use super::hamiltonian::leftmost_graph;
use super::intended::{
    data_residual, intended, intended_bound, self_map, with_factor_error, Extra,
};
use super::quadratic::{psd_factor, Quadratic};
use super::refine::{norm2_bound_symmetric, Operator};
use super::{bass, relative_residual, CareOptions, CareSolution};
use crate::linalg::dense::{matmul, matmul_tn, norm_fro, symmetrize};
use crate::linalg::schur::RealSchur;
use crate::linalg::sylvester::Lyapunov;
use crate::Result;
use nalgebra::DMatrix;

/// A closed-loop solution is accepted only with a forward-error bound at most this (relative,
/// Frobenius).
pub const FORWARD_ERROR_LIMIT: f64 = 1e-6;

/// An eigenvalue of the final closed loop counts as stable when `−Re λ` exceeds this multiple of
/// its first-order perturbation bound `κ(λ)·‖E‖`. `‖E‖` is itself a worst-case bound (rounding
/// bounds and the proven distance to `X*`, measured errors being orders of magnitude below it), so
/// no further factor is applied; a factor 2 would refuse n = 40 stiff problems whose slow
/// eigenvalue is 1.6–1.8 bounds from the axis.
pub const CLOSED_LOOP_FACTOR: f64 = 1.0;

/// The factor of test (a) for a solution that replaces a refusal of the Hamiltonian route for a
/// computed stable subspace that is not Lagrangian. That refusal comes both for stable
/// Hamiltonian eigenvalues within a few hundred perturbation bounds of their mirror images (CAREX
/// 14: margin `M = 137` in test (a)'s units, `X` conditioned `~1e13`), kept as marginal, and for
/// stiff models whose slow eigenvalues are `1e-9` of `‖H‖` (`M = 2.6e3 … 6.8e5` on the audit's 14
/// cases): see the parent module's `routes`. A policy threshold on the certified margin, not a
/// condition of the proof (which factor 1 already completes).
pub const NOT_LAGRANGIAN_MARGIN: f64 = 1e3;

/// A solution whose bound is first order ([`Proof::FirstOrder`]) is accepted with a bound at
/// most this (the caller keeps it only when it is below the Hamiltonian route's).
const FIRST_ORDER_LIMIT: f64 = 1e-3;

/// Newton steps on the intended data of a Cholesky-derived factor at most (one is enough when
/// the factor's solution is within ~1e-12 of the intended one).
const INTENDED_STEPS: usize = 2;

/// What an accepted solution must prove: its error bound and its closed loop's margin.
#[derive(Clone, Copy)]
pub(super) struct Acceptance {
    /// The kind of error bound.
    pub(super) proof: Proof,
    /// Every closed-loop eigenvalue must have `−Re λ` above this multiple of its perturbation
    /// bound (test (a)): [`CLOSED_LOOP_FACTOR`], or [`NOT_LAGRANGIAN_MARGIN`].
    pub(super) margin: f64,
}

/// What the error bound of an accepted solution must prove.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Proof {
    /// Existence and the bound with the quadratic term (Newton–Kantorovich or Brouwer): needed
    /// where the closed-loop route replaces a refusal.
    Strict,
    /// The quadratic term when its test passes, else the estimate `‖Δ̂‖ + √n·ℓ·(errs + 2‖Δ̂B‖²)`
    /// (as SLICOT's FERR and [`refine::error_bounds`](super::refine::error_bounds) when norm bounds
    /// overestimate): where the closed-loop route replaces a Hamiltonian solution with a larger
    /// bound (module `scaled_start`; the test is hopeless there: `κ_B² ≈ ℓ·‖BᵀPB‖ ~ 1e11` for
    /// `R = 1e-12`, the measured Newton constant ~1e6 relative).
    FirstOrder,
}

/// The stabilising solution by the closed-loop route, `None` when it cannot be certified as
/// `accept` asks. The iteration starts from `start` when given (Newton's iteration on the residual
/// from that stabilising approximation, [`newton_from`]), else from the graph of the leftmost
/// Hamiltonian eigenvalues completed by Bass's gain (module documentation; always with the
/// strict proof).
pub(super) fn solve(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
    factor_error: FactorError,
    (start, accept): (Option<&DMatrix<f64>>, Acceptance),
) -> Result<Option<CareSolution>> {
    let n = a.nrows();
    if n == 0 || !(factor_error.e < 1.0 && factor_error.delta.is_finite()) {
        return Ok(None);
    }
    let own;
    let (b, quad) = match factor {
        Some(b) => (b, Quadratic::Factor(b)),
        None => {
            // G = 0 (A must then be stable: X solves the Lyapunov equation) has the factor 0.
            own = match psd_factor(g) {
                Some(f) => f,
                None if g.iter().all(|&v| v == 0.0) => DMatrix::zeros(n, 1),
                None => return Ok(None),
            };
            (&own, Quadratic::Dense(g))
        }
    };
    if let Some(x0) = start {
        let Some((x, steps)) = newton_from(a, quad, q, x0.clone())? else {
            return Ok(None);
        };
        return certify(a, g, q, quad, (x, steps), &factor_error, accept);
    }
    let x0 = soft(leftmost_graph(a, g, q, opts))?.flatten();
    let k0 = match x0 {
        Some(x) => matmul_tn(b, &x),
        None => DMatrix::zeros(b.ncols(), n),
    };
    let Some(k0) = soft(bass::stabilise(a, b, &k0))?.flatten() else {
        return Ok(None);
    };
    let Some((x, steps)) = iterate(a, b, q, k0)? else {
        return Ok(None);
    };
    let strict = Acceptance {
        proof: Proof::Strict,
        ..accept
    };
    certify(a, g, q, quad, (x, steps), &factor_error, strict)
}

/// Compensated refinement of the Kleinman limit, then the acceptance tests (a) and (b) of the
/// module documentation.
fn certify(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    quad: Quadratic<'_>,
    (x0, steps): (DMatrix<f64>, usize),
    factor_error: &FactorError,
    accept: Acceptance,
) -> Result<Option<CareSolution>> {
    let proof = accept.proof;
    let n = a.nrows();
    let ones = vec![1.0; n];
    let fresh = |x: &DMatrix<f64>| {
        Lyapunov::new(&closed_loop(a, quad, x))
            .and_then(|l| l.with_singular_rtol(0.0))
            .ok()
            .map(|l| Operator::Fresh(Box::new(l), &ones[..]))
    };
    let Some(op) = fresh(&x0) else {
        return Ok(None);
    };
    let Some(c) = compensated_refinement(a, q, quad, &op, &fresh, &x0)? else {
        return Ok(None);
    };
    let (mut x, mut r_f, mut arith_f, mut steps) = (c.x, c.r, c.arith, steps + c.steps);
    // With the a-posteriori factor bound, the intended data's residual and closed loop are
    // formed (module `intended`) and certified, after at most INTENDED_STEPS Newton steps on
    // them when needed (the factor's solution is off by the data's error: ~1e-13 at κ(R) = 1e14,
    // which is far above the ulps of X through F); otherwise the factor's, with the norm bound
    // of the data's error added to the residual's (`intended::data_residual`).
    let mut tries = 0;
    let (bound, intended, extra) = loop {
        let acl_f = closed_loop(a, quad, &x);
        let intended = match (quad, &factor_error.known) {
            (Quadratic::Factor(f), Some(known)) => {
                Some(intended(&acl_f, &r_f, &x, f, factor_error, known))
            }
            _ => None,
        };
        let (acl, r, arith, extra) = match &intended {
            Some(it) => (
                &it.acl,
                &it.r,
                arith_f + it.r_err,
                Some(Extra {
                    w: it.w,
                    d: it.d,
                    formation: it.formation,
                }),
            ),
            None => (
                &acl_f,
                &r_f,
                arith_f + data_residual(quad, &x, factor_error),
                None,
            ),
        };
        let Some(lyap) = soft(Lyapunov::new(acl).and_then(|l| l.with_singular_rtol(0.0)))? else {
            return Ok(None);
        };
        match certificate(&lyap, acl, quad, (r, arith, 0.0), g, &x, (extra, proof))? {
            Some(b) if b.forward <= FORWARD_ERROR_LIMIT => break (b, intended, extra),
            _ if intended.is_some() && tries < INTENDED_STEPS => {
                crate::cancel::check("the Newton steps on the intended Riccati data")?;
                let Some(dl) = soft(lyap.solve_adjoint(&(-r)))? else {
                    return Ok(None);
                };
                x = symmetrize(&(&x + &dl));
                r_f = quad.residual_compensated(a, q, &x);
                if !r_f.iter().all(|v| v.is_finite()) {
                    return Ok(None);
                }
                arith_f = arith_bound(a, q, quad, &x, &r_f).0;
                tries += 1;
                steps += 1;
            }
            Some(b) if proof == Proof::FirstOrder && b.forward <= FIRST_ORDER_LIMIT => {
                break (b, intended, extra)
            }
            _ if proof == Proof::Strict => {
                let at = (&acl_f, &r_f, arith_f);
                match certify_at_double_double_point(quad, g, &x, at, factor_error, proof)? {
                    Some(found) if found.0.forward <= FORWARD_ERROR_LIMIT => break found,
                    _ => return Ok(None),
                }
            }
            _ => return Ok(None),
        }
    };
    let bound = match extra {
        Some(ex) => intended_bound(bound, quad, ex),
        None => with_factor_error(bound, quad, &x, factor_error),
    };
    // The closed loop of X + Δ̂, nearer that of X* (the gain `Bᵀ(X + Δ̂)` formed as
    // `BᵀX + BᵀΔ̂`: Δ̂ is often below the ulps of X).
    let corrected = match (quad, &intended) {
        (Quadratic::Factor(b), Some(it)) => &it.acl - matmul(b, &matmul_tn(b, &bound.d)),
        (Quadratic::Factor(b), None) => a - matmul(b, &(matmul_tn(b, &x) + matmul_tn(b, &bound.d))),
        (Quadratic::Dense(g), _) => a - (matmul(g, &x) + matmul(g, &bound.d)),
    };
    let Some(schur) = soft(RealSchur::new(&corrected))? else {
        return Ok(None);
    };
    let extra_formation = extra.map_or(0.0, |ex| ex.formation);
    let Some(abscissa) = stability_margin(&schur, quad, &x, &bound, (extra_formation, accept))
    else {
        return Ok(None);
    };
    let (forward_error, trace_error) = (bound.forward, bound.trace);
    Ok(Some(CareSolution {
        residual: relative_residual(a, g, q, &x, &r_f),
        x,
        forward_error,
        trace_error,
        rcond: f64::NAN,
        closed_loop_abscissa: abscissa,
        axis_margin: f64::NAN,
        marginal: false,
        newton_steps: steps,
        scaling: 1.0,
    }))
}

/// What the Newton–Kantorovich certificate proves about the final `X`.
pub(super) struct Bound {
    /// The Newton correction `Δ̂ ≈ Ω⁻¹(−R(X))`.
    pub(super) d: DMatrix<f64>,
    /// A bound on `‖G(X* − X − Δ̂)‖₂`, the distance of the closed loop of `X*` from that of
    /// `X + Δ̂`.
    pub(super) shift: f64,
    /// A bound on `‖(X* − X − Δ̂)B‖₂` (for a factored `G = BBᵀ`; `shift = ‖B‖₂·through_b`): the
    /// closed loop of `X*` is that of `X + Δ̂` perturbed by `B·V`, `‖V‖₂ ≤ through_b`.
    pub(super) through_b: f64,
    /// A bound on a further perturbation `W` of the closed loop of `X*` that does not act through
    /// `B` (`‖W‖₂`; the error `δ` of a Cholesky-derived factor, module `intended`).
    pub(super) unstructured: f64,
    /// A bound on `‖X* − X − Δ̂‖_F`.
    pub(super) beyond: f64,
    /// A bound on `‖X* − X‖_F / ‖X‖_F`.
    pub(super) forward: f64,
    /// A bound on `|tr X* − tr X|`.
    pub(super) trace: f64,
}

/// The existence-and-error certificate of `X` from its own factored closed loop `acl = A − GX`
/// and its compensated residual `r` (arithmetic error at most `arith`, Frobenius); `None` when it
/// fails.
///
/// `X* = X + Δ` solves the CARE iff `Δ = Φ(Δ) := Ω⁻¹(−R + ΔGΔ)`, `Ω(Δ) = A_cᵀΔ + ΔA_c`.
/// `−Ω⁻¹` is a positive map and `P = −Ω⁻¹(I) ≻ 0`, so `−‖C‖P ⪯ −Ω⁻¹(C) ⪯ ‖C‖P` for symmetric `C`,
/// whence `‖Ω⁻¹(C)‖₂ ≤ ℓ‖C‖₂` (`ℓ = ‖P‖₂`, Russo–Dye) and, writing `Ω⁻¹(C) = P^{1/2}ZP^{1/2}`,
/// `‖Z‖ ≤ ‖C‖`, `‖Ω⁻¹(C)B‖₂ ≤ κ_B‖C‖₂` with `κ_B = √(ℓ‖BᵀPB‖₂)` — much smaller than `ℓ‖B‖₂`
/// when `G = BBᵀ` is large (an ill-conditioned `R`) or stiff. The quadratic term
/// `ΔGΔ = (ΔB)(ΔB)ᵀ` has norm `u² = ‖ΔB‖₂²` and `ΔGΔ − Δ'GΔ'` at most `(u + u')‖(Δ − Δ')B‖₂`.
///
/// The first-order step `Ω⁻¹(−R)` is `Δ̂ = Δ̂₁ + Δ̂₂` up to `ℓ·errs` (and `κ_B·errs` through `B`):
/// `Δ̂₁ = Ω⁻¹(−R̂)` computed, `Δ̂₂ = Ω⁻¹(−R_s)` its correction from `R_s = Ω(Δ̂₁) + R̂` accumulated
/// in double-double, and `errs` = the error of `R_s` (compensated rounding, `eps·‖R_s‖`, and the
/// rounding of `A_c` acting on `Δ̂₁`), plus the second solve's residual
/// `(ρ + γ)(2‖A_c‖‖Δ̂₂‖ + ‖R_s‖)`, plus `arith`. With `u₀ = ‖Δ̂B‖ + κ_B·errs` and
/// `h = κ_B u₀ < ¼`, `Φ` maps the set `‖ΔB‖₂ ≤ u`, `u = 2u₀/(1 + √(1 − 4h))` (the smaller root of `κ_B u² − u + u₀`), into itself and contracts
/// there in `‖(·)B‖` (factor `2κ_B u < 1`), while `‖Φ(Δ) − Φ(Δ')‖₂ ≤ 2ℓu‖(Δ − Δ')B‖₂`: the
/// iterates converge to a solution `X*` with `‖X* − X − Δ̂‖_F ≤ √n·ℓ·(errs + u²)` and
/// `‖G(X* − X − Δ̂)‖₂ ≤ ‖B‖₂κ_B(errs + u²)`. `P` and `‖BᵀPB‖` are taken as computed. The
/// residual is that of the data as given (doubles); their representation of other intended
/// values is not included. For a dense `G` (no factor) `κ_B = ℓ‖G‖^{1/2}`, the classical
/// Newton–Kantorovich constant.
///
/// With `extra` (the intended data of a Cholesky-derived factor, `G = (F + δ)W(F + δ)ᵀ`, module
/// `intended`; `acl` and `r` are then the intended closed loop and residual), the quadratic
/// term is not seen through `F` alone: `‖ΔGΔ‖₂ ≤ w(‖ΔF‖₂ + d‖Δ‖₂)²`, and existence is shown on
/// a set bounding both `‖ΔF‖₂` and `‖Δ‖₂` (`intended::self_map`, Brouwer); `u²` above is
/// replaced by that bound on the quadratic term.
pub(super) fn certificate(
    lyap: &Lyapunov,
    acl: &DMatrix<f64>,
    quad: Quadratic<'_>,
    (r, arith, more): (&DMatrix<f64>, f64, f64),
    g: &DMatrix<f64>,
    x: &DMatrix<f64>,
    (extra, proof): (Option<Extra>, Proof),
) -> Result<Option<Bound>> {
    let n = x.nrows();
    let Some(p) = soft(lyap.solve_adjoint(&DMatrix::identity(n, n)))? else {
        return Ok(None);
    };
    let Some(sol) = soft(lyap.solve_adjoint_with_info(&(-r)))? else {
        return Ok(None);
    };
    let ell = norm2_bound_symmetric(&p);
    let gn = norm2_bound_symmetric(g);
    let formation = quad.formation(x) + extra.map_or(0.0, |ex| ex.formation) + more;
    let gamma = (2.0 * n as f64 + 4.0) * f64::EPSILON;
    // Δ̂ is checked by its own residual R_s = Ω(Δ̂) + R̂, accumulated in double-double, and
    // corrected once: Ω⁻¹(−R̂) = Δ̂ + Δ̂₂ + Ω⁻¹(−R_s − Ω(Δ̂₂)) with Δ̂₂ = Ω⁻¹(−R̂_s) computed.
    let d1 = symmetrize(&sol.x);
    let rs = super::compensated::residual(acl, None, None, r, &d1);
    let ws = norm_fro(&(matmul_tn(&acl.abs(), &d1.abs()) * 2.0)) + norm_fro(r);
    let rs_error = 2.0 * f64::EPSILON * norm_fro(&rs)
        + 2.0 * gamma * gamma * ws
        + formation * 2.0 * norm_fro(&d1);
    let Some(sol2) = soft(lyap.solve_adjoint_with_info(&(-&rs)))? else {
        return Ok(None);
    };
    let e2 = (sol2.residual + gamma) * (2.0 * norm_fro(acl) * norm_fro(&sol2.x) + norm_fro(&rs));
    let d = &d1 + &sol2.x;
    let dn_f = norm_fro(&d);
    let solve_error = e2 + rs_error;
    let errs = solve_error + arith;
    // The quadratic term's constants: ‖Ω⁻¹(C)B‖₂ ≤ κ_B‖C‖₂ with κ_B = √(ℓ‖BᵀPB‖₂) (P = −Ω⁻¹(I)),
    // or κ_B = ℓ‖B‖₂ = ℓ√‖G‖₂ for a dense G, where B is not at hand.
    let (kappa_b, b_norm) = match quad {
        Quadratic::Factor(b) => {
            let btb = matmul_tn(b, b);
            let b2 = btb.symmetric_eigen().eigenvalues.max().max(0.0).sqrt();
            (
                (ell * norm2_bound_symmetric(&matmul_tn(b, &matmul(&p, b)))).sqrt(),
                b2.min(norm_fro(b)),
            )
        }
        Quadratic::Dense(_) => (ell * gn.sqrt(), gn.sqrt()),
    };
    let seen = match quad {
        Quadratic::Factor(b) => norm_fro(&matmul(&d, b)),
        Quadratic::Dense(_) => norm2_bound_symmetric(&d) * gn.sqrt(),
    };
    let u0 = seen + kappa_b * errs;
    // The quadratic term's bound when the Newton–Kantorovich (or Brouwer) test passes; else its
    // value at Δ̂, ‖Δ̂B‖², twice (as the generalised form; a case had 3.9e-5 > 5.5e-6 without).
    let quadratic = match extra {
        None => {
            let h = kappa_b * u0;
            (h < 0.25).then(|| {
                let u = 2.0 * u0 / (1.0 + (1.0 - 4.0 * h).sqrt());
                u * u
            })
        }
        Some(ex) => {
            let v0 = norm_fro(&d) + ell * errs; // (Δ̂ need not be exactly symmetric)
            self_map(u0, v0, kappa_b, ell, ex)
        }
    };
    let rest = match (quadratic, proof) {
        (Some(q), _) => errs + q,
        (None, Proof::FirstOrder) => errs + 2.0 * seen * seen,
        (None, Proof::Strict) => return Ok(None),
    };
    let xn = norm_fro(x);
    let forward = if xn > 0.0 {
        (dn_f + (n as f64).sqrt() * ell * rest) / xn + f64::EPSILON
    } else {
        f64::INFINITY
    };
    let trace = d.trace().abs() + p.trace().abs() * rest + f64::EPSILON * x.trace().abs();
    // X* − (X + Δ̂) = Ω⁻¹(−R) − Δ̂ + Ω⁻¹(ΔGΔ): seen through B, at most κ_B·(errs + u²).
    let through_b = kappa_b * rest;
    let shift = b_norm * through_b;
    Ok(forward.is_finite().then_some(Bound {
        d,
        shift,
        through_b,
        unstructured: 0.0,
        beyond: (n as f64).sqrt() * ell * rest,
        forward,
        trace,
    }))
}

/// The spectral abscissa of the factored closed loop when every eigenvalue is left of the axis by
/// more than `accept.margin` ([`CLOSED_LOOP_FACTOR`] or [`NOT_LAGRANGIAN_MARGIN`]) times its
/// perturbation bound (test (a)); `None` otherwise.
///
/// The bound is first order: `κ(λ)·‖E‖` for the unstructured part `E` (the Schur backward error
/// and the rounding of `A − GX`) plus, for the distance `B·V` to the closed loop of `X*`
/// (`‖V‖₂ ≤` [`Bound::through_b`]), `κ_B(λ)·‖V‖₂` with `κ_B(λ) = ‖Bᵀy‖‖x‖/|yᴴx|` the
/// eigenvalue's sensitivity to perturbations through the input ([`input_condition`]; at most
/// `κ(λ)‖B‖₂`, the unstructured figure, which is used when it is smaller): a slow mode the input
/// barely reaches barely moves when the gain does. For a dense `G` (no factor) the unstructured
/// `κ(λ)·‖G(X* − X − Δ̂)‖₂` is used. A perturbation that does not act through `B`
/// ([`Bound::unstructured`]) adds `κ(λ)·‖W‖₂`. With a first-order error bound
/// ([`Proof::FirstOrder`]) the distance to `X*` is not proven and only `κ(λ)·‖E‖` is used: the
/// closed loop is judged as the Hamiltonian route judges its eigenvalues, by its own rounding.
fn stability_margin(
    schur: &RealSchur,
    quad: Quadratic<'_>,
    x: &DMatrix<f64>,
    bound: &Bound,
    (extra_formation, accept): (f64, Acceptance),
) -> Option<f64> {
    let proof = accept.proof;
    let tn = norm_fro(&schur.t);
    let eps = f64::EPSILON;
    // Backward error of the Schur form and rounding of A − GX.
    let pert = eps * tn + quad.formation(x) + extra_formation;
    let zb = match quad {
        Quadratic::Factor(b) => Some(matmul_tn(&schur.z, b)),
        Quadratic::Dense(_) => None,
    };
    let mut abscissa = f64::NEG_INFINITY;
    for (k, size) in schur.blocks() {
        let re = schur.t[(k, k)];
        let kappa = condition(&schur.t, k, size, tn);
        // The distance to A − GX*: through B when G is factored (with a first-order bound, only
        // the closed loop's own rounding: the distance to X* is not proven).
        let moved = if proof == Proof::FirstOrder {
            0.0
        } else {
            (match &zb {
                Some(zb) => (kappa * bound.shift)
                    .min(input_condition(&schur.t, k, size, tn, zb) * bound.through_b),
                None => kappa * bound.shift,
            }) + kappa * bound.unstructured
        };
        if !(-re > accept.margin * (kappa * pert + moved)) {
            return None;
        }
        abscissa = abscissa.max(re);
    }
    Some(abscissa)
}
