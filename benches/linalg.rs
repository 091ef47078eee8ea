//! Criterion benchmarks of the dense linear algebra. One function per group; add new groups
//! (e.g. `lyapunov`, `care`) as further functions and list them in `criterion_group!` below.
//!
//! Run with `cargo bench --bench linalg` (or `cargo bench --bench linalg -- schur` for one group).

use capalloc::linalg::schur::RealSchur;
use capalloc::linalg::testing::Rng;
use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::hint::black_box;
use std::time::Duration;

/// Problem sizes shared by the groups.
const SIZES: [usize; 4] = [4, 16, 64, 200];

/// Fewer samples for the large sizes so a full run stays short on a shared machine.
fn configure(
    group: &mut criterion::BenchmarkGroup<'_, criterion::measurement::WallTime>,
    n: usize,
) {
    if n >= 200 {
        group.sample_size(10);
        group.measurement_time(Duration::from_secs(4));
    } else {
        group.sample_size(30);
        group.measurement_time(Duration::from_secs(2));
    }
    group.warm_up_time(Duration::from_millis(500));
}

/// `RealSchur::new` on a Gaussian random `n × n` matrix.
fn bench_schur(c: &mut Criterion) {
    let mut group = c.benchmark_group("schur");
    for &n in &SIZES {
        configure(&mut group, n);
        let a = Rng::new(n as u64).matrix(n, n);
        group.bench_with_input(BenchmarkId::from_parameter(n), &a, |b, a| {
            b.iter(|| RealSchur::new(black_box(a)).unwrap())
        });
    }
    group.finish();
}

/// `reorder(lhp)` alone, on the Schur form of a Gaussian random `n × n` matrix (about half of
/// the eigenvalues move). The clone of the factorisation is included; it is O(n²).
fn bench_reorder(c: &mut Criterion) {
    let mut group = c.benchmark_group("reorder");
    for &n in &SIZES {
        configure(&mut group, n);
        let a = Rng::new(n as u64).matrix(n, n);
        let s = RealSchur::new(&a).unwrap();
        group.bench_with_input(BenchmarkId::from_parameter(n), &s, |b, s| {
            b.iter(|| {
                let mut s = s.clone();
                black_box(s.reorder(|re, _| re < 0.0).unwrap())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_schur, bench_reorder);
criterion_main!(benches);
