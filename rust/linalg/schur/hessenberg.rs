//! Blocked Householder reduction to upper Hessenberg form, in the style of LAPACK's dgehrd with
//! dlahr2's panel factorisation, and the blocked accumulation of `Z` (dorghr), on column-major
//! `n × n` slices. A cancellation poll runs before every panel and before every block of `Z`,
//! so a reduction of order 1500 stops within a few hundredths of a second of a cancel.
//!
//! The algorithm, for a panel of `ib` columns starting at column `p` (reflector `k` acts on rows
//! `k+1..n`, `v_k = (0, …, 0, 1, A[k+2..n, k])`):
//!
//! * panel (dlahr2): for each column `j = p + c`, apply the `c` reflectors of the panel found so
//!   far from the right (`A[:, j] −= Y[:, ..c]·V[j, ..c]ᵀ`) and from the left
//!   (`(I − V Tᵀ Vᵀ)`), generate reflector `j` (`larfg`), then extend `Y = A·V·T` (`A` as it was
//!   before the panel) and the upper triangular `T` with `Q_panel = I − V T Vᵀ`;
//! * trailing update: `A ← (I − V Tᵀ Vᵀ)(A − Y Vᵀ)` on the columns right of the panel, and the
//!   rows above the panel's reach of its own columns, all as matrix products (faer's `matmul`,
//!   sequential);
//! * `Z = Q_0 Q_1 ⋯` formed backwards from the identity, each block reflector as three products
//!   (`W = Vᵀ Z`, `W ← T W`, `Z −= V W`).
//!
//! Every column is reduced by the panel code (the last panel is simply narrower), so there is no
//! separate unblocked tail.

use super::kernels::larfg as larfg_plain;
use faer::linalg::matmul::matmul;
use faer::prelude::Reborrow;
use faer::{Accum, MatMut, MatRef, Par};

/// Panel width (columns per block reflector) for order `n`. Measured on the 2-core development
/// machine (`hessenberg_timing`): 16 is 10–20 % faster than 32 up to n ≈ 400 (less extra work
/// in `T` and the top rows of `Y`); from n ≈ 600 on the widths 16…32 are within noise and 32
/// forms `Z` faster (rank-32 updates).
pub(super) fn panel_width(n: usize) -> usize {
    if n < 600 {
        16
    } else {
        32
    }
}

/// Reduces the column-major `n × n` matrix `h` (`n ≥ 3`) to upper Hessenberg form in place with
/// panels of `nb ≥ 1` columns and returns the orthogonal `Z` (column-major) with `A = Z H Zᵀ`;
/// entries below the subdiagonal are set to exactly zero.
///
/// `poll` is called before every panel and before every block of `Z`; its first error is
/// returned at once, leaving `h` partially reduced (unusable).
pub(super) fn reduce_blocked<E>(
    h: &mut [f64],
    n: usize,
    nb: usize,
    poll: &mut impl FnMut() -> Result<(), E>,
) -> Result<Vec<f64>, E> {
    assert!(n >= 3 && nb >= 1 && h.len() == n * n);
    let nb = nb.min(n - 2);
    // Per panel starting at column p: its T in columns p..p+ib of `ts` (rows 0..ib, ld nb).
    let mut ts = vec![0.0; nb * (n - 2)];
    let mut ws = Workspace::new(n, nb);
    let mut p = 0;
    while p < n - 2 {
        poll()?;
        let ib = nb.min(n - 2 - p);
        let t = &mut ts[p * nb..(p + ib) * nb];
        panel(h, n, p, ib, nb, t, &mut ws);
        trailing_update(h, n, p, ib, nb, t, &mut ws);
        p += ib;
    }
    let z = form_z(h, n, nb, &ts, &mut ws, poll)?;
    for j in 0..n {
        for x in &mut h[j * n + (j + 2).min(n)..(j + 1) * n] {
            *x = 0.0;
        }
    }
    Ok(z)
}

/// dlarfg with `beta = −sign(alpha)·‖(alpha, x)‖₂` correct to about half an ulp (a double-double
/// sum of squares and one Newton step on the square root), so that `τ` and `v` describe an
/// orthogonal reflector to working precision however long `x` is. `kernels::larfg`'s fast path
/// sums the squares plainly, which is right for the short vectors of the QR sweeps but loses up
/// to `√m` ulps in `beta` on long columns. Measured on CAREX 20's balanced 842×842 Hamiltonian:
/// normwise backward error of the reduction 2.5e-15 with the plain sum, 1.3e-15 with this one
/// (LAPACK's dgehrd 1.4e-15, faer 1.3e-15), worst column-wise 1.0e-13 → 2.8e-14 (LAPACK 3.3e-14);
/// and the asymmetry of the CARE's stable subspace, which depends on it, 3.6e-8…6.8e-8 →
/// 5.2e-9…1.6e-8 over panel widths 1…48 (see `solve_care`'s `LAGRANGIAN_TOL`, 1.5e-8).
/// Outside the range where no square can overflow or underflow, the scaled `kernels::larfg`.
pub(super) fn larfg(alpha: f64, x: &mut [f64]) -> (f64, f64) {
    let mx = x.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
    if mx == 0.0 {
        return (alpha, 0.0);
    }
    if !(mx > 1e-150 && mx < 1e150 && alpha.abs() < 1e150) {
        return larfg_plain(alpha, x);
    }
    let beta = -norm_dd(alpha, x).copysign(alpha);
    let tau = (beta - alpha) / beta;
    let scal = 1.0 / (alpha - beta);
    x.iter_mut().for_each(|v| *v *= scal);
    (beta, tau)
}

/// `‖(alpha, x)‖₂` to about half an ulp for entries whose squares neither overflow nor underflow.
fn norm_dd(alpha: f64, x: &[f64]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "avx2,fma")]
        fn fast(alpha: f64, x: &[f64]) -> f64 {
            norm_dd_impl(alpha, x)
        }
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { fast(alpha, x) };
        }
    }
    norm_dd_impl(alpha, x)
}

#[inline(always)]
fn norm_dd_impl(alpha: f64, x: &[f64]) -> f64 {
    // Knuth's TwoSum: s + e = a + b exactly.
    #[inline(always)]
    fn two_sum(a: f64, b: f64) -> (f64, f64) {
        let s = a + b;
        let bb = s - a;
        (s, (a - (s - bb)) + (b - bb))
    }
    // hi + lo = alpha² + Σ x² (each square split exactly into v·v and its FMA error), four lanes.
    let mut hi = [alpha * alpha, 0.0, 0.0, 0.0];
    let mut lo = [alpha.mul_add(alpha, -hi[0]), 0.0, 0.0, 0.0];
    let chunks = x.chunks_exact(4);
    let rest = chunks.remainder();
    for ch in chunks {
        for q in 0..4 {
            let p = ch[q] * ch[q];
            let (t, e) = two_sum(hi[q], p);
            hi[q] = t;
            lo[q] += e + ch[q].mul_add(ch[q], -p);
        }
    }
    for &v in rest {
        let p = v * v;
        let (t, e) = two_sum(hi[0], p);
        hi[0] = t;
        lo[0] += e + v.mul_add(v, -p);
    }
    let (mut s, mut c) = (hi[0], lo[0]);
    for q in 1..4 {
        let (t, e) = two_sum(s, hi[q]);
        s = t;
        c += e + lo[q];
    }
    // r = √s rounded, then one Newton step on s + c: r + (s + c − r²)/(2r), r² exactly by FMA.
    let r = s.sqrt();
    let rr = r * r;
    r + ((s - rr) - r.mul_add(r, -rr) + c) / (2.0 * r)
}

/// Scratch buffers, allocated once per reduction.
struct Workspace {
    /// `V` of the current panel, `n × nb` column-major: row `i` is row `i` of the matrix
    /// (explicit zeros above each reflector's unit entry).
    v: Vec<f64>,
    /// `Y = A·V·T`, `n × nb`.
    y: Vec<f64>,
    /// `nb × n` products (`Vᵀ A`, `Vᵀ Z`) and their `T`-multiples.
    w: Vec<f64>,
    w2: Vec<f64>,
    /// `n × nb` temporary for the top rows of `Y`.
    tmp: Vec<f64>,
    /// Short vector of the panel's left update.
    s: Vec<f64>,
}

impl Workspace {
    fn new(n: usize, nb: usize) -> Self {
        Workspace {
            v: vec![0.0; n * nb],
            y: vec![0.0; n * nb],
            w: vec![0.0; nb * n],
            w2: vec![0.0; nb * n],
            tmp: vec![0.0; n * nb],
            s: vec![0.0; nb],
        }
    }
}

/// Column-major view of the `nr × nc` block at `(r, c)` of a buffer with leading dimension `ld`.
fn view(s: &[f64], ld: usize, r: usize, c: usize, nr: usize, nc: usize) -> MatRef<'_, f64> {
    MatRef::from_column_major_slice_with_stride(s, ld, s.len() / ld, ld).submatrix(r, c, nr, nc)
}

/// Mutable counterpart of [`view`].
fn view_mut(s: &mut [f64], ld: usize, r: usize, c: usize, nr: usize, nc: usize) -> MatMut<'_, f64> {
    let cols = s.len() / ld;
    MatMut::from_column_major_slice_with_stride_mut(s, ld, cols, ld).submatrix_mut(r, c, nr, nc)
}

/// dlahr2: reduces columns `p..p+ib` (rows `p+1..n`), leaving the reflectors in `h` below the
/// subdiagonal, `V` and `Y` (rows `p+1..n`) in `ws`, `T` in `t` (ld `ldt`).
fn panel(
    h: &mut [f64],
    n: usize,
    p: usize,
    ib: usize,
    ldt: usize,
    t: &mut [f64],
    ws: &mut Workspace,
) {
    let m = n - p - 1;
    for c in 0..ib {
        let j = p + c;
        if c > 0 {
            // Right: A[p+1.., j] −= Y[p+1.., ..c]·V[j, ..c]ᵀ.
            matmul(
                view_mut(h, n, p + 1, j, m, 1),
                Accum::Add,
                view(&ws.y, n, p + 1, 0, m, c),
                view(&ws.v, n, j, 0, 1, c).transpose(),
                -1.0,
                Par::Seq,
            );
            // Left: b ← (I − V Tᵀ Vᵀ) b for b = A[p+1.., j].
            {
                let s = &mut ws.s[..c];
                matmul(
                    MatMut::from_column_major_slice_mut(s, c, 1),
                    Accum::Replace,
                    view(&ws.v, n, p + 1, 0, m, c).transpose(),
                    view(h, n, p + 1, j, m, 1),
                    1.0,
                    Par::Seq,
                );
                // s ← Tᵀ s (T upper triangular; descending r reads only unchanged entries).
                for r in (0..c).rev() {
                    let tc = &t[r * ldt..r * ldt + r + 1];
                    s[r] = tc.iter().zip(&s[..=r]).map(|(a, b)| a * b).sum();
                }
                matmul(
                    view_mut(h, n, p + 1, j, m, 1),
                    Accum::Add,
                    view(&ws.v, n, p + 1, 0, m, c),
                    MatRef::from_column_major_slice(s, c, 1),
                    -1.0,
                    Par::Seq,
                );
            }
        }
        // Reflector j annihilates A[j+2.., j].
        let col = &mut h[j * n + j + 1..(j + 1) * n];
        let (beta, tau) = larfg(col[0], &mut col[1..]);
        col[0] = beta;
        {
            let vc = &mut ws.v[c * n..(c + 1) * n];
            vc[..=j].iter_mut().for_each(|x| *x = 0.0);
            vc[j + 1] = 1.0;
            vc[j + 2..].copy_from_slice(&h[j * n + j + 2..(j + 1) * n]);
        }
        let len = n - j - 1;
        // Y[p+1.., c] = A[p+1.., j+1..]·v (the columns right of j are as before the panel).
        matmul(
            view_mut(&mut ws.y, n, p + 1, c, m, 1),
            Accum::Replace,
            view(h, n, p + 1, j + 1, m, len),
            view(&ws.v, n, j + 1, c, len, 1),
            1.0,
            Par::Seq,
        );
        if c > 0 {
            // T[..c, c] = V[j+1.., ..c]ᵀ v, then Y[:, c] −= Y[:, ..c]·T[..c, c].
            matmul(
                view_mut(t, ldt, 0, c, c, 1),
                Accum::Replace,
                view(&ws.v, n, j + 1, 0, len, c).transpose(),
                view(&ws.v, n, j + 1, c, len, 1),
                1.0,
                Par::Seq,
            );
            let (y0, y1) = view_mut(&mut ws.y, n, p + 1, 0, m, c + 1).split_at_col_mut(c);
            matmul(
                y1,
                Accum::Add,
                y0.rb(),
                view(t, ldt, 0, c, c, 1),
                -1.0,
                Par::Seq,
            );
        }
        ws.y[c * n + p + 1..(c + 1) * n]
            .iter_mut()
            .for_each(|x| *x *= tau);
        // T[..c, c] ← −τ·T[..c, ..c]·T[..c, c] (ascending r reads only unchanged entries).
        for r in 0..c {
            let mut acc = 0.0;
            for k in r..c {
                acc += t[r + k * ldt] * t[k + c * ldt];
            }
            t[r + c * ldt] = -tau * acc;
        }
        t[c + c * ldt] = tau;
    }
}

/// dgehrd's update after a panel: top rows of `Y`, `A ← A − Y Vᵀ` right of the panel and above
/// it, then `A ← (I − V Tᵀ Vᵀ) A` on rows `p+1..` right of the panel.
fn trailing_update(
    h: &mut [f64],
    n: usize,
    p: usize,
    ib: usize,
    ldt: usize,
    t: &[f64],
    ws: &mut Workspace,
) {
    let m = n - p - 1;
    let tm = view(t, ldt, 0, 0, ib, ib);
    // Y[..p+1, :] = A[..p+1, p+1..]·V·T.
    matmul(
        view_mut(&mut ws.tmp, n, 0, 0, p + 1, ib),
        Accum::Replace,
        view(h, n, 0, p + 1, p + 1, m),
        view(&ws.v, n, p + 1, 0, m, ib),
        1.0,
        Par::Seq,
    );
    matmul(
        view_mut(&mut ws.y, n, 0, 0, p + 1, ib),
        Accum::Replace,
        view(&ws.tmp, n, 0, 0, p + 1, ib),
        tm,
        1.0,
        Par::Seq,
    );
    let q = p + ib;
    // A[:, q..] −= Y·V[q.., :]ᵀ.
    matmul(
        view_mut(h, n, 0, q, n, n - q),
        Accum::Add,
        view(&ws.y, n, 0, 0, n, ib),
        view(&ws.v, n, q, 0, n - q, ib).transpose(),
        -1.0,
        Par::Seq,
    );
    // A[..p+1, p+1..q] −= Y[..p+1, :]·V[p+1..q, :]ᵀ (the panel's own columns above its rows).
    if ib > 1 {
        matmul(
            view_mut(h, n, 0, p + 1, p + 1, ib - 1),
            Accum::Add,
            view(&ws.y, n, 0, 0, p + 1, ib),
            view(&ws.v, n, p + 1, 0, ib - 1, ib).transpose(),
            -1.0,
            Par::Seq,
        );
    }
    // A[p+1.., q..] ← (I − V Tᵀ Vᵀ)·A[p+1.., q..].
    let nc = n - q;
    matmul(
        view_mut(&mut ws.w, ib, 0, 0, ib, nc),
        Accum::Replace,
        view(&ws.v, n, p + 1, 0, m, ib).transpose(),
        view(h, n, p + 1, q, m, nc),
        1.0,
        Par::Seq,
    );
    matmul(
        view_mut(&mut ws.w2, ib, 0, 0, ib, nc),
        Accum::Replace,
        tm.transpose(),
        view(&ws.w, ib, 0, 0, ib, nc),
        1.0,
        Par::Seq,
    );
    matmul(
        view_mut(h, n, p + 1, q, m, nc),
        Accum::Add,
        view(&ws.v, n, p + 1, 0, m, ib),
        view(&ws.w2, ib, 0, 0, ib, nc),
        -1.0,
        Par::Seq,
    );
}

/// dorghr: `Z = Q_0 Q_1 ⋯` from the reflectors stored below the subdiagonal of `h` and the
/// panels' `T` in `ts`, applying the block reflectors backwards to the identity.
fn form_z<E>(
    h: &[f64],
    n: usize,
    nb: usize,
    ts: &[f64],
    ws: &mut Workspace,
    poll: &mut impl FnMut() -> Result<(), E>,
) -> Result<Vec<f64>, E> {
    let mut z = vec![0.0; n * n];
    for i in 0..n {
        z[i * n + i] = 1.0;
    }
    let npanels = (n - 2).div_ceil(nb);
    for b in (0..npanels).rev() {
        poll()?;
        let p = b * nb;
        let ib = nb.min(n - 2 - p);
        let m = n - p - 1;
        for c in 0..ib {
            let j = p + c;
            let vc = &mut ws.v[c * n..(c + 1) * n];
            vc[..=j].iter_mut().for_each(|x| *x = 0.0);
            vc[j + 1] = 1.0;
            vc[j + 2..].copy_from_slice(&h[j * n + j + 2..(j + 1) * n]);
        }
        let tm = view(&ts[p * nb..(p + ib) * nb], nb, 0, 0, ib, ib);
        // Z[p+1.., p+1..] ← (I − V T Vᵀ)·Z[p+1.., p+1..]. Columns p+1..=p+ib are still unit
        // vectors here, which the products do not exploit (ib/m of the work).
        matmul(
            view_mut(&mut ws.w, ib, 0, 0, ib, m),
            Accum::Replace,
            view(&ws.v, n, p + 1, 0, m, ib).transpose(),
            view(&z, n, p + 1, p + 1, m, m),
            1.0,
            Par::Seq,
        );
        matmul(
            view_mut(&mut ws.w2, ib, 0, 0, ib, m),
            Accum::Replace,
            tm,
            view(&ws.w, ib, 0, 0, ib, m),
            1.0,
            Par::Seq,
        );
        matmul(
            view_mut(&mut z, n, p + 1, p + 1, m, m),
            Accum::Add,
            view(&ws.v, n, p + 1, 0, m, ib),
            view(&ws.w2, ib, 0, 0, ib, m),
            -1.0,
            Par::Seq,
        );
    }
    Ok(z)
}

#[cfg(test)]
mod tests;
