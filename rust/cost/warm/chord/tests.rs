//! Chord warm starts against the plain warm start and the cold solve: `Σ`, `η`, the gradient and
//! a Hessian-vector product, error bounds that cover the distance to the cold solution, and the
//! factorisations saved — near, far and on a stiff model.

use super::super::tests::rates;
use crate::cost::warm::{Fallback, WarmParams};
use crate::cost::{CostOptions, CostPoint, Evaluation};
use crate::linalg::testing::Rng;
use crate::network::{random_block_network, Network};
use nalgebra::DMatrix;
use std::sync::Arc;

fn chord_opts(chord_steps: usize) -> CostOptions {
    CostOptions {
        warm: WarmParams {
            chord_steps,
            ..WarmParams::default()
        },
        ..CostOptions::default()
    }
}

fn perturbed(r: &[f64], rel: f64, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    r.iter()
        .map(|v| v * (1.0 + rel * (2.0 * rng.uniform() - 1.0)))
        .collect()
}

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum();
    let n: f64 = b.iter().map(|y| y * y).sum();
    (d / n).sqrt()
}

fn rel_mat(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

/// The chord point, the plain warm point (tangent predictor, fresh Schur forms) and the cold
/// point at `r1`, all from the point at `r0`; returns the chord's and the plain start's
/// factorisations.
fn check(net: Network, r0: &[f64], r1: &[f64]) -> (usize, usize, Option<Fallback>) {
    let shared = Arc::new(net);
    let nn = shared.num_sensors();
    let p0 = CostPoint::at(Arc::clone(&shared), r0, &CostOptions::default()).unwrap();
    let cold = CostPoint::at(Arc::clone(&shared), r1, &CostOptions::default()).unwrap();
    let plain = p0.warm(r1, &CostOptions::default()).unwrap();
    let chord = p0.warm(r1, &chord_opts(8)).unwrap();
    let (ec, ep, e0) = (chord.evaluation(), plain.evaluation(), cold.evaluation());
    let info = ec.warm_info().unwrap().clone();
    let d = rel_mat(ec.sigma(), e0.sigma());
    assert!(d <= 1e-12, "‖Σ_chord − Σ_cold‖ = {d:.2e} ({info:?})");
    assert!(rel_mat(ec.sigma(), ep.sigma()) <= 1e-12);
    // The reported bound covers the distance to the cold solution up to the cold one's accuracy.
    assert!(
        d <= ec.forward_error() + e0.forward_error(),
        "{d:.2e} > {:.2e} + {:.2e} ({info:?})",
        ec.forward_error(),
        e0.forward_error()
    );
    // As tight as the plain warm start's bound, or within the rounding floor mapped through
    // `Ω⁻¹` (measured 1.3e-11 against 4e-13 at N = 8, move 1e-6: the plain start ended in a
    // compensated refinement step, the chord at the floor without one).
    assert!(
        ec.forward_error() <= (2.0 * ep.forward_error()).max(1e-10),
        "{:.2e} vs {:.2e} ({info:?})",
        ec.forward_error(),
        ep.forward_error()
    );
    let dv = (ec.value() - e0.value()).abs();
    assert!(dv <= ec.value_error() + e0.value_error(), "{dv:.2e}");
    let dg = rel(chord.gradient(), cold.gradient());
    assert!(dg <= 1e-11, "gradient {dg:.2e}");
    let v: Vec<f64> = (0..nn).map(|i| 1.0 - 0.3 * i as f64).collect();
    let (hc, h0) = (
        chord.hvp(std::slice::from_ref(&v)).unwrap(),
        cold.hvp(std::slice::from_ref(&v)).unwrap(),
    );
    assert!(rel(&hc[0], &h0[0]) <= 1e-10, "{:.2e}", rel(&hc[0], &h0[0]));
    let care = ec.care();
    assert!(care.closed_loop_abscissa < 0.0 && care.residual < 1e-12);
    if info.fallback.is_none() {
        assert_eq!(care.newton_steps, info.steps);
    }
    let pinfo = ep.warm_info().unwrap();
    (info.factorizations, pinfo.factorizations, info.fallback)
}

#[test]
fn near_points_need_one_schur_form_and_agree() {
    for (seed, nn) in [(31u64, 8usize), (32, 40)] {
        let net = random_block_network(seed, &vec![2; nn], &vec![1; nn], 0.05);
        let r0 = rates(nn, seed);
        for step in [1e-6, 1e-4, 1e-3] {
            let (fc, fp, fb) = check(net.clone(), &r0, &perturbed(&r0, step, seed + 1));
            eprintln!("N = {nn}, move {step:e}: chord {fc}, plain {fp} Schur forms");
            assert_eq!(fb, None);
            assert_eq!(fc, 1, "move {step:e}");
            assert!(fc <= fp);
        }
    }
}

#[test]
fn far_points_agree_through_the_newton_iteration() {
    // A move of 30 %: the chord stops early (slow linear rate), Newton goes on from it.
    let nn = 6;
    let net = random_block_network(33, &vec![2; nn], &vec![1; nn], 0.2);
    let r0 = rates(nn, 33);
    for step in [0.05, 0.3] {
        let (fc, fp, fb) = check(net.clone(), &r0, &perturbed(&r0, step, 34));
        eprintln!("move {step}: chord {fc}, plain {fp} Schur forms, {fb:?}");
    }
}

#[test]
fn stiff_models_agree() {
    // Subsystem time scales from 1e-3 to 1e3 (four subsystems).
    let net = super::super::tests::stiff_network();
    let r0 = rates(4, 9);
    for step in [1e-4, 1e-2, 0.3] {
        let (fc, fp, fb) = check(net.clone(), &r0, &perturbed(&r0, step, 3));
        eprintln!("stiff, move {step}: chord {fc}, plain {fp} Schur forms, {fb:?}");
    }
}

#[test]
fn without_chord_steps_the_warm_start_is_unchanged() {
    let nn = 10;
    let net = Arc::new(random_block_network(35, &vec![2; nn], &vec![1; nn], 0.05));
    let r0 = rates(nn, 35);
    let r1 = perturbed(&r0, 1e-3, 36);
    let p0 = CostPoint::at(Arc::clone(&net), &r0, &CostOptions::default()).unwrap();
    let a = p0.warm(&r1, &CostOptions::default()).unwrap();
    let b = p0.warm(&r1, &chord_opts(0)).unwrap();
    assert_eq!(a.evaluation().sigma(), b.evaluation().sigma());
    assert_eq!(a.gradient(), b.gradient());
    assert_eq!(b.evaluation().warm_info().unwrap().chord_steps, 0);
    // Without a factored start (a plain evaluation) there is no chord either.
    let e0 = Evaluation::new(&net, &r0, &CostOptions::default()).unwrap();
    let e1 = Evaluation::warm(&net, &r1, &chord_opts(8), &e0).unwrap();
    assert_eq!(e1.warm_info().unwrap().chord_steps, 0);
}
