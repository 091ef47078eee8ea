//! Symplectic balancing of a Hamiltonian matrix (Benner 2001; the scaling of scipy's
//! `solve_continuous_are(balanced=True)` and of SLICOT MB04DD).
//!
//! A diagonal similarity `D_b M D_b⁻¹` of the off-diagonal magnitudes `M = |H|` (diagonal removed) is
//! found as LAPACK's dgebal finds it (rows and columns of equal 2-norm, powers of two, no
//! permutation), and then forced into the symplectic form `T = diag(D, D⁻¹)`, `D = diag(2^k)`, with
//! `k_i` the rounded mean of the two exponents it must approximate (`k_i ≈ e_i ≈ −e_{n+i}`). A
//! symplectic similarity keeps the Hamiltonian structure, and for `H = [[A, −G], [−Q, −Aᵀ]]`
//!
//! `T H T⁻¹ = [[D A D⁻¹, −D G D], [−D⁻¹ Q D⁻¹, −(D A D⁻¹)ᵀ]]`,
//!
//! the Hamiltonian of the CARE with data `(DAD⁻¹, DGD, D⁻¹QD⁻¹)`, whose solution is `X̃ = D⁻¹ X D⁻¹`.
//! Powers of two make every scaling exact in floating point.

use nalgebra::DMatrix;

/// At most this many sweeps over all rows and columns (dgebal needs a handful; the bound makes the
/// loop finite whatever the values).
const MAX_SWEEPS: usize = 64;

/// Exponents are kept within `±MAX_EXPONENT` so that `D G D` and `D⁻¹ Q D⁻¹` cannot be scaled out of
/// the floating-point range by the balancing itself (entries are at most `2^(2·MAX_EXPONENT)` times
/// larger or smaller).
const MAX_EXPONENT: i32 = 200;

/// The exponents `k` of the symplectic balancing `D = diag(2^k)` of the Hamiltonian of
/// `AᵀX + XA − XGX + Q = 0` (all zero when the Hamiltonian is already balanced).
pub fn symplectic_exponents(a: &DMatrix<f64>, g: &DMatrix<f64>, q: &DMatrix<f64>) -> Vec<i32> {
    let n = a.nrows();
    let m = 2 * n;
    // |H| without its diagonal, kept scaled as the exponents change: M'_{ij} = M_{ij}·2^(e_i − e_j).
    let mut h = DMatrix::<f64>::zeros(m, m);
    for j in 0..n {
        for i in 0..n {
            h[(i, j)] = a[(i, j)].abs();
            h[(i, n + j)] = g[(i, j)].abs();
            h[(n + i, j)] = q[(i, j)].abs();
            h[(n + i, n + j)] = a[(j, i)].abs();
        }
    }
    for i in 0..m {
        h[(i, i)] = 0.0;
    }
    let e = dgebal_exponents(&mut h);
    (0..n)
        .map(|i| {
            let k = (f64::from(e[i] - e[n + i]) / 2.0).round() as i32;
            k.clamp(-MAX_EXPONENT, MAX_EXPONENT)
        })
        .collect()
}

/// dgebal's scaling loop (2-norms, powers of two, the 0.95 acceptance rule that prevents cycling)
/// on the non-negative matrix `m`, which is scaled in place. Returns the exponents `e` with
/// `m_out = diag(2^e) m_in diag(2^−e)`.
fn dgebal_exponents(m: &mut DMatrix<f64>) -> Vec<i32> {
    let n = m.nrows();
    let mut e = vec![0i32; n];
    for _ in 0..MAX_SWEEPS {
        let mut changed = false;
        for i in 0..n {
            let c = m.column(i).norm();
            let r = m.row(i).norm();
            if !(c > 0.0 && r > 0.0 && c.is_finite() && r.is_finite()) {
                continue;
            }
            // Row i times f, column i over f: the power of two f with c/f ≈ r·f, from the
            // exponents directly (no loop on the values).
            let f_exp = ((c.log2() - r.log2()) / 2.0).round();
            if !f_exp.is_finite() || f_exp == 0.0 {
                continue;
            }
            let f_exp = f_exp.clamp(-64.0, 64.0) as i32;
            let total = e[i] + f_exp;
            if total.abs() > 2 * MAX_EXPONENT {
                continue;
            }
            let f = 2f64.powi(f_exp);
            if c / f + r * f >= 0.95 * (c + r) {
                continue;
            }
            // Row i multiplied by f, column i divided by f (M' = F M F⁻¹).
            for j in 0..n {
                m[(i, j)] *= f;
                m[(j, i)] /= f;
            }
            e[i] = total;
            changed = true;
        }
        if !changed {
            break;
        }
    }
    e
}

/// `D A D⁻¹`, `D G D`, `D⁻¹ Q D⁻¹` for `D = diag(2^k)` (exact).
pub fn apply(
    k: &[i32],
    a: &DMatrix<f64>,
    g: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> (DMatrix<f64>, DMatrix<f64>, DMatrix<f64>) {
    let d: Vec<f64> = k.iter().map(|&e| 2f64.powi(e)).collect();
    let n = a.nrows();
    let ab = DMatrix::from_fn(n, n, |i, j| a[(i, j)] * d[i] / d[j]);
    (ab, congruence(g, &d, 1.0), inverse_congruence(q, &d, 1.0))
}

/// `s·D M D` for the diagonal `D = diag(d)` (exact for powers of two).
pub fn congruence(m: &DMatrix<f64>, d: &[f64], s: f64) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)] * d[i] * d[j] * s)
}

/// `D⁻¹ M D⁻¹ / s` for the diagonal `D = diag(d)` (exact for powers of two).
pub fn inverse_congruence(m: &DMatrix<f64>, d: &[f64], s: f64) -> DMatrix<f64> {
    // Multiplying by the reciprocals is the same (every step exact or rounded at the same point)
    // when they are normal powers of two; otherwise divide.
    let normal = |v: f64| (2f64.powi(-1000)..=2f64.powi(1000)).contains(&v.abs());
    if !(normal(s) && d.iter().all(|&v| normal(v))) {
        return DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)] / d[i] / d[j] / s);
    }
    let rd: Vec<f64> = d.iter().map(|&v| 1.0 / v).collect();
    let rs = 1.0 / s;
    let mut out = m.clone();
    for (j, col) in out.as_mut_slice().chunks_exact_mut(m.nrows()).enumerate() {
        let cj = rd[j];
        for (v, &ri) in col.iter_mut().zip(&rd) {
            *v = *v * ri * cj * rs;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    #[test]
    fn balanced_problem_has_the_hamiltonian_of_the_similarity() {
        let mut rng = Rng::new(4);
        let n = 4;
        let mut a = rng.matrix(n, n);
        let mut g = rng.psd(n, n);
        let mut q = rng.psd(n, n);
        // Bad scaling: state 0 in micro-units, state 3 in mega-units.
        let s = [1e-6, 1.0, 1.0, 1e6];
        for i in 0..n {
            for j in 0..n {
                a[(i, j)] *= s[i] / s[j];
                g[(i, j)] *= s[i] * s[j];
                q[(i, j)] /= s[i] * s[j];
            }
        }
        let k = symplectic_exponents(&a, &g, &q);
        assert!(k[0] > 10 && k[3] < -10, "{k:?}");
        let (ab, gb, qb) = apply(&k, &a, &g, &q);
        // The balanced data are within a few powers of two of unit scale.
        for m in [&ab, &gb, &qb] {
            assert!(m.amax() < 1e3, "{m}");
        }
    }

    #[test]
    fn zero_and_subnormal_data_terminate() {
        let n = 3;
        let z = DMatrix::<f64>::zeros(n, n);
        assert_eq!(symplectic_exponents(&z, &z, &z), vec![0; n]);
        let tiny = DMatrix::from_element(n, n, 5e-324);
        let big = DMatrix::from_element(n, n, 1e300);
        let k = symplectic_exponents(&tiny, &big, &tiny);
        assert!(k.iter().all(|e| e.abs() <= MAX_EXPONENT));
    }
}
