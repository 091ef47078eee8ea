//! The separable allocation problem of a decoupled network (ε = 0): subsystem `i` with its own
//! sensor has the cost `η_i(r_i) = tr Σ_i(r_i)` of its small CARE, and
//!
//! `minimise Σ_i η_i(r_min + γ_i)   subject to   γ ≥ 0,  Σ γ_i = σ`.
//!
//! Its optimum is the start of Newton's method on a weakly coupled network (the coupled optimum
//! is `O(ε)` away), and *is* the optimum when ε = 0.
//!
//! **Method.** Newton's method with the exact (diagonal) Hessian `diag η_i''`: the quadratic model
//! `Σ g_i d_i + ½ h_i d_i²` over `{γ + d ≥ 0, Σ d = 0}` is minimised exactly by
//! `γ_i + d_i = max(0, γ_i − (g_i − λ)/h_i)`, the multiplier `λ` found on the sorted breakpoints
//! `g_i − h_i γ_i` (`Σ_i` of the right-hand side is continuous and nondecreasing in `λ`); then an
//! Armijo search on `Σ η_i`. It stops on the Frank–Wolfe certificate
//! `Σ γ_i (g_i − min_j g_j) ≤ tol·η` (an upper bound on the distance to the optimum value for convex
//! `η_i`), when no descent is left, when the gap has not halved in three steps (its rounding
//! floor), or after `max_iter` steps: the result is a start, and says how far it got (`gap`). A
//! step whose predicted decrease is at the rounding level of `η` is taken in full (values cannot
//! tell it apart from noise), as the Python Newton does. Each step costs `N` small CARE solves with one more Lyapunov solve for
//! `η_i'` and one for `η_i''` each.

use crate::cost::{CostOptions, Evaluation, Threads};
use crate::network::Network;
use crate::{Error, Result};

/// The decoupled optimum (or the best point reached).
#[derive(Debug, Clone)]
pub struct SeparableAllocation {
    /// `γ` on the simplex of height `σ`.
    pub gamma: Vec<f64>,
    /// `Σ η_i(r_min + γ_i)`.
    pub value: f64,
    /// The Frank–Wolfe gap at `γ`.
    pub gap: f64,
    /// Newton steps taken.
    pub iterations: usize,
}

/// `(η_i, η_i', η_i'')` of one single-sensor subsystem at rate `r`.
fn block(net: &Network, r: f64, opts: &CostOptions) -> Result<(f64, f64, f64)> {
    let ev = Evaluation::new(net, &[r], opts)?;
    let adj = ev.adjoint()?;
    let h = adj.hessian(Threads::Sequential)?;
    Ok((ev.value(), adj.gradient()[0], h[(0, 0)]))
}

/// Puts the rounding error of `Σ x` on the largest entry, keeping `x ≥ 0`.
fn fix_sum(x: &mut [f64], sigma: f64) {
    for v in x.iter_mut() {
        *v = v.max(0.0);
    }
    let k = (0..x.len()).fold(0, |k, i| if x[i] > x[k] { i } else { k });
    let s: f64 = x.iter().sum();
    x[k] = (x[k] + sigma - s).max(0.0);
}

/// The minimiser of `Σ g_i d_i + ½ h_i d_i²` over `{γ + d ≥ 0, Σ d = 0}`, as the point `γ + d`.
fn diagonal_qp(g: &[f64], h: &[f64], gamma: &[f64], sigma: f64) -> Vec<f64> {
    let nn = g.len();
    let bp: Vec<f64> = (0..nn).map(|i| g[i] - h[i] * gamma[i]).collect();
    let mut order: Vec<usize> = (0..nn).collect();
    order.sort_by(|&a, &b| bp[a].total_cmp(&bp[b]));
    // With the k smallest breakpoints active: Σ (γ_i − (g_i − λ)/h_i) = σ.
    let (mut s1, mut s2) = (0.0, 0.0);
    let mut lam = bp[order[0]];
    for (k, &i) in order.iter().enumerate() {
        s1 += gamma[i] - g[i] / h[i];
        s2 += 1.0 / h[i];
        lam = (sigma - s1) / s2;
        if k + 1 == nn || lam <= bp[order[k + 1]] {
            break;
        }
    }
    let mut x: Vec<f64> = (0..nn)
        .map(|i| (gamma[i] - (g[i] - lam) / h[i]).max(0.0))
        .collect();
    fix_sum(&mut x, sigma);
    x
}

/// `Σ γ_i (g_i − min g)`.
fn frank_wolfe_gap(gamma: &[f64], g: &[f64]) -> f64 {
    let m = g.iter().copied().fold(f64::INFINITY, f64::min);
    gamma.iter().zip(g).map(|(a, b)| a * (b - m)).sum()
}

/// Solves the separable problem for single-sensor subsystems `blocks` (see the module
/// documentation), from the uniform start.
///
/// # Errors
/// [`Error::InvalidInput`] for a subsystem with other than one sensor, `r_min ≤ 0`, `σ < 0` or a
/// non-finite `tol`; the cost's errors (a subsystem without a stabilising solution, …);
/// [`Error::Interrupted`].
pub fn separable_allocation(
    blocks: &[Network],
    r_min: f64,
    sigma: f64,
    tol: f64,
    max_iter: usize,
    opts: &CostOptions,
) -> Result<SeparableAllocation> {
    let nn = blocks.len();
    if nn == 0 || blocks.iter().any(|b| b.num_sensors() != 1) {
        return Err(Error::InvalidInput(
            "the separable allocation needs subsystems with one sensor each".into(),
        ));
    }
    if !(r_min > 0.0 && r_min.is_finite() && sigma >= 0.0 && sigma.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "the separable allocation needs r_min > 0 and sigma ≥ 0 (finite), got {r_min}, {sigma}"
        )));
    }
    if !(tol >= 0.0 && tol.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "tol must be finite and ≥ 0, got {tol}"
        )));
    }
    let mut gamma = vec![sigma / nn as f64; nn];
    let mut cur = evaluate(blocks, r_min, &gamma, opts)?;
    let mut it = 0;
    // The gap at its rounding floor: the best one has not halved in three steps.
    let (mut best, mut since) = (f64::INFINITY, 0);
    loop {
        let gap = frank_wolfe_gap(&gamma, &cur.g);
        if gap < 0.5 * best {
            (best, since) = (gap, 0);
        } else {
            since += 1;
        }
        if gap <= tol * cur.f.abs() || it == max_iter || nn == 1 || since >= 3 {
            break;
        }
        let Some((x, slope)) = newton_step(&cur, &gamma, sigma) else {
            break;
        };
        if -slope <= NOISE_DECREASE * cur.f.abs() {
            // The predicted decrease is at the rounding level of the value: comparing values
            // measures noise, so the full step is taken (progress is judged by the gap).
            cur = evaluate(blocks, r_min, &x, opts)?;
            gamma = x;
        } else {
            let Some((next, point)) = armijo(blocks, r_min, sigma, &gamma, &x, &cur, slope, opts)?
            else {
                break;
            };
            gamma = next;
            cur = point;
        }
        it += 1;
    }
    Ok(SeparableAllocation {
        gap: frank_wolfe_gap(&gamma, &cur.g),
        gamma,
        value: cur.f,
        iterations: it,
    })
}

/// Predicted decreases below this times `|η|` are at the rounding level of η.
const NOISE_DECREASE: f64 = 1e3 * f64::EPSILON;

/// Value, gradient and curvatures of the separable cost at one point.
struct Point {
    f: f64,
    g: Vec<f64>,
    h: Vec<f64>,
}

fn evaluate(blocks: &[Network], r_min: f64, gamma: &[f64], opts: &CostOptions) -> Result<Point> {
    crate::cancel::check("the separable allocation")?;
    let nn = blocks.len();
    let mut p = Point {
        f: 0.0,
        g: vec![0.0; nn],
        h: vec![0.0; nn],
    };
    for i in 0..nn {
        let (fi, gi, hi) = block(&blocks[i], r_min + gamma[i], opts)?;
        p.f += fi;
        p.g[i] = gi;
        p.h[i] = hi;
    }
    Ok(p)
}

/// The Newton point `γ + d` of the diagonal quadratic model and the slope `gᵀd`; `None` when no
/// descent is left (or the curvatures are not usable).
fn newton_step(p: &Point, gamma: &[f64], sigma: f64) -> Option<(Vec<f64>, f64)> {
    // η_i is convex; a curvature that rounding made non-positive is raised to a small one.
    let hmax = p.h.iter().copied().fold(0.0, f64::max);
    if !(hmax > 0.0 && hmax.is_finite()) {
        return None;
    }
    let h: Vec<f64> = p.h.iter().map(|v| v.max(1e-12 * hmax)).collect();
    let x = diagonal_qp(&p.g, &h, gamma, sigma);
    let d: Vec<f64> = x.iter().zip(gamma).map(|(a, b)| a - b).collect();
    // gᵀd with Σd = 0, measured against the |d|-weighted mean of g (Σd carries rounding).
    let wsum: f64 = d.iter().map(|v| v.abs()).sum();
    if !(wsum > 0.0) {
        return None;
    }
    let c = d.iter().zip(&p.g).map(|(a, b)| a.abs() * b).sum::<f64>() / wsum;
    let slope: f64 = d.iter().zip(&p.g).map(|(a, b)| (b - c) * a).sum();
    (slope < 0.0).then_some((x, slope))
}

/// Backtracking along `γ + t(x − γ)` until `η` decreases by `1e-4·t·slope` (at most 60
/// halvings); the accepted point with its evaluation, `None` when none is found.
#[allow(clippy::too_many_arguments)]
fn armijo(
    blocks: &[Network],
    r_min: f64,
    sigma: f64,
    gamma: &[f64],
    x: &[f64],
    cur: &Point,
    slope: f64,
    opts: &CostOptions,
) -> Result<Option<(Vec<f64>, Point)>> {
    let mut t = 1.0;
    for _ in 0..60 {
        let mut trial: Vec<f64> = gamma.iter().zip(x).map(|(a, b)| a + t * (b - a)).collect();
        fix_sum(&mut trial, sigma);
        if trial == gamma {
            break;
        }
        let p = evaluate(blocks, r_min, &trial, opts)?;
        if p.f <= cur.f + 1e-4 * t * slope {
            return Ok(Some((trial, p)));
        }
        t *= 0.5;
    }
    Ok(None)
}

#[cfg(test)]
mod tests;
