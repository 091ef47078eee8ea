//! The adjoint state at one rate vector and everything derived from it: the gradient (one
//! adjoint Lyapunov solve), the Hessian (`N` more solves on one real Schur form of `A_cl`) and
//! Hessian-vector products (two more solves each). The formulas are in the parent module.

use super::pool::in_pool;
use super::{Evaluation, Handle, Threads};
use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, symmetrize};
use crate::linalg::sylvester::Lyapunov;
use crate::network::Network;
use crate::{Error, Result};
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

/// `Σ_{k ∈ cols} ⟨a[:, k], b[:, k]⟩`.
fn column_dots(a: &DMatrix<f64>, b: &DMatrix<f64>, cols: std::ops::Range<usize>) -> f64 {
    cols.map(|k| a.column(k).dot(&b.column(k))).sum()
}

/// The adjoint state at one rate vector: `Y`, the gradient, and the Schur form of `A_cl` for
/// further solves. Borrows its [`Evaluation`] ([`Evaluation::adjoint`]) or owns it
/// ([`Evaluation::into_adjoint`], [`CostPoint`](super::CostPoint)).
#[derive(Debug, Clone)]
pub struct Adjoint<'e, 'a> {
    eval: Handle<'e, Evaluation<'a>>,
    lyap: Arc<Lyapunov>,
    y: DMatrix<f64>,
    yu: DMatrix<f64>,
    gradient: Vec<f64>,
    /// The data of Hessian-vector products in Schur coordinates, formed on the first product.
    coords: OnceLock<SchurCoordinates>,
}

/// `U`, `C̃`, `R C̃` (`R = diag(r_i I_{p_i})`), `Y` and `Y U` in the Schur coordinates of `A_cl`
/// (`Xᵀ ↦ Zᵀ X` for the `n × P` ones, `Zᵀ Y Z`): a Hessian-vector product then needs no
/// congruence with `Z` (see [`Adjoint::hvp`]).
#[derive(Debug, Clone)]
struct SchurCoordinates {
    u: DMatrix<f64>,
    c: DMatrix<f64>,
    rc: DMatrix<f64>,
    y: DMatrix<f64>,
    yu: DMatrix<f64>,
}

impl<'e, 'a> Adjoint<'e, 'a> {
    pub(super) fn with_handle(eval: Handle<'e, Evaluation<'a>>) -> Result<Self> {
        let n = eval.net.order();
        // A warm-started evaluation hands over the Schur form of its final closed loop.
        let lyap = match &eval.factor {
            Some(f) => Arc::clone(f),
            None => Arc::new(Lyapunov::new(&eval.a_cl)?),
        };
        let rhs = match eval.net.error_weight() {
            Some(m) => -m,
            None => -DMatrix::<f64>::identity(n, n),
        };
        let y = symmetrize(&lyap.solve_adjoint(&rhs)?);
        let yu = matmul(&y, &eval.u);
        let offsets = eval.net.offsets();
        let gradient = (0..eval.net.num_sensors())
            .map(|i| -column_dots(&eval.u, &yu, offsets[i]..offsets[i + 1]))
            .collect();
        Ok(Adjoint {
            eval,
            lyap,
            y,
            yu,
            gradient,
            coords: OnceLock::new(),
        })
    }

    /// The real Schur form of `A_cl` (as a Lyapunov operator).
    pub(super) fn closed_loop_factor(&self) -> &Lyapunov {
        &self.lyap
    }

    /// The evaluation (`Σ`, `η`, `A_cl`, the rates, the network).
    pub fn evaluation(&self) -> &Evaluation<'a> {
        &self.eval
    }

    /// `∇η(r)`, `∂η/∂r_i = −tr(ĉ_iᵀ Σ Y Σ ĉ_i)`.
    pub fn gradient(&self) -> &[f64] {
        &self.gradient
    }

    /// The adjoint solution `Y` of `A_clᵀ Y + Y A_cl = −M` (`M = I` without a weight).
    pub fn y(&self) -> &DMatrix<f64> {
        &self.y
    }

    /// `Σ'_i = ∂Σ/∂r_i`, the solution of `A_cl Σ'_i + Σ'_i A_clᵀ = Σ C_i Σ` (symmetric).
    pub fn sigma_derivative(&self, i: usize) -> Result<DMatrix<f64>> {
        let net: &Network = &self.eval.net;
        if i >= net.num_sensors() {
            return Err(Error::InvalidInput(format!(
                "sensor index {i} out of range (N = {})",
                net.num_sensors()
            )));
        }
        let off = net.offsets();
        let ui = self
            .eval
            .u
            .columns(off[i], off[i + 1] - off[i])
            .into_owned();
        let rhs = symmetrize(&matmul_nt(&ui, &ui));
        Ok(symmetrize(&self.lyap.solve(&rhs)?))
    }

    /// `C̃ᵀ S` (`P × n`), using the sensors' row supports.
    fn ct_times(&self, s: &DMatrix<f64>) -> DMatrix<f64> {
        let net: &Network = &self.eval.net;
        let off = net.offsets();
        let mut e = DMatrix::zeros(net.total_outputs(), s.ncols());
        for (k, sensor) in net.sensors().iter().enumerate() {
            e.rows_mut(off[k], sensor.outputs())
                .copy_from(&sensor.left_mul_t(s));
        }
        e
    }

    /// `Y = K Kᵀ`: Cholesky, or a symmetric square root if rounding made `Y` indefinite.
    fn y_factor(&self) -> Result<DMatrix<f64>> {
        match self.y.clone().cholesky() {
            Some(ch) => Ok(ch.l()),
            None => {
                // nalgebra's `symmetric_eigen()` iterates without bound (forever on NaN).
                let n = self.y.nrows();
                let eig = self
                    .y
                    .clone()
                    .try_symmetric_eigen(f64::EPSILON, 30 * n.max(10) * n.max(1))
                    .ok_or_else(|| {
                        Error::Convergence(
                            "the symmetric eigensolver for the adjoint Y did not converge within \
                             its bound of 30·max(10, n)·n sweeps (Y has non-finite entries?)"
                                .into(),
                        )
                    })?;
                let mut v = eig.eigenvectors;
                for (j, lambda) in eig.eigenvalues.iter().enumerate() {
                    let s = lambda.max(0.0).sqrt();
                    v.column_mut(j).scale_mut(s);
                }
                Ok(v)
            }
        }
    }

    /// The exact Hessian `∇²η(r)` (`N × N`, symmetric): `N` Lyapunov solves on the Schur form of
    /// `A_cl` already computed, spread over `threads` (the result does not depend on it).
    /// Memory: `O(N·P·n)` for the Gram factor.
    pub fn hessian(&self, threads: Threads) -> Result<DMatrix<f64>> {
        let all: Vec<usize> = (0..self.eval.net.num_sensors()).collect();
        self.hessian_block(&all, threads)
    }

    /// The principal block `[∇²η(r)]_{JJ}` (`|J| × |J|`, symmetric) on the sensors `idx = J` (in
    /// that order): only the `|J|` solves for `Σ'_i`, `i ∈ J` — what Newton's method on a face
    /// of the simplex needs. The full Hessian is the block on every sensor, computed the same way.
    pub fn hessian_block(&self, idx: &[usize], threads: Threads) -> Result<DMatrix<f64>> {
        let net: &Network = &self.eval.net;
        let (n, nn, pp) = (net.order(), net.num_sensors(), net.total_outputs());
        if let Some(&bad) = idx.iter().find(|&&i| i >= nn) {
            return Err(Error::InvalidInput(format!(
                "sensor index {bad} out of range (N = {nn})"
            )));
        }
        let kk = idx.len();
        let off = net.offsets();
        let k = self.y_factor()?;
        let sqrt_r: Vec<f64> = self.eval.r.iter().map(|v| v.sqrt()).collect();

        // For sensor i = idx[a]: Σ'_i, E_i = C̃ᵀ Σ'_i, T2[a, b] = tr(Y Σ'_i C_j Σ) (j = idx[b]) =
        // ⟨E_i[j-rows], (Y u_j)ᵀ⟩, and M_i = R^{1/2} E_i K (flattened).
        // Column a of `gram` is vec(M_i); chunk a of `t2_data` is row a of T2. Filled in place
        // (in parallel over a when asked), so the Gram factor is the only O(|J|·P·n) allocation.
        let mut gram_data = vec![0.0; pp * n * kk];
        let mut t2_data = vec![0.0; kk * kk];
        let fill_column = |s: DMatrix<f64>, col: &mut [f64], t2row: &mut [f64]| {
            let mut e = self.ct_times(&s);
            for (t, &j) in t2row.iter_mut().zip(idx) {
                *t = (off[j]..off[j + 1])
                    .map(|c| e.row(c).transpose().dot(&self.yu.column(c)))
                    .sum();
            }
            for (j, sr) in sqrt_r.iter().enumerate() {
                e.rows_mut(off[j], off[j + 1] - off[j]).scale_mut(*sr);
            }
            col.copy_from_slice(matmul(&e, &k).as_slice());
        };
        // The columns may run on pool threads: each takes the caller's cancellation token.
        let token = crate::cancel::current();
        let fill = |(a, (col, t2row)): (usize, (&mut [f64], &mut [f64]))| -> Result<()> {
            let s = crate::cancel::with_token(token.as_ref(), || {
                crate::cancel::check("the Hessian's Lyapunov solves")?;
                self.sigma_derivative(idx[a])
            })?;
            fill_column(s, col, t2row);
            Ok(())
        };
        // Not worth waking threads for a few small solves.
        let threads = if kk < 4 || n < 8 {
            Threads::Sequential
        } else {
            threads
        };
        if kk > 0 {
            in_pool(threads, |parallel| {
                if parallel {
                    gram_data
                        .par_chunks_mut(pp * n)
                        .zip(t2_data.par_chunks_mut(kk))
                        .enumerate()
                        .try_for_each(fill)
                } else {
                    gram_data
                        .chunks_mut(pp * n)
                        .zip(t2_data.chunks_mut(kk))
                        .enumerate()
                        .try_for_each(fill)
                }
            })??;
        }
        let gram = DMatrix::from_vec(pp * n, kk, gram_data);
        // Column-major from row-major data: this is T2ᵀ, and only T2 + T2ᵀ is needed.
        let t2 = DMatrix::from_vec(kk, kk, t2_data);
        let t1 = matmul_tn(&gram, &gram);
        let h = (t1 + &t2 + t2.transpose()) * -2.0;
        Ok(symmetrize(&h))
    }

    /// Hessian-vector products `∇²η(r) v` for each `v` in `vs` (each of length `N`): two Lyapunov
    /// solves per vector on the Schur form of `A_cl` already computed.
    pub fn hvp(&self, vs: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        vs.iter().map(|v| self.hvp_one(v)).collect()
    }

    /// The Schur-coordinate data of the products (formed once per point: `3 n²P + 2n³`).
    fn coordinates(&self) -> &SchurCoordinates {
        self.coords.get_or_init(|| {
            let net: &Network = &self.eval.net;
            let z = self.lyap.schur_vectors();
            let mut c = DMatrix::zeros(net.order(), net.total_outputs());
            for (s, &off) in net.sensors().iter().zip(net.offsets()) {
                c.columns_mut(off, s.outputs()).copy_from(s.matrix());
            }
            let c = matmul_tn(z, &c);
            let mut rc = c.clone();
            for (j, s) in net.sensors().iter().enumerate() {
                rc.columns_mut(net.offsets()[j], s.outputs())
                    .scale_mut(self.eval.r[j]);
            }
            SchurCoordinates {
                u: matmul_tn(z, &self.eval.u),
                c,
                rc,
                y: self.y_schur_coordinates(z),
                yu: matmul_tn(z, &self.yu),
            }
        })
    }

    /// `Zᵀ Y Z`: without an error weight `Y` solves `A_clᵀ Y + Y A_cl = −I`, whose right-hand side
    /// is `−I` in every orthonormal basis, so a triangular solve gives it directly (the `2n³` of
    /// the congruence saved); with a weight `M`, the congruence of `Y`.
    fn y_schur_coordinates(&self, z: &DMatrix<f64>) -> DMatrix<f64> {
        if self.eval.net.error_weight().is_none() {
            let n = z.nrows();
            let minus_eye = DMatrix::from_diagonal_element(n, n, -1.0);
            if let Ok(y) = self.lyap.solve_schur_coordinates(minus_eye, true) {
                return y;
            }
        }
        symmetrize(&matmul_tn(z, &matmul(&self.y, z)))
    }

    /// One product in the Schur coordinates `X̃ = Zᵀ X Z` of `A_cl = Z T Zᵀ`: the formulas of the
    /// parent module with `Σ C_v Σ = Ũ diag(v) Ũᵀ`, `B̃ = C̃ (R C̃ᵀ Σ̃'_v + diag(v) Ũᵀ)`,
    /// `M̃ = B̃ Ỹ`, `(∇²η v)_i = 2 tr(ũ_iᵀ Z̃ ũ_i) − 2 tr((Ỹũ_i)ᵀ Σ̃'_v c̃_i)` (traces are
    /// invariant under the orthogonal change of basis). Two triangular solves and six `n²P`
    /// products, instead of two solves with their `3n³` congruences and an `n³` product.
    fn hvp_one(&self, v: &[f64]) -> Result<Vec<f64>> {
        let net: &Network = &self.eval.net;
        let nn = net.num_sensors();
        if v.len() != nn {
            return Err(Error::Shape(format!(
                "v must have one entry per sensor ({nn}), got {}",
                v.len()
            )));
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(Error::NonFinite(format!("v[{i}] = {} is not finite", v[i])));
        }
        let off = net.offsets();
        let k = self.coordinates();
        let mut uv = k.u.clone();
        for j in 0..nn {
            uv.columns_mut(off[j], off[j + 1] - off[j]).scale_mut(v[j]);
        }
        let rhs = symmetrize(&matmul_nt(&uv, &k.u));
        let sv = self.lyap.solve_schur_coordinates(rhs, false)?;
        let mut inner = matmul_tn(&k.rc, &sv);
        inner += uv.transpose();
        let m = matmul(&k.c, &matmul(&inner, &k.y));
        let z = self
            .lyap
            .solve_schur_coordinates(symmetrize(&m) * -1.0, true)?;
        let zu = matmul(&z, &k.u);
        let svc = matmul(&sv, &k.c);
        Ok((0..nn)
            .map(|i| {
                let cols = off[i]..off[i + 1];
                2.0 * column_dots(&k.u, &zu, cols.clone()) - 2.0 * column_dots(&k.yu, &svc, cols)
            })
            .collect())
    }

    /// [`hvp`](Self::hvp) in the original coordinates (two full Lyapunov solves): the
    /// independent route the tests compare the Schur-coordinate products with.
    #[cfg(test)]
    pub(super) fn hvp_congruence(&self, v: &[f64]) -> Result<Vec<f64>> {
        let net: &Network = &self.eval.net;
        let nn = net.num_sensors();
        let off = net.offsets();
        let (u, r) = (&self.eval.u, &self.eval.r);
        // Σ C_v Σ = U diag(v) Uᵀ.
        let mut uv = u.clone();
        for j in 0..nn {
            uv.columns_mut(off[j], off[j + 1] - off[j]).scale_mut(v[j]);
        }
        let rhs = symmetrize(&matmul_nt(&uv, u));
        let sv = symmetrize(&self.lyap.solve(&rhs)?);
        // B = W Σ'_v + C_v Σ: rows of sensor j get ĉ_j,loc (r_j ĉ_jᵀ Σ'_v + v_j u_jᵀ).
        let n = net.order();
        let mut b = DMatrix::zeros(n, n);
        for (j, s) in net.sensors().iter().enumerate() {
            let rows = s.rows();
            if rows.is_empty() {
                continue;
            }
            let mut inner = s.left_mul_t(&sv) * r[j];
            let uj = u.columns(off[j], s.outputs());
            inner += uj.transpose() * v[j];
            let mut target = b.rows_mut(rows.start, rows.len());
            target.gemm(1.0, s.local(), &inner, 1.0);
        }
        let m = matmul(&b, &self.y);
        let z = self.lyap.solve_adjoint(&(symmetrize(&m) * -1.0))?;
        let zu = matmul(&z, u);
        Ok((0..nn)
            .map(|i| {
                let cols = off[i]..off[i + 1];
                let svc = net.sensors()[i].right_mul(&sv);
                let third: f64 = cols
                    .clone()
                    .enumerate()
                    .map(|(c, k)| self.yu.column(k).dot(&svc.column(c)))
                    .sum();
                2.0 * column_dots(u, &zu, cols) - 2.0 * third
            })
            .collect())
    }
}
