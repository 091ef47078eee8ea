use std::hint::black_box;
use std::time::Duration;

use capalloc::linalg::schur::RealSchur;
use capalloc::linalg::sylvester::{solve_lyapunov, Lyapunov};
use capalloc::linalg::testing::Rng;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};

/// Lyapunov `A X + X Aᵀ = Q` at n = 4, 16, 64, 200 (Gaussian `A`: mixed spectrum, mostly complex
/// pairs; `Q` symmetric positive semidefinite), split into the full solve (what scipy's
/// `solve_continuous_lyapunov` does), the Schur step alone, and a solve with a precomputed factor
/// (what each of many right-hand sides costs), for symmetric and general `Q`.
fn bench_lyapunov(c: &mut Criterion) {
    let mut group = c.benchmark_group("lyapunov");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    for &n in &[4usize, 16, 64, 200] {
        let mut rng = Rng::new(n as u64);
        let a = rng.matrix(n, n);
        let q = rng.psd(n, n);
        let qn = rng.matrix(n, n);
        if n >= 64 {
            group.sample_size(20);
        }
        group.bench_with_input(BenchmarkId::new("full", n), &n, |b, _| {
            b.iter(|| solve_lyapunov(black_box(&a), black_box(&q)).unwrap())
        });
        group.bench_with_input(BenchmarkId::new("schur_only", n), &n, |b, _| {
            b.iter(|| RealSchur::new(black_box(&a)).unwrap())
        });
        let lyap = Lyapunov::new(&a).unwrap();
        group.bench_with_input(BenchmarkId::new("factored_solve", n), &n, |b, _| {
            b.iter(|| lyap.solve(black_box(&q)).unwrap())
        });
        group.bench_with_input(
            BenchmarkId::new("factored_solve_nonsym_q", n),
            &n,
            |b, _| b.iter(|| lyap.solve(black_box(&qn)).unwrap()),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_lyapunov);
criterion_main!(benches);
