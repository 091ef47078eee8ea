// Why this module is long: one algorithm, LAPACK's double-shift Francis QR (dlahqr) with its small-matrix
// Hessenberg reduction and blocked reflector application, which share one storage convention.
//! Hessenberg reduction and the Francis double-shift QR iteration (in the style of LAPACK's
//! dlahqr with `wantt = wantz = true`), on column-major `n × n` slices.

use super::kernels::{lanv2, larfg, rot_cols, rot_rows, EPS, SAFMIN};
use crate::linalg::dense::{axpy, dot};

/// Reduces the column-major `n × n` matrix `h` to upper Hessenberg form in place and returns the
/// orthogonal `Z` (column-major) with `A = Z H Zᵀ`. Entries below the subdiagonal are set to
/// exactly zero. Up to order [`SMALL_HESSENBERG`] this is the unblocked Householder reduction
/// [`hessenberg_small`]; above, the blocked reduction of `hessenberg.rs` (LAPACK's
/// dgehrd/dlahr2/dorghr), which polls the cancellation token before every panel and every block
/// of `Z`.
///
/// Errors: [`Error::Interrupted`](crate::Error::Interrupted) if this thread's computation is
/// cancelled during a blocked reduction (`h` is then partially reduced and unusable).
pub(super) fn hessenberg_reduce(h: &mut [f64], n: usize) -> crate::Result<Vec<f64>> {
    #[cfg(test)]
    if n > SMALL_HESSENBERG && FAER_REDUCTION.with(|c| c.get()) {
        return Ok(hessenberg_faer(h, n));
    }
    if n > SMALL_HESSENBERG {
        let nb = super::hessenberg::panel_width(n);
        return super::hessenberg::reduce_blocked(h, n, nb, &mut || {
            #[cfg(test)]
            cancel_after_polls();
            crate::cancel::check("the Hessenberg reduction")
        });
    }
    let mut z = vec![0.0; n * n];
    for i in 0..n {
        z[i * n + i] = 1.0;
    }
    if n > 2 {
        hessenberg_small(h, &mut z, n);
    }
    Ok(z)
}

#[cfg(test)]
thread_local! {
    /// Tests only: after this many more polls of blocked reductions on this thread, the next one
    /// cancels the thread's token (a cancellation at a chosen point, e.g. inside an AED window).
    pub(crate) static CANCEL_AFTER_POLLS: std::cell::Cell<Option<usize>> =
        const { std::cell::Cell::new(None) };
}

#[cfg(test)]
fn cancel_after_polls() {
    CANCEL_AFTER_POLLS.with(|c| match c.get() {
        Some(0) => {
            c.set(None);
            if let Some(t) = crate::cancel::current() {
                t.cancel();
            }
        }
        Some(k) => c.set(Some(k - 1)),
        None => {}
    });
}

#[cfg(test)]
thread_local! {
    /// Tests only: use [`hessenberg_faer`] above [`SMALL_HESSENBERG`] on this thread (before/after
    /// timings of whole computations in one binary).
    pub(crate) static FAER_REDUCTION: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// The reduction this crate used above [`SMALL_HESSENBERG`] before `hessenberg.rs`: one call to
/// faer's blocked Hessenberg kernel and one to form `Z` (neither can be interrupted). Kept for
/// the comparison tests and timings.
#[cfg(test)]
pub(super) fn hessenberg_faer(h: &mut [f64], n: usize) -> Vec<f64> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::evd::hessenberg;
    use faer::linalg::householder;
    use faer::{Conj, MatMut, MatRef, Par};
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

/// Up to this order the unblocked reduction [`hessenberg_small`] is used (faer's blocked kernel
/// has more overhead than it saves on matrices that fit in L1).
const SMALL_HESSENBERG: usize = 80;

/// Unblocked Householder reduction to Hessenberg form (LAPACK's dgehd2) followed by the backward
/// accumulation of `Z` (dorg2r), for small `n`; `z` must hold the identity on entry.
pub(super) fn hessenberg_small(h: &mut [f64], z: &mut [f64], n: usize) {
    crate::linalg::dispatch_avx2!(
        hessenberg_small_avx2,
        hessenberg_small_impl,
        (h: &mut [f64], z: &mut [f64], n: usize) -> ()
    )
}

#[inline(always)]
fn hessenberg_small_impl(h: &mut [f64], z: &mut [f64], n: usize) {
    let ld = n;
    // Reflector k acts on rows/columns k+1..n: v = (1, h[k+2..n, k]) after the reduction.
    let mut taus = vec![0.0f64; n];
    let mut v = vec![0.0f64; n];
    let mut w = vec![0.0f64; n];
    for k in 0..n - 2 {
        let m = n - k - 1;
        let col = &mut h[k * ld + k + 1..(k + 1) * ld];
        let (beta, tau) = larfg(col[0], &mut col[1..]);
        taus[k] = tau;
        if tau == 0.0 {
            continue;
        }
        col[0] = 1.0;
        v[..m].copy_from_slice(col);
        col[0] = beta;
        let v = &v[..m];
        // Right: H[:, k+1..] ← H[:, k+1..] (I − τ v vᵀ), w = H[:, k+1..] v.
        w.iter_mut().for_each(|x| *x = 0.0);
        for (c, &vc) in v.iter().enumerate() {
            let j = k + 1 + c;
            axpy(vc, &h[j * ld..(j + 1) * ld], &mut w);
        }
        for (c, &vc) in v.iter().enumerate() {
            let j = k + 1 + c;
            axpy(-tau * vc, &w, &mut h[j * ld..(j + 1) * ld]);
        }
        // Left: H[k+1.., k+1..] ← (I − τ v vᵀ) H[k+1.., k+1..].
        for j in k + 1..n {
            let cj = &mut h[j * ld + k + 1..(j + 1) * ld];
            let s = dot(v, cj);
            axpy(-tau * s, v, cj);
        }
    }
    // Z = H_0 H_1 ⋯ H_{n−3}, accumulated backwards on the trailing blocks (dorg2r).
    for k in (0..n - 2).rev() {
        let tau = taus[k];
        if tau == 0.0 {
            continue;
        }
        let m = n - k - 1;
        v[0] = 1.0;
        v[1..m].copy_from_slice(&h[k * ld + k + 2..(k + 1) * ld]);
        let v = &v[..m];
        for j in k + 1..n {
            let cj = &mut z[j * ld + k + 1..(j + 1) * ld];
            let s = dot(v, cj);
            if s != 0.0 {
                axpy(-tau * s, v, cj);
            }
        }
    }
    for j in 0..n {
        for x in &mut h[j * ld + (j + 2).min(n)..(j + 1) * ld] {
            *x = 0.0;
        }
    }
}

/// QR iteration on the upper Hessenberg `h` (column-major `n × n`): the multishift code with
/// aggressive early deflation for `n ≥ multishift::NMIN`, else the Francis double-shift QR below,
/// accumulating the transformations into the columns of `z` (column-major `n × n`). On success
/// `h` is upper
/// quasi-triangular with every 2×2 block standardised (as dlanv2) and exact zeros below the
/// subdiagonal and below every 1×1 block. On failure returns the (0-based) row index of the
/// eigenvalue that did not converge within `30·max(10, n)` iterations.
pub(super) fn francis_qr(h: &mut [f64], z: &mut [f64], n: usize) -> Result<(), usize> {
    if n >= super::multishift::NMIN {
        return super::multishift::multishift_qr(h, z, n);
    }
    francis_qr_window(h, z, n, 0, n.saturating_sub(1))
}

/// The double-shift QR iteration restricted to the diagonal window `ilo..=ihi` of the `n × n`
/// upper Hessenberg `h` (LAPACK's dlahqr with `wantt = wantz = true`): the transformations are
/// applied to the full rows and columns of `h` and to all of `z`. The window must be isolated
/// (`H(ilo, ilo−1) = 0` and `H(ihi+1, ihi) = 0`). On failure returns the (0-based) row of the
/// eigenvalue that did not converge; rows below it are then converged (and the matrices still
/// hold a valid orthogonal similarity).
pub(super) fn francis_qr_window(
    h: &mut [f64],
    z: &mut [f64],
    n: usize,
    ilo: usize,
    ihi: usize,
) -> Result<(), usize> {
    crate::linalg::dispatch_avx2!(
        francis_qr_avx2,
        francis_qr_impl,
        (h: &mut [f64], z: &mut [f64], n: usize, ilo: usize, ihi: usize) -> Result<(), usize>
    )
}

#[inline(always)]
fn francis_qr_impl(
    h: &mut [f64],
    z: &mut [f64],
    n: usize,
    ilo: usize,
    ihi: usize,
) -> Result<(), usize> {
    const DAT1: f64 = 0.75;
    const DAT2: f64 = -0.4375;
    const KEXSH: usize = 10;
    if n <= 1 || ihi <= ilo {
        return Ok(());
    }
    let ld = n;
    macro_rules! hh {
        ($i:expr, $j:expr) => {
            h[($i) + ($j) * ld]
        };
    }
    for j in ilo..ihi.saturating_sub(1) {
        hh!(j + 2, j) = 0.0;
        if j + 3 <= ihi {
            hh!(j + 3, j) = 0.0;
        }
    }
    let nh = ihi - ilo + 1;
    let ulp = EPS;
    let smlnum = SAFMIN * (nh as f64 / ulp);
    let itmax = 30 * nh.max(10);
    let mut kdefl = 0usize;
    let mut v = [0.0f64; 3];
    let mut group: Vec<Refl> = Vec::with_capacity(GROUP);
    let mut wbuf = vec![0.0f64; (GROUP + 2) * COL_BLOCK];

    // `i` is the last row of the active block; the loop ends when every row has deflated.
    let mut i_plus_1 = ihi + 1;
    while i_plus_1 > ilo {
        let i = i_plus_1 - 1;
        let mut l = ilo;
        let mut converged = false;
        for _its in 0..=itmax {
            // Cancelled: report this row as unconverged; RealSchur::new turns it into
            // Error::Interrupted (the matrices still hold a valid orthogonal similarity).
            if crate::cancel::is_cancelled() {
                return Err(i);
            }
            // Look for a single small subdiagonal element.
            let mut k = i;
            while k > l {
                let hkk1 = hh!(k, k - 1).abs();
                if hkk1 <= smlnum {
                    break;
                }
                let mut tst = hh!(k - 1, k - 1).abs() + hh!(k, k).abs();
                if tst == 0.0 {
                    if k >= ilo + 2 {
                        tst += hh!(k - 1, k - 2).abs();
                    }
                    if k < ihi {
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
            if l > ilo {
                hh!(l, l - 1) = 0.0;
            }
            if l + 1 >= i {
                converged = true;
                break;
            }
            kdefl += 1;

            // Shifts: exceptional ones every KEXSH iterations without deflation.
            let (h11, h12, h21, h22);
            if kdefl.is_multiple_of(2 * KEXSH) {
                let s = hh!(i, i - 1).abs() + hh!(i - 1, i - 2).abs();
                h11 = DAT1 * s + hh!(i, i);
                h12 = DAT2 * s;
                h21 = s;
                h22 = h11;
            } else if kdefl.is_multiple_of(KEXSH) {
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

            // Double-shift QR step: chase the bulge from row m to row i. The reflectors are
            // processed in groups of GROUP: inside a group each one is applied at once only to
            // the part of H near the diagonal (rows/columns from the group's first row on, up
            // to the group's last column); the parts far from the diagonal (columns right of
            // the group, rows above it) and Z receive the whole group afterwards in one fused,
            // cache-friendly pass. Every entry sees exactly the same operations in the same
            // order as with immediate updates, so the result is bitwise the same.
            let mut kg = m;
            while kg < i {
                let gfirst = kg;
                let glast = (gfirst + GROUP).min(i) - 1;
                let ncol_end = (glast + 3).min(n);
                group.clear();
                for k in gfirst..=glast {
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
                        // Use this instead of H(k, k−1) = −H(k, k−1) to avoid a bug when v(2)
                        // and v(3) underflow.
                        hh!(k, k - 1) *= 1.0 - t1;
                    }
                    if t1 == 0.0 {
                        continue;
                    }
                    let r = Refl::new(k, nr, v[1], if nr == 3 { v[2] } else { 0.0 }, t1);
                    if n <= SMALL_N {
                        // Small matrices: apply at once to the full rows, columns and Z.
                        for col in h[k * ld..n * ld].chunks_exact_mut(ld) {
                            r.apply_segment(&mut col[k..k + nr]);
                        }
                        r.apply_cols(h, ld, 0..(k + 3).min(i) + 1);
                        r.apply_cols(z, ld, 0..n);
                        continue;
                    }
                    // Rows k..k+nr of H, columns k..ncol_end (the rest is deferred).
                    for col in h[k * ld..ncol_end * ld].chunks_exact_mut(ld) {
                        r.apply_segment(&mut col[k..k + nr]);
                    }
                    // Columns k..k+nr of H, rows gfirst..=min(k+3, i) (rows above deferred).
                    let rmax = (k + 3).min(i) + 1;
                    r.apply_cols(h, ld, gfirst..rmax);
                    group.push(r);
                }
                if !group.is_empty() {
                    apply_group_rows(
                        h,
                        ld,
                        gfirst,
                        (glast + 3).min(n),
                        ncol_end..n,
                        &group,
                        &mut wbuf,
                    );
                    apply_group_cols(h, ld, 0..gfirst, &group);
                    apply_group_cols(z, ld, 0..n, &group);
                }
                kg = glast + 1;
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

/// Below this order reflectors are applied at once (no grouping).
const SMALL_N: usize = 64;

/// Reflectors per group in the bulge chase (see `francis_qr`).
const GROUP: usize = 16;
/// Rows per block when a group is applied to columns (keeps the block in L1).
const ROW_BLOCK: usize = 64;

/// A reflector `I − t1·v·vᵀ` with `v = (1, v2, v3)` acting on rows/columns `k..k+nr`
/// (`nr = 2` ignores `v3`); `t2 = t1·v2`, `t3 = t1·v3`.
#[derive(Debug, Clone, Copy)]
struct Refl {
    k: usize,
    nr: usize,
    v2: f64,
    v3: f64,
    t1: f64,
    t2: f64,
    t3: f64,
}

impl Refl {
    #[inline]
    fn new(k: usize, nr: usize, v2: f64, v3: f64, t1: f64) -> Self {
        Refl {
            k,
            nr,
            v2,
            v3,
            t1,
            t2: t1 * v2,
            t3: t1 * v3,
        }
    }

    /// Applies the reflector to a contiguous segment of length `nr` (part of one column).
    #[inline(always)]
    fn apply_segment(&self, c: &mut [f64]) {
        if self.nr == 3 {
            let sum = c[0] + self.v2 * c[1] + self.v3 * c[2];
            c[0] -= sum * self.t1;
            c[1] -= sum * self.t2;
            c[2] -= sum * self.t3;
        } else {
            let sum = c[0] + self.v2 * c[1];
            c[0] -= sum * self.t1;
            c[1] -= sum * self.t2;
        }
    }

    /// Applies the reflector from the right to columns `k..k+nr`, rows `rows`.
    #[inline(always)]
    fn apply_cols(&self, m: &mut [f64], ld: usize, rows: std::ops::Range<usize>) {
        if rows.is_empty() {
            return;
        }
        let k = self.k;
        if self.nr == 3 {
            let (c0, rest) = m[k * ld..(k + 3) * ld].split_at_mut(ld);
            let (c1, c2) = rest.split_at_mut(ld);
            let (c0, c1, c2) = (&mut c0[rows.clone()], &mut c1[rows.clone()], &mut c2[rows]);
            for ((a, b), c) in c0.iter_mut().zip(c1.iter_mut()).zip(c2.iter_mut()) {
                let sum = *a + self.v2 * *b + self.v3 * *c;
                *a -= sum * self.t1;
                *b -= sum * self.t2;
                *c -= sum * self.t3;
            }
        } else {
            let (c0, c1) = m[k * ld..(k + 2) * ld].split_at_mut(ld);
            let (c0, c1) = (&mut c0[rows.clone()], &mut c1[rows]);
            for (a, b) in c0.iter_mut().zip(c1.iter_mut()) {
                let sum = *a + self.v2 * *b;
                *a -= sum * self.t1;
                *b -= sum * self.t2;
            }
        }
    }
}

/// Columns per block when a group is applied to rows.
const COL_BLOCK: usize = 128;

/// Applies a group of reflectors, in order, from the left to rows `r0..r1` (which contain every
/// reflector's rows) of the columns `cols` of `m`. Blocks of columns are copied into a row-major
/// buffer so that each reflector becomes a contiguous, vectorisable pass over the columns (and
/// overlapping column segments do not stall on store forwarding).
#[inline(always)]
fn apply_group_rows(
    m: &mut [f64],
    ld: usize,
    r0: usize,
    r1: usize,
    cols: std::ops::Range<usize>,
    group: &[Refl],
    wbuf: &mut [f64],
) {
    let nrow = r1 - r0;
    let mut c0 = cols.start;
    while c0 < cols.end {
        let cw = (c0 + COL_BLOCK).min(cols.end) - c0;
        // Gather: W[q][c] = m[r0 + q, c0 + c], row stride COL_BLOCK.
        for c in 0..cw {
            let col = &m[(c0 + c) * ld + r0..(c0 + c) * ld + r1];
            for (q, &x) in col.iter().enumerate() {
                wbuf[q * COL_BLOCK + c] = x;
            }
        }
        for r in group {
            let q = r.k - r0;
            let (w0, rest) = wbuf[q * COL_BLOCK..].split_at_mut(COL_BLOCK);
            let (w1, rest) = rest.split_at_mut(COL_BLOCK);
            let (w0, w1) = (&mut w0[..cw], &mut w1[..cw]);
            if r.nr == 3 {
                let w2 = &mut rest[..cw];
                for ((a, b), c) in w0.iter_mut().zip(w1.iter_mut()).zip(w2.iter_mut()) {
                    let sum = *a + r.v2 * *b + r.v3 * *c;
                    *a -= sum * r.t1;
                    *b -= sum * r.t2;
                    *c -= sum * r.t3;
                }
            } else {
                for (a, b) in w0.iter_mut().zip(w1.iter_mut()) {
                    let sum = *a + r.v2 * *b;
                    *a -= sum * r.t1;
                    *b -= sum * r.t2;
                }
            }
        }
        // Scatter back.
        for c in 0..cw {
            let col = &mut m[(c0 + c) * ld + r0..(c0 + c) * ld + r1];
            for (q, x) in col.iter_mut().enumerate() {
                *x = wbuf[q * COL_BLOCK + c];
            }
        }
        let _ = nrow;
        c0 += cw;
    }
}

/// Applies a group of reflectors, in order, from the right to the rows `rows` of `m`, one block
/// of `ROW_BLOCK` rows at a time so that the touched columns stay in cache.
#[inline(always)]
fn apply_group_cols(m: &mut [f64], ld: usize, rows: std::ops::Range<usize>, group: &[Refl]) {
    let mut r0 = rows.start;
    while r0 < rows.end {
        let r1 = (r0 + ROW_BLOCK).min(rows.end);
        for r in group {
            r.apply_cols(m, ld, r0..r1);
        }
        r0 = r1;
    }
}
