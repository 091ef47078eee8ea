//! Criterion benches for the Hamiltonian/Schur CARE solver at n = 4, 16, 64, 200.
//!
//! Run with `cargo bench --bench care`. Problems are deterministic random, stabilisable and
//! detectable (m = n/2 inputs, Q positive definite), as in `benches/compare_linalg.py`.

use capalloc::care::{solve_care, CareOptions};
use capalloc::linalg::testing::Rng;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use nalgebra::DMatrix;
use std::hint::black_box;

fn problem(n: usize) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let mut rng = Rng::new(n as u64);
    let a = rng.matrix(n, n) / (n as f64).sqrt();
    let b = rng.matrix(n, (n / 2).max(1));
    let g = &b * b.transpose();
    let q = rng.psd(n, n) / n as f64 + DMatrix::identity(n, n);
    (a, g, q)
}

fn bench_care(c: &mut Criterion) {
    let mut group = c.benchmark_group("care");
    for &n in &[4usize, 16, 64, 200] {
        let (a, g, q) = problem(n);
        if n >= 64 {
            group.sample_size(10);
        }
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |bch, _| {
            bch.iter(|| solve_care(black_box(&a), &g, &q, &CareOptions::default()).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench_care);
criterion_main!(benches);
