//! Hessenberg reduction and the Francis double-shift QR iteration (in the style of LAPACK's
//! dlahqr with `wantt = wantz = true`), on column-major `n × n` slices.

use super::kernels::{lanv2, larfg, rot_cols, rot_rows, EPS, SAFMIN};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::hessenberg;
use faer::linalg::householder;
use faer::{Conj, MatMut, MatRef, Par};

/// Reduces the column-major `n × n` matrix `h` to upper Hessenberg form in place (blocked
/// Householder reduction from faer) and returns the orthogonal `Z` (column-major) with
/// `A = Z H Zᵀ`. Entries below the subdiagonal are set to exactly zero.
pub(super) fn hessenberg_reduce(h: &mut [f64], n: usize) -> Vec<f64> {
    let mut z = vec![0.0; n * n];
    for i in 0..n {
        z[i * n + i] = 1.0;
    }
    if n <= 2 {
        return z;
    }
    let bs = faer::linalg::qr::no_pivoting::factor::recommended_block_size::<f64>(n - 1, n - 1);
    let mut hh = vec![0.0; bs * (n - 1)];
    let req = hessenberg::hessenberg_in_place_scratch::<f64>(n, bs, Par::Seq, Default::default())
        .or(
            householder::apply_block_householder_sequence_on_the_right_in_place_scratch::<f64>(
                n - 1,
                bs,
                n - 1,
            ),
        );
    let mut buf = MemBuffer::new(req);
    let stack = MemStack::new(&mut buf);
    {
        let a = MatMut::from_column_major_slice_mut(h, n, n);
        let fac = MatMut::from_column_major_slice_mut(&mut hh, bs, n - 1);
        hessenberg::hessenberg_in_place(a, fac, Par::Seq, stack, Default::default());
    }
    {
        let a = MatRef::from_column_major_slice(h, n, n);
        let fac = MatRef::from_column_major_slice(&hh, bs, n - 1);
        let zm = MatMut::from_column_major_slice_mut(&mut z, n, n);
        householder::apply_block_householder_sequence_on_the_right_in_place_with_conj(
            a.submatrix(1, 0, n - 1, n - 1),
            fac,
            Conj::No,
            zm.submatrix_mut(1, 1, n - 1, n - 1),
            Par::Seq,
            stack,
        );
    }
    for j in 0..n {
        for v in &mut h[j * n + (j + 2).min(n)..(j + 1) * n] {
            *v = 0.0;
        }
    }
    z
}

/// Francis double-shift QR on the upper Hessenberg `h` (column-major `n × n`), accumulating the
/// transformations into the columns of `z` (column-major `n × n`). On success `h` is upper
/// quasi-triangular with every 2×2 block standardised (as dlanv2) and exact zeros below the
/// subdiagonal and below every 1×1 block. On failure returns the (0-based) row index of the
/// eigenvalue that did not converge within `30·max(10, n)` iterations.
pub(super) fn francis_qr(h: &mut [f64], z: &mut [f64], n: usize) -> Result<(), usize> {
    const DAT1: f64 = 0.75;
    const DAT2: f64 = -0.4375;
    const KEXSH: usize = 10;
    if n <= 1 {
        return Ok(());
    }
    let ld = n;
    macro_rules! hh {
        ($i:expr, $j:expr) => {
            h[($i) + ($j) * ld]
        };
    }
    for j in 0..n.saturating_sub(3) {
        hh!(j + 2, j) = 0.0;
        hh!(j + 3, j) = 0.0;
    }
    if n >= 3 {
        hh!(n - 1, n - 3) = 0.0;
    }
    let ulp = EPS;
    let smlnum = SAFMIN * (n as f64 / ulp);
    let itmax = 30 * n.max(10);
    let mut kdefl = 0usize;
    let mut v = [0.0f64; 3];

    // `i` is the last row of the active block; the loop ends when every row has deflated.
    let mut i_plus_1 = n;
    while i_plus_1 > 0 {
        let i = i_plus_1 - 1;
        let mut l = 0usize;
        let mut converged = false;
        for _its in 0..=itmax {
            // Look for a single small subdiagonal element.
            let mut k = i;
            while k > l {
                let hkk1 = hh!(k, k - 1).abs();
                if hkk1 <= smlnum {
                    break;
                }
                let mut tst = hh!(k - 1, k - 1).abs() + hh!(k, k).abs();
                if tst == 0.0 {
                    if k >= 2 {
                        tst += hh!(k - 1, k - 2).abs();
                    }
                    if k + 1 < n {
                        tst += hh!(k + 1, k).abs();
                    }
                }
                // Conservative deflation criterion of Ahues & Tisseur (LAWN 122, 1997).
                if hkk1 <= ulp * tst {
                    let hk1k = hh!(k - 1, k).abs();
                    let ab = hkk1.max(hk1k);
                    let ba = hkk1.min(hk1k);
                    let hkk = hh!(k, k).abs();
                    let dif = (hh!(k - 1, k - 1) - hh!(k, k)).abs();
                    let aa = hkk.max(dif);
                    let bb = hkk.min(dif);
                    let s = aa + ab;
                    if ba * (ab / s) <= smlnum.max(ulp * (bb * (aa / s))) {
                        break;
                    }
                }
                k -= 1;
            }
            l = k;
            if l > 0 {
                hh!(l, l - 1) = 0.0;
            }
            if l + 1 >= i {
                converged = true;
                break;
            }
            kdefl += 1;

            // Shifts: exceptional ones every KEXSH iterations without deflation.
            let (h11, h12, h21, h22);
            if kdefl % (2 * KEXSH) == 0 {
                let s = hh!(i, i - 1).abs() + hh!(i - 1, i - 2).abs();
                h11 = DAT1 * s + hh!(i, i);
                h12 = DAT2 * s;
                h21 = s;
                h22 = h11;
            } else if kdefl % KEXSH == 0 {
                let s = hh!(l + 1, l).abs() + hh!(l + 2, l + 1).abs();
                h11 = DAT1 * s + hh!(l, l);
                h12 = DAT2 * s;
                h21 = s;
                h22 = h11;
            } else {
                h11 = hh!(i - 1, i - 1);
                h21 = hh!(i, i - 1);
                h12 = hh!(i - 1, i);
                h22 = hh!(i, i);
            }
            let s = h11.abs() + h12.abs() + h21.abs() + h22.abs();
            let (rt1r, rt1i, rt2r, rt2i);
            if s == 0.0 {
                rt1r = 0.0;
                rt1i = 0.0;
                rt2r = 0.0;
                rt2i = 0.0;
            } else {
                let (h11, h12, h21, h22) = (h11 / s, h12 / s, h21 / s, h22 / s);
                let tr = 0.5 * (h11 + h22);
                let det = (h11 - tr) * (h22 - tr) - h12 * h21;
                let rtdisc = det.abs().sqrt();
                if det >= 0.0 {
                    // Complex conjugate shifts.
                    rt1r = tr * s;
                    rt2r = rt1r;
                    rt1i = rtdisc * s;
                    rt2i = -rt1i;
                } else {
                    // Real shifts: use the one closer to h22 twice.
                    let a = tr + rtdisc;
                    let b = tr - rtdisc;
                    let r = if (a - h22).abs() <= (b - h22).abs() {
                        a
                    } else {
                        b
                    };
                    rt1r = r * s;
                    rt2r = rt1r;
                    rt1i = 0.0;
                    rt2i = 0.0;
                }
            }

            // Look for two consecutive small subdiagonal elements.
            let mut m = i - 2;
            loop {
                let h21s0 = hh!(m + 1, m);
                let s = (hh!(m, m) - rt2r).abs() + rt2i.abs() + h21s0.abs();
                let h21s = h21s0 / s;
                v[0] = h21s * hh!(m, m + 1) + (hh!(m, m) - rt1r) * ((hh!(m, m) - rt2r) / s)
                    - rt1i * (rt2i / s);
                v[1] = h21s * (hh!(m, m) + hh!(m + 1, m + 1) - rt1r - rt2r);
                v[2] = h21s * hh!(m + 2, m + 1);
                let s = v[0].abs() + v[1].abs() + v[2].abs();
                v[0] /= s;
                v[1] /= s;
                v[2] /= s;
                if m == l {
                    break;
                }
                let h00 = hh!(m, m - 1).abs() * (v[1].abs() + v[2].abs());
                let h01 = v[0].abs()
                    * (hh!(m - 1, m - 1).abs() + hh!(m, m).abs() + hh!(m + 1, m + 1).abs());
                if h00 <= ulp * h01 {
                    break;
                }
                m -= 1;
            }

            // Double-shift QR step: chase the bulge from row m to row i.
            for k in m..i {
                let nr = 3.min(i - k + 1);
                if k > m {
                    for r in 0..nr {
                        v[r] = hh!(k + r, k - 1);
                    }
                }
                let (beta, t1) = larfg(v[0], &mut v[1..nr]);
                v[0] = beta;
                if k > m {
                    hh!(k, k - 1) = beta;
                    hh!(k + 1, k - 1) = 0.0;
                    if k + 1 < i {
                        hh!(k + 2, k - 1) = 0.0;
                    }
                } else if m > l {
                    // Use this instead of H(k, k−1) = −H(k, k−1) to avoid a bug when v(2) and
                    // v(3) underflow.
                    hh!(k, k - 1) *= 1.0 - t1;
                }
                if t1 == 0.0 {
                    continue;
                }
                let v2 = v[1];
                let t2 = t1 * v2;
                if nr == 3 {
                    let v3 = v[2];
                    let t3 = t1 * v3;
                    // Rows k..k+3 of H, columns k..n.
                    for col in h[k * ld..].chunks_exact_mut(ld) {
                        let c = &mut col[k..k + 3];
                        let sum = c[0] + v2 * c[1] + v3 * c[2];
                        c[0] -= sum * t1;
                        c[1] -= sum * t2;
                        c[2] -= sum * t3;
                    }
                    // Columns k..k+3 of H, rows 0..=min(k+3, i).
                    let rmax = (k + 3).min(i) + 1;
                    apply_cols3(h, ld, k, rmax, v2, v3, t1, t2, t3);
                    apply_cols3(z, ld, k, n, v2, v3, t1, t2, t3);
                } else {
                    for col in h[k * ld..].chunks_exact_mut(ld) {
                        let c = &mut col[k..k + 2];
                        let sum = c[0] + v2 * c[1];
                        c[0] -= sum * t1;
                        c[1] -= sum * t2;
                    }
                    apply_cols2(h, ld, k, i + 1, v2, t1, t2);
                    apply_cols2(z, ld, k, n, v2, t1, t2);
                }
            }
        }
        if !converged {
            return Err(i);
        }
        if l + 1 == i {
            // A 2×2 block: standardise it and apply the rotation to the rest of H and to Z.
            let r = lanv2(hh!(i - 1, i - 1), hh!(i - 1, i), hh!(i, i - 1), hh!(i, i));
            hh!(i - 1, i - 1) = r.a;
            hh!(i - 1, i) = r.b;
            hh!(i, i - 1) = r.c;
            hh!(i, i) = r.d;
            rot_rows(h, ld, i - 1, i + 1..n, r.cs, r.sn);
            rot_cols(h, ld, i - 1, 0..i - 1, r.cs, r.sn);
            rot_cols(z, ld, i - 1, 0..n, r.cs, r.sn);
        }
        kdefl = 0;
        i_plus_1 = l;
    }
    Ok(())
}

/// Columns `k..k+3`, rows `0..rows`: `x ← x − (x·v)·(t1, t2, t3)` with `v = (1, v2, v3)`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn apply_cols3(
    m: &mut [f64],
    ld: usize,
    k: usize,
    rows: usize,
    v2: f64,
    v3: f64,
    t1: f64,
    t2: f64,
    t3: f64,
) {
    let (c0, rest) = m[k * ld..(k + 3) * ld].split_at_mut(ld);
    let (c1, c2) = rest.split_at_mut(ld);
    for ((a, b), c) in c0[..rows]
        .iter_mut()
        .zip(c1[..rows].iter_mut())
        .zip(c2[..rows].iter_mut())
    {
        let sum = *a + v2 * *b + v3 * *c;
        *a -= sum * t1;
        *b -= sum * t2;
        *c -= sum * t3;
    }
}

/// Columns `k..k+2`, rows `0..rows`: `x ← x − (x·v)·(t1, t2)` with `v = (1, v2)`.
#[inline]
fn apply_cols2(m: &mut [f64], ld: usize, k: usize, rows: usize, v2: f64, t1: f64, t2: f64) {
    let (c0, c1) = m[k * ld..(k + 2) * ld].split_at_mut(ld);
    for (a, b) in c0[..rows].iter_mut().zip(c1[..rows].iter_mut()) {
        let sum = *a + v2 * *b;
        *a -= sum * t1;
        *b -= sum * t2;
    }
}
