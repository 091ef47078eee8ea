//! Warm-started evaluations against cold ones: equality of `Σ`, `η` and the derivatives, error
//! bounds that cover the difference, and every fallback path.

use super::*;
use crate::cancel::{with_token, Token};
use crate::cost::Threads;
use crate::cost::{CostOptions, CostPoint, Evaluation};
use crate::linalg::testing::Rng;
use crate::network::random_block_network;
use nalgebra::DMatrix;
use std::sync::Arc;

fn opts() -> CostOptions {
    CostOptions::default()
}

/// Rates in [0.5, 2.5) (`nn` sensors).
pub(super) fn rates(nn: usize, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    (0..nn).map(|_| 0.5 + 2.0 * rng.uniform()).collect()
}

/// `r` with every entry multiplied by `1 ± rel` (random signs).
fn perturbed(r: &[f64], rel: f64, seed: u64) -> Vec<f64> {
    let mut rng = Rng::new(seed);
    r.iter()
        .map(|v| v * (1.0 + if rng.uniform() < 0.5 { -rel } else { rel }))
        .collect()
}

fn rel_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

/// Warm (from the cold solution at `r0`) against cold at `r1`: `Σ` within `tol` relative and
/// within the sum of both error bounds, `η` within the sum of both trace bounds. Returns the
/// warm evaluation's info.
fn compare(net: &Network, r0: &[f64], r1: &[f64], tol: f64) -> WarmInfo {
    let from = Evaluation::new(net, r0, &opts()).unwrap();
    let cold = Evaluation::new(net, r1, &opts()).unwrap();
    let warm = Evaluation::warm(net, r1, &opts(), &from).unwrap();
    let info = warm.warm_info().unwrap().clone();
    let d = rel_diff(warm.sigma(), cold.sigma());
    assert!(
        d <= tol,
        "‖Σ_warm − Σ_cold‖/‖Σ‖ = {d:.2e} > {tol:.0e} ({info:?})"
    );
    // The bounds are rigorous for each solution, so the difference is within their sum.
    let bound = warm.forward_error() + cold.forward_error();
    assert!(
        d <= bound * (1.0 + 1e-12),
        "difference {d:.2e} exceeds the bounds' sum {bound:.2e} ({info:?})"
    );
    let dv = (warm.value() - cold.value()).abs();
    assert!(
        dv <= warm.value_error() + cold.value_error(),
        "|Δη| = {dv:.2e} > {:.2e} + {:.2e}",
        warm.value_error(),
        cold.value_error()
    );
    // Diagnostics are filled in either case.
    let care = warm.care();
    assert!(care.forward_error.is_finite() && care.trace_error.is_finite());
    assert!(care.closed_loop_abscissa < 0.0 && care.residual < 1e-12);
    assert!(!care.marginal);
    if info.fallback.is_none() {
        assert!(care.rcond.is_nan() && care.axis_margin.is_nan());
        assert_eq!(care.newton_steps, info.steps);
        // The abscissa of the cold solution's closed loop (the cold solve's own figure comes from
        // the Hamiltonian's eigenvalues, less accurate for slow modes at high rates).
        let reference = crate::linalg::schur::RealSchur::new(cold.closed_loop())
            .unwrap()
            .eigenvalues()
            .iter()
            .map(|e| e.0)
            .fold(f64::NEG_INFINITY, f64::max);
        let diff = (care.closed_loop_abscissa - reference).abs();
        assert!(diff <= 1e-8 * reference.abs(), "{diff:.2e}");
    }
    info
}

#[test]
fn nearby_points_converge_in_a_few_steps_to_the_cold_solution() {
    for (seed, nn) in [(1u64, 5usize), (2, 10), (3, 20)] {
        let net = random_block_network(seed, &vec![2; nn], &vec![1; nn], 0.1);
        let r0 = rates(nn, seed);
        for (k, rel) in [1e-3, 1e-2, 5e-2].into_iter().enumerate() {
            let r1 = perturbed(&r0, rel, seed + 10 * k as u64);
            let info = compare(&net, &r0, &r1, 1e-13);
            assert_eq!(info.fallback, None, "N = {nn}, rel = {rel}");
            assert!(info.factorizations <= 6, "N = {nn}, rel = {rel}: {info:?}");
        }
    }
}

#[test]
fn far_points_agree_whether_or_not_they_fall_back() {
    for (seed, nn) in [(4u64, 6usize), (5, 12)] {
        let net = random_block_network(seed, &vec![2; nn], &vec![1; nn], 0.3);
        let r0 = rates(nn, seed);
        for rel in [0.2, 0.5] {
            let r1 = perturbed(&r0, rel, seed + 1);
            let info = compare(&net, &r0, &r1, 1e-13);
            eprintln!("N = {nn}, rel = {rel}: {info:?}");
        }
        // Rates a factor 100 apart.
        let r1: Vec<f64> = r0.iter().map(|v| v * 100.0).collect();
        let info = compare(&net, &r0, &r1, 1e-13);
        eprintln!("N = {nn}, ×100: {info:?}");
    }
}

#[test]
fn derivatives_of_a_warm_evaluation_equal_the_cold_ones() {
    let net = random_block_network(7, &[2, 3, 2, 2, 1], &[1, 1, 2, 1, 1], 0.3);
    let r0 = rates(5, 7);
    let r1 = perturbed(&r0, 1e-2, 8);
    let from = Evaluation::new(&net, &r0, &opts()).unwrap();
    let cold = Evaluation::new(&net, &r1, &opts()).unwrap();
    let warm = Evaluation::warm(&net, &r1, &opts(), &from).unwrap();
    assert_eq!(warm.warm_info().unwrap().fallback, None);
    let (ca, wa) = (cold.adjoint().unwrap(), warm.adjoint().unwrap());
    let g = DMatrix::from_column_slice(5, 1, ca.gradient());
    let gw = DMatrix::from_column_slice(5, 1, wa.gradient());
    assert!(rel_diff(&gw, &g) <= 1e-12, "{:.2e}", rel_diff(&gw, &g));
    let (hc, hw) = (
        ca.hessian(Threads::Sequential).unwrap(),
        wa.hessian(Threads::Sequential).unwrap(),
    );
    assert!(rel_diff(&hw, &hc) <= 1e-12, "{:.2e}", rel_diff(&hw, &hc));
    let vs = vec![vec![1.0, -0.5, 2.0, 0.0, 0.3]];
    let (vc, vw) = (ca.hvp(&vs).unwrap(), wa.hvp(&vs).unwrap());
    let (vc, vw) = (
        DMatrix::from_column_slice(5, 1, &vc[0]),
        DMatrix::from_column_slice(5, 1, &vw[0]),
    );
    assert!(rel_diff(&vw, &vc) <= 1e-12, "{:.2e}", rel_diff(&vw, &vc));
    // The owned point warm-starts the same way.
    let shared = Arc::new(net.clone());
    let p0 = CostPoint::at(Arc::clone(&shared), &r0, &opts()).unwrap();
    let p1 = p0.warm(&r1, &opts()).unwrap();
    let info = p1.evaluation().warm_info().unwrap();
    assert!(info.predicted && info.fallback.is_none(), "{info:?}");
    let s1 = p1.evaluation().sigma();
    assert!(rel_diff(s1, cold.sigma()) <= 1e-13);
    let g1 = DMatrix::from_column_slice(5, 1, p1.gradient());
    assert!(rel_diff(&g1, &g) <= 1e-12, "{:.2e}", rel_diff(&g1, &g));
    let v1 = DMatrix::from_column_slice(5, 1, &p1.hvp(&vs).unwrap()[0]);
    assert!(rel_diff(&v1, &vc) <= 1e-12);
}

#[test]
fn the_tangent_predictor_saves_a_factorisation_and_agrees() {
    for (seed, nn) in [(21u64, 8usize), (22, 40)] {
        let net = random_block_network(seed, &vec![2; nn], &vec![1; nn], 0.1);
        let r0 = rates(nn, seed);
        let from = Evaluation::new(&net, &r0, &opts()).unwrap();
        let point = from.adjoint().unwrap();
        for rel in [1e-3, 1e-2, 0.1, 0.6] {
            let r1 = perturbed(&r0, rel, seed);
            let cold = Evaluation::new(&net, &r1, &opts()).unwrap();
            let plain = Evaluation::warm(&net, &r1, &opts(), &from).unwrap();
            let pred = point.warm_evaluation(&r1, &opts()).unwrap();
            let (ip, iq) = (plain.warm_info().unwrap(), pred.warm_info().unwrap());
            eprintln!("N = {nn}, rel = {rel}: plain {ip:?}, predicted {iq:?}");
            assert!(rel_diff(pred.sigma(), cold.sigma()) <= 1e-13);
            if rel <= 1e-2 {
                assert!(iq.predicted && iq.fallback.is_none(), "{iq:?}");
                assert!(iq.factorizations <= ip.factorizations, "{iq:?} vs {ip:?}");
            }
        }
    }
}

/// A stiff block network: subsystem time scales from 1e-3 to 1e3.
pub(super) fn stiff_network() -> Network {
    let nn = 4;
    let base = random_block_network(9, &vec![2; nn], &vec![1; nn], 0.05);
    let mut a = base.a().clone();
    for i in 0..nn {
        let s = 10f64.powi(2 * i as i32 - 3);
        a.view_mut((2 * i, 2 * i), (2, 2)).scale_mut(s);
        a[(2 * i, 2 * i)] -= s;
        a[(2 * i + 1, 2 * i + 1)] -= s;
    }
    let sensors = base.sensors().iter().map(|s| s.matrix().clone()).collect();
    Network::new(a, base.g().clone(), sensors).unwrap()
}

#[test]
fn stiff_models_agree() {
    let net = stiff_network();
    let r0 = rates(4, 9);
    for rel in [1e-3, 1e-2, 0.3] {
        let info = compare(&net, &r0, &perturbed(&r0, rel, 3), 1e-12);
        eprintln!("stiff, rel = {rel}: {info:?}");
    }
}

#[test]
fn high_rates_agree() {
    let net = random_block_network(12, &[2; 5], &[1; 5], 0.1);
    for scale in [1e6, 1e9, 1e12] {
        let r0: Vec<f64> = rates(5, 12).iter().map(|v| v * scale).collect();
        let r1 = perturbed(&r0, 1e-2, 4);
        let info = compare(&net, &r0, &r1, 1e-12);
        eprintln!("rates ×{scale:.0e}: {info:?}");
        // Accepted only with a Newton–Kantorovich proof; where the norm bounds cannot give one
        // (h ≥ 1/4 at the highest rates) the answer is the cold solve's, and says so.
        match &info.fallback {
            None => {}
            Some(Fallback::NotCertified { h }) => assert!(!(*h < 0.25), "h = {h}"),
            Some(other) => panic!("unexpected fallback {other}"),
        }
        if scale <= 1e6 {
            assert_eq!(info.fallback, None, "rates ×{scale:.0e}");
        }
    }
}

#[test]
fn the_certificate_bounds_cover_the_distance_to_a_refined_reference() {
    // From a start 10 % away: the accepted result's own bounds (not only their sum with the
    // cold solve's) cover its distance to the cold solution up to the cold solution's accuracy.
    for (seed, nn, scale) in [(21u64, 6usize, 1.0), (22, 8, 1e3), (23, 5, 1e5)] {
        let net = random_block_network(seed, &vec![2; nn], &vec![1; nn], 0.2);
        let r0: Vec<f64> = rates(nn, seed).iter().map(|v| v * scale).collect();
        let r1 = perturbed(&r0, 0.1, seed);
        let from = Evaluation::new(&net, &r0, &opts()).unwrap();
        let cold = Evaluation::new(&net, &r1, &opts()).unwrap();
        let warm = Evaluation::warm(&net, &r1, &opts(), &from).unwrap();
        let info = warm.warm_info().unwrap();
        assert_eq!(info.fallback, None, "seed {seed}");
        let care = warm.care();
        let d = rel_diff(warm.sigma(), cold.sigma());
        assert!(d <= care.forward_error + cold.forward_error(), "{d:.2e}");
        assert!(care.forward_error < 1e-10 && care.trace_error < 1e-10 * warm.value().abs());
        let dv = (warm.value() - cold.value()).abs();
        assert!(dv <= care.trace_error + cold.value_error(), "{dv:.2e}");
    }
}

#[test]
fn a_start_that_is_not_stabilising_falls_back_to_the_same_answer() {
    let net = random_block_network(13, &[2; 4], &[1; 4], 0.1);
    let r = rates(4, 13);
    // Σ₀ = 0: the closed loop is A itself, which has unstable eigenvalues here.
    let unstable = crate::linalg::schur::RealSchur::new(net.a())
        .unwrap()
        .eigenvalues()
        .iter()
        .any(|e| e.0 >= 0.0);
    assert!(unstable, "the test needs an unstable A");
    let cold = Evaluation::new(&net, &r, &opts()).unwrap();
    let warm = Evaluation::warm_from_sigma(&net, &r, &opts(), &DMatrix::zeros(8, 8)).unwrap();
    let info = warm.warm_info().unwrap();
    assert!(
        matches!(
            info.fallback,
            Some(Fallback::NotStabilising { step: 0, .. })
        ),
        "{info:?}"
    );
    assert_eq!(warm.sigma(), cold.sigma());
    assert_eq!(warm.forward_error(), cold.forward_error());
    assert!(!warm.care().rcond.is_nan());
    assert_eq!(
        warm.adjoint().unwrap().gradient(),
        cold.adjoint().unwrap().gradient()
    );
}

#[test]
fn non_finite_and_overflowing_starts_fall_back() {
    let net = random_block_network(14, &[2; 3], &[1; 3], 0.1);
    let r = rates(3, 14);
    let cold = Evaluation::new(&net, &r, &opts()).unwrap();
    let good = cold.sigma().clone();
    let mut starts = Vec::new();
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut s = good.clone();
        s[(1, 2)] = bad;
        s[(2, 1)] = bad;
        starts.push(s);
    }
    // Finite but overflowing in the closed loop and the residual.
    starts.push(&good * 1e300);
    starts.push(&good * -1e300);
    for s in &starts {
        let warm = Evaluation::warm_from_sigma(&net, &r, &opts(), s).unwrap();
        let info = warm.warm_info().unwrap();
        assert!(info.fallback.is_some(), "{info:?}");
        assert_eq!(warm.sigma(), cold.sigma(), "{info:?}");
    }
}

#[test]
fn the_step_bound_is_honoured() {
    let net = random_block_network(15, &[2; 4], &[1; 4], 0.1);
    let r0 = rates(4, 15);
    let r1 = perturbed(&r0, 0.1, 1);
    let from = Evaluation::new(&net, &r0, &opts()).unwrap();
    let cold = Evaluation::new(&net, &r1, &opts()).unwrap();
    for max_steps in [0, 1] {
        let o = CostOptions {
            warm: WarmParams {
                max_steps,
                chord_steps: 0,
                compensated: true,
            },
            ..opts()
        };
        let warm = Evaluation::warm(&net, &r1, &o, &from).unwrap();
        let info = warm.warm_info().unwrap();
        assert_eq!(
            info.fallback,
            Some(Fallback::StepLimit { steps: max_steps })
        );
        assert!(info.factorizations <= max_steps + 1);
        assert_eq!(warm.sigma(), cold.sigma());
    }
    // From its own solution the warm start is accepted with no correction at all.
    let again = Evaluation::warm(&net, &r1, &opts(), &cold).unwrap();
    let info = again.warm_info().unwrap();
    assert!(
        info.fallback.is_none() && info.factorizations <= 2,
        "{info:?}"
    );
}

#[test]
fn bad_input_and_cancellation_are_errors() {
    let net = random_block_network(16, &[2; 3], &[1; 3], 0.1);
    let r = rates(3, 16);
    let from = Evaluation::new(&net, &r, &opts()).unwrap();
    let err = Evaluation::warm_from_sigma(&net, &r, &opts(), &DMatrix::zeros(5, 5)).unwrap_err();
    assert!(matches!(err, Error::Shape(_)), "{err}");
    let err = Evaluation::warm(&net, &[1.0, -1.0, 1.0], &opts(), &from).unwrap_err();
    assert!(matches!(err, Error::InvalidInput(_)), "{err}");
    let t = Token::new();
    t.cancel();
    let res = with_token(Some(&t), || Evaluation::warm(&net, &r, &opts(), &from));
    assert!(matches!(res, Err(Error::Interrupted(_))), "{res:?}");
}

#[test]
fn without_compensated_refinement_the_bounds_still_cover_the_cold_solution() {
    // `WarmParams::compensated = false` (the filtration's path points): a stalled iteration ends
    // at the working-precision floor. The answer is still within both error bounds of the cold
    // solution, its own bounds are those of that floor, and it never takes more corrections or
    // Schur forms than the refined one (stiff models, where the refinement happens, and plain
    // ones, where nothing changes).
    let cases = [
        (stiff_network(), rates(4, 9)),
        (
            random_block_network(31, &[2; 8], &[1; 8], 0.05),
            rates(8, 31),
        ),
    ];
    let mut refined_somewhere = false;
    for (net, r0) in cases {
        for rel in [1e-6, 1e-3, 1e-1] {
            let r1 = perturbed(&r0, rel, 5);
            let from = Evaluation::new(&net, &r0, &opts()).unwrap();
            let cold = Evaluation::new(&net, &r1, &opts()).unwrap();
            let refined = Evaluation::warm(&net, &r1, &opts(), &from).unwrap();
            let o = CostOptions {
                warm: WarmParams {
                    compensated: false,
                    ..WarmParams::default()
                },
                ..opts()
            };
            let plain = Evaluation::warm(&net, &r1, &o, &from).unwrap();
            let (pi, ri) = (plain.warm_info().unwrap(), refined.warm_info().unwrap());
            assert_eq!(pi.fallback, ri.fallback, "move {rel:e}");
            assert!(pi.steps <= ri.steps && pi.factorizations <= ri.factorizations);
            refined_somewhere |= ri.steps > pi.steps;
            let d = rel_diff(plain.sigma(), cold.sigma());
            assert!(
                d <= plain.forward_error() + cold.forward_error(),
                "move {rel:e}: {d:.2e} > {:.2e} + {:.2e} ({pi:?})",
                plain.forward_error(),
                cold.forward_error()
            );
            let d = rel_diff(plain.sigma(), refined.sigma());
            assert!(d <= plain.forward_error() + refined.forward_error());
            let dv = (plain.value() - cold.value()).abs();
            assert!(dv <= plain.value_error() + cold.value_error(), "{dv:.2e}");
            let care = plain.care();
            assert!(care.closed_loop_abscissa < 0.0 && care.residual < 1e-12);
            assert!(care.forward_error < 1e-9);
        }
    }
    // The opt-out was exercised: somewhere the default refined further.
    assert!(refined_somewhere);
}
