//! Criterion benchmarks of the cost evaluator on random block networks with `N` subsystems of size
//! 2 and one output each (`n = 2N`): value, value + gradient, Hessian, one Hessian-vector product,
//! and a batch of 16 value + gradient evaluations.
//!
//! Run with `cargo bench --bench cost` (or `cargo bench --bench cost -- gradient` for one group).

use capalloc::cost::{self, CostOptions, Evaluation, Threads};
use capalloc::network::{random_block_network, Network};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::hint::black_box;
use std::time::Duration;

/// Numbers of subsystems.
const SIZES: [usize; 4] = [5, 20, 50, 200];

fn configure(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    nn: usize,
) {
    if nn >= 200 {
        group.sample_size(10);
        group.measurement_time(Duration::from_secs(8));
    } else {
        group.sample_size(20);
        group.measurement_time(Duration::from_secs(2));
    }
    group.warm_up_time(Duration::from_millis(300));
}

fn problem(nn: usize) -> (Network, Vec<f64>) {
    let net = random_block_network(nn as u64, &vec![2; nn], &vec![1; nn], 0.1);
    let r = (0..nn).map(|i| 0.5 + (i % 7) as f64 * 0.4).collect();
    (net, r)
}

fn bench_cost(c: &mut Criterion) {
    let opts = CostOptions::default();
    let mut group = c.benchmark_group("cost");
    for &nn in &SIZES {
        configure(&mut group, nn);
        let (net, r) = problem(nn);
        group.bench_with_input(BenchmarkId::from_parameter(nn), &r, |b, r| {
            b.iter(|| cost::cost(&net, black_box(r), &opts).unwrap())
        });
    }
    group.finish();
}

fn bench_gradient(c: &mut Criterion) {
    let opts = CostOptions::default();
    let mut group = c.benchmark_group("value_gradient");
    for &nn in &SIZES {
        configure(&mut group, nn);
        let (net, r) = problem(nn);
        group.bench_with_input(BenchmarkId::from_parameter(nn), &r, |b, r| {
            b.iter(|| cost::value_gradient(&net, black_box(r), &opts).unwrap())
        });
    }
    group.finish();
}

fn bench_hessian(c: &mut Criterion) {
    let opts = CostOptions::default();
    let mut group = c.benchmark_group("hessian_sequential");
    for &nn in &SIZES {
        configure(&mut group, nn);
        let (net, r) = problem(nn);
        group.bench_with_input(BenchmarkId::from_parameter(nn), &r, |b, r| {
            b.iter(|| {
                cost::value_gradient_hessian(&net, black_box(r), &opts, Threads::Sequential)
                    .unwrap()
            })
        });
    }
    group.finish();
}

/// One Hessian-vector product at a point whose Riccati solution and adjoint are already known.
fn bench_hvp(c: &mut Criterion) {
    let opts = CostOptions::default();
    let mut group = c.benchmark_group("hvp_at_point");
    for &nn in &SIZES {
        configure(&mut group, nn);
        let (net, r) = problem(nn);
        let ev = Evaluation::new(&net, &r, &opts).unwrap();
        let adj = ev.adjoint().unwrap();
        let v = vec![(0..nn).map(|i| (i as f64).sin()).collect::<Vec<f64>>()];
        group.bench_with_input(BenchmarkId::from_parameter(nn), &v, |b, v| {
            b.iter(|| adj.hvp(black_box(v)).unwrap())
        });
    }
    group.finish();
}

fn bench_batch(c: &mut Criterion) {
    let opts = CostOptions::default();
    let mut group = c.benchmark_group("value_gradient_many_16");
    for &nn in &SIZES[..3] {
        configure(&mut group, nn);
        let (net, r) = problem(nn);
        let rows: Vec<Vec<f64>> = (0..16)
            .map(|k| r.iter().map(|x| x * (1.0 + 0.01 * k as f64)).collect())
            .collect();
        group.bench_with_input(BenchmarkId::from_parameter(nn), &rows, |b, rows| {
            b.iter(|| {
                cost::value_gradient_many(&net, black_box(rows), &opts, Threads::All).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(
    benches,
    bench_cost,
    bench_gradient,
    bench_hessian,
    bench_hvp,
    bench_batch
);
criterion_main!(benches);
