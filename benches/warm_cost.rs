//! Criterion benchmarks of warm-started cost evaluations: a cold `Evaluation::new` + gradient
//! against a warm-started evaluation + gradient from the solution at a point 1 % away — from its
//! `Evaluation` (`Evaluation::warm`: Newton–Kleinman from its `Σ`) and from its `Adjoint`
//! (`Adjoint::warm_evaluation`: the same with the tangent predictor on the point's factored
//! closed loop, as a Newton path has it) — on random block networks with `N` subsystems of 2
//! states and one output each (`n = 2N`).
//!
//! Run with `cargo bench --bench warm_cost` (one BLAS thread:
//! `OPENBLAS_NUM_THREADS=1 cargo bench --bench warm_cost -- --warm-up-time 1 --measurement-time 5`).

use capalloc::cost::{CostOptions, Evaluation};
use capalloc::network::{random_block_network, Network};
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::hint::black_box;

/// Numbers of subsystems (`n = 2N` = 20, 100, 400).
const SIZES: [usize; 3] = [10, 50, 200];

fn problem(nn: usize) -> (Network, Vec<f64>, Vec<f64>) {
    let net = random_block_network(nn as u64, &vec![2; nn], &vec![1; nn], 0.1);
    let r0: Vec<f64> = (0..nn).map(|i| 0.5 + (i % 7) as f64 * 0.4).collect();
    // 1 % away, alternating signs.
    let r1 = r0
        .iter()
        .enumerate()
        .map(|(i, v)| v * if i % 2 == 0 { 1.01 } else { 0.99 })
        .collect();
    (net, r0, r1)
}

fn bench_warm(c: &mut Criterion) {
    let opts = CostOptions::default();
    let mut group = c.benchmark_group("warm_cost");
    for &nn in &SIZES {
        if nn >= 200 {
            group.sample_size(10);
        } else {
            group.sample_size(20);
        }
        let (net, r0, r1) = problem(nn);
        let from = Evaluation::new(&net, &r0, &opts).unwrap();
        let point = from.adjoint().unwrap();
        let cold = Evaluation::new(&net, &r1, &opts).unwrap();
        for probe in [
            Evaluation::warm(&net, &r1, &opts, &from).unwrap(),
            point.warm_evaluation(&r1, &opts).unwrap(),
        ] {
            eprintln!(
                "N = {nn}: {:?}; |η_warm − η_cold| / η = {:.1e}, value_error / η = {:.1e}",
                probe.warm_info(),
                (probe.value() - cold.value()).abs() / cold.value(),
                probe.value_error() / cold.value()
            );
        }
        group.bench_with_input(BenchmarkId::new("cold", nn), &r1, |b, r| {
            b.iter(|| {
                let ev = Evaluation::new(&net, black_box(r), &opts).unwrap();
                let adj = ev.adjoint().unwrap();
                black_box(adj.gradient()[0])
            })
        });
        group.bench_with_input(BenchmarkId::new("warm", nn), &r1, |b, r| {
            b.iter(|| {
                let ev = Evaluation::warm(&net, black_box(r), &opts, &from).unwrap();
                let adj = ev.adjoint().unwrap();
                black_box(adj.gradient()[0])
            })
        });
        group.bench_with_input(BenchmarkId::new("warm_from_point", nn), &r1, |b, r| {
            b.iter(|| {
                let ev = point.warm_evaluation(black_box(r), &opts).unwrap();
                let adj = ev.adjoint().unwrap();
                black_box(adj.gradient()[0])
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_warm);
criterion_main!(benches);
