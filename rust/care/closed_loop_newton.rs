//! The two Newton iterations of the closed-loop route (module `kleinman`) on the `n × n` closed
//! loop: Kleinman's form from a stabilising gain, and the residual (defect-correction) form from
//! a stabilising approximation of `X` (module `scaled_start`).

use super::quadratic::Quadratic;
use crate::linalg::dense::{matmul, matmul_tn, norm_fro, symmetrize};
use crate::linalg::sylvester::Lyapunov;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// Kleinman steps at most (from a poor start the early steps roughly halve the excess `X_k − X*`;
/// quadratic convergence then needs a handful).
const MAX_STEPS: usize = 100;

/// `Ok(None)` for a failure of an intermediate computation, an interrupt passed on.
pub(super) fn soft<T>(r: Result<T>) -> Result<Option<T>> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(Error::Interrupted(m)) => Err(Error::Interrupted(m)),
        Err(_) => Ok(None),
    }
}

/// Kleinman's iteration from the stabilising gain `k`: the last iterate and the number of steps,
/// `None` when a closed loop is not stable by its computed spectrum or a solve fails.
pub(super) fn iterate(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
    mut k: DMatrix<f64>,
) -> Result<Option<(DMatrix<f64>, usize)>> {
    let n = a.nrows();
    let mut prev: Option<DMatrix<f64>> = None;
    let mut last_change = f64::INFINITY;
    let mut steps = 0;
    for _ in 0..MAX_STEPS {
        crate::cancel::check("the Newton–Kleinman iteration of the Riccati solution")?;
        let acl = a - matmul(b, &k);
        let Some(lyap) = soft(Lyapunov::new(&acl).and_then(|l| l.with_singular_rtol(0.0)))? else {
            return Ok(None);
        };
        if lyap.schur().eigenvalues().iter().any(|e| !(e.0 < 0.0)) {
            return Ok(None);
        }
        let rhs = symmetrize(&(-(q + matmul_tn(&k, &k))));
        let Some(x) = soft(lyap.solve_adjoint(&rhs))? else {
            return Ok(None);
        };
        let x = symmetrize(&x);
        if !x.iter().all(|v| v.is_finite()) {
            return Ok(None);
        }
        steps += 1;
        k = matmul_tn(b, &x);
        let done = prev.as_ref().is_some_and(|p| {
            let change = norm_fro(&(&x - p));
            let xn = norm_fro(&x);
            // Converged, or at the rounding floor (no longer shrinking, and small).
            let stop = change <= 16.0 * n as f64 * f64::EPSILON * xn
                || (change > 0.5 * last_change && change <= 1e-3 * xn);
            last_change = change;
            stop
        });
        prev = Some(x);
        if done {
            break;
        }
    }
    Ok(prev.map(|x| (x, steps)))
}

/// Newton's iteration on the residual, `(A − GX_k)ᵀΔ + Δ(A − GX_k) = −R(X_k)`,
/// `X_{k+1} = X_k + Δ`, from a stabilising `x`: an iterate and the number of steps, `None` when a
/// closed loop is not stable by its computed spectrum or a solve fails. Unlike Kleinman's form
/// (whose right-hand side `Q + KᵀK` cancels to the size of `X` when the gain is large: a floor at
/// ~1e-5 relative for `R = 1e-12`), the corrections shrink to the level at which the closed
/// loop's Lyapunov solves are accurate. Early steps from a poor start halve the excess (or shrink
/// it more slowly for a while, ratios up to ~0.9); then the corrections fall quadratically to a
/// floor: a few ulps, or a noise of the solves' accuracy (~1e-6 relative for one `R = 1e-12` case
/// whose closed loop spans `−1.6e6 … −1`, with exact residuals and gains alike). The iteration
/// returns `X + Δ` at a correction below `16·n·eps·‖X‖`; once the smallest correction so far is
/// below `1e-3·‖X‖` and [`FLOOR_STEPS`] steps have not improved on it, the iterate with that
/// smallest correction, corrected; likewise after [`MAX_STEPS`].
pub(super) fn newton_from(
    a: &DMatrix<f64>,
    quad: Quadratic<'_>,
    q: &DMatrix<f64>,
    mut x: DMatrix<f64>,
) -> Result<Option<(DMatrix<f64>, usize)>> {
    let n = a.nrows();
    // The iterate after the smallest correction so far, its size and the step it was taken at.
    let mut best: Option<(DMatrix<f64>, f64, usize)> = None;
    for steps in 0..MAX_STEPS {
        crate::cancel::check("the Newton iteration of the Riccati solution")?;
        let Some(lyap) =
            soft(Lyapunov::new(&closed_loop(a, quad, &x)).and_then(|l| l.with_singular_rtol(0.0)))?
        else {
            return Ok(None);
        };
        if lyap.schur().eigenvalues().iter().any(|e| !(e.0 < 0.0)) {
            return Ok(None);
        }
        let r = quad.residual(a, q, &x);
        let Some(d) = soft(lyap.solve_adjoint(&(-r)))? else {
            return Ok(None);
        };
        let (change, xn) = (norm_fro(&d), norm_fro(&x));
        if !change.is_finite() {
            return Ok(None);
        }
        x = symmetrize(&(&x + &d));
        if change <= 16.0 * n as f64 * f64::EPSILON * xn {
            return Ok(Some((x, steps + 1)));
        }
        match &best {
            Some((_, smallest, _)) if change >= *smallest => {}
            _ => best = Some((x.clone(), change, steps + 1)),
        }
        if let Some((_, smallest, at)) = &best {
            if *smallest <= 1e-3 * xn && steps + 1 >= at + FLOOR_STEPS {
                break;
            }
        }
    }
    Ok(best.map(|(x, _, at)| (x, at)))
}

/// Newton steps without a smaller correction after which [`newton_from`] stops at its floor.
const FLOOR_STEPS: usize = 4;

/// `A − GX` (from the factor when there is one).
pub(super) fn closed_loop(a: &DMatrix<f64>, quad: Quadratic<'_>, x: &DMatrix<f64>) -> DMatrix<f64> {
    match quad {
        Quadratic::Factor(b) => a - matmul(b, &matmul_tn(b, x)),
        Quadratic::Dense(g) => a - matmul(g, x),
    }
}
