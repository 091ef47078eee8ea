//! Unit tests of slots of unequal length (sample costs, a budget, the idle tail) and of the
//! weighted cost `tr(M Σ̄)`: against a hand-written iteration of the slot maps, the paper's case
//! bit for bit, and the budget and count limits of the search kernels.
use super::doubling::{fixed_point, steady_state, DoublingOptions};
use super::search::{
    greedy_pass, greedy_pass_limits, neighbourhood, neighbourhood_until, schedule_cost,
    CountLimits, Objective,
};
use super::sensitivity::{screen, screen_with};
use super::tests::network;
use super::*;
use crate::linalg::testing::Rng;
use crate::linalg::van_loan::van_loan;

/// The period map by hand: per slot `E_i S E_iᵀ + H_i` over `b_i τ₀` then the information-form
/// update, then the idle prediction; iterated from `I` until it settles.
fn by_hand(sys: &SampledSystem, tau: f64, budget: f64, slots: &[usize]) -> DMatrix<f64> {
    let n = sys.order();
    let t0 = tau / budget;
    let b = sys.costs();
    let idle = budget - slots.iter().map(|&i| b[i]).sum::<f64>();
    let mut s = DMatrix::<f64>::identity(n, n);
    for _ in 0..20_000 {
        let prev = s.clone();
        for &i in slots {
            let v = van_loan(sys.a(), sys.q(), b[i] * t0).unwrap();
            let p = &v.e * &s * v.e.transpose() + &v.h;
            let c = &sys.sensors()[i] * tau.sqrt();
            let info = p.try_inverse().unwrap() + &c * c.transpose();
            s = info.try_inverse().unwrap();
        }
        if idle > 0.0 {
            let v = van_loan(sys.a(), sys.q(), idle * t0).unwrap();
            s = &v.e * &s * v.e.transpose() + &v.h;
        }
        if (&s - &prev).norm() <= 1e-15 * s.norm() {
            break;
        }
    }
    s
}

#[test]
fn unequal_slots_and_idle_tail_match_the_slot_maps() {
    let mut rng = Rng::new(21);
    let sys = network(&mut rng, 3, 3)
        .with_costs(vec![1.0, 2.5, 0.5])
        .unwrap();
    let slots = [0, 1, 2, 2, 0, 1];
    for budget in [9.0, 12.25] {
        let disc = sys.discretise_budget(0.5, budget).unwrap();
        let ss = steady_state(&disc, &slots, &DoublingOptions::default()).unwrap();
        let want = by_hand(&sys, 0.5, budget, &slots);
        assert!((&ss.boundary - &want).norm() <= 1e-10 * want.norm());
        let fp = fixed_point(&disc, &slots, &DMatrix::zeros(3, 3), 1e-14, 100_000).unwrap();
        assert!((&fp.sigma - &ss.boundary).norm() <= 1e-11 * want.norm());
        assert!(ss.residual < 1e-12);
    }
    // Above the budget: refused.
    let disc = sys.discretise_budget(0.5, 7.5).unwrap();
    assert!(matches!(
        disc.period_triplet(&slots),
        Err(Error::InvalidInput(_))
    ));
}

#[test]
fn unit_costs_are_the_paper_case_bit_for_bit() {
    let mut rng = Rng::new(22);
    let sys = network(&mut rng, 3, 3);
    let unit = sys.clone().with_costs(vec![1.0; 3]).unwrap();
    let slots = [0, 1, 2, 0, 1, 0, 2];
    let opts = DoublingOptions::default();
    let a = sys.discretise(0.4, slots.len()).unwrap();
    let b = unit.discretise_budget(0.4, slots.len() as f64).unwrap();
    assert_eq!(
        a.period_triplet(&slots).unwrap(),
        b.period_triplet(&slots).unwrap()
    );
    for obj in [Objective::Boundary, Objective::Average] {
        let ca = schedule_cost(&a, &slots, obj, &opts).unwrap();
        assert_eq!(
            ca.to_bits(),
            schedule_cost(&b, &slots, obj, &opts).unwrap().to_bits()
        );
        let na = neighbourhood(&a, &slots, obj, 1, &opts).unwrap();
        let nb = neighbourhood(&b, &slots, obj, 1, &opts).unwrap();
        assert_eq!(na.reassign, nb.reassign);
        let p = a.period_triplet(&slots).unwrap();
        let sa = screen(&a, &slots, &p, obj, 1, &opts).unwrap();
        let sb = screen(&b, &slots, &p, obj, 1, &opts).unwrap();
        assert_eq!(sa.reassign, sb.reassign);
        assert_eq!(sa.swap, sb.swap);
    }
    let s0 = DMatrix::identity(3, 3);
    assert_eq!(
        greedy_pass(&a, &s0, 2).unwrap(),
        greedy_pass(&b, &s0, 2).unwrap()
    );
}

#[test]
fn weighted_cost_is_the_trace_against_m() {
    let mut rng = Rng::new(23);
    let m = rng.psd(3, 3) + DMatrix::identity(3, 3) * 0.1;
    let sys = network(&mut rng, 3, 2);
    let weighted = sys.clone().with_weight(Some(m.clone())).unwrap();
    let slots = [0, 1, 1, 0, 1];
    let opts = DoublingOptions::default();
    let d = sys.discretise(0.3, 5).unwrap();
    let dw = weighted.discretise(0.3, 5).unwrap();
    let ss = steady_state(&d, &slots, &opts).unwrap();
    let b = schedule_cost(&dw, &slots, Objective::Boundary, &opts).unwrap();
    assert!((b - (&m * &ss.boundary).trace()).abs() <= 1e-13 * b);
    let avg = ss.posteriors.iter().map(|p| (&m * p).trace()).sum::<f64>() / 5.0;
    let a = schedule_cost(&dw, &slots, Objective::Average, &opts).unwrap();
    assert!((a - avg).abs() <= 1e-13 * a);
    assert!(sys.clone().with_weight(Some(DMatrix::zeros(2, 2))).is_err());
}

#[test]
fn kernels_respect_the_budget_and_the_caps() {
    let mut rng = Rng::new(24);
    let sys = network(&mut rng, 3, 3)
        .with_costs(vec![1.0, 2.0, 0.5])
        .unwrap();
    let disc = sys.discretise_budget(0.4, 8.0).unwrap();
    let limits = CountLimits {
        min: vec![1, 1, 1],
        max: vec![usize::MAX, 2, 4],
    };
    let (slots, _) = greedy_pass_limits(&disc, &DMatrix::identity(3, 3), &limits).unwrap();
    let mut counts = [0usize; 3];
    for &i in &slots {
        counts[i] += 1;
    }
    assert!(disc.used(&slots) <= 8.0 && counts[1] <= 2 && counts[2] <= 4);
    assert!(counts.iter().all(|&c| c >= 1));
    // Nothing more fits: every sensor is capped or too expensive for the budget left.
    let left = 8.0 - disc.used(&slots);
    assert!((0..3).all(|i| counts[i] >= limits.max[i] || disc.costs[i] > left));
    let slots = vec![0, 1, 2, 0, 2];
    let opts = DoublingOptions::default();
    let nb = neighbourhood_until(&disc, &slots, Objective::Boundary, &limits, &opts, None).unwrap();
    let p = disc.period_triplet(&slots).unwrap();
    let sc = screen_with(&disc, &slots, &p, Objective::Boundary, &limits, &opts).unwrap();
    let used = disc.used(&slots);
    for l in 0..slots.len() {
        for j in 0..3 {
            let i = slots[l];
            let mut c = [0usize; 3];
            slots.iter().for_each(|&k| c[k] += 1);
            let ok = j != i
                && c[i] > limits.min[i]
                && c[j] < limits.max[j]
                && used - disc.costs[i] + disc.costs[j] <= 8.0;
            assert_eq!(nb.reassign[(l, j)].is_finite(), ok, "slot {l} to {j}");
            assert_eq!(
                sc.reassign[(l, j)].is_finite(),
                ok,
                "screen: slot {l} to {j}"
            );
        }
    }
    // With idle time a rotation moves the tail: costed exactly, not screened.
    assert!(nb.rotate[1..].iter().all(|v| v.is_finite()));
    assert!(sc.rotate[1..].iter().all(|v| v.is_infinite()));
}
