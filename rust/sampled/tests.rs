// Why this module is long: the unit tests of the sampled system (doubling, schedules, neighbourhood
// screening) against closed forms and brute force, in one place.
use super::doubling::{
    doubling, fixed_point, propagate, spectral_radius, steady_state, DoublingOptions, SteadyState,
};
use super::existence::{aliasing_pair, unobservable_dimension};
use super::search::{
    greedy_pass, neighbourhood, neighbourhood_until, schedule_cost, CountLimits, Objective,
};
use super::*;
use crate::care::{solve_care, CareOptions};
use crate::linalg::testing::Rng;

fn rel(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm().max(f64::MIN_POSITIVE)
}

/// A random stable-ish network: `n` states, `nsens` sensors with one output each, `Q ≻ 0`.
pub(super) fn network(rng: &mut Rng, n: usize, nsens: usize) -> SampledSystem {
    let mut a = rng.matrix(n, n) * (0.6 / (n as f64).sqrt());
    for i in 0..n {
        a[(i, i)] -= 0.3;
    }
    let q = rng.psd(n, n) * (1.0 / n as f64) + DMatrix::identity(n, n) * 0.2;
    let sensors = (0..nsens).map(|_| rng.matrix(n, 1)).collect();
    SampledSystem::new(a, q, sensors).unwrap()
}

fn interleaved(counts: &[usize]) -> Vec<usize> {
    // Sensor i's k-th slot at ideal position (k + 1/2) r / r_i; stable sort.
    let r: usize = counts.iter().sum();
    let mut keys: Vec<(f64, usize)> = Vec::new();
    for (i, &ri) in counts.iter().enumerate() {
        for k in 0..ri {
            keys.push(((k as f64 + 0.5) * r as f64 / ri as f64, i));
        }
    }
    keys.sort_by(|x, y| x.partial_cmp(y).unwrap());
    keys.into_iter().map(|(_, i)| i).collect()
}

fn random_psd(rng: &mut Rng, n: usize, scale: f64) -> DMatrix<f64> {
    rng.psd(n, n) * scale
}

#[test]
fn star_product_is_composition() {
    let mut rng = Rng::new(1);
    for &n in &[1usize, 3, 6] {
        let t1 = Triplet {
            a: rng.matrix(n, n),
            g: random_psd(&mut rng, n, 0.5),
            h: random_psd(&mut rng, n, 0.7),
        };
        let t2 = Triplet {
            a: rng.matrix(n, n),
            g: random_psd(&mut rng, n, 0.3),
            h: random_psd(&mut rng, n, 1.1),
        };
        let x = random_psd(&mut rng, n, 1.0);
        let direct = t2.apply(&t1.apply(&x).unwrap()).unwrap();
        let composed = t1.then(&t2).unwrap().apply(&x).unwrap();
        assert!(rel(&composed, &direct) < 1e-12, "n={n}");
        // The identity is neutral.
        let id = Triplet::identity(n);
        assert!(rel(&id.then(&t1).unwrap().a, &t1.a) < 1e-14);
        assert!(rel(&t1.then(&id).unwrap().h, &t1.h) < 1e-14);
    }
}

#[test]
fn slot_triplet_is_predict_then_update() {
    let mut rng = Rng::new(2);
    let sys = network(&mut rng, 4, 2);
    let disc = sys.discretise(0.3, 5).unwrap();
    for i in 0..2 {
        let two_step = Triplet::predict(&disc.e, &disc.h)
            .then(&Triplet::update(&disc.cbar[i]))
            .unwrap();
        let s = &disc.slots[i];
        assert!(rel(&s.a, &two_step.a) < 1e-12);
        assert!(rel(&s.g, &two_step.g) < 1e-12);
        assert!(rel(&s.h, &two_step.h) < 1e-12);
        let x = random_psd(&mut rng, 4, 2.0);
        assert!(rel(&s.apply(&x).unwrap(), &disc.slot_map(i, &x).unwrap()) < 1e-12);
        // Joseph form agrees with the information form ((P⁻¹ + c̄c̄ᵀ)⁻¹).
        let p = disc.predict(&x);
        let info = (p.clone().try_inverse().unwrap() + &disc.cbar[i] * disc.cbar[i].transpose())
            .try_inverse()
            .unwrap();
        assert!(rel(&disc.update(i, &p).unwrap(), &info) < 1e-11);
    }
}

#[test]
fn doubling_agrees_with_fixed_point_iteration() {
    let mut rng = Rng::new(3);
    for &(n, nsens, r, tau) in &[
        (2usize, 1usize, 1usize, 0.5),
        (4, 2, 10, 0.05),
        (5, 3, 37, 1.3),
    ] {
        let sys = network(&mut rng, n, nsens);
        let slots: Vec<usize> = (0..r).map(|l| l % nsens).collect();
        let disc = sys.discretise(tau, r).unwrap();
        let ss = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
        let fp = fixed_point(&disc, &slots, &DMatrix::zeros(n, n), 1e-15, 200_000).unwrap();
        let e = rel(&ss.boundary, &fp.sigma);
        assert!(e < 1e-12, "n={n} r={r}: doubling vs iteration {e:e}");
        assert!(ss.residual < 1e-12, "residual {}", ss.residual);
        assert!(ss.spectral_radius < 1.0);
        assert!(ss.steps < 30);
        assert_eq!(ss.posteriors.len(), r);
        assert!(rel(ss.posteriors.last().unwrap(), &ss.boundary) < 1e-12);
    }
}

#[test]
fn steady_state_does_not_depend_on_initial_covariance() {
    let mut rng = Rng::new(4);
    let sys = network(&mut rng, 3, 2);
    let slots = vec![0, 1, 1, 0, 1];
    let disc = sys.discretise(0.7, 5).unwrap();
    let ss = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
    let s0 = random_psd(&mut rng, 3, 10.0);
    let fp = fixed_point(&disc, &slots, &s0, 1e-15, 1_000_000).unwrap();
    assert!(rel(&ss.boundary, &fp.sigma) < 1e-12);
}

/// Fast-sampling Σ of `AΣ + ΣAᵀ − ΣWΣ + Q = 0`, `W = Σ r_i ĉ_iĉ_iᵀ`: control form with `Aᵀ`.
fn fast_sampling(sys: &SampledSystem, counts: &[usize]) -> DMatrix<f64> {
    let n = sys.order();
    let mut w = DMatrix::zeros(n, n);
    for (c, &r) in sys.sensors().iter().zip(counts) {
        w += c * c.transpose() * r as f64;
    }
    solve_care(&sys.a().transpose(), &w, sys.q(), &CareOptions::default())
        .unwrap()
        .x
}

#[test]
fn corollary_1_first_order_convergence() {
    let mut rng = Rng::new(5);
    let sys = network(&mut rng, 4, 3);
    let counts = [3usize, 5, 2];
    let slots = interleaved(&counts);
    let eta = fast_sampling(&sys, &counts).trace();
    let mut errs = Vec::new();
    for k in 0..5 {
        let tau = 0.2 / 2f64.powi(k);
        let disc = sys.discretise(tau, slots.len()).unwrap();
        let ss = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
        errs.push((ss.eta_boundary() - eta).abs());
    }
    for w in errs.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(
            (order - 1.0).abs() < 0.15,
            "observed order {order} ({errs:?})"
        );
    }
}

/// `F(Σ) = AΣ + ΣAᵀ − Σ W Σ + Q` with the corrected sign; `sign = +1` is the paper's misprint.
fn drift(sys: &SampledSystem, counts: &[usize], s: &DMatrix<f64>, sign: f64) -> DMatrix<f64> {
    let n = sys.order();
    let mut w = DMatrix::zeros(n, n);
    for (c, &r) in sys.sensors().iter().zip(counts) {
        w += c * c.transpose() * r as f64;
    }
    sys.a() * s + s * sys.a().transpose() + s * w * s * sign + sys.q()
}

#[test]
fn small_tau_expansion_has_the_corrected_sign() {
    let mut rng = Rng::new(6);
    let sys = network(&mut rng, 3, 2);
    let slots = vec![0, 1, 1, 0, 1, 1];
    let counts = [2usize, 4];
    let s = random_psd(&mut rng, 3, 1.0) + DMatrix::identity(3, 3) * 0.5;
    let (mut good, mut bad) = (Vec::new(), Vec::new());
    for k in 0..5 {
        let tau = 0.01 / 2f64.powi(k);
        let disc = sys.discretise(tau, slots.len()).unwrap();
        let (_, posts) = propagate(&disc, &slots, &s).unwrap();
        let phi = posts.last().unwrap();
        good.push((phi - &s - drift(&sys, &counts, &s, -1.0) * tau).norm());
        bad.push((phi - &s - drift(&sys, &counts, &s, 1.0) * tau).norm());
    }
    for w in good.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(
            (order - 2.0).abs() < 0.2,
            "corrected sign: remainder order {order}"
        );
    }
    for w in bad.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!(
            (order - 1.0).abs() < 0.2,
            "paper's sign: remainder order {order}"
        );
    }
}

#[test]
fn orderings_with_equal_counts_differ_by_order_tau() {
    let mut rng = Rng::new(7);
    let sys = network(&mut rng, 4, 2);
    let inter = vec![0, 1, 0, 1, 0, 1];
    let block = vec![0, 0, 0, 1, 1, 1];
    let mut diffs = Vec::new();
    for k in 0..5 {
        let tau = 0.05 / 2f64.powi(k);
        let disc = sys.discretise(tau, 6).unwrap();
        let a = steady_state(&disc, &inter, &DoublingOptions::default()).unwrap();
        let b = steady_state(&disc, &block, &DoublingOptions::default()).unwrap();
        diffs.push((a.eta_boundary() - b.eta_boundary()).abs());
    }
    for w in diffs.windows(2) {
        let order = (w[0] / w[1]).log2();
        assert!((order - 1.0).abs() < 0.2, "order {order} ({diffs:?})");
    }
}

#[test]
fn existence_checks() {
    // Harmonic oscillator with period 2π/ω: τ = π/ω aliases the pair ±iω.
    let w = 2.0;
    let a = DMatrix::from_row_slice(2, 2, &[-0.1, w, -w, -0.1]);
    let tau = std::f64::consts::PI / w;
    assert!(aliasing_pair(&a, tau, 1e-8).unwrap().is_some());
    assert!(aliasing_pair(&a, 0.9 * tau, 1e-8).unwrap().is_none());
    assert!(aliasing_pair(&a, -1.0, 1e-8).is_err());
    // Observability: a sensor on one of two decoupled states sees only that one.
    let d = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, -2.0]);
    let c1 = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
    assert_eq!(unobservable_dimension(&d, &c1, 1e-10).unwrap(), 1);
    let c2 = DMatrix::from_column_slice(2, 1, &[1.0, 1.0]);
    assert_eq!(unobservable_dimension(&d, &c2, 1e-10).unwrap(), 0);
    // Equal eigenvalues and one output: never observable.
    let i2 = -DMatrix::<f64>::identity(2, 2);
    assert_eq!(unobservable_dimension(&i2, &c2, 1e-10).unwrap(), 1);
    let sys = SampledSystem::new(d.clone(), DMatrix::identity(2, 2), vec![c1, c2]).unwrap();
    assert!(sys.check_existence(0.1, &[0, 0]).is_err());
    assert!(sys.check_existence(0.1, &[0, 1]).is_ok());
    assert!(sys.check_existence(0.1, &[2]).is_err());
}

#[test]
fn undetected_modes_are_errors_not_numbers() {
    // Marginal undetected mode (a pure integrator the sensor does not see): linear growth.
    let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, 0.0]);
    let c = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
    let sys = SampledSystem::new(a, DMatrix::identity(2, 2), vec![c.clone()]).unwrap();
    let disc = sys.discretise(0.5, 2).unwrap();
    let err = steady_state(&disc, &[0, 0], &DoublingOptions::default()).unwrap_err();
    assert!(
        matches!(&err, Error::Convergence(m) if m.contains("doubling did not converge")),
        "{err:?}"
    );
    // Unstable undetected mode: overflow, reported as non-convergence.
    let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, 0.5]);
    let sys = SampledSystem::new(a, DMatrix::identity(2, 2), vec![c.clone()]).unwrap();
    let disc = sys.discretise(0.5, 2).unwrap();
    let err = steady_state(&disc, &[0, 0], &DoublingOptions::default()).unwrap_err();
    assert!(matches!(err, Error::Convergence(_)), "{err:?}");
    // Unstable mode without noise: the limit from Σ = 0 is not stabilising.
    let a = DMatrix::from_row_slice(1, 1, &[0.5]);
    let c = DMatrix::from_column_slice(1, 1, &[1.0]);
    let sys = SampledSystem::new(a, DMatrix::zeros(1, 1), vec![c]).unwrap();
    let disc = sys.discretise(0.5, 1).unwrap();
    let err = steady_state(&disc, &[0], &DoublingOptions::default()).unwrap_err();
    assert!(matches!(err, Error::Convergence(m) if m.contains("not stabilising")));
}

#[test]
fn input_validation() {
    let mut rng = Rng::new(8);
    let sys = network(&mut rng, 3, 2);
    assert!(matches!(
        sys.discretise(0.0, 3),
        Err(Error::InvalidInput(_))
    ));
    assert!(matches!(
        sys.discretise(f64::NAN, 3),
        Err(Error::InvalidInput(_))
    ));
    assert!(matches!(
        sys.discretise(1.0, 0),
        Err(Error::InvalidInput(_))
    ));
    let disc = sys.discretise(1.0, 3).unwrap();
    // Two slots of a budget of three: one idle unit; four are above the budget.
    assert!(disc.period_triplet(&[0, 1]).is_ok());
    assert!(disc.period_triplet(&[0, 1, 0, 1]).is_err());
    assert!(disc.period_triplet(&[0, 1, 2]).is_err());
    let bad = SampledSystem::new(
        DMatrix::identity(2, 2),
        DMatrix::identity(2, 2),
        vec![DMatrix::zeros(3, 1)],
    );
    assert!(matches!(bad, Err(Error::Shape(_))));
}

#[test]
fn neighbourhood_deadline_skips_candidates_but_keeps_exact_ones() {
    let mut rng = Rng::new(9);
    let sys = network(&mut rng, 3, 3);
    let slots = vec![0, 1, 2, 0, 1, 0, 2];
    let disc = sys.discretise(0.8, slots.len()).unwrap();
    let opts = DoublingOptions::default();
    let full = neighbourhood(&disc, &slots, Objective::Boundary, 1, &opts).unwrap();
    assert!(full.complete);
    let lim = CountLimits::common(1, 3);
    let far = std::time::Instant::now() + std::time::Duration::from_secs(3600);
    let same =
        neighbourhood_until(&disc, &slots, Objective::Boundary, &lim, &opts, Some(far)).unwrap();
    assert!(same.complete && same.reassign == full.reassign && same.swap == full.swap);
    // A deadline already passed: no candidate is evaluated, the current cost still is.
    let past = std::time::Instant::now();
    let none =
        neighbourhood_until(&disc, &slots, Objective::Boundary, &lim, &opts, Some(past)).unwrap();
    assert!(!none.complete);
    assert_eq!(none.current, full.current);
    assert!(none
        .reassign
        .iter()
        .chain(&none.swap)
        .all(|v| v.is_infinite()));
    assert!(none.rotate[1..].iter().all(|v| v.is_infinite()));
    // Skipped candidates are not counted as evaluated; a full neighbourhood counts every move
    // that is neither a no-op nor starving a sensor (counted here from the rules, not the costs).
    assert_eq!(none.evaluated, 0);
    let count = |i: usize| slots.iter().filter(|&&k| k == i).count();
    let reassigns = (0..slots.len())
        .map(|l| if count(slots[l]) > 1 { 2 } else { 0 })
        .sum::<usize>();
    let swaps = slots.windows(2).filter(|w| w[0] != w[1]).count();
    let rotations = slots.len() - 1;
    assert_eq!(full.evaluated, reassigns + swaps + rotations);
    assert_eq!(same.evaluated, full.evaluated);
}

#[test]
fn neighbourhood_matches_direct_evaluation() {
    let mut rng = Rng::new(9);
    let sys = network(&mut rng, 3, 3);
    let slots = vec![0, 1, 2, 0, 1, 0, 2];
    let disc = sys.discretise(0.8, slots.len()).unwrap();
    let opts = DoublingOptions::default();
    for obj in [Objective::Boundary, Objective::Average] {
        let nb = neighbourhood(&disc, &slots, obj, 1, &opts).unwrap();
        let direct = |s: &[usize]| schedule_cost(&disc, s, obj, &opts).unwrap();
        assert!((nb.current - direct(&slots)).abs() < 1e-12 * nb.current);
        for l in 0..slots.len() {
            for j in 0..3 {
                let v = nb.reassign[(l, j)];
                let mut s = slots.clone();
                s[l] = j;
                let starving = slots.iter().filter(|&&i| i == slots[l]).count() <= 1;
                if j == slots[l] || starving {
                    assert!(v.is_infinite());
                } else {
                    assert!((v - direct(&s)).abs() < 1e-11 * v, "reassign {l}->{j}");
                }
            }
        }
        for l in 0..slots.len() - 1 {
            let mut s = slots.clone();
            s.swap(l, l + 1);
            assert!((nb.swap[l] - direct(&s)).abs() < 1e-11 * nb.swap[l]);
        }
        for k in 1..slots.len() {
            let s: Vec<usize> = slots[k..].iter().chain(&slots[..k]).copied().collect();
            match obj {
                Objective::Boundary => {
                    assert!((nb.rotate[k] - direct(&s)).abs() < 1e-11 * nb.rotate[k])
                }
                Objective::Average => {
                    assert!(nb.rotate[k].is_infinite());
                    assert!((direct(&s) - nb.current).abs() < 1e-11 * nb.current);
                }
            }
        }
    }
}

#[test]
fn greedy_pass_respects_minimum_counts() {
    let mut rng = Rng::new(10);
    let mut sys = network(&mut rng, 3, 3);
    // Make sensor 2 nearly useless so the greedy rule would never pick it.
    let mut sensors = sys.sensors().to_vec();
    sensors[2] *= 1e-3;
    sys = SampledSystem::new(sys.a().clone(), sys.q().clone(), sensors).unwrap();
    let disc = sys.discretise(0.5, 9).unwrap();
    let (slots, s) = greedy_pass(&disc, &DMatrix::identity(3, 3), 2).unwrap();
    assert_eq!(slots.len(), 9);
    for i in 0..3 {
        assert!(slots.iter().filter(|&&j| j == i).count() >= 2, "{slots:?}");
    }
    let (_, posts) = propagate(&disc, &slots, &DMatrix::identity(3, 3)).unwrap();
    assert!(rel(&s, posts.last().unwrap()) < 1e-14);
    assert!(greedy_pass(&disc, &DMatrix::identity(3, 3), 4).is_err());
}

#[test]
fn doubling_alone_gives_the_steady_state_boundary() {
    // Doubling alone (no per-slot pass) gives the same boundary covariance as steady_state.
    let mut rng = Rng::new(11);
    let sys = network(&mut rng, 3, 2);
    let slots = vec![0, 1, 0];
    let disc = sys.discretise(0.25, 3).unwrap();
    let t = disc.period_triplet(&slots).unwrap();
    let d = doubling(&t, &DoublingOptions::default()).unwrap();
    let ss: SteadyState = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
    assert_eq!(d.sigma, ss.boundary);
}

#[test]
fn doubling_meets_its_stopping_contract() {
    // The documented contract of `doubling`: it returns at the first step whose relative change is
    // at most `tol`, and reports that change; the result is then a fixed point of the period map
    // to within the reported change (the sequence `T^m(0)` increases in the PSD order, so one
    // period's increment is below the last doubling step's increment). Quadratic convergence
    // makes a looser stopping rule (e.g. `rel ≤ √tol`) give the same Σ to rounding; only these
    // reported numbers reveal it.
    let mut rng = Rng::new(21);
    for &(n, nsens, r, tau) in &[
        (2usize, 1usize, 1usize, 0.5),
        (4, 2, 10, 0.05),
        (5, 3, 37, 1.3),
    ] {
        let sys = network(&mut rng, n, nsens);
        let slots: Vec<usize> = (0..r).map(|l| l % nsens).collect();
        let disc = sys.discretise(tau, r).unwrap();
        let t = disc.period_triplet(&slots).unwrap();
        for &tol in &[1e-4, 1e-8, 1e-12] {
            let opts = DoublingOptions { tol, max_steps: 64 };
            let d = doubling(&t, &opts).unwrap();
            assert!(
                d.rel_change <= tol,
                "n={n} tol={tol:e}: rel_change {:e}",
                d.rel_change
            );
            let residual = rel(&t.apply(&d.sigma).unwrap(), &d.sigma);
            assert!(
                residual <= d.rel_change.max(1e-14),
                "n={n} tol={tol:e}: residual {residual:e} > rel_change {:e}",
                d.rel_change
            );
            // It stopped at the first step that met tol: one step fewer does not.
            if d.steps > 1 {
                let fewer = DoublingOptions {
                    tol,
                    max_steps: d.steps - 1,
                };
                assert!(doubling(&t, &fewer).is_err(), "n={n} tol={tol:e}");
            }
        }
        let ss = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
        assert!(ss.rel_change <= 1e-12, "rel_change {:e}", ss.rel_change);
        assert!(ss.residual <= 1e-12, "residual {:e}", ss.residual);
    }
}

#[test]
fn doubling_reports_the_relative_change_of_its_last_step() {
    // rel_change recomputed independently: H after 2^(k−1) periods by composing the period
    // triplet with itself k − 1 times, against the returned H after 2^k periods.
    let mut rng = Rng::new(22);
    let sys = network(&mut rng, 4, 2);
    let slots = vec![0, 1, 1, 0, 1];
    let disc = sys.discretise(0.3, slots.len()).unwrap();
    let t = disc.period_triplet(&slots).unwrap();
    for &tol in &[1e-6, 1e-12] {
        let d = doubling(&t, &DoublingOptions { tol, max_steps: 64 }).unwrap();
        let mut prev = t.clone();
        for _ in 1..d.steps {
            prev = prev.then(&prev).unwrap();
        }
        let expect = (&d.sigma - &prev.h).norm() / d.sigma.norm();
        assert!(
            (d.rel_change - expect).abs() <= 1e-12 * expect.max(1e-300) + 1e-300,
            "tol={tol:e}: reported {:e}, recomputed {expect:e}",
            d.rel_change
        );
        let ns = d.sigma.norm();
        assert!(
            ns > 2.0,
            "‖Σ‖ = {ns}: too close to 1 to tell dh/nh from dh·nh"
        );
    }
    // The documented defaults.
    let o = DoublingOptions::default();
    assert_eq!((o.tol, o.max_steps), (1e-12, 64));
}

#[test]
fn spectral_radius_of_known_matrices() {
    assert_eq!(spectral_radius(&DMatrix::zeros(3, 3)).unwrap(), 0.0);
    // Rotation by 90° scaled by 0.5: eigenvalues ±0.5i.
    let m = DMatrix::from_row_slice(2, 2, &[0.0, -0.5, 0.5, 0.0]);
    assert!((spectral_radius(&m).unwrap() - 0.5).abs() < 1e-15);
    let m = DMatrix::from_row_slice(2, 2, &[0.9, 5.0, 0.0, -0.3]);
    assert!((spectral_radius(&m).unwrap() - 0.9).abs() < 1e-15);
}

#[test]
fn slot_average_is_the_mean_of_the_posterior_traces() {
    let mut rng = Rng::new(23);
    let sys = network(&mut rng, 3, 2);
    let slots = vec![0, 1, 1, 0];
    let disc = sys.discretise(0.4, slots.len()).unwrap();
    let ss = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
    let mean = ss.posteriors.iter().map(|p| p.trace()).sum::<f64>() / 4.0;
    assert!((ss.eta_average() - mean).abs() <= 1e-14 * mean);
    assert!((ss.eta_boundary() - ss.boundary.trace()).abs() <= 1e-14 * mean);
    // The posteriors differ from slot to slot, so the two conventions differ.
    assert!((ss.eta_average() - ss.eta_boundary()).abs() > 1e-6 * mean);
}

#[test]
fn residual_is_the_relative_one_period_change() {
    // With a loose tol the boundary is not yet a fixed point to rounding: the reported residual
    // must be ‖Φ_R(Σ) − Σ‖_F / ‖Σ‖_F, recomputed here by one pass of the slot maps.
    let mut rng = Rng::new(24);
    let sys = network(&mut rng, 3, 2);
    let slots = vec![0, 1, 0];
    let disc = sys.discretise(0.05, slots.len()).unwrap();
    let opts = DoublingOptions {
        tol: 1e-2,
        max_steps: 64,
    };
    let ss = steady_state(&disc, &slots, &opts).unwrap();
    let (_, posts) = propagate(&disc, &slots, &ss.boundary).unwrap();
    let expect = (posts.last().unwrap() - &ss.boundary).norm() / ss.boundary.norm();
    assert!(expect > 1e-12, "converged too far to test: {expect:e}");
    let ns = ss.boundary.norm();
    assert!(
        (ns * ns - 1.0).abs() > 1e-3,
        "‖Σ‖ = {ns}: too close to 1 to tell /‖Σ‖ from ·‖Σ‖"
    );
    assert!(
        (ss.residual - expect).abs() <= 1e-10 * expect,
        "{} vs {expect}",
        ss.residual
    );
}

#[test]
fn fixed_point_of_a_noiseless_stable_system_is_zero_at_once() {
    // Q = 0 and Σ₀ = 0: every period maps 0 to 0, so the iteration stops after one period with
    // a zero relative change (0/0 is defined as 0 there, not NaN).
    let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.3, 0.0, -0.5]);
    let c = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
    let sys = SampledSystem::new(a, DMatrix::zeros(2, 2), vec![c]).unwrap();
    let disc = sys.discretise(0.5, 2).unwrap();
    let fp = fixed_point(&disc, &[0, 0], &DMatrix::zeros(2, 2), 1e-12, 10).unwrap();
    assert_eq!((fp.periods, fp.rel_change), (1, 0.0));
    assert_eq!(fp.sigma, DMatrix::zeros(2, 2));
    // The steady state is Σ = 0 too, with a zero (not NaN) residual.
    let ss = steady_state(&disc, &[0, 0], &DoublingOptions::default()).unwrap();
    assert_eq!(ss.boundary, DMatrix::zeros(2, 2));
    assert_eq!((ss.residual, ss.rel_change), (0.0, 0.0));
}

#[test]
fn a_marginally_stable_limit_is_an_error() {
    // Undamped oscillator sampled every half period (ωτ = π): the velocity is never seen, its
    // variance grows until the doubling's change falls below rounding (ρ = 1 − O(eps)).
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 2.0, -2.0, 0.0]);
    let c = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
    let sys = SampledSystem::new(a, DMatrix::identity(2, 2), vec![c]).unwrap();
    let disc = sys.discretise(std::f64::consts::FRAC_PI_2, 1).unwrap();
    let err = steady_state(&disc, &[0], &DoublingOptions::default()).unwrap_err();
    assert!(
        matches!(&err, Error::Convergence(m) if m.contains("only marginally stable")),
        "{err:?}"
    );
}

#[test]
fn a_limit_with_spectral_radius_exactly_one_is_not_stabilising() {
    // A noiseless integrator: E = e^{0·τ} = 1 exactly, the limit from Σ = 0 is Σ = 0 and its
    // closed loop M = E has ρ = 1 exactly — not stabilising (the boundary case of ρ ≥ 1).
    let a = DMatrix::from_row_slice(1, 1, &[0.0]);
    let c = DMatrix::from_column_slice(1, 1, &[1.0]);
    let sys = SampledSystem::new(a, DMatrix::zeros(1, 1), vec![c]).unwrap();
    let disc = sys.discretise(0.5, 1).unwrap();
    let t = disc.period_triplet(&[0]).unwrap();
    let d = doubling(&t, &DoublingOptions::default()).unwrap();
    assert_eq!(d.sigma, DMatrix::zeros(1, 1));
    assert_eq!(super::doubling::monodromy(&t, &d.sigma).unwrap().1, 1.0);
    let err = steady_state(&disc, &[0], &DoublingOptions::default()).unwrap_err();
    assert!(
        matches!(&err, Error::Convergence(m) if m.contains("not stabilising")),
        "{err:?}"
    );
}
