//! The core Newton loop against an independent route (the separable solution at ε = 0, where the
//! coupled problem is the separable one), its certificate on coupled networks, and its refusals.

use super::*;
use crate::allocation::separable_allocation;
use crate::network::random_block_network;

fn opts() -> CostOptions {
    CostOptions::default()
}

#[test]
fn at_eps_zero_it_reaches_the_separable_optimum() {
    let sizes = [2usize; 5];
    let full = Arc::new(random_block_network(31, &sizes, &[1; 5], 0.0));
    let blocks: Vec<Network> = (0..5)
        .map(|i| {
            let a = full.a().view((2 * i, 2 * i), (2, 2)).into_owned();
            let g = full.g().view((2 * i, 2 * i), (2, 2)).into_owned();
            let c = full.sensors()[i]
                .matrix()
                .view((2 * i, 0), (2, 1))
                .into_owned();
            Network::new(a, g, vec![c]).unwrap()
        })
        .collect();
    let sep = separable_allocation(&blocks, 1.0, 7.0, 1e-14, 50, &opts()).unwrap();
    let res = newton_exact(&full, 1.0, 7.0, &[1.4; 5], 1e-13, 200, false, &opts()).unwrap();
    assert!(res.iterations >= 1);
    for (a, b) in res.gamma.iter().zip(&sep.gamma) {
        assert!((a - b).abs() <= 1e-6, "{:?} vs {:?}", res.gamma, sep.gamma);
    }
    assert!((res.value - sep.value).abs() <= 1e-12 * sep.value);
}

#[test]
fn on_coupled_networks_the_certificate_holds_warm_or_cold() {
    for (seed, nn, eps) in [(1u64, 4usize, 0.1), (2, 8, 0.3), (3, 12, 0.05)] {
        let net = Arc::new(random_block_network(seed, &vec![2; nn], &vec![1; nn], eps));
        let sigma = 2.0 * nn as f64;
        let g0 = vec![2.0; nn];
        let cold = newton_exact(&net, 1.0, sigma, &g0, 1e-12, 200, false, &opts()).unwrap();
        let warm = newton_exact(&net, 1.0, sigma, &g0, 1e-12, 200, true, &opts()).unwrap();
        for res in [&cold, &warm] {
            let s: f64 = res.gamma.iter().sum();
            assert!((s - sigma).abs() <= 1e-13 * sigma);
            assert!(res.gamma.iter().all(|v| *v >= 0.0));
            // The gradient returned is the cost's at γ (an independent evaluation).
            let r: Vec<f64> = res.gamma.iter().map(|g| g + 1.0).collect();
            let (f, g) = crate::cost::value_gradient(&net, &r, &opts()).unwrap();
            assert!((f - res.value).abs() <= 1e-13 * f);
            let gap = frank_wolfe_gap(&res.gamma, &g);
            assert!(gap <= 1e-12 * f + 10.0 * res.value_error, "gap {gap:.2e}");
        }
        assert!((cold.value - warm.value).abs() <= 1e-13 * cold.value);
    }
}

#[test]
fn bad_input_is_refused_and_the_step_bound_honoured() {
    let net = Arc::new(random_block_network(4, &[2; 3], &[1; 3], 0.2));
    let o = opts();
    assert!(newton_exact(&net, 1.0, 3.0, &[1.0; 2], 1e-12, 10, false, &o).is_err());
    assert!(newton_exact(&net, 1.0, 3.0, &[1.0, -1.0, 3.0], 1e-12, 10, false, &o).is_err());
    assert!(newton_exact(&net, 1.0, 0.0, &[0.0; 3], 1e-12, 10, false, &o).is_err());
    assert!(newton_exact(&net, 1.0, 3.0, &[1.0; 3], f64::NAN, 10, false, &o).is_err());
    let e = newton_exact(&net, 1.0, 3.0, &[3.0, 0.0, 0.0], 1e-15, 1, false, &o);
    assert!(matches!(e, Err(Error::Convergence(_))), "{:?}", e.err());
}
