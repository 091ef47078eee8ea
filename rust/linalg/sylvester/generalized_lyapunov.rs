//! The generalised Lyapunov operator `X ↦ Aᵀ X E + Eᵀ X A` with the pencil `(A, E)` factored once
//! by its real generalised Schur form (SLICOT SG03AD, Penzl's method), for many symmetric
//! right-hand sides.
//!
//! With `A = Q S Zᵀ`, `E = Q T Zᵀ` ([`GeneralizedSchur`]) and `Y = Qᵀ X Q`,
//!
//! ```text
//! Aᵀ X E + Eᵀ X A = C   ⇔   Sᵀ Y T + Tᵀ Y S = Zᵀ C Z,   X = Q Y Qᵀ.
//! ```
//!
//! `S` upper quasi-triangular and `T` upper triangular make the transformed equation block lower
//! triangular in `Y`'s block columns and, within a block column, in its block rows: block
//! `(I, J)` satisfies
//!
//! ```text
//! S_IIᵀ Y_IJ T_JJ + T_IIᵀ Y_IJ S_JJ = W_IJ − Σ_{(p, q) < (I, J)} (S_pIᵀ Y_pq T_qJ + T_pIᵀ Y_pq S_qJ),
//! ```
//!
//! a system of order `|I|·|J| ≤ 4` (Kronecker form `(T_JJᵀ ⊗ S_IIᵀ + S_JJᵀ ⊗ T_IIᵀ) vec Y_IJ`),
//! solved by Gaussian elimination with complete pivoting. Its pivots are
//! `t_ii t_jj (λ_i + λ_j)` for the generalised eigenvalues `λ = s/t`: the equation is singular
//! iff two eigenvalues sum to zero. A pivot below `rtol` times the size of the products that
//! form it (`|s_ii t_jj| + |t_ii s_jj|` for 1×1 blocks) stops the solve with
//! [`Error::SingularProblem`] — a relative test that an ill-conditioned `E` (tiny `t_ii`, huge
//! eigenvalues) does not trigger. `Y` is symmetric for symmetric `C`; only its lower block
//! triangle is solved and the upper one copied. The sums are accumulated block column by block
//! column (`w = Y[:, <J] T[<J, J]`, `v = Y[:, <J] S[<J, J]`), `O(n³)` in all.
//!
//! Working on the pencil, not on `A E⁻¹`, keeps the solve backward stable for ill-conditioned
//! `E`: the QZ form is exact for `(A + δA, E + δE)` with `‖δA‖ ~ eps‖A‖`, `‖δE‖ ~ eps‖E‖`.

use super::DEFAULT_SINGULAR_RTOL;
use crate::linalg::dense::{check_finite, check_shape, dot, matmul, matmul_tn, symmetrize};
use crate::linalg::qz::GeneralizedSchur;
use crate::{Error, Result};
use nalgebra::DMatrix;

/// The operator `X ↦ Aᵀ X E + Eᵀ X A` with `(A, E)` in generalised Schur form.
#[derive(Debug, Clone)]
pub struct GeneralizedLyapunov {
    form: GeneralizedSchur,
    rtol: f64,
}

impl GeneralizedLyapunov {
    /// Factors the pencil `(a, e)` (square, same order, finite).
    pub fn new(a: &DMatrix<f64>, e: &DMatrix<f64>) -> Result<Self> {
        Ok(GeneralizedLyapunov {
            form: GeneralizedSchur::new(a, e)?,
            rtol: DEFAULT_SINGULAR_RTOL,
        })
    }

    /// The generalised Schur form of the pencil.
    pub fn form(&self) -> &GeneralizedSchur {
        &self.form
    }

    /// Solves `Aᵀ X E + Eᵀ X A = C` for symmetric `C` (symmetrised; the solution is exactly
    /// symmetric). Errors: [`Error::Shape`], [`Error::NonFinite`], [`Error::SingularProblem`]
    /// (two eigenvalues summing to zero to within the tolerance, or a solution that overflows).
    pub fn solve_adjoint(&self, c: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let n = self.form.order();
        check_shape("C", c, n, n)?;
        check_finite("C", c)?;
        let f = &self.form;
        let w = symmetrize(&matmul_tn(&f.z, &matmul(&symmetrize(c), &f.z)));
        let y = triangular(&f.s, &f.t, &w, &f.blocks(), self.rtol)?;
        let x = symmetrize(&matmul(&f.q, &matmul(&y, &f.q.transpose())));
        if x.iter().all(|v| v.is_finite()) {
            Ok(x)
        } else {
            Err(Error::SingularProblem(
                "the generalised Lyapunov solution is not representable (overflow)".into(),
            ))
        }
    }
}

/// `Sᵀ Y T + Tᵀ Y S = W` for symmetric `W` (module documentation), `blocks` the diagonal blocks.
fn triangular(
    s: &DMatrix<f64>,
    t: &DMatrix<f64>,
    w: &DMatrix<f64>,
    blocks: &[(usize, usize)],
    rtol: f64,
) -> Result<DMatrix<f64>> {
    let n = s.nrows();
    let mut y = DMatrix::<f64>::zeros(n, n);
    for (jb, &(j0, bj)) in blocks.iter().enumerate() {
        crate::cancel::check("the generalised Lyapunov solve")?;
        // Rows above the diagonal block: by symmetry, from the block rows solved before.
        for i in 0..j0 {
            for c in 0..bj {
                y[(i, j0 + c)] = y[(j0 + c, i)];
            }
        }
        // rhs = W[:, J] − Sᵀ w − Tᵀ v with w = Y[:, <J] T[<J, J], v = Y[:, <J] S[<J, J]
        // (rows from j0 on).
        let mut rhs = w.view((j0, j0), (n - j0, bj)).into_owned();
        if j0 > 0 {
            let y_left = y.view((0, 0), (n, j0));
            let wv = y_left * t.view((0, j0), (j0, bj));
            let vv = y_left * s.view((0, j0), (j0, bj));
            rhs -= s.view((0, j0), (n, n - j0)).transpose() * wv;
            rhs -= t.view((0, j0), (n, n - j0)).transpose() * vv;
        }
        let (s_jj, t_jj) = (block(s, j0, j0, bj, bj), block(t, j0, j0, bj, bj));
        for &(i0, bi) in &blocks[jb..] {
            let mut r = [[0.0f64; 2]; 2];
            for (row, r_row) in r.iter_mut().enumerate().take(bi) {
                for (c, v) in r_row.iter_mut().enumerate().take(bj) {
                    *v = rhs[(i0 - j0 + row, c)];
                }
            }
            if i0 > 0 {
                // Σ_{p < I} S_pIᵀ Y_pJ T_JJ + T_pIᵀ Y_pJ S_JJ: columns of S, T and Y are
                // contiguous (column-major), so each entry is one dot product.
                let (sv, tv, yv) = (s.as_slice(), t.as_slice(), y.as_slice());
                let mut a1 = [[0.0f64; 2]; 2];
                let mut a2 = [[0.0f64; 2]; 2];
                for c in 0..bj {
                    let yc = &yv[(j0 + c) * n..(j0 + c) * n + i0];
                    for row in 0..bi {
                        let col = (i0 + row) * n;
                        a1[row][c] = dot(&sv[col..col + i0], yc);
                        a2[row][c] = dot(&tv[col..col + i0], yc);
                    }
                }
                for row in 0..bi {
                    for c in 0..bj {
                        let mut acc = 0.0;
                        for k in 0..bj {
                            acc += a1[row][k] * t_jj[k][c] + a2[row][k] * s_jj[k][c];
                        }
                        r[row][c] -= acc;
                    }
                }
            }
            let (s_ii, t_ii) = (block(s, i0, i0, bi, bi), block(t, i0, i0, bi, bi));
            let sol = small_solve(&s_ii, &t_ii, &s_jj, &t_jj, &r, (bi, bj), rtol)?;
            for (row, sol_row) in sol.iter().enumerate().take(bi) {
                for (c, v) in sol_row.iter().enumerate().take(bj) {
                    y[(i0 + row, j0 + c)] = *v;
                }
            }
        }
    }
    // The diagonal blocks are symmetric in exact arithmetic; the upper triangle mirrors the lower.
    Ok(DMatrix::from_fn(n, n, |i, j| {
        if i >= j {
            y[(i, j)]
        } else {
            y[(j, i)]
        }
    }))
}

/// The `br × bc` block of `m` at `(r0, c0)` (`br, bc ≤ 2`), zero-padded.
fn block(m: &DMatrix<f64>, r0: usize, c0: usize, br: usize, bc: usize) -> [[f64; 2]; 2] {
    let mut out = [[0.0f64; 2]; 2];
    for (i, row) in out.iter_mut().enumerate().take(br) {
        for (j, v) in row.iter_mut().enumerate().take(bc) {
            *v = m[(r0 + i, c0 + j)];
        }
    }
    out
}

/// `S_IIᵀ Y T_JJ + T_IIᵀ Y S_JJ = R` (order `bi·bj ≤ 4`) by complete pivoting.
fn small_solve(
    s_ii: &[[f64; 2]; 2],
    t_ii: &[[f64; 2]; 2],
    s_jj: &[[f64; 2]; 2],
    t_jj: &[[f64; 2]; 2],
    r: &[[f64; 2]; 2],
    (bi, bj): (usize, usize),
    rtol: f64,
) -> Result<[[f64; 2]; 2]> {
    let m = bi * bj;
    // K[r + c·bi][r' + c'·bi] = T_JJ[c', c]·S_II[r', r] + S_JJ[c', c]·T_II[r', r].
    let mut k = [[0.0f64; 4]; 4];
    let mut scale = 0.0f64;
    for c in 0..bj {
        for row in 0..bi {
            for c2 in 0..bj {
                for r2 in 0..bi {
                    let p1 = t_jj[c2][c] * s_ii[r2][row];
                    let p2 = s_jj[c2][c] * t_ii[r2][row];
                    k[row + c * bi][r2 + c2 * bi] = p1 + p2;
                    scale = scale.max(p1.abs() + p2.abs());
                }
            }
        }
    }
    let mut rhs = [0.0f64; 4];
    for c in 0..bj {
        for row in 0..bi {
            rhs[row + c * bi] = r[row][c];
        }
    }
    let smin = rtol * scale;
    let mut perm = [0usize, 1, 2, 3];
    for step in 0..m {
        // Complete pivoting.
        let (mut pi, mut pj, mut best) = (step, step, -1.0);
        for (i, row) in k.iter().enumerate().take(m).skip(step) {
            for (j, v) in row.iter().enumerate().take(m).skip(step) {
                if v.abs() > best {
                    (pi, pj, best) = (i, j, v.abs());
                }
            }
        }
        if !(best > smin) || best < f64::MIN_POSITIVE {
            return Err(Error::SingularProblem(format!(
                "the generalised Lyapunov equation is singular to working precision (pivot \
                 {best:.1e} against {scale:.1e}): two generalised eigenvalues sum to zero"
            )));
        }
        k.swap(step, pi);
        rhs.swap(step, pi);
        for row in k.iter_mut() {
            row.swap(step, pj);
        }
        perm.swap(step, pj);
        for i in step + 1..m {
            let f = k[i][step] / k[step][step];
            for j in step..m {
                k[i][j] -= f * k[step][j];
            }
            rhs[i] -= f * rhs[step];
        }
    }
    let mut sol = [0.0f64; 4];
    for i in (0..m).rev() {
        let mut acc = rhs[i];
        for j in i + 1..m {
            acc -= k[i][j] * sol[j];
        }
        sol[i] = acc / k[i][i];
    }
    let mut out = [[0.0f64; 2]; 2];
    for (pos, &var) in perm.iter().enumerate().take(m) {
        out[var % bi][var / bi] = sol[pos];
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::dense::norm_fro;
    use crate::linalg::testing::Rng;

    fn apply(a: &DMatrix<f64>, e: &DMatrix<f64>, x: &DMatrix<f64>) -> DMatrix<f64> {
        a.transpose() * x * e + e.transpose() * x * a
    }

    #[test]
    fn solves_random_stable_pencils_to_small_residuals() {
        let mut rng = Rng::new(21);
        for &n in &[1usize, 2, 3, 5, 8, 17, 30] {
            let e = rng.matrix(n, n) + DMatrix::identity(n, n) * 3.0;
            // A = (M − shift·I) E with M shifted stable: the pencil's eigenvalues are M's.
            let m = rng.matrix(n, n);
            let shift = m
                .complex_eigenvalues()
                .iter()
                .map(|l| l.re)
                .fold(0.0, f64::max)
                + 1.0;
            let a = (m - DMatrix::identity(n, n) * shift) * &e;
            let c = -rng.psd(n, n) - DMatrix::identity(n, n);
            let op = GeneralizedLyapunov::new(&a, &e).unwrap();
            let x = op.solve_adjoint(&c).unwrap();
            let res = norm_fro(&(apply(&a, &e, &x) - &c));
            let scale = 2.0 * norm_fro(&a) * norm_fro(&e) * norm_fro(&x) + norm_fro(&c);
            assert!(res <= 1e-14 * scale, "n={n}: {:e}", res / scale);
            assert_eq!(x, x.transpose());
            // A stable pencil and C ⪯ 0 give X ⪰ 0.
            assert!(x.clone().symmetric_eigen().eigenvalues.min() > -1e-12 * x.norm());
        }
    }

    #[test]
    fn an_ill_conditioned_e_is_solved_to_a_backward_stable_residual() {
        let mut rng = Rng::new(4);
        let n = 6;
        let u = rng.matrix(n, n).qr().q();
        let v = rng.matrix(n, n).qr().q();
        for k in [4, 8, 12] {
            let d = DMatrix::from_diagonal(&nalgebra::DVector::from_fn(n, |i, _| {
                10f64.powf(-(k as f64) * i as f64 / (n - 1) as f64)
            }));
            let e = &u * d * v.transpose();
            let a = -(&e) * 2.0 + rng.matrix(n, n) * 0.1;
            let op = match GeneralizedLyapunov::new(&a, &e) {
                Ok(op) => op,
                Err(err) => panic!("k={k}: {err}"),
            };
            let c = -DMatrix::identity(n, n);
            let x = op.solve_adjoint(&c).unwrap();
            let res = norm_fro(&(apply(&a, &e, &x) - &c));
            let scale = 2.0 * norm_fro(&a) * norm_fro(&e) * norm_fro(&x) + norm_fro(&c);
            assert!(res <= 1e-13 * scale, "k={k}: {:e}", res / scale);
        }
    }

    #[test]
    fn a_singular_equation_is_refused() {
        // Eigenvalues ±1: λ₁ + λ₂ = 0.
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let e = DMatrix::identity(2, 2);
        let op = GeneralizedLyapunov::new(&a, &e).unwrap();
        assert!(matches!(
            op.solve_adjoint(&DMatrix::identity(2, 2)),
            Err(Error::SingularProblem(_))
        ));
    }
}
