//! Reordering of a real Schur form by adjacent block swaps, as LAPACK's dtrexc/dlaexc: 1×1–1×1
//! swaps by a Givens rotation; swaps involving a 2×2 block by solving the small Sylvester
//! equation `T11·X − X·T22 = scale·T12` (dlasy2-style, with complete pivoting and perturbed
//! pivots), a QR factorisation of `[X; scale·I]`, a provisional swap on a copy of the diagonal
//! block, the swap-rejection test and, if accepted, the update of T and Z and re-standardisation
//! of the 2×2 blocks with dlanv2.

// The 2×2/4×4 kernels below read most clearly with explicit indices.
#![allow(clippy::needless_range_loop)]

use super::kernels::{
    lanv2, larfg, lartg, refl3_cols, refl3_rows, rot_cols, rot_rows, EPS, SAFMIN,
};

/// Why an adjacent swap was not performed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct SwapRejected {
    /// The largest entry the swap would have left where zeros belong.
    pub residual: f64,
    /// The threshold it exceeded, `max(20·eps·‖D‖_max, smlnum)`.
    pub threshold: f64,
}

/// The threshold of the swap-rejection test for a diagonal block with max-norm `dnorm`.
pub(super) fn rejection_threshold(dnorm: f64) -> f64 {
    (20.0 * EPS * dnorm).max(SAFMIN / EPS)
}

/// Whether a provisional swap whose would-be-zero entries have max-norm `residual` is accepted.
pub(super) fn swap_accepted(residual: f64, dnorm: f64) -> bool {
    // `!(a > b)` so that a NaN residual is rejected too.
    residual <= rejection_threshold(dnorm)
}

/// Solves `T11·X − X·T22 = scale·B` for the `n1 × n2` matrix `X` (`n1, n2 ∈ {1, 2}`), the way
/// LAPACK's dlasy2 does with `isgn = −1`: Gaussian elimination with complete pivoting on the
/// Kronecker form, pivots smaller than `smin = max(eps·max|T11, T22|, smlnum)` perturbed to
/// `smin`, and `0 < scale ≤ 1` chosen so that `X` does not overflow. Matrices are row-major 2×2
/// arrays; returns `(X, scale, perturbed)`.
pub(super) fn small_sylvester(
    t11: &[[f64; 2]; 2],
    n1: usize,
    t22: &[[f64; 2]; 2],
    n2: usize,
    b: &[[f64; 2]; 2],
) -> ([[f64; 2]; 2], f64, bool) {
    let smlnum = SAFMIN / EPS;
    let bignum = 1.0 / smlnum;
    let m = n1 * n2;
    // Unknown (i, j) of X has index i + j·n1.
    let mut a = [[0.0f64; 4]; 4];
    let mut rhs = [0.0f64; 4];
    let mut tmax = 0.0f64;
    for i in 0..n1 {
        for k in 0..n1 {
            tmax = tmax.max(t11[i][k].abs());
        }
    }
    for i in 0..n2 {
        for k in 0..n2 {
            tmax = tmax.max(t22[i][k].abs());
        }
    }
    for j in 0..n2 {
        for i in 0..n1 {
            let row = i + j * n1;
            rhs[row] = b[i][j];
            for k in 0..n1 {
                a[row][k + j * n1] += t11[i][k];
            }
            for k in 0..n2 {
                a[row][i + k * n1] -= t22[k][j];
            }
        }
    }
    let smin = (EPS * tmax).max(smlnum);
    let mut perturbed = false;
    let mut colperm = [0usize, 1, 2, 3];
    for s in 0..m {
        // Complete pivoting.
        let (mut pr, mut pc, mut best) = (s, s, -1.0f64);
        for r in s..m {
            for c in s..m {
                if a[r][c].abs() > best {
                    best = a[r][c].abs();
                    pr = r;
                    pc = c;
                }
            }
        }
        if pr != s {
            a.swap(pr, s);
            rhs.swap(pr, s);
        }
        if pc != s {
            for row in a.iter_mut() {
                row.swap(pc, s);
            }
            colperm.swap(pc, s);
        }
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        let tiny = !(a[s][s].abs() >= smin); // also true for NaN
        if tiny {
            a[s][s] = smin;
            perturbed = true;
        }
        for r in s + 1..m {
            let l = a[r][s] / a[s][s];
            if l != 0.0 {
                for c in s + 1..m {
                    a[r][c] -= l * a[s][c];
                }
                rhs[r] -= l * rhs[s];
            }
            a[r][s] = 0.0;
        }
    }
    // Back substitution with scaling against overflow.
    let mut scale = 1.0f64;
    let mut y = [0.0f64; 4];
    for s in (0..m).rev() {
        let mut num = rhs[s];
        for c in s + 1..m {
            num -= a[s][c] * y[c];
        }
        let piv = a[s][s].abs();
        if num.abs() > 1.0 && piv < num.abs() / bignum {
            let f = 0.5 * piv * bignum / num.abs();
            scale *= f;
            num *= f;
            for v in rhs.iter_mut() {
                *v *= f;
            }
            for v in y.iter_mut() {
                *v *= f;
            }
        }
        y[s] = num / a[s][s];
    }
    let mut x = [[0.0f64; 2]; 2];
    for s in 0..m {
        let idx = colperm[s];
        x[idx % n1][idx / n1] = y[s];
    }
    (x, scale, perturbed)
}

/// Applies `H = I − τ·v·vᵀ` from the left to rows `r0..r0+3`, columns `c0..c1` of a 4×4 array.
fn refl_left4(d: &mut [[f64; 4]; 4], r0: usize, c0: usize, c1: usize, v: [f64; 3], tau: f64) {
    for c in c0..c1 {
        let s = v[0] * d[r0][c] + v[1] * d[r0 + 1][c] + v[2] * d[r0 + 2][c];
        for q in 0..3 {
            d[r0 + q][c] -= tau * s * v[q];
        }
    }
}

/// Applies `H = I − τ·v·vᵀ` from the right to columns `c0..c0+3`, rows `r0..r1` of a 4×4 array.
fn refl_right4(d: &mut [[f64; 4]; 4], c0: usize, r0: usize, r1: usize, v: [f64; 3], tau: f64) {
    for row in d[r0..r1].iter_mut() {
        let s = v[0] * row[c0] + v[1] * row[c0 + 1] + v[2] * row[c0 + 2];
        for q in 0..3 {
            row[c0 + q] -= tau * s * v[q];
        }
    }
}

/// Swaps the adjacent diagonal blocks `T11` (order `n1`, starting at row `j1`) and `T22` (order
/// `n2`) of the column-major `n × n` quasi-triangular `t`, updating `z` (column-major `n × n`)
/// — LAPACK's dlaexc. On rejection nothing is modified.
pub(super) fn swap_adjacent(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    j1: usize,
    n1: usize,
    n2: usize,
) -> Result<(), SwapRejected> {
    crate::linalg::dispatch_avx2!(
        swap_adjacent_avx2,
        swap_adjacent_impl,
        (t: &mut [f64], z: &mut [f64], n: usize, j1: usize, n1: usize, n2: usize) -> Result<(), SwapRejected>
    )
}

#[inline(always)]
fn swap_adjacent_impl(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    j1: usize,
    n1: usize,
    n2: usize,
) -> Result<(), SwapRejected> {
    debug_assert!((1..=2).contains(&n1) && (1..=2).contains(&n2) && j1 + n1 + n2 <= n);
    let ld = n;
    let at = |t: &[f64], i: usize, j: usize| t[i + j * ld];
    let j2 = j1 + 1;
    if n1 == 1 && n2 == 1 {
        let t11 = at(t, j1, j1);
        let t22 = at(t, j2, j2);
        let (cs, sn, _) = lartg(at(t, j1, j2), t22 - t11);
        rot_rows(t, ld, j1, j1 + 2..n, cs, sn);
        rot_cols(t, ld, j1, 0..j1, cs, sn);
        t[j1 + j1 * ld] = t22;
        t[j2 + j2 * ld] = t11;
        rot_cols(z, ld, j1, 0..n, cs, sn);
        return Ok(());
    }

    let nd = n1 + n2;
    let mut d = [[0.0f64; 4]; 4];
    let mut dnorm = 0.0f64;
    for (r, row) in d.iter_mut().enumerate().take(nd) {
        for (c, e) in row.iter_mut().enumerate().take(nd) {
            *e = at(t, j1 + r, j1 + c);
            dnorm = dnorm.max(e.abs());
        }
    }
    let mut a11 = [[0.0; 2]; 2];
    let mut a22 = [[0.0; 2]; 2];
    let mut a12 = [[0.0; 2]; 2];
    for r in 0..n1 {
        for c in 0..n1 {
            a11[r][c] = d[r][c];
        }
        for c in 0..n2 {
            a12[r][c] = d[r][n1 + c];
        }
    }
    for r in 0..n2 {
        for c in 0..n2 {
            a22[r][c] = d[n1 + r][n1 + c];
        }
    }
    let (x, scale, _) = small_sylvester(&a11, n1, &a22, n2, &a12);

    match (n1, n2) {
        (1, 2) => {
            // Reflector H with (scale, x11, x12)·H = (0, 0, *).
            let mut u = [scale, x[0][0]];
            let (_, tau) = larfg(x[0][1], &mut u);
            let v = [u[0], u[1], 1.0];
            let t11 = at(t, j1, j1);
            refl_left4(&mut d, 0, 0, 3, v, tau);
            refl_right4(&mut d, 0, 0, 3, v, tau);
            let residual = d[2][0].abs().max(d[2][1].abs()).max((d[2][2] - t11).abs());
            if !swap_accepted(residual, dnorm) {
                return Err(SwapRejected {
                    residual,
                    threshold: rejection_threshold(dnorm),
                });
            }
            refl3_rows(t, ld, j1, j1..n, v, tau);
            refl3_cols(t, ld, j1, 0..j2 + 1, v, tau);
            t[j1 + 2 + j1 * ld] = 0.0;
            t[j1 + 2 + j2 * ld] = 0.0;
            t[j1 + 2 + (j1 + 2) * ld] = t11;
            refl3_cols(z, ld, j1, 0..n, v, tau);
        }
        (2, 1) => {
            // Reflector H with H·(−x11, −x21, scale) = (*, 0, 0).
            let mut u = [-x[1][0], scale];
            let (_, tau) = larfg(-x[0][0], &mut u);
            let v = [1.0, u[0], u[1]];
            let t33 = at(t, j1 + 2, j1 + 2);
            refl_left4(&mut d, 0, 0, 3, v, tau);
            refl_right4(&mut d, 0, 0, 3, v, tau);
            let residual = d[1][0].abs().max(d[2][0].abs()).max((d[0][0] - t33).abs());
            if !swap_accepted(residual, dnorm) {
                return Err(SwapRejected {
                    residual,
                    threshold: rejection_threshold(dnorm),
                });
            }
            refl3_cols(t, ld, j1, 0..j1 + 3, v, tau);
            refl3_rows(t, ld, j1, j2..n, v, tau);
            t[j1 + j1 * ld] = t33;
            t[j2 + j1 * ld] = 0.0;
            t[j1 + 2 + j1 * ld] = 0.0;
            refl3_cols(z, ld, j1, 0..n, v, tau);
        }
        _ => {
            // H2·H1·[−X; scale·I] = [R; 0] with R upper triangular.
            let mut u1 = [-x[1][0], scale];
            let (_, tau1) = larfg(-x[0][0], &mut u1);
            let v1 = [1.0, u1[0], u1[1]];
            // Column 2 of [−X; scale·I] after H1 (rows 2..4 feed H2).
            let temp = -tau1 * (x[0][1] + v1[1] * x[1][1]);
            let mut u2 = [-temp * v1[2], scale];
            let (_, tau2) = larfg(-temp * v1[1] - x[1][1], &mut u2);
            let v2 = [1.0, u2[0], u2[1]];
            refl_left4(&mut d, 0, 0, 4, v1, tau1);
            refl_right4(&mut d, 0, 0, 4, v1, tau1);
            refl_left4(&mut d, 1, 0, 4, v2, tau2);
            refl_right4(&mut d, 1, 0, 4, v2, tau2);
            let residual = d[2][0]
                .abs()
                .max(d[2][1].abs())
                .max(d[3][0].abs())
                .max(d[3][1].abs());
            if !swap_accepted(residual, dnorm) {
                return Err(SwapRejected {
                    residual,
                    threshold: rejection_threshold(dnorm),
                });
            }
            refl3_rows(t, ld, j1, j1..n, v1, tau1);
            refl3_cols(t, ld, j1, 0..j1 + 4, v1, tau1);
            refl3_rows(t, ld, j2, j1..n, v2, tau2);
            refl3_cols(t, ld, j2, 0..j1 + 4, v2, tau2);
            for r in j1 + 2..j1 + 4 {
                for c in j1..j1 + 2 {
                    t[r + c * ld] = 0.0;
                }
            }
            refl3_cols(z, ld, j1, 0..n, v1, tau1);
            refl3_cols(z, ld, j2, 0..n, v2, tau2);
        }
    }

    if n2 == 2 {
        // Standardise the new leading 2×2 block.
        standardise(t, z, n, j1);
    }
    if n1 == 2 {
        // Standardise the new trailing 2×2 block.
        standardise(t, z, n, j1 + n2);
    }
    Ok(())
}

/// Re-standardises the 2×2 block at rows/columns `j, j+1` with dlanv2, applying the rotation to
/// the rest of T and to Z. The block may split into two 1×1 blocks (exact zero subdiagonal).
#[inline(always)]
pub(super) fn standardise(t: &mut [f64], z: &mut [f64], n: usize, j: usize) {
    let ld = n;
    let r = lanv2(
        t[j + j * ld],
        t[j + (j + 1) * ld],
        t[j + 1 + j * ld],
        t[j + 1 + (j + 1) * ld],
    );
    t[j + j * ld] = r.a;
    t[j + (j + 1) * ld] = r.b;
    t[j + 1 + j * ld] = r.c;
    t[j + 1 + (j + 1) * ld] = r.d;
    rot_rows(t, ld, j, j + 2..n, r.cs, r.sn);
    rot_cols(t, ld, j, 0..j, r.cs, r.sn);
    rot_cols(z, ld, j, 0..n, r.cs, r.sn);
}

/// Size (1 or 2) of the block starting at row `j`.
#[inline]
pub(super) fn block_size_at(t: &[f64], n: usize, j: usize) -> usize {
    if j + 1 < n && t[j + 1 + j * n] != 0.0 {
        2
    } else {
        1
    }
}

/// Size (1 or 2) of the block ending at row `j`.
#[inline]
fn block_size_ending_at(t: &[f64], n: usize, j: usize) -> usize {
    if j >= 1 && t[j + (j - 1) * n] != 0.0 {
        2
    } else {
        1
    }
}

/// Moves the diagonal block starting at row `ifst` to start at row `ilst` by adjacent swaps
/// (LAPACK's dtrexc; both directions). `ifst` and `ilst` are first adjusted to the first row of
/// their blocks. Returns the row where the block finally starts. On rejection, returns the
/// rejection and the row the block had reached; T and Z then hold the partially moved (still
/// valid) Schur form.
pub(super) fn move_block(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    ifst: usize,
    ilst: usize,
) -> Result<usize, (SwapRejected, usize)> {
    crate::linalg::dispatch_avx2!(
        move_block_avx2,
        move_block_impl,
        (t: &mut [f64], z: &mut [f64], n: usize, ifst: usize, ilst: usize) -> Result<usize, (SwapRejected, usize)>
    )
}

#[inline(always)]
fn move_block_impl(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    ifst: usize,
    ilst: usize,
) -> Result<usize, (SwapRejected, usize)> {
    if n <= 1 {
        return Ok(ifst.min(n.saturating_sub(1)));
    }
    let mut ifst = ifst;
    let mut ilst = ilst;
    if ifst > 0 && t[ifst + (ifst - 1) * n] != 0.0 {
        ifst -= 1;
    }
    let mut nbf = block_size_at(t, n, ifst);
    if ilst > 0 && t[ilst + (ilst - 1) * n] != 0.0 {
        ilst -= 1;
    }
    let nbl = block_size_at(t, n, ilst);
    if ifst == ilst {
        return Ok(ilst);
    }
    let mut here = ifst;
    if ifst < ilst {
        // Move down.
        if nbf == 2 && nbl == 1 {
            ilst -= 1;
        }
        if nbf == 1 && nbl == 2 {
            ilst += 1;
        }
        let mut guard = 0usize;
        while here < ilst {
            guard += 1;
            if guard > 2 * n {
                break;
            }
            if nbf != 3 {
                if here + nbf >= n {
                    break;
                }
                let nbnext = block_size_at(t, n, here + nbf);
                swap_adjacent(t, z, n, here, nbf, nbnext).map_err(|e| (e, here))?;
                here += nbnext;
                if nbf == 2 && t[here + 1 + here * n] == 0.0 {
                    nbf = 3;
                }
            } else {
                // Two 1×1 blocks (a split 2×2) at here, here+1: move each individually.
                if here + 2 >= n {
                    break;
                }
                let nbnext = block_size_at(t, n, here + 2);
                swap_adjacent(t, z, n, here + 1, 1, nbnext).map_err(|e| (e, here))?;
                if nbnext == 2 && t[here + 2 + (here + 1) * n] != 0.0 {
                    swap_adjacent(t, z, n, here, 1, 2).map_err(|e| (e, here))?;
                } else {
                    swap_adjacent(t, z, n, here, 1, 1).map_err(|e| (e, here))?;
                    if nbnext == 2 {
                        swap_adjacent(t, z, n, here + 1, 1, 1).map_err(|e| (e, here))?;
                    }
                }
                here += nbnext;
            }
        }
    } else {
        // Move up.
        let mut guard = 0usize;
        while here > ilst {
            guard += 1;
            if guard > 2 * n {
                break;
            }
            let nbnext = block_size_ending_at(t, n, here - 1);
            if nbf != 3 {
                swap_adjacent(t, z, n, here - nbnext, nbnext, nbf).map_err(|e| (e, here))?;
                here -= nbnext;
                if nbf == 2 && t[here + 1 + here * n] == 0.0 {
                    nbf = 3;
                }
            } else {
                // Two 1×1 blocks (a split 2×2) at here, here+1: move each individually.
                swap_adjacent(t, z, n, here - nbnext, nbnext, 1).map_err(|e| (e, here))?;
                // The block passed over now occupies here−nbnext+1..=here.
                if nbnext == 2 && t[here + (here - 1) * n] != 0.0 {
                    swap_adjacent(t, z, n, here - 1, 2, 1).map_err(|e| (e, here))?;
                } else {
                    swap_adjacent(t, z, n, here, 1, 1).map_err(|e| (e, here))?;
                    if nbnext == 2 {
                        swap_adjacent(t, z, n, here - 1, 1, 1).map_err(|e| (e, here))?;
                    }
                }
                here -= nbnext;
            }
        }
    }
    Ok(here)
}
