//! The exact schedule kernel ([`super::exact_dfs`]) against brute force on tiny cases.
use super::doubling::DoublingOptions;
use super::exact_dfs::{exact_schedule, ExactProblem};
use super::search::{schedule_cost, Objective};
use super::tests::network;
use super::Discretisation;
use crate::linalg::testing::Rng;
use nalgebra::DMatrix;

/// The relaxed factor of every non-empty set: its sensors side by side (`c̄c̄ᵀ = Σ c̄_ic̄_iᵀ`,
/// which is `⪰` each `c̄_ic̄_iᵀ`).
fn stacked(disc: &Discretisation) -> Vec<DMatrix<f64>> {
    let n_s = disc.n_sensors();
    (1..(1u32 << n_s))
        .map(|mask| {
            let cols: Vec<_> = (0..n_s)
                .filter(|i| mask & (1 << i) != 0)
                .map(|i| disc.cbar[i].clone())
                .collect();
            let k: usize = cols.iter().map(|c| c.ncols()).sum();
            let mut out = DMatrix::zeros(disc.order(), k);
            let mut at = 0;
            for c in cols {
                out.columns_mut(at, c.ncols()).copy_from(&c);
                at += c.ncols();
            }
            out
        })
        .collect()
}

/// The least cost over every schedule of `len` slots with each count in `lo..=hi`.
fn brute(disc: &Discretisation, obj: Objective, len: usize, lo: &[usize], hi: &[usize]) -> f64 {
    let n_s = disc.n_sensors();
    let mut best = f64::INFINITY;
    for code in 0..n_s.pow(len as u32) {
        let slots: Vec<usize> = (0..len).map(|l| code / n_s.pow(l as u32) % n_s).collect();
        let ok = (0..n_s).all(|i| {
            let k = slots.iter().filter(|&&s| s == i).count();
            lo[i] <= k && k <= hi[i]
        });
        if ok {
            let c = schedule_cost(disc, &slots, obj, &DoublingOptions::default()).unwrap();
            best = best.min(c);
        }
    }
    best
}

fn problem<'a>(
    disc: &'a Discretisation,
    objective: Objective,
    len: usize,
    limits: (Vec<usize>, Vec<usize>),
    node_limit: usize,
) -> ExactProblem<'a> {
    ExactProblem {
        disc,
        objective,
        len,
        lo: limits.0,
        hi: limits.1,
        relaxed: stacked(disc),
        symmetric: objective == Objective::Average,
        incumbent: f64::INFINITY,
        node_limit,
        deadline: None,
    }
}

#[test]
fn exact_schedule_equals_brute_force_on_tiny_cases() {
    let mut rng = Rng::new(7);
    let sys = network(&mut rng, 3, 3);
    let len = 6;
    let disc = sys.discretise(0.5, len).unwrap();
    for obj in [Objective::Boundary, Objective::Average] {
        for limits in [
            (vec![1, 1, 1], vec![6, 6, 6]),
            (vec![2, 0, 1], vec![3, 2, 6]),
        ] {
            let want = brute(&disc, obj, len, &limits.0, &limits.1);
            let got = exact_schedule(&problem(&disc, obj, len, limits.clone(), 1 << 30)).unwrap();
            assert!(got.complete, "{obj:?}");
            let slots = got.slots.expect("beats an infinite incumbent");
            let again = schedule_cost(&disc, &slots, obj, &DoublingOptions::default()).unwrap();
            assert_eq!(again, got.cost);
            assert!(
                (got.cost - want).abs() <= 1e-12 * want,
                "{obj:?} {} {want}",
                got.cost
            );
            assert!(got.lower_bound <= want * (1.0 + 1e-12));
            // A node limit keeps a valid bound.
            for cut in [1, 3, 10] {
                let part = exact_schedule(&problem(&disc, obj, len, limits.clone(), cut)).unwrap();
                assert!(
                    part.lower_bound <= want * (1.0 + 1e-12),
                    "{obj:?} cut {cut}"
                );
                assert!(part.cost >= want * (1.0 - 1e-12));
            }
        }
    }
}
