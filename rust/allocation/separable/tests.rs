//! The separable optimum against an independent route: nested bisection on the KKT multiplier
//! (`η_i'(r_i) = μ` on the active set, solved rate by rate), and the refusals.

use super::*;
use crate::cost::value_gradient;
use crate::network::random_block_network;

fn blocks(count: usize, seed: u64) -> Vec<Network> {
    (0..count)
        .map(|k| random_block_network(seed + k as u64, &[2], &[1], 0.0))
        .collect()
}

fn slope(net: &Network, r: f64) -> f64 {
    value_gradient(net, &[r], &CostOptions::default())
        .unwrap()
        .1[0]
}

/// `γ_i(μ)`: 0 when `η_i'(r_min) ≥ μ`, else the root of `η_i'(r_min + γ) = μ` (η_i' increases).
fn gamma_of(net: &Network, r_min: f64, sigma: f64, mu: f64) -> f64 {
    if slope(net, r_min) >= mu {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0, sigma);
    if slope(net, r_min + hi) <= mu {
        return hi;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if slope(net, r_min + mid) < mu {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The optimum by bisection on `μ` (`Σ γ_i(μ)` increases with `μ`).
fn by_bisection(nets: &[Network], r_min: f64, sigma: f64) -> Vec<f64> {
    let mut lo = nets
        .iter()
        .map(|b| slope(b, r_min))
        .fold(f64::INFINITY, f64::min);
    let mut hi = nets
        .iter()
        .map(|b| slope(b, r_min + sigma))
        .fold(f64::NEG_INFINITY, f64::max);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        let s: f64 = nets.iter().map(|b| gamma_of(b, r_min, sigma, mid)).sum();
        if s < sigma {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let mu = 0.5 * (lo + hi);
    nets.iter().map(|b| gamma_of(b, r_min, sigma, mu)).collect()
}

#[test]
fn the_newton_solution_is_the_bisection_solution() {
    for (count, seed, sigma) in [(2, 1, 3.0), (5, 7, 10.0), (6, 20, 0.5)] {
        let nets = blocks(count, seed);
        let sol =
            separable_allocation(&nets, 1.0, sigma, 1e-13, 50, &CostOptions::default()).unwrap();
        let reference = by_bisection(&nets, 1.0, sigma);
        assert!(sol.gap <= 1e-12 * sol.value, "gap {:.2e}", sol.gap);
        let s: f64 = sol.gamma.iter().sum();
        assert!((s - sigma).abs() <= 1e-14 * sigma.max(1.0) * count as f64);
        for (a, b) in sol.gamma.iter().zip(&reference) {
            assert!(
                (a - b).abs() <= 1e-7 * sigma,
                "{:?} vs {reference:?}",
                sol.gamma
            );
        }
    }
}

#[test]
fn bad_input_is_refused() {
    let nets = blocks(3, 2);
    let o = CostOptions::default();
    assert!(separable_allocation(&[], 1.0, 1.0, 1e-12, 10, &o).is_err());
    assert!(separable_allocation(&nets, 0.0, 1.0, 1e-12, 10, &o).is_err());
    assert!(separable_allocation(&nets, 1.0, -1.0, 1e-12, 10, &o).is_err());
    assert!(separable_allocation(&nets, 1.0, 1.0, f64::NAN, 10, &o).is_err());
    let two = random_block_network(3, &[2, 2], &[1, 1], 0.0);
    assert!(separable_allocation(&[two], 1.0, 1.0, 1e-12, 10, &o).is_err());
    // Zero steps: the uniform start itself.
    let sol = separable_allocation(&nets, 1.0, 3.0, 1e-12, 0, &o).unwrap();
    assert_eq!(sol.gamma, vec![1.0; 3]);
    assert_eq!(sol.iterations, 0);
}
