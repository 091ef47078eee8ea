//! Unit tests of the schedule search's speed kernels against the plain routes: the doubling cut
//! short by an incumbent ([`super::pruned`]) against the full doubling (unit and unequal slot
//! lengths with an idle tail, a weight), the star product of order ≥ `TRANSPOSED_LU_MIN` against
//! the map applied twice, and the batched gains against a hand-written loop.
use super::gains::slot_gains;
use super::pruned::{steady_cost_below, Bounded, PRUNE_MARGIN};
use super::search::{steady_cost, Objective};
use super::star_tree::{candidate_costs, StarTree};
use super::tests::network;
use super::triplet::TRANSPOSED_LU_MIN;
use super::*;
use crate::linalg::testing::Rng;
use crate::sampled::doubling::DoublingOptions;

/// The systems of the tests: the paper's case, sample costs with an idle tail, a weight.
fn discretisations(rng: &mut Rng) -> Vec<(Discretisation, Vec<usize>)> {
    let slots = vec![0, 1, 2, 2, 0, 1, 0];
    let plain = network(rng, 4, 3);
    let costly = network(rng, 4, 3).with_costs(vec![1.0, 2.5, 0.5]).unwrap();
    let m = rng.psd(4, 4) + DMatrix::identity(4, 4) * 0.1;
    let weighted = network(rng, 4, 3).with_weight(Some(m)).unwrap();
    vec![
        (plain.discretise(0.5, 7).unwrap(), slots.clone()),
        (costly.discretise_budget(0.5, 12.25).unwrap(), slots.clone()),
        (weighted.discretise(0.4, 7).unwrap(), slots),
    ]
}

#[test]
fn pruned_doubling_is_the_doubling_or_a_proof_of_a_dearer_candidate() {
    let mut rng = Rng::new(41);
    let opts = DoublingOptions::default();
    for (disc, slots) in discretisations(&mut rng) {
        let t = disc.period_triplet(&slots).unwrap();
        let exact = steady_cost(&disc, &t, &slots, Objective::Boundary, &opts).unwrap();
        // No incumbent, or one above the cost: the same arithmetic, bit for bit.
        for inc in [None, Some(exact.cost), Some(exact.cost * 1.5)] {
            match steady_cost_below(&disc, &t, &slots, Objective::Boundary, &opts, inc).unwrap() {
                Bounded::Costed(sc) => {
                    assert_eq!(sc.cost, exact.cost);
                    assert_eq!(sc.sigma, exact.sigma);
                    assert_eq!(sc.monodromy, exact.monodromy);
                }
                Bounded::Above(_) => panic!("pruned although the incumbent is not below"),
            }
        }
        // An incumbent below the cost: cut short with a true lower bound above it (or costed).
        for frac in [0.5, 0.9, 0.999] {
            let inc = exact.cost * frac;
            match steady_cost_below(&disc, &t, &slots, Objective::Boundary, &opts, Some(inc))
                .unwrap()
            {
                Bounded::Above(lower) => {
                    assert!(lower > inc * (1.0 + PRUNE_MARGIN));
                    assert!(lower <= exact.cost * (1.0 + 1e-14));
                }
                Bounded::Costed(sc) => assert_eq!(sc.cost, exact.cost),
            }
        }
        // A far lower incumbent is always cut short; the average objective never is.
        let far = steady_cost_below(&disc, &t, &slots, Objective::Boundary, &opts, Some(1e-9));
        assert!(matches!(far.unwrap(), Bounded::Above(_)));
        let avg = steady_cost(&disc, &t, &slots, Objective::Average, &opts).unwrap();
        match steady_cost_below(&disc, &t, &slots, Objective::Average, &opts, Some(1e-9)).unwrap() {
            Bounded::Costed(sc) => assert_eq!(sc.cost, avg.cost),
            Bounded::Above(_) => panic!("the average objective is not bounded"),
        }
    }
}

#[test]
fn candidate_costs_with_an_incumbent_keep_every_improving_candidate_exact() {
    let mut rng = Rng::new(42);
    let opts = DoublingOptions::default();
    for (disc, base) in discretisations(&mut rng) {
        let tree = StarTree::new(&disc, &base).unwrap();
        let mut cands = vec![];
        for l in 0..base.len() {
            for j in 0..3 {
                let mut c = base.clone();
                c[l] = j;
                if disc.check_schedule(&c).is_ok() {
                    cands.push(c);
                }
            }
        }
        let obj = Objective::Boundary;
        let all = candidate_costs(&disc, &tree, &cands, obj, &opts, None, None).unwrap();
        let current = all.costs[0]; // slot 0 given to sensor 0: the base schedule itself
        assert_eq!(cands[0], base);
        let cut = candidate_costs(&disc, &tree, &cands, obj, &opts, None, Some(current)).unwrap();
        for (a, b) in all.costs.iter().zip(&cut.costs) {
            if *a <= current {
                assert_eq!(a, b); // every candidate that could be taken: its exact cost
            } else {
                assert!(*b == *a || *b == f64::INFINITY);
            }
        }
        let (ka, _, sa) = all.best.unwrap();
        let (kb, _, sb) = cut.best.unwrap();
        assert_eq!((ka, sa.cost), (kb, sb.cost));
    }
}

#[test]
fn star_product_of_large_order_is_the_composed_map() {
    let mut rng = Rng::new(43);
    let n = TRANSPOSED_LU_MIN + 4;
    let sys = network(&mut rng, n, 3);
    let disc = sys.discretise(0.3, 4).unwrap();
    let t1 = disc.period_triplet(&[0, 1]).unwrap();
    let t2 = disc.period_triplet(&[2, 0]).unwrap();
    let both = t1.then(&t2).unwrap();
    let x = rng.psd(n, n);
    let want = t2.apply(&t1.apply(&x).unwrap()).unwrap();
    let got = both.apply(&x).unwrap();
    assert!((&got - &want).norm() <= 1e-12 * want.norm());
    // The doubling's fixed point at this order is a fixed point of the period map.
    let t = disc.period_triplet(&[0, 1, 2, 1]).unwrap();
    let ss = doubling::steady_state(&disc, &[0, 1, 2, 1], &DoublingOptions::default()).unwrap();
    let image = t.apply(&ss.boundary).unwrap();
    assert!((&image - &ss.boundary).norm() <= 1e-12 * ss.boundary.norm());
}

#[test]
fn batched_gains_are_the_per_sensor_traces() {
    let mut rng = Rng::new(44);
    let n = 6;
    let cbar: Vec<DMatrix<f64>> = (0..4).map(|k| rng.matrix(n, 1 + k % 2)).collect();
    let p1 = rng.psd(n, n) + DMatrix::identity(n, n);
    let p2 = rng.psd(n, n) + DMatrix::identity(n, n);
    let mu = rng.psd(n, n);
    let priors = vec![&p1, &p2, &p1, &p2];
    let got = slot_gains(&priors, &cbar, &mu).unwrap();
    for (k, c) in cbar.iter().enumerate() {
        let p = priors[k];
        let x = p * c;
        let s = DMatrix::identity(c.ncols(), c.ncols()) + c.transpose() * &x;
        let want = (s.try_inverse().unwrap() * x.transpose() * &mu * &x).trace();
        assert!((got[k] - want).abs() <= 1e-12 * want.abs().max(1.0));
    }
}
