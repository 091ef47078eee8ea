//! Deterministic random matrices for tests and benchmarks (no dependency on `rand`).
//! Not part of the public API.

use nalgebra::DMatrix;

/// SplitMix64's increment (the golden ratio in 64 bits).
const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64 generator with Box–Muller normals. Deterministic for a given seed.
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        Rng {
            state: seed ^ GOLDEN,
            spare: None,
        }
    }

    /// Next raw 64-bit value.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(GOLDEN);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }

    /// The generator as if `k` more standard normals had been drawn (`k` even, no spare held: two
    /// raw values per pair of normals), without drawing them.
    pub fn skip_normals(&mut self, k: u64) {
        assert!(k.is_multiple_of(2) && self.spare.is_none());
        self.state = self.state.wrapping_add(k.wrapping_mul(GOLDEN));
    }

    /// An `r × c` matrix of standard normals.
    pub fn matrix(&mut self, r: usize, c: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |_, _| self.normal())
    }

    /// A random orthogonal matrix (QR of a Gaussian matrix).
    pub fn orthogonal(&mut self, n: usize) -> DMatrix<f64> {
        self.matrix(n, n).qr().q()
    }

    /// A matrix `Q B Qᵀ` with prescribed eigenvalues: `real` ones and complex pairs `re ± i·im`.
    pub fn with_eigenvalues(&mut self, real: &[f64], pairs: &[(f64, f64)]) -> DMatrix<f64> {
        let n = real.len() + 2 * pairs.len();
        let mut b = DMatrix::zeros(n, n);
        let mut k = 0;
        for &(re, im) in pairs {
            b[(k, k)] = re;
            b[(k + 1, k + 1)] = re;
            b[(k, k + 1)] = im;
            b[(k + 1, k)] = -im;
            k += 2;
        }
        for &l in real {
            b[(k, k)] = l;
            k += 1;
        }
        for j in 0..n {
            for i in 0..j {
                if b[(i, j)] == 0.0 {
                    b[(i, j)] = 0.3 * self.normal();
                }
            }
        }
        let q = self.orthogonal(n);
        &q * b * q.transpose()
    }

    /// A symmetric positive semidefinite `n × n` matrix of rank `rank`.
    pub fn psd(&mut self, n: usize, rank: usize) -> DMatrix<f64> {
        let g = self.matrix(n, rank);
        &g * g.transpose()
    }
}
