//! Newton's method with the exact Hessian on the simplex (sequential quadratic programming) for
//! Theorem 1's problem `minimise η(r_min + γ) over {γ ≥ 0, Σγ = σ}`, the whole loop in one call:
//! the Python package's `allocation.newton` (variant `"exact"`) step for step, for small networks
//! where a Python round trip per evaluation costs as much as the evaluation.
//!
//! Each step: the point at `r = r_min + γ` (value, gradient, Hessian from one CARE solve and `N + 1`
//! Lyapunov solves on one Schur form); the Frank–Wolfe certificate
//! `gap = Σγ_i(g_i − min g) ≤ tol·|η|` stops it; otherwise the quadratic model
//! `gᵀd + ½dᵀHd` (`H` symmetrised and regularised by `1e-12·max|H_ii|`) is minimised over the
//! simplex exactly by a primal active-set method (equality-constrained steps on a face from the
//! bordered KKT system; a blocking bound joins the working set; a bound with a negative
//! multiplier leaves it), then an Armijo search on `η` along `γ + t d`, each trial put exactly on
//! the simplex. A predicted decrease at the rounding level of `η` (`−gᵀd ≤ 1e3·eps·|η|`) is taken
//! in full (values would compare noise). It also stops when the gap has not halved in three
//! steps (its rounding floor), when no descent is left or when no decrease is representable; the
//! caller judges the certificate. More than `max_iter` steps is a [`Error::Convergence`].
//!
//! Points may be warm-started from the previous one ([`CostPoint::warm`]); after a warm start
//! that falls back to the cold solve, the later points are solved cold.

use crate::cost::{cost, CostOptions, CostPoint, Threads};
use crate::network::Network;
use crate::{Error, Result};
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;

/// The result of [`newton_exact`]: the last point and what is known there.
pub struct NewtonAllocation {
    /// `γ` on the simplex.
    pub gamma: Vec<f64>,
    /// Newton steps taken.
    pub iterations: usize,
    /// `η(r_min + γ)`.
    pub value: f64,
    /// `∇η(r_min + γ)`.
    pub gradient: Vec<f64>,
    /// The bound on `|η − η_exact|` at that point.
    pub value_error: f64,
}

/// Predicted decreases below this times `|η|` are at the rounding level of η.
const NOISE_DECREASE: f64 = 1e3 * f64::EPSILON;

/// `x ≥ 0` with `Σx = σ` to the last bit as far as possible (the rounding on the largest entry).
fn fix_sum(x: &mut [f64], sigma: f64) {
    for v in x.iter_mut() {
        *v = v.max(0.0);
    }
    let k = (0..x.len()).fold(0, |k, i| if x[i] > x[k] { i } else { k });
    let s: f64 = x.iter().sum();
    x[k] += sigma - s;
    x[k] = x[k].max(0.0);
}

fn frank_wolfe_gap(gamma: &[f64], g: &[f64]) -> f64 {
    let m = g.iter().copied().fold(f64::INFINITY, f64::min);
    gamma.iter().zip(g).map(|(a, b)| a * (b - m)).sum()
}

/// `gᵀd` for `Σd = 0`, measured against the `|d|`-weighted mean of `g` (`Σd` carries rounding).
fn slope(g: &[f64], d: &[f64]) -> f64 {
    let total: f64 = d.iter().map(|v| v.abs()).sum();
    let c = if total > 0.0 {
        d.iter().zip(g).map(|(a, b)| a.abs() * b).sum::<f64>() / total
    } else {
        g.iter().sum::<f64>() / g.len() as f64
    };
    g.iter().zip(d).map(|(b, a)| (b - c) * a).sum()
}

/// Solves `[[H_FF, −1], [1ᵀ, 0]] [p; λ] = [−grad_F; 0]`.
fn face_step(h: &DMatrix<f64>, grad: &[f64], free: &[usize]) -> Result<(Vec<f64>, f64)> {
    let k = free.len();
    let mut m = DMatrix::zeros(k + 1, k + 1);
    let mut rhs = DVector::zeros(k + 1);
    for (a, &i) in free.iter().enumerate() {
        for (b, &j) in free.iter().enumerate() {
            m[(a, b)] = h[(i, j)];
        }
        m[(a, k)] = -1.0;
        m[(k, a)] = 1.0;
        rhs[a] = -grad[i];
    }
    let sol = m
        .lu()
        .solve(&rhs)
        .ok_or_else(|| Error::SingularProblem("the simplex QP's face system is singular".into()))?;
    Ok(((0..k).map(|a| sol[a]).collect(), sol[k]))
}

/// Minimises `cᵀx + ½xᵀHx` over `{x ≥ 0, Σx = σ}` from the feasible `x0` (primal active set;
/// `H` symmetric positive definite).
fn simplex_qp(
    h: &DMatrix<f64>,
    c: &[f64],
    x0: &[f64],
    sigma: f64,
    max_iter: usize,
) -> Result<Vec<f64>> {
    let n = c.len();
    let mut x = x0.to_vec();
    let mut fixed: Vec<bool> = x.iter().map(|&v| v <= 0.0).collect();
    for i in 0..n {
        if fixed[i] {
            x[i] = 0.0;
        }
    }
    for _ in 0..max_iter {
        let free: Vec<usize> = (0..n).filter(|&i| !fixed[i]).collect();
        let grad: Vec<f64> = (0..n)
            .map(|i| c[i] + (0..n).map(|j| h[(i, j)] * x[j]).sum::<f64>())
            .collect();
        let (p, lam) = face_step(h, &grad, &free)?;
        let scale = x.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        if p.iter().fold(0.0f64, |m, v| m.max(v.abs())) <= 1e-14 * scale {
            // The bound multipliers of the fixed indices; the most negative leaves the set.
            let thresh = -1e-14 * lam.abs().max(1.0);
            let leave = (0..n)
                .filter(|&i| fixed[i] && grad[i] - lam < thresh)
                .min_by(|&a, &b| (grad[a] - lam).total_cmp(&(grad[b] - lam)));
            match leave {
                None => {
                    fix_sum(&mut x, sigma);
                    return Ok(x);
                }
                Some(i) => fixed[i] = false,
            }
            continue;
        }
        let (mut alpha, mut block) = (1.0, None);
        for (&i, &pi) in free.iter().zip(&p) {
            if pi < 0.0 {
                let t = -x[i] / pi;
                if t < alpha {
                    (alpha, block) = (t, Some(i));
                }
            }
        }
        for (&i, &pi) in free.iter().zip(&p) {
            x[i] += alpha * pi;
        }
        if let Some(b) = block {
            x[b] = 0.0;
            fixed[b] = true;
        }
        for v in x.iter_mut() {
            *v = v.max(0.0);
        }
    }
    Err(Error::Convergence(format!(
        "simplex QP did not terminate in {max_iter} iterations (n = {n})"
    )))
}

/// The evaluation points of the loop: the last one kept, the next warm-started from it.
struct Points<'n> {
    net: &'n Arc<Network>,
    opts: &'n CostOptions,
    r_min: f64,
    warm: bool,
    last: Option<(Vec<f64>, CostPoint)>,
}

impl Points<'_> {
    /// The point at `r_min + γ` (the kept one when `γ` is unchanged).
    fn at(&mut self, gamma: &[f64]) -> Result<&CostPoint> {
        let fresh = !matches!(&self.last, Some((key, _)) if key.as_slice() == gamma);
        if fresh {
            let r: Vec<f64> = gamma.iter().map(|g| g + self.r_min).collect();
            let point = match &self.last {
                Some((_, prev)) if self.warm => {
                    let p = prev.warm(&r, self.opts)?;
                    let fell_back = p
                        .evaluation()
                        .warm_info()
                        .is_some_and(|w| w.fallback.is_some());
                    if fell_back {
                        self.warm = false;
                    }
                    p
                }
                _ => CostPoint::at(Arc::clone(self.net), &r, self.opts)?,
            };
            self.last = Some((gamma.to_vec(), point));
        }
        Ok(&self.last.as_ref().expect("a point was just stored").1)
    }

    fn cost(&self, gamma: &[f64]) -> Result<f64> {
        let r: Vec<f64> = gamma.iter().map(|g| g + self.r_min).collect();
        cost(self.net, &r, self.opts)
    }
}

/// Backtracking on `η` along `γ + t d` (the first trial through a full point, which the next
/// step reuses); `None` when no decrease is found or representable.
fn armijo(
    pts: &mut Points<'_>,
    gamma: &[f64],
    d: &[f64],
    f0: f64,
    slope: f64,
    sigma: f64,
) -> Result<Option<Vec<f64>>> {
    let feasible = |t: f64| {
        let mut x: Vec<f64> = gamma.iter().zip(d).map(|(a, b)| a + t * b).collect();
        fix_sum(&mut x, sigma);
        x
    };
    if -slope <= NOISE_DECREASE * f0.abs().max(1e-300) {
        let trial = feasible(1.0);
        pts.at(&trial)?;
        return Ok(Some(trial));
    }
    let start = feasible(0.0);
    let mut t = 1.0;
    for k in 0..60 {
        let trial = feasible(t);
        if trial == start {
            break;
        }
        let f = if k == 0 {
            pts.at(&trial)?.evaluation().value()
        } else {
            pts.cost(&trial)?
        };
        if f <= f0 + 1e-4 * t * slope {
            return Ok(Some(trial));
        }
        t *= 0.5;
    }
    Ok(None)
}

/// Newton's method with the exact Hessian from `gamma0` (see the module documentation);
/// evaluation points are warm-started from the previous one when `warm`.
///
/// # Errors
/// [`Error::InvalidInput`] for `gamma0` of the wrong length or not on the simplex, `σ ≤ 0` or a
/// bad `tol`; the cost's errors; [`Error::Convergence`] after `max_iter` steps;
/// [`Error::Interrupted`].
#[allow(clippy::too_many_arguments)]
pub fn newton_exact(
    net: &Arc<Network>,
    r_min: f64,
    sigma: f64,
    gamma0: &[f64],
    tol: f64,
    max_iter: usize,
    warm: bool,
    opts: &CostOptions,
) -> Result<NewtonAllocation> {
    let nn = net.num_sensors();
    if gamma0.len() != nn || gamma0.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err(Error::InvalidInput(format!(
            "gamma0 must be {nn} finite non-negative numbers"
        )));
    }
    if !(sigma > 0.0 && sigma.is_finite() && r_min > 0.0 && r_min.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "newton needs sigma > 0 and r_min > 0 (finite), got {sigma}, {r_min}"
        )));
    }
    if !(tol > 0.0 && tol.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "tol must be finite and > 0, got {tol}"
        )));
    }
    let mut pts = Points {
        net,
        opts,
        r_min,
        warm,
        last: None,
    };
    let mut gamma = gamma0.to_vec();
    let (mut best, mut since) = (f64::INFINITY, 0usize);
    for it in 0..max_iter {
        crate::cancel::check("Newton's method on the simplex")?;
        let point = pts.at(&gamma)?;
        let (f, g) = (point.evaluation().value(), point.gradient().to_vec());
        let gap = frank_wolfe_gap(&gamma, &g);
        let done = |gamma: Vec<f64>, point: &CostPoint| NewtonAllocation {
            gamma,
            iterations: it,
            value: f,
            gradient: g.clone(),
            value_error: point.evaluation().value_error(),
        };
        if gap <= tol * f.abs().max(1e-300) {
            return Ok(done(gamma, point));
        }
        let mut h = point.hessian(Threads::Sequential)?;
        h = (&h + h.transpose()) * 0.5;
        let hmax = (0..nn)
            .fold(0.0f64, |m, i| m.max(h[(i, i)].abs()))
            .max(1e-300);
        for i in 0..nn {
            h[(i, i)] += 1e-12 * hmax;
        }
        let hg = &h * DVector::from_column_slice(&gamma);
        let c: Vec<f64> = (0..nn).map(|i| g[i] - hg[i]).collect();
        let x = simplex_qp(&h, &c, &gamma, sigma, 20 * nn + 100)?;
        let d: Vec<f64> = x.iter().zip(&gamma).map(|(a, b)| a - b).collect();
        let s = slope(&g, &d);
        if s >= 0.0 {
            return Ok(done(gamma, point));
        }
        // The certificate at its rounding floor: the best gap has not halved in three steps.
        if gap < 0.5 * best {
            (best, since) = (gap, 0);
        } else {
            since += 1;
        }
        if since >= 3 {
            return Ok(done(gamma, point));
        }
        let value_error = point.evaluation().value_error();
        match armijo(&mut pts, &gamma, &d, f, s, sigma)? {
            Some(next) => gamma = next,
            None => {
                return Ok(NewtonAllocation {
                    gamma,
                    iterations: it,
                    value: f,
                    gradient: g,
                    value_error,
                })
            }
        }
    }
    Err(Error::Convergence(format!(
        "newton did not converge in {max_iter} iterations"
    )))
}

#[cfg(test)]
mod tests;
