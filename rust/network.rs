//! The network model of the paper in its general (assembled) form.
//!
//! A network is `dx = A x dt + G dw` observed by `N` sensors; sensor `i` measures `ĉ_iᵀ x` with unit
//! noise intensity (scale `ĉ_i` to model another intensity), at a rate `r_i ≥ 0` (a sensor at rate 0
//! contributes nothing; the Riccati solve then needs the other sensors to detect the state). With
//! `C_i = ĉ_i ĉ_iᵀ` and `W(r) = Σ r_i C_i`, the steady-state error covariance of the Kalman–Bucy
//! filter is the stabilising solution of the filter-form CARE
//! `A Σ + Σ Aᵀ − Σ W(r) Σ + G Gᵀ = 0` (see [`crate::cost`]).
//!
//! `G` is `n × m` for any `m ≥ 1` (the noise enters through `m` channels), so `Q = G Gᵀ` may be
//! singular. This type checks what can be checked cheaply and exactly: shapes and finiteness.
//! System-theoretic properties (observability of each subsystem, detectability of the whole, no
//! noise-free mode on the imaginary axis, regularity) are checked by the Python layer
//! (`capalloc_rs.Network`); a network that fails them makes the cost evaluation fail with the
//! CARE's own error (no stabilising solution).
//!
//! Sensors are stored with their row support: when `ĉ_i` is nonzero only in rows `lo..hi` (the
//! block of subsystem `i` in the paper's model), products with `ĉ_i` cost `O((hi − lo)·p_i)` per
//! column instead of `O(n·p_i)`.

use crate::linalg::dense::{check_finite, check_square, matmul_nt, symmetrize};
use crate::{Error, Result};
use nalgebra::DMatrix;
use std::ops::Range;

/// One sensor: the full `n × p` matrix `ĉ` and its nonzero row range.
#[derive(Debug, Clone)]
pub struct Sensor {
    c: DMatrix<f64>,
    rows: Range<usize>,
    local: DMatrix<f64>,
}

impl Sensor {
    fn new(c: DMatrix<f64>) -> Self {
        let nonzero_row = |i: &usize| c.row(*i).iter().any(|v| *v != 0.0);
        let lo = (0..c.nrows()).find(nonzero_row);
        let rows = match lo {
            None => 0..0,
            Some(lo) => {
                let hi = (0..c.nrows()).rev().find(nonzero_row).unwrap_or(lo) + 1;
                lo..hi
            }
        };
        let local = c.rows(rows.start, rows.len()).into_owned();
        Sensor { c, rows, local }
    }

    /// The full `n × p` matrix `ĉ`.
    pub fn matrix(&self) -> &DMatrix<f64> {
        &self.c
    }

    /// Number of outputs `p`.
    pub fn outputs(&self) -> usize {
        self.c.ncols()
    }

    /// The rows outside which `ĉ` is zero (empty for an all-zero sensor).
    pub fn rows(&self) -> Range<usize> {
        self.rows.clone()
    }

    /// `ĉ` restricted to [`Sensor::rows`].
    pub fn local(&self) -> &DMatrix<f64> {
        &self.local
    }

    /// `M ĉ` for an `m × n` matrix `M`, using the row support of `ĉ`.
    pub fn right_mul(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        let cols = m.columns(self.rows.start, self.rows.len());
        let mut out = DMatrix::zeros(m.nrows(), self.outputs());
        out.gemm(1.0, &cols, &self.local, 0.0);
        out
    }

    /// `ĉᵀ M` for an `n × m` matrix `M`, using the row support of `ĉ`.
    pub fn left_mul_t(&self, m: &DMatrix<f64>) -> DMatrix<f64> {
        let rows = m.rows(self.rows.start, self.rows.len());
        let mut out = DMatrix::zeros(self.outputs(), m.ncols());
        out.gemm_tr(1.0, &self.local, &rows, 0.0);
        out
    }
}

/// The model `(A, G, ĉ_1, …, ĉ_N)`. Immutable once built.
#[derive(Debug, Clone)]
pub struct Network {
    a: DMatrix<f64>,
    g: DMatrix<f64>,
    q: DMatrix<f64>,
    sensors: Vec<Sensor>,
    offsets: Vec<usize>,
    weight: Option<Weight>,
}

/// The weight `M ⪰ 0` of a weighted error `η_M = tr(M Σ)`, with `‖M‖₂`.
#[derive(Debug, Clone)]
struct Weight {
    m: DMatrix<f64>,
    norm2: f64,
}

impl Network {
    /// Builds and validates a network: `A` square `n × n`, `G` `n × m` with `m ≥ 1` (`Q = G Gᵀ`
    /// may be singular), both finite, at least one sensor, each `ĉ_i` finite with `n` rows and at
    /// least one column. Errors name the offending field (`sensor i` counts from 0).
    pub fn new(a: DMatrix<f64>, g: DMatrix<f64>, sensors: Vec<DMatrix<f64>>) -> Result<Self> {
        let n = check_square("A", &a)?;
        check_finite("A", &a)?;
        if g.nrows() != n || g.ncols() == 0 {
            return Err(Error::Shape(format!(
                "G must be {n}×m with m ≥ 1 (n rows like A), got {}×{}",
                g.nrows(),
                g.ncols()
            )));
        }
        check_finite("G", &g)?;
        if sensors.is_empty() {
            return Err(Error::Shape("the network needs at least one sensor".into()));
        }
        let mut offsets = Vec::with_capacity(sensors.len() + 1);
        offsets.push(0);
        for (i, c) in sensors.iter().enumerate() {
            if c.nrows() != n || c.ncols() == 0 {
                return Err(Error::Shape(format!(
                    "sensor {i}: ĉ_{i} must be {n}×p with p ≥ 1, got {}×{}",
                    c.nrows(),
                    c.ncols()
                )));
            }
            check_finite(&format!("sensor {i}: ĉ_{i}"), c)?;
            offsets.push(offsets[i] + c.ncols());
        }
        let q = symmetrize(&matmul_nt(&g, &g));
        let sensors = sensors.into_iter().map(Sensor::new).collect();
        Ok(Network {
            a,
            g,
            q,
            sensors,
            offsets,
            weight: None,
        })
    }

    /// The same network with the error weighted by `M`: the cost becomes `η_M(r) = tr(M Σ(r))`.
    /// `M` must be `n × n`, finite, symmetric (to `1e-12` relative to its largest entry; it is
    /// symmetrised), positive semidefinite (smallest eigenvalue above `−n·ε·‖M‖₂`) and nonzero.
    pub fn with_error_weight(mut self, m: DMatrix<f64>) -> Result<Self> {
        let n = self.order();
        if m.nrows() != n || m.ncols() != n {
            return Err(Error::Shape(format!(
                "the weight M must be {n}×{n} like A, got {}×{}",
                m.nrows(),
                m.ncols()
            )));
        }
        check_finite("the weight M", &m)?;
        let scale = m.amax();
        if (&m - m.transpose()).amax() > 1e-12 * scale {
            return Err(Error::InvalidInput(
                "the weight M must be symmetric (to 1e-12 relative to its largest entry)".into(),
            ));
        }
        let m = symmetrize(&m);
        let eig = m.clone().symmetric_eigen().eigenvalues;
        let norm2 = eig.amax();
        if norm2 == 0.0 {
            return Err(Error::InvalidInput("the weight M must be nonzero".into()));
        }
        let lo = eig.min();
        if lo < -(n as f64) * f64::EPSILON * norm2 {
            return Err(Error::InvalidInput(format!(
                "the weight M must be positive semidefinite, its smallest eigenvalue is {lo:.3e}"
            )));
        }
        self.weight = Some(Weight { m, norm2 });
        Ok(self)
    }

    /// The weight `M` of the error (`None`: `M = I`, the plain trace).
    pub fn error_weight(&self) -> Option<&DMatrix<f64>> {
        self.weight.as_ref().map(|w| &w.m)
    }

    /// `‖M‖₂` (1 without a weight).
    pub fn error_weight_norm(&self) -> f64 {
        self.weight.as_ref().map_or(1.0, |w| w.norm2)
    }

    /// The error figure of a covariance `X`: `tr(M X)` (`tr X` without a weight).
    pub fn weighted_trace(&self, x: &DMatrix<f64>) -> f64 {
        match &self.weight {
            None => x.diagonal().iter().sum(),
            Some(w) => w.m.iter().zip(x.iter()).map(|(a, b)| a * b).sum(),
        }
    }

    /// The state dimension `n`.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// The number of sensors `N`.
    pub fn num_sensors(&self) -> usize {
        self.sensors.len()
    }

    /// The total number of outputs `P = Σ p_i`.
    pub fn total_outputs(&self) -> usize {
        self.offsets[self.sensors.len()]
    }

    /// Column offsets of the sensors in `[ĉ_1 … ĉ_N]` (length `N + 1`).
    pub fn offsets(&self) -> &[usize] {
        &self.offsets
    }

    /// The drift matrix `A`.
    pub fn a(&self) -> &DMatrix<f64> {
        &self.a
    }

    /// The noise matrix `G` (`n × m`).
    pub fn g(&self) -> &DMatrix<f64> {
        &self.g
    }

    /// The process noise covariance `Q = G Gᵀ` (exactly symmetric).
    pub fn q(&self) -> &DMatrix<f64> {
        &self.q
    }

    /// The sensors.
    pub fn sensors(&self) -> &[Sensor] {
        &self.sensors
    }

    /// Checks a rate vector: length `N`, every entry finite and `≥ 0`.
    pub fn check_rates(&self, r: &[f64]) -> Result<()> {
        if r.len() != self.num_sensors() {
            return Err(Error::Shape(format!(
                "r must have one rate per sensor ({}), got {}",
                self.num_sensors(),
                r.len()
            )));
        }
        if let Some(i) = r.iter().position(|v| !v.is_finite()) {
            return Err(Error::NonFinite(format!("r[{i}] = {} is not finite", r[i])));
        }
        if let Some(i) = r.iter().position(|v| *v < 0.0) {
            return Err(Error::InvalidInput(format!(
                "rates must be non-negative, got r[{i}] = {}",
                r[i]
            )));
        }
        Ok(())
    }

    /// `W(r) = Σ r_i ĉ_i ĉ_iᵀ`, assembled on the sensors' row supports in `O(Σ m_i² p_i)` after
    /// zeroing (`m_i` the support size). Exactly symmetric.
    pub fn weight(&self, r: &[f64]) -> Result<DMatrix<f64>> {
        self.check_rates(r)?;
        Ok(self.weight_unchecked(r))
    }

    pub(crate) fn weight_unchecked(&self, r: &[f64]) -> DMatrix<f64> {
        let n = self.order();
        let mut w = DMatrix::zeros(n, n);
        for (s, &ri) in self.sensors.iter().zip(r) {
            let rows = s.rows();
            let m = rows.len();
            if m == 0 {
                continue;
            }
            let mut block = w.view_mut((rows.start, rows.start), (m, m));
            block.gemm(ri, &s.local, &s.local.transpose(), 1.0);
        }
        symmetrize(&w)
    }
}

/// A random block network for tests and benchmarks (not part of the API): subsystem `i` has
/// `sizes[i]` states and one sensor with `outputs[i]` outputs on its own block; `A_i` Gaussian
/// (typically with unstable modes), `G_i = I + 0.3·(strictly lower Gaussian)`, couplings
/// `ε·(Gaussian)/√n` between every pair. Observable with probability one.
#[doc(hidden)]
pub fn random_block_network(seed: u64, sizes: &[usize], outputs: &[usize], eps: f64) -> Network {
    let mut rng = crate::linalg::testing::Rng::new(seed);
    let n: usize = sizes.iter().sum();
    let mut a = rng.matrix(n, n) * (eps / (n as f64).sqrt());
    let mut g = DMatrix::zeros(n, n);
    let mut sensors = Vec::with_capacity(sizes.len());
    let mut lo = 0;
    for (&ni, &pi) in sizes.iter().zip(outputs) {
        a.view_mut((lo, lo), (ni, ni))
            .copy_from(&(rng.matrix(ni, ni) * (1.0 / (ni as f64).sqrt())));
        for j in 0..ni {
            g[(lo + j, lo + j)] = 1.0;
            for i in (j + 1)..ni {
                g[(lo + i, lo + j)] = 0.3 * rng.normal();
            }
        }
        let mut c = DMatrix::zeros(n, pi);
        c.view_mut((lo, 0), (ni, pi)).copy_from(&rng.matrix(ni, pi));
        sensors.push(c);
        lo += ni;
    }
    Network::new(a, g, sensors).expect("random networks are valid")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    fn block_sensor(n: usize, lo: usize, c: &DMatrix<f64>) -> DMatrix<f64> {
        let mut full = DMatrix::zeros(n, c.ncols());
        full.view_mut((lo, 0), (c.nrows(), c.ncols())).copy_from(c);
        full
    }

    #[test]
    fn weight_matches_the_dense_sum() {
        let mut rng = Rng::new(1);
        let n = 7;
        let sensors = vec![
            block_sensor(n, 0, &rng.matrix(2, 1)),
            block_sensor(n, 2, &rng.matrix(3, 2)),
            rng.matrix(n, 1),
            DMatrix::zeros(n, 1),
        ];
        let net = Network::new(rng.matrix(n, n), DMatrix::identity(n, n), sensors.clone()).unwrap();
        assert_eq!(net.sensors()[0].rows(), 0..2);
        assert_eq!(net.sensors()[1].rows(), 2..5);
        assert_eq!(net.sensors()[2].rows(), 0..n);
        assert_eq!(net.sensors()[3].rows(), 0..0);
        assert_eq!(net.offsets(), &[0, 1, 3, 4, 5]);
        let r = [0.5, 2.0, 1.5, 3.0];
        let w = net.weight(&r).unwrap();
        let mut dense = DMatrix::zeros(n, n);
        for (c, ri) in sensors.iter().zip(r) {
            dense += c * c.transpose() * ri;
        }
        assert!((&w - &dense).norm() <= 1e-14 * dense.norm());
        assert_eq!(w, w.transpose());
        let m = rng.matrix(3, n);
        for (s, c) in net.sensors().iter().zip(&sensors) {
            assert!((s.right_mul(&m) - &m * c).norm() <= 1e-14 * (1.0 + m.norm()));
            let mt = m.transpose();
            assert!((s.left_mul_t(&mt) - c.transpose() * &mt).norm() <= 1e-14 * (1.0 + m.norm()));
        }
    }

    #[test]
    fn bad_input_names_the_field() {
        let n = 3;
        let a = DMatrix::<f64>::identity(n, n);
        let c = DMatrix::<f64>::from_element(n, 1, 1.0);
        let err = Network::new(a.clone(), DMatrix::identity(2, 2), vec![c.clone()]).unwrap_err();
        assert!(
            matches!(&err, Error::Shape(m) if m.contains("G must be")),
            "{err}"
        );
        let err = Network::new(a.clone(), DMatrix::zeros(n, 0), vec![c.clone()]).unwrap_err();
        assert!(
            matches!(&err, Error::Shape(m) if m.contains("m ≥ 1")),
            "{err}"
        );
        // A rectangular or singular G is a valid noise model (Q = G Gᵀ singular).
        assert!(Network::new(a.clone(), DMatrix::zeros(n, 1), vec![c.clone()]).is_ok());
        assert!(Network::new(a.clone(), DMatrix::zeros(n, n), vec![c.clone()]).is_ok());
        let err = Network::new(a.clone(), a.clone(), vec![]).unwrap_err();
        assert!(matches!(err, Error::Shape(_)));
        let err = Network::new(
            a.clone(),
            a.clone(),
            vec![c.clone(), DMatrix::from_element(2, 1, 1.0)],
        )
        .unwrap_err();
        assert!(
            matches!(&err, Error::Shape(m) if m.contains("sensor 1")),
            "{err}"
        );
        let mut bad = c.clone();
        bad[1] = f64::NAN;
        let err = Network::new(a.clone(), a.clone(), vec![c.clone(), bad]).unwrap_err();
        assert!(
            matches!(&err, Error::NonFinite(m) if m.contains("sensor 1")),
            "{err}"
        );
        let net = Network::new(a.clone(), a.clone(), vec![c.clone(), c]).unwrap();
        assert!(matches!(net.check_rates(&[1.0]), Err(Error::Shape(_))));
        assert!(matches!(
            net.check_rates(&[1.0, -0.5]),
            Err(Error::InvalidInput(m)) if m.contains("r[1]")
        ));
        assert!(net.check_rates(&[1.0, 0.0]).is_ok());
        assert!(matches!(
            net.check_rates(&[f64::INFINITY, 1.0]),
            Err(Error::NonFinite(_))
        ));
    }
}
