//! Steps 1–6 of the Hamiltonian/Schur route of the CARE (see the parent module): the norm-scaled,
//! symplectically balanced Hamiltonian `H = [[Ã, −G̃], [−Q̃, −Ãᵀ]]`, its ordered real Schur form,
//! the graph `X = U21 U11⁻¹` of the stable invariant subspace (with the Lagrangian check of that
//! subspace), Newton refinement through the closed-loop Lyapunov operator of the Schur form, and
//! the forward-error bound of [`super::refine::error_bounds`].

use super::closed_loop_newton::soft;
use super::compensated::{compensated_refinement, CERTIFY_MAX_ORDER, COMPENSATED_MAX_ORDER};
use super::quadratic::Quadratic;
use super::refine::{self, ClosedLoop, Operator};
use super::{
    axis, balance, relative_residual, CareOptions, CareSolution, BLIND_STEP, BLIND_STEP_MIN_ORDER,
};
use crate::linalg::dense::{matmul, matmul_tn, norm_fro, symmetrize, Lu};
use crate::linalg::schur::RealSchur;
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Relative asymmetry of `U11ᵀU21` above which the computed stable subspace is declared not
/// Lagrangian, i.e. eigenvalues are too near the imaginary axis for a trustworthy solution.
/// Perturbation theory: eigenvalues at distance δ from the axis perturb the subspace by ~eps/δ, so
/// this threshold corresponds to δ ≈ √eps·‖H‖ — scale-blind: stiff models exceed it with slow
/// eigenvalues thousands of their own bounds from the axis, so the caller tries the closed-loop
/// route on such a refusal (with a larger margin, `kleinman::NOT_LAGRANGIAN_MARGIN`).
const LAGRANGIAN_TOL: f64 = 1.5e-8;

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

/// The power of two nearest `v > 0`.
pub(super) fn pow2_near(v: f64) -> f64 {
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

/// Steps 1–6 of the module documentation; `not_lagrangian` is set when the answer (a refusal or
/// a marginal solution) is due to a stable subspace that is not Lagrangian.
pub(super) fn hamiltonian_route(
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
            "G = B R⁻¹ Bᵀ is zero: no input acts on the system; a stabilising solution then exists \
             only when A is stable (X solves the Lyapunov equation AᵀX + XA + Q = 0), which \
             could not be established"
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

/// The start of the closed-loop route (module `kleinman`): the graph `X` of the invariant subspace of the `n` leftmost eigenvalues of the scaled,
/// balanced Hamiltonian; `None` when a complex pair straddles the cut or `U11` is singular.
pub(super) fn leftmost_graph(
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
    opts: &CareOptions,
) -> Result<Option<DMatrix<f64>>> {
    let n = a.nrows();
    let sc = scaled_hamiltonian(a, g, q, opts)?;
    let mut schur = RealSchur::new(&sc.h)?;
    let mut re: Vec<f64> = schur.eigenvalues().iter().map(|e| e.0).collect();
    re.sort_by(f64::total_cmp);
    let cut = re[n - 1];
    if !(re[n] > cut) {
        return Ok(None);
    }
    if schur.reorder(|r, _| r <= cut)? != n {
        return Ok(None);
    }
    let u11 = schur.z.view((0, 0), (n, n)).transpose();
    let Some(lu) = soft(Lu::new(&u11))? else {
        return Ok(None);
    };
    let mut xb = schur.z.view((n, 0), (n, n)).transpose();
    lu.solve_in_place(&mut xb);
    let x = balance::congruence(&symmetrize(&xb), &sc.d, sc.s);
    Ok(x.iter().all(|v| v.is_finite()).then_some(x))
}
