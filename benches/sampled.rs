//! Criterion benchmarks of the sampled system on the network of `benches/compare_sampled.py`
//! (four weakly coupled scalar subsystems, n = 4, N = 4, period τ = 0.02, round-robin schedule):
//! composing the period triplet, the steady state by doubling (with the per-slot pass), the plain
//! fixed-point iteration it replaces, one exhaustive local-search neighbourhood, and the kernels of
//! the screened search that replaces it: the first-order screen of the whole neighbourhood, the
//! star-product tree and the exact cost of a one-slot change on it.
//!
//! Run with `cargo bench --bench sampled` (or `-- doubling` for one group).

use capalloc::linalg::testing::Rng;
use capalloc::sampled::doubling::{fixed_point, steady_state, DoublingOptions};
use capalloc::sampled::search::{neighbourhood, Objective};
use capalloc::sampled::sensitivity::screen;
use capalloc::sampled::star_tree::{candidate_costs, StarTree};
use capalloc::sampled::SampledSystem;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::DMatrix;
use std::hint::black_box;
use std::time::Duration;

const TAU: f64 = 0.02;

fn system() -> SampledSystem {
    let mut rng = Rng::new(3);
    let diag = [-0.25, -0.3, -0.35, -0.4];
    let a = DMatrix::from_fn(
        4,
        4,
        |i, j| {
            if i == j {
                diag[i]
            } else {
                0.05 * rng.normal()
            }
        },
    );
    let sensors = (0..4)
        .map(|i| DMatrix::from_fn(4, 1, |k, _| if k == i { 0.05 } else { 0.0 }))
        .collect();
    SampledSystem::new(a, DMatrix::identity(4, 4), sensors).expect("valid network")
}

fn round_robin(r: usize) -> Vec<usize> {
    (0..r).map(|l| l % 4).collect()
}

fn bench_period_triplet(c: &mut Criterion) {
    let sys = system();
    let mut group = c.benchmark_group("period_triplet");
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(2));
    for &r in &[10usize, 100, 1000] {
        let disc = sys.discretise(TAU, r).unwrap();
        let slots = round_robin(r);
        group.bench_with_input(BenchmarkId::from_parameter(r), &slots, |b, s| {
            b.iter(|| disc.period_triplet(black_box(s)).unwrap())
        });
    }
    group.finish();
}

fn bench_doubling(c: &mut Criterion) {
    let sys = system();
    let opts = DoublingOptions::default();
    let mut group = c.benchmark_group("doubling");
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(2));
    for &r in &[10usize, 100, 1000] {
        let slots = round_robin(r);
        group.bench_with_input(BenchmarkId::from_parameter(r), &slots, |b, s| {
            b.iter(|| {
                let disc = sys.discretise(TAU, r).unwrap();
                steady_state(&disc, black_box(s), &opts).unwrap()
            })
        });
    }
    group.finish();
}

fn bench_fixed_point(c: &mut Criterion) {
    let sys = system();
    let mut group = c.benchmark_group("fixed_point_iteration");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(4));
    for &r in &[10usize, 100] {
        let disc = sys.discretise(TAU, r).unwrap();
        let slots = round_robin(r);
        let zero = DMatrix::zeros(4, 4);
        group.bench_with_input(BenchmarkId::from_parameter(r), &slots, |b, s| {
            b.iter(|| fixed_point(&disc, black_box(s), &zero, 1e-15, 1_000_000).unwrap())
        });
    }
    group.finish();
}

fn bench_neighbourhood(c: &mut Criterion) {
    let sys = system();
    let opts = DoublingOptions::default();
    let mut group = c.benchmark_group("neighbourhood");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(3));
    let r = 100;
    let disc = sys.discretise(TAU, r).unwrap();
    let slots = round_robin(r);
    group.bench_function("boundary/100", |b| {
        b.iter(|| neighbourhood(&disc, black_box(&slots), Objective::Boundary, 1, &opts).unwrap())
    });
    group.finish();
}

fn bench_screened(c: &mut Criterion) {
    let sys = system();
    let opts = DoublingOptions::default();
    let mut group = c.benchmark_group("screened");
    group.sample_size(10);
    group.warm_up_time(Duration::from_millis(300));
    group.measurement_time(Duration::from_secs(3));
    let r = 100;
    let disc = sys.discretise(TAU, r).unwrap();
    let slots = round_robin(r);
    let period = disc.period_triplet(&slots).unwrap();
    group.bench_function("screen/boundary/100", |b| {
        b.iter(|| {
            screen(
                &disc,
                black_box(&slots),
                &period,
                Objective::Boundary,
                1,
                &opts,
            )
            .unwrap()
        })
    });
    group.bench_function("screen/average/100", |b| {
        b.iter(|| {
            screen(
                &disc,
                black_box(&slots),
                &period,
                Objective::Average,
                1,
                &opts,
            )
            .unwrap()
        })
    });
    group.bench_function("star_tree/build/100", |b| {
        b.iter(|| StarTree::new(&disc, black_box(&slots)).unwrap())
    });
    let tree = StarTree::new(&disc, &slots).unwrap();
    let mut one = slots.clone();
    one[37] = (one[37] + 1) % 4;
    let cands = vec![one];
    group.bench_function("star_tree/one_slot_cost/100", |b| {
        b.iter(|| {
            candidate_costs(
                &disc,
                &tree,
                black_box(&cands),
                Objective::Boundary,
                &opts,
                None,
                None,
            )
            .unwrap()
        })
    });
    group.finish();
}

criterion_group!(
    benches,
    bench_period_triplet,
    bench_doubling,
    bench_fixed_point,
    bench_neighbourhood,
    bench_screened
);
criterion_main!(benches);
