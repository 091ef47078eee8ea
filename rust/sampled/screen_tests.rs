//! Unit tests of the screened search's kernels: the star-product tree against the plain
//! composition, and the first-order screen against exact costs (finite differences, rotations).
use super::search::{schedule_cost, Objective};
use super::sensitivity::{screen, stein};
use super::star_tree::{candidate_costs, StarTree};
use super::*;
use crate::linalg::testing::Rng;
use crate::sampled::doubling::DoublingOptions;

/// `n` states, the given sensors (one output each), a stable-ish drift, `Q ≻ 0`.
fn system(rng: &mut Rng, n: usize, sensors: Vec<DMatrix<f64>>) -> SampledSystem {
    let mut a = rng.matrix(n, n) * (0.6 / (n as f64).sqrt());
    for i in 0..n {
        a[(i, i)] -= 0.3;
    }
    let q = rng.psd(n, n) * (1.0 / n as f64) + DMatrix::identity(n, n) * 0.2;
    SampledSystem::new(a, q, sensors).unwrap()
}

fn slots_of(rng: &mut Rng, r: usize, nsens: usize) -> Vec<usize> {
    (0..r)
        .map(|l| {
            if l < nsens {
                l
            } else {
                (rng.normal().abs() * 7.0) as usize % nsens
            }
        })
        .collect()
}

#[test]
fn tree_composes_exactly_as_the_plain_composition() {
    let mut rng = Rng::new(11);
    let sensors = (0..3).map(|_| rng.matrix(4, 1)).collect();
    let sys = system(&mut rng, 4, sensors);
    for &r in &[1usize, 2, 3, 7, 16, 29] {
        let disc = sys.discretise(0.4, r).unwrap();
        let base = slots_of(&mut rng, r, 3);
        let mut tree = StarTree::new(&disc, &base).unwrap();
        assert_eq!(
            tree.root(&disc).unwrap(),
            disc.period_triplet(&base).unwrap()
        );
        for trial in 0..5 {
            let mut cand = base.clone();
            for _ in 0..=trial {
                let l = (rng.normal().abs() * 13.0) as usize % r;
                cand[l] = (cand[l] + 1) % 3;
            }
            // Bit for bit: the same association of the same star products.
            let plain = disc.period_triplet(&cand).unwrap();
            assert_eq!(*tree.compose(&disc, &cand).unwrap(), plain);
            // Adopting the recomposed segments is the same tree as updating to the candidate.
            let (t, delta) = tree.compose_delta(&disc, &cand).unwrap();
            assert_eq!(t, plain);
            let mut adopted = tree.clone();
            adopted.adopt(&cand, delta);
            tree.update(&disc, &cand).unwrap();
            assert_eq!(tree.root(&disc).unwrap(), plain);
            assert_eq!(adopted.root(&disc).unwrap(), plain);
            assert_eq!(tree.slots(), &cand[..]);
        }
    }
}

#[test]
fn tree_recomposes_many_changed_slots_bitwise() {
    // A batch of moves all over the period (as an accepted batch of swaps): every kept segment
    // recomposed, with the same products in the same association as the plain composition.
    let mut rng = Rng::new(13);
    let sensors = (0..3).map(|_| rng.matrix(4, 1)).collect();
    let sys = system(&mut rng, 4, sensors);
    let r = 70;
    let disc = sys.discretise(0.4, r).unwrap();
    let base = slots_of(&mut rng, r, 3);
    let tree = StarTree::new(&disc, &base).unwrap();
    for stride in [2usize, 3, 5] {
        let mut cand = base.clone();
        for l in (0..r).step_by(stride) {
            cand[l] = (cand[l] + 1) % 3;
        }
        let plain = disc.period_triplet(&cand).unwrap();
        assert_eq!(*tree.compose(&disc, &cand).unwrap(), plain);
        let (t, delta) = tree.compose_delta(&disc, &cand).unwrap();
        assert_eq!(t, plain);
        let mut adopted = tree.clone();
        adopted.adopt(&cand, delta);
        assert_eq!(adopted.root(&disc).unwrap(), plain);
        let mut updated = tree.clone();
        updated.update(&disc, &cand).unwrap();
        assert_eq!(adopted.root(&disc).unwrap(), updated.root(&disc).unwrap());
    }
}

#[test]
fn candidate_costs_equal_schedule_costs() {
    let mut rng = Rng::new(12);
    let sensors = (0..3).map(|_| rng.matrix(5, 1)).collect();
    let sys = system(&mut rng, 5, sensors);
    let disc = sys.discretise(0.5, 12).unwrap();
    let opts = DoublingOptions::default();
    let base = slots_of(&mut rng, 12, 3);
    let tree = StarTree::new(&disc, &base).unwrap();
    let mut cands = vec![base.clone()];
    for l in 0..12 {
        let mut c = base.clone();
        c[l] = (c[l] + 2) % 3;
        cands.push(c);
    }
    let mut rot = base.clone();
    rot.rotate_left(5);
    cands.push(rot);
    for obj in [Objective::Boundary, Objective::Average] {
        let cc = candidate_costs(&disc, &tree, &cands, obj, &opts, None, None).unwrap();
        assert!(cc.complete && cc.evaluated == cands.len());
        for (c, v) in cands.iter().zip(&cc.costs) {
            assert_eq!(*v, schedule_cost(&disc, c, obj, &opts).unwrap());
        }
        // The cheapest candidate is kept (ties to the lowest index), with its steady state.
        let (k, _, steady) = cc.best.unwrap();
        let min = cc.costs.iter().cloned().fold(f64::INFINITY, f64::min);
        assert_eq!(k, cc.costs.iter().position(|&v| v == min).unwrap());
        assert_eq!(steady.cost, min);
    }
}

#[test]
fn stein_solves_the_stein_equation() {
    let mut rng = Rng::new(13);
    let m = rng.matrix(6, 6) * 0.25;
    let c = rng.psd(6, 6) + DMatrix::identity(6, 6);
    let (x, steps) = stein(&m, &c, 64).unwrap();
    let resid = &x - m.transpose() * &x * &m - &c;
    assert!(resid.norm() <= 1e-13 * x.norm(), "{}", resid.norm());
    assert!(steps < 64);
    assert!(stein(
        &(DMatrix::identity(3, 3) * 1.5),
        &DMatrix::identity(3, 3),
        64
    )
    .is_err());
}

/// A third sensor that is the first one scaled by `1 + eps`: reassigning one of sensor 0's slots
/// to it is a perturbation of size `eps`, whose exact effect the screen predicts to `O(eps²)`.
#[test]
fn screen_is_the_first_order_change_of_the_cost() {
    let mut rng = Rng::new(14);
    let c0 = rng.matrix(4, 1);
    let eps = 1e-4;
    let sensors = vec![c0.clone(), rng.matrix(4, 1), &c0 * (1.0 + eps)];
    let sys = system(&mut rng, 4, sensors);
    let r = 9;
    let disc = sys.discretise(0.6, r).unwrap();
    let opts = DoublingOptions::default();
    let slots = vec![0, 1, 0, 1, 1, 0, 0, 1, 2];
    let period = disc.period_triplet(&slots).unwrap();
    for obj in [Objective::Boundary, Objective::Average] {
        let sc = screen(&disc, &slots, &period, obj, 1, &opts).unwrap();
        let base = schedule_cost(&disc, &slots, obj, &opts).unwrap();
        assert_eq!(sc.current, base);
        for l in (0..r).filter(|&l| slots[l] == 0) {
            let mut cand = slots.clone();
            cand[l] = 2;
            let exact = schedule_cost(&disc, &cand, obj, &opts).unwrap() - base;
            let pred = sc.reassign[(l, 2)];
            assert!(exact < 0.0, "more information must lower the cost");
            assert!(
                (pred - exact).abs() <= 1e-3 * exact.abs(),
                "{obj:?} slot {l}: predicted {pred:e}, exact {exact:e}"
            );
        }
        // A swap of two different sensors is no small change here (two slots of nine at a long
        // period): the screen is only an estimate; it has the sign of the exact change.
        for l in 0..r - 1 {
            if slots[l] != slots[l + 1] {
                let mut cand = slots.clone();
                cand.swap(l, l + 1);
                let exact = schedule_cost(&disc, &cand, obj, &opts).unwrap() - base;
                if exact.abs() > 1e-3 * base {
                    assert_eq!(
                        sc.swap[l] < 0.0,
                        exact < 0.0,
                        "swap {l}: {} vs {exact}",
                        sc.swap[l]
                    );
                }
            }
        }
    }
    // Rotations: the same orbit, so the exact boundary cost.
    let sc = screen(&disc, &slots, &period, Objective::Boundary, 1, &opts).unwrap();
    for k in 0..r {
        let mut rot = slots.clone();
        rot.rotate_left(k);
        let exact = schedule_cost(&disc, &rot, Objective::Boundary, &opts).unwrap();
        assert!(
            (sc.rotate[k] - exact).abs() <= 1e-12 * exact,
            "rotation {k}"
        );
    }
    // Moves that would starve a sensor below min_count are not screened.
    // Counts (4, 4, 1): with min_count 3 only sensor 2's slot may not move.
    let strict = screen(&disc, &slots, &period, Objective::Boundary, 3, &opts).unwrap();
    for l in 0..r {
        for j in 0..3 {
            let movable = slots[l] != 2 && j != slots[l];
            assert_eq!(
                strict.reassign[(l, j)].is_finite(),
                movable,
                "slot {l} to {j}"
            );
        }
    }
}

#[test]
fn tree_recomposes_bitwise_with_parallel_halves() {
    // 32 states and 70 slots: segments of 16 slots or more compose their halves on two threads
    // (star_tree's PARALLEL_SLOTS, PARALLEL_ORDER), with the same association: the same bits.
    let mut rng = Rng::new(17);
    let sensors = (0..3).map(|_| rng.matrix(32, 1)).collect();
    let sys = system(&mut rng, 32, sensors);
    let r = 70;
    let disc = sys.discretise(0.4, r).unwrap();
    let base = slots_of(&mut rng, r, 3);
    let tree = StarTree::new(&disc, &base).unwrap();
    assert_eq!(
        tree.root(&disc).unwrap(),
        disc.period_triplet(&base).unwrap()
    );
    for stride in [2usize, 7] {
        let mut cand = base.clone();
        for l in (0..r).step_by(stride) {
            cand[l] = (cand[l] + 1) % 3;
        }
        let plain = disc.period_triplet(&cand).unwrap();
        let (t, delta) = tree.compose_delta(&disc, &cand).unwrap();
        assert_eq!(t, plain);
        let mut adopted = tree.clone();
        adopted.adopt(&cand, delta);
        let mut updated = tree.clone();
        updated.update(&disc, &cand).unwrap();
        assert_eq!(adopted.root(&disc).unwrap(), plain);
        assert_eq!(updated.root(&disc).unwrap(), plain);
    }
}

#[test]
fn a_past_deadline_stops_the_tree_the_screen_and_the_costings() {
    use super::sensitivity::{screen_at_until, screen_with_until};
    use super::star_tree::check_deadline;
    use crate::sampled::doubling::{doubling, monodromy};
    use crate::sampled::search::CountLimits;
    use std::time::{Duration, Instant};
    let mut rng = Rng::new(18);
    let sensors = (0..3).map(|_| rng.matrix(5, 1)).collect();
    let sys = system(&mut rng, 5, sensors);
    let r = 12;
    let disc = sys.discretise(0.5, r).unwrap();
    let opts = DoublingOptions::default();
    let limits = CountLimits::common(1, 3);
    let base = slots_of(&mut rng, r, 3);
    let past = Some(Instant::now());
    let later = Some(Instant::now() + Duration::from_secs(3600));
    assert!(check_deadline(past).is_err() && check_deadline(None).is_ok());
    assert!(StarTree::new_until(&disc, &base, past).unwrap().is_none());
    let tree = StarTree::new_until(&disc, &base, later).unwrap().unwrap();
    let mut cand = base.clone();
    cand[3] = (cand[3] + 1) % 3;
    assert!(matches!(
        tree.compose_delta_until(&disc, &cand, past),
        Err(Error::Interrupted(_))
    ));
    let mut moved = tree.clone();
    assert!(moved.update_until(&disc, &cand, past).is_err());
    let period = disc.period_triplet(&base).unwrap();
    let obj = Objective::Boundary;
    assert!(
        screen_with_until(&disc, &base, &period, obj, &limits, &opts, past)
            .unwrap()
            .is_none()
    );
    let d = doubling(&period, &opts).unwrap();
    let (m, rho) = monodromy(&period, &d.sigma).unwrap();
    assert!(
        screen_at_until(&disc, &base, &d.sigma, &m, rho, obj, &limits, past)
            .unwrap()
            .is_none()
    );
    // Before the deadline: the screen of no deadline.
    let full = screen(&disc, &base, &period, obj, 1, &opts).unwrap();
    let timed = screen_with_until(&disc, &base, &period, obj, &limits, &opts, later)
        .unwrap()
        .unwrap();
    assert_eq!(
        (timed.current, &timed.reassign, &timed.swap),
        (full.current, &full.reassign, &full.swap)
    );
    let cands = vec![cand.clone(), base.clone()];
    let cc = candidate_costs(&disc, &tree, &cands, obj, &opts, past, None).unwrap();
    assert!(!cc.complete && cc.evaluated == 0 && cc.costs.iter().all(|c| c.is_infinite()));
    let cc = candidate_costs(&disc, &tree, &cands, obj, &opts, later, None).unwrap();
    assert!(cc.complete && cc.evaluated == 2);
    assert_eq!(
        cc.costs[1],
        schedule_cost(&disc, &base, obj, &opts).unwrap()
    );
}
