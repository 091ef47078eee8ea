// Why this module is long: one algorithm, LAPACK's small-bulge multishift QR with aggressive early
// deflation (dlaqr0/dlaqr3/dlaqr5): shift choice, deflation window and bulge sweep share workspace.
//! Small-bulge multishift QR with aggressive early deflation (Braman, Byers & Mathias, SIMAX
//! 2002), in the structure of LAPACK's dlaqr0 (driver), dlaqr3 (aggressive early deflation) and
//! dlaqr5 (a chain of tightly packed 3×3 bulges whose transformations are accumulated in a small
//! orthogonal matrix and applied to the far parts of `H` and to `Z` by matrix multiplication).
//!
//! Small active blocks, the deflation windows and anything the multishift iteration cannot finish
//! within its iteration bound go to the double-shift code ([`francis_qr_window`]), so every 2×2
//! block of the result is standardised by dlanv2 exactly as before.

use super::hqr::{francis_qr_window, hessenberg_reduce};
use super::kernels::{lanv2, larfg, EPS, SAFMIN};
use super::reorder::move_block;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};

/// Active blocks smaller than this are finished by the double-shift code (LAPACK's NMIN).
pub(super) const NMIN: usize = 75;
/// Skip the sweep when AED deflated at least this percentage of the window (LAPACK's NIBBLE).
const NIBBLE: usize = 14;
/// Iterations without deflation after which the deflation window grows (LAPACK's KEXNW).
const KEXNW: usize = 5;
/// Iterations without deflation after which exceptional shifts are used (LAPACK's KEXSH).
const KEXSH: usize = 6;

/// Number of simultaneous shifts for an active block of order `nh` (LAPACK's iparmq, ISPEC = 15).
fn recommended_shifts(nh: usize) -> usize {
    let mut ns = 2;
    if nh >= 30 {
        ns = 4;
    }
    if nh >= 60 {
        ns = 10;
    }
    if nh >= 150 {
        let lg = (nh as f64).log2().round().max(1.0) as usize;
        ns = 10usize.max(nh / lg);
    }
    if nh >= 590 {
        ns = 64;
    }
    if nh >= 3000 {
        ns = 128;
    }
    if nh >= 6000 {
        ns = 256;
    }
    2usize.max(ns - ns % 2)
}

/// Deflation window size for an active block of order `nh` (LAPACK's iparmq, ISPEC = 13).
fn recommended_window(nh: usize) -> usize {
    let ns = recommended_shifts(nh);
    if nh <= 500 {
        ns
    } else {
        3 * ns / 2
    }
}

/// Counters of the last multishift run on this thread (tests only): AED calls, eigenvalues
/// deflated by AED, eigenvalues deflated by the first AED, sweeps, double-shift fallbacks after
/// the iteration bound.
#[cfg(test)]
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Stats {
    pub aed_calls: usize,
    pub aed_deflated: usize,
    pub first_aed_deflated: Option<usize>,
    pub sweeps: usize,
    pub fallbacks: usize,
}

#[cfg(test)]
thread_local! {
    pub(super) static STATS: std::cell::Cell<Stats> = std::cell::Cell::new(Stats::default());
}

#[cfg(test)]
thread_local! {
    /// Replaces the multishift iteration bound (tests of the double-shift fallback).
    pub(super) static ITMAX_OVERRIDE: std::cell::Cell<Option<usize>> = const { std::cell::Cell::new(None) };
}

#[cfg(test)]
fn record(f: impl FnOnce(&mut Stats)) {
    STATS.with(|c| {
        let mut s = c.get();
        f(&mut s);
        c.set(s);
    });
}

/// Scratch buffers reused across iterations.
#[derive(Default)]
struct Work {
    t: Vec<f64>,
    v: Vec<f64>,
    u: Vec<f64>,
    tmp: Vec<f64>,
    small: Vec<f64>,
}

/// Multishift QR with AED on the whole `n × n` upper Hessenberg `h`, accumulating into `z`.
/// Same contract as [`super::hqr::francis_qr`].
pub(super) fn multishift_qr(h: &mut [f64], z: &mut [f64], n: usize) -> Result<(), usize> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above).
            return unsafe { multishift_avx2(h, z, n) };
        }
    }
    multishift_impl(h, z, n)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn multishift_avx2(h: &mut [f64], z: &mut [f64], n: usize) -> Result<(), usize> {
    multishift_impl(h, z, n)
}

#[inline(always)]
fn multishift_impl(h: &mut [f64], z: &mut [f64], n: usize) -> Result<(), usize> {
    if n < NMIN {
        return francis_qr_window(h, z, n, 0, n.saturating_sub(1));
    }
    let ld = n;
    // Exact zeros below the subdiagonal.
    for j in 0..n {
        for v in &mut h[j * ld + (j + 2).min(n)..(j + 1) * ld] {
            *v = 0.0;
        }
    }
    let mut w = Work::default();
    #[cfg(test)]
    STATS.with(|c| c.set(Stats::default()));
    let nwmax = ((n - 1) / 3).max(2);
    let nsmax = {
        let s = ((n - 3) / 6).max(2);
        s - s % 2
    };
    let nsr_all = recommended_shifts(n);
    let nwr_all = recommended_window(n).max(2).min(nwmax);
    let mut nw = nwr_all;
    let mut ndec: isize = -1;
    let mut ndfl = 1usize;
    let itmax = 30 * n.max(10);
    #[cfg(test)]
    let itmax = ITMAX_OVERRIDE.with(|c| c.get()).unwrap_or(itmax);
    let ulp = EPS;
    let smlnum = SAFMIN * (n as f64 / ulp);

    // `kend = kbot + 1`: rows kend.. have converged.
    let mut kend = n;
    let mut it = 0usize;
    while kend > 0 {
        if crate::cancel::is_cancelled() {
            return Err(kend - 1);
        }
        if it >= itmax {
            // Out of multishift iterations: finish with the double-shift code.
            #[cfg(test)]
            record(|s| s.fallbacks += 1);
            return francis_qr_window(h, z, n, 0, kend - 1);
        }
        it += 1;
        let kbot = kend - 1;
        let mut ktop = kbot;
        while ktop > 0 && h[ktop + (ktop - 1) * ld] != 0.0 {
            ktop -= 1;
        }
        let nh = kbot - ktop + 1;
        if nh < NMIN {
            small_block(h, z, n, ktop, kbot, &mut w)?;
            kend = ktop;
            ndfl = 1;
            continue;
        }

        // Deflation window size.
        let nwupbd = nh.min(nwmax);
        if ndfl < KEXNW {
            nw = nwupbd.min(nwr_all);
        } else {
            nw = nwupbd.min(2 * nw);
        }
        if nw < nwmax {
            if nw + 1 >= nh {
                nw = nh;
            } else {
                let kwtop = kbot + 1 - nw;
                if kwtop >= ktop + 2
                    && h[kwtop + (kwtop - 1) * ld].abs() > h[kwtop - 1 + (kwtop - 2) * ld].abs()
                {
                    nw += 1;
                }
            }
        }
        if ndfl < KEXNW {
            ndec = -1;
        } else if ndec >= 0 || nw >= nwupbd {
            ndec += 1;
            if (nw as isize) - ndec < 2 {
                ndec = 0;
            }
            nw = (nw as isize - ndec).max(2) as usize;
        }

        // Aggressive early deflation.
        let (shifts, nd) = aed(h, z, n, ktop, kbot, nw, &mut w);
        if crate::cancel::is_cancelled() {
            return Err(kend - 1);
        }
        #[cfg(test)]
        record(|s| {
            s.aed_calls += 1;
            s.aed_deflated += nd;
            s.first_aed_deflated.get_or_insert(nd);
        });
        let kend_new = kend - nd;
        let kbot = match kend_new.checked_sub(1) {
            Some(k) => k,
            None => {
                kend = 0;
                continue;
            }
        };
        kend = kend_new;
        let nact = kbot + 1 - ktop.min(kbot + 1);

        if nd == 0 || (100 * nd <= nw * NIBBLE && nact > NMIN.min(nwmax)) {
            let ns = nsmax.min(nsr_all).min(2usize.max(kbot - ktop));
            let ns = ns - ns % 2;
            let bulges = if ndfl.is_multiple_of(KEXSH) {
                exceptional_shifts(h, ld, ktop, kbot, ns)
            } else {
                let mut shifts = shifts;
                if shifts.len() <= ns / 2 {
                    shifts = trailing_shifts(h, ld, ktop, kbot, ns, &mut w);
                }
                choose_shifts(h, ld, kbot, shifts, ns)
            };
            if !bulges.is_empty() {
                sweep(h, z, n, ktop, kbot, &bulges, &mut w);
                #[cfg(test)]
                record(|s| s.sweeps += 1);
                vigilant_deflation(h, ld, ktop, kbot, smlnum);
            }
        }
        ndfl = if nd > 0 { 1 } else { ndfl + 1 };
    }
    Ok(())
}

/// A shift: `(re, im)`; complex shifts come in conjugate pairs.
type Shift = (f64, f64);

/// A bulge: two shifts, either both real or a conjugate pair.
type Bulge = [Shift; 2];

/// Exceptional shifts as in dlaqr0: from the 2×2 matrices `[[0.75·s + h_ii, s], [−0.4375·s,
/// 0.75·s + h_ii]]`, `s = |h_{i,i−1}| + |h_{i−1,i−2}|`, down the bottom of the active block.
fn exceptional_shifts(h: &[f64], ld: usize, ktop: usize, kbot: usize, ns: usize) -> Vec<Bulge> {
    let mut out = Vec::new();
    let mut i = kbot;
    while out.len() < ns / 2 && i >= ktop + 2 {
        let ss = h[i + (i - 1) * ld].abs() + h[i - 1 + (i - 2) * ld].abs();
        let aa = 0.75 * ss + h[i + i * ld];
        let r = lanv2(aa, ss, -0.4375 * ss, aa);
        let e = r.eigenvalues();
        out.push([e[0], e[1]]);
        i -= 2;
    }
    if out.is_empty() {
        let x = h[kbot + kbot * ld];
        out.push([(x, 0.0), (x, 0.0)]);
    }
    out
}

/// Eigenvalues of the trailing `ns × ns` principal submatrix of the active block, used as shifts
/// when AED leaves too few (dlaqr0 computes them with dlahqr/dlaqr4 on a copy).
fn trailing_shifts(
    h: &[f64],
    ld: usize,
    ktop: usize,
    kbot: usize,
    ns: usize,
    w: &mut Work,
) -> Vec<Shift> {
    let m = ns.min(kbot + 1 - ktop).max(2);
    let ks = kbot + 1 - m;
    w.small.clear();
    w.small.resize(m * m, 0.0);
    for j in 0..m {
        for i in 0..m.min(j + 2) {
            w.small[i + j * m] = h[ks + i + (ks + j) * ld];
        }
    }
    let mut zz = vec![0.0; m * m];
    for i in 0..m {
        zz[i + i * m] = 1.0;
    }
    match francis_qr_window(&mut w.small, &mut zz, m, 0, m - 1) {
        Ok(()) => block_eigenvalues(&w.small, m, 0, m),
        Err(_) => {
            // Fall back to the eigenvalues of the trailing 2×2 block.
            let (a, b, c, d) = (
                h[kbot - 1 + (kbot - 1) * ld],
                h[kbot - 1 + kbot * ld],
                h[kbot + (kbot - 1) * ld],
                h[kbot + kbot * ld],
            );
            let r = lanv2(a, b, c, d);
            r.eigenvalues().to_vec()
        }
    }
}

/// Eigenvalues of the standardised quasi-triangular `t` (order `m`) on rows `from..to`.
fn block_eigenvalues(t: &[f64], m: usize, from: usize, to: usize) -> Vec<Shift> {
    let mut out = Vec::with_capacity(to - from);
    let mut k = from;
    while k < to {
        if k + 1 < to && t[k + 1 + k * m] != 0.0 {
            let r = lanv2(
                t[k + k * m],
                t[k + (k + 1) * m],
                t[k + 1 + k * m],
                t[k + 1 + (k + 1) * m],
            );
            let e = r.eigenvalues();
            out.push(e[0]);
            out.push(e[1]);
            k += 2;
        } else {
            out.push((t[k + k * m], 0.0));
            k += 1;
        }
    }
    out
}

/// Picks up to `ns` shifts of smallest magnitude from `shifts` (a list in which conjugate pairs
/// are adjacent) and groups them into bulges: conjugate pairs stay together, real shifts are
/// paired. With a single bulge of two real shifts, the one closer to `h_{kbot,kbot}` is used
/// twice (as dlaqr0).
fn choose_shifts(h: &[f64], ld: usize, kbot: usize, shifts: Vec<Shift>, ns: usize) -> Vec<Bulge> {
    // Units: a conjugate pair or a real shift.
    let mut units: Vec<(Shift, bool)> = Vec::new();
    let mut i = 0;
    while i < shifts.len() {
        let s = shifts[i];
        if s.1 != 0.0 && i + 1 < shifts.len() && shifts[i + 1].1 == -s.1 {
            units.push(((s.0, s.1.abs()), true));
            i += 2;
        } else if s.1 != 0.0 {
            // An unpaired complex value (should not happen): use its real part.
            units.push(((s.0, 0.0), false));
            i += 1;
        } else {
            units.push((s, false));
            i += 1;
        }
    }
    // Smallest magnitude first.
    units.sort_by(|a, b| {
        let ma = a.0 .0.abs() + a.0 .1.abs();
        let mb = b.0 .0.abs() + b.0 .1.abs();
        ma.partial_cmp(&mb).unwrap_or(std::cmp::Ordering::Equal)
    });
    let mut bulges: Vec<Bulge> = Vec::new();
    let mut pending_real: Option<f64> = None;
    for ((re, im), cplx) in units {
        if 2 * bulges.len() >= ns {
            break;
        }
        if cplx {
            bulges.push([(re, im), (re, -im)]);
        } else if let Some(r0) = pending_real.take() {
            bulges.push([(r0, 0.0), (re, 0.0)]);
        } else {
            pending_real = Some(re);
        }
    }
    if bulges.is_empty() {
        if let Some(r) = pending_real {
            bulges.push([(r, 0.0), (r, 0.0)]);
        }
    }
    if bulges.len() == 1 && bulges[0][0].1 == 0.0 {
        let hkk = h[kbot + kbot * ld];
        let (a, b) = (bulges[0][0].0, bulges[0][1].0);
        let r = if (a - hkk).abs() < (b - hkk).abs() {
            a
        } else {
            b
        };
        bulges[0] = [(r, 0.0), (r, 0.0)];
    }
    bulges
}

/// Sets to zero every subdiagonal entry of the active block that is negligible by the
/// Ahues–Tisseur criterion (as dlahqr, and dlaqr5's vigilant deflation).
fn vigilant_deflation(h: &mut [f64], ld: usize, ktop: usize, kbot: usize, smlnum: f64) {
    let ulp = EPS;
    for k in ktop + 1..=kbot {
        let hkk1 = h[k + (k - 1) * ld].abs();
        if hkk1 == 0.0 {
            continue;
        }
        if hkk1 <= smlnum {
            h[k + (k - 1) * ld] = 0.0;
            continue;
        }
        let mut tst = h[k - 1 + (k - 1) * ld].abs() + h[k + k * ld].abs();
        if tst == 0.0 {
            if k >= ktop + 2 {
                tst += h[k - 1 + (k - 2) * ld].abs();
            }
            if k < kbot {
                tst += h[k + 1 + k * ld].abs();
            }
        }
        if hkk1 <= ulp * tst {
            let hk1k = h[k - 1 + k * ld].abs();
            let ab = hkk1.max(hk1k);
            let ba = hkk1.min(hk1k);
            let hkk = h[k + k * ld].abs();
            let dif = (h[k - 1 + (k - 1) * ld] - h[k + k * ld]).abs();
            let aa = hkk.max(dif);
            let bb = hkk.min(dif);
            let s = aa + ab;
            if ba * (ab / s) <= smlnum.max(ulp * (bb * (aa / s))) {
                h[k + (k - 1) * ld] = 0.0;
            }
        }
    }
}

/// `M[r0..r0+nr, c0..c0+k] ← M[r0..r0+nr, c0..c0+k] · U` (`U` column-major `k × k`).
#[allow(clippy::too_many_arguments)]
fn mul_right(
    m: &mut [f64],
    ld: usize,
    r0: usize,
    nr: usize,
    c0: usize,
    u: &[f64],
    k: usize,
    tmp: &mut Vec<f64>,
) {
    if nr == 0 || k == 0 {
        return;
    }
    tmp.clear();
    tmp.reserve(nr * k);
    for j in 0..k {
        let s = (c0 + j) * ld + r0;
        tmp.extend_from_slice(&m[s..s + nr]);
    }
    let dst = MatMut::from_column_major_slice_with_stride_mut(&mut m[r0 + c0 * ld..], nr, k, ld);
    matmul(
        dst,
        Accum::Replace,
        MatRef::from_column_major_slice(tmp, nr, k),
        MatRef::from_column_major_slice(u, k, k),
        1.0,
        Par::Seq,
    );
}

/// `M[r0..r0+k, c0..c0+nc] ← Uᵀ · M[r0..r0+k, c0..c0+nc]` (`U` column-major `k × k`).
#[allow(clippy::too_many_arguments)]
fn mul_left_t(
    m: &mut [f64],
    ld: usize,
    r0: usize,
    k: usize,
    c0: usize,
    nc: usize,
    u: &[f64],
    tmp: &mut Vec<f64>,
) {
    if nc == 0 || k == 0 {
        return;
    }
    tmp.clear();
    tmp.reserve(k * nc);
    for j in 0..nc {
        let s = (c0 + j) * ld + r0;
        tmp.extend_from_slice(&m[s..s + k]);
    }
    let dst = MatMut::from_column_major_slice_with_stride_mut(&mut m[r0 + c0 * ld..], k, nc, ld);
    matmul(
        dst,
        Accum::Replace,
        MatRef::from_column_major_slice(u, k, k).transpose(),
        MatRef::from_column_major_slice(tmp, k, nc),
        1.0,
        Par::Seq,
    );
}

/// Applies the window transformation `V` (column-major `k × k`, acting on rows/columns
/// `w0..w0+k`) to the parts of `h` outside the window (`rows 0..w0` on the right, columns
/// `w0+k..n` on the left) and to all rows of `z`.
pub(super) fn apply_far(
    h: &mut [f64],
    z: &mut [f64],
    n: usize,
    w0: usize,
    k: usize,
    v: &[f64],
    tmp: &mut Vec<f64>,
) {
    mul_right(h, n, 0, w0, w0, v, k, tmp);
    mul_left_t(h, n, w0, k, w0 + k, n - w0 - k, v, tmp);
    mul_right(z, n, 0, n, w0, v, k, tmp);
}

/// Finishes the isolated active block `ktop..=kbot` with the double-shift code on a copy, then
/// applies its orthogonal factor to the rest of `H` and to `Z` by matrix products (cheaper than
/// updating the full rows and columns reflector by reflector). If the copy does not converge, the
/// block is done in place, which reports the failure.
fn small_block(
    h: &mut [f64],
    z: &mut [f64],
    n: usize,
    ktop: usize,
    kbot: usize,
    w: &mut Work,
) -> Result<(), usize> {
    let ld = n;
    let m = kbot + 1 - ktop;
    if m <= 2 {
        return francis_qr_window(h, z, n, ktop, kbot);
    }
    w.t.clear();
    w.t.resize(m * m, 0.0);
    for j in 0..m {
        for i in 0..m.min(j + 2) {
            w.t[i + j * m] = h[ktop + i + (ktop + j) * ld];
        }
    }
    w.v.clear();
    w.v.resize(m * m, 0.0);
    for i in 0..m {
        w.v[i + i * m] = 1.0;
    }
    if francis_qr_window(&mut w.t, &mut w.v, m, 0, m - 1).is_err() {
        return francis_qr_window(h, z, n, ktop, kbot);
    }
    for j in 0..m {
        for i in 0..m {
            h[ktop + i + (ktop + j) * ld] = if i <= j + 1 { w.t[i + j * m] } else { 0.0 };
        }
    }
    apply_far(h, z, n, ktop, m, &w.v, &mut w.tmp);
    Ok(())
}

/// Aggressive early deflation (LAPACK's dlaqr3) on the trailing window of order `nw` of the
/// active block `ktop..=kbot`. Returns the undeflated eigenvalues of the window (to be used as
/// shifts) and the number of deflated eigenvalues.
fn aed(
    h: &mut [f64],
    z: &mut [f64],
    n: usize,
    ktop: usize,
    kbot: usize,
    nw: usize,
    w: &mut Work,
) -> (Vec<Shift>, usize) {
    let ld = n;
    let ulp = EPS;
    let smlnum = SAFMIN * (n as f64 / ulp);
    let jw = nw.min(kbot + 1 - ktop);
    let kwtop = kbot + 1 - jw;
    let mut s = if kwtop == ktop {
        0.0
    } else {
        h[kwtop + (kwtop - 1) * ld]
    };
    if jw == 1 {
        let hkk = h[kwtop + kwtop * ld];
        if s.abs() <= smlnum.max(ulp * hkk.abs()) {
            if kwtop > ktop {
                h[kwtop + (kwtop - 1) * ld] = 0.0;
            }
            return (Vec::new(), 1);
        }
        return (vec![(hkk, 0.0)], 0);
    }

    // Copy the window into T (Hessenberg part only) and compute its Schur form T = Vᵀ W V.
    w.t.clear();
    w.t.resize(jw * jw, 0.0);
    for j in 0..jw {
        for i in 0..jw.min(j + 2) {
            w.t[i + j * jw] = h[kwtop + i + (kwtop + j) * ld];
        }
    }
    w.v.clear();
    w.v.resize(jw * jw, 0.0);
    for i in 0..jw {
        w.v[i + i * jw] = 1.0;
    }
    let infqr = match francis_qr_window(&mut w.t, &mut w.v, jw, 0, jw - 1) {
        Ok(()) => 0,
        Err(i) => i + 1,
    };
    let (t, v) = (&mut w.t, &mut w.v);

    // Deflation detection: test the spike entries of the trailing blocks; move undeflatable
    // blocks to the top (just below the unconverged part).
    let mut ns = jw;
    let mut ilst = infqr;
    while ilst < ns {
        let bulge = ns >= 2 && ns - 2 >= ilst && t[ns - 1 + (ns - 2) * jw] != 0.0;
        if !bulge {
            let mut scale = t[ns - 1 + (ns - 1) * jw].abs();
            if scale == 0.0 {
                scale = s.abs();
            }
            if (s * v[(ns - 1) * jw]).abs() <= smlnum.max(ulp * scale) {
                ns -= 1;
            } else {
                if move_block(t, v, jw, ns - 1, ilst).is_err() {
                    break;
                }
                ilst += 1;
            }
        } else {
            let a = t[ns - 1 + (ns - 1) * jw].abs();
            let mut scale =
                a + t[ns - 1 + (ns - 2) * jw].abs().sqrt() * t[ns - 2 + (ns - 1) * jw].abs().sqrt();
            if scale == 0.0 {
                scale = s.abs();
            }
            let spike = (s * v[(ns - 1) * jw])
                .abs()
                .max((s * v[(ns - 2) * jw]).abs());
            if spike <= smlnum.max(ulp * scale) {
                ns -= 2;
            } else {
                if move_block(t, v, jw, ns - 2, ilst).is_err() {
                    break;
                }
                ilst += 2;
            }
        }
    }
    if ns == 0 {
        s = 0.0;
    }
    let shifts = block_eigenvalues(t, jw, infqr, ns);
    let nd = jw - ns;

    if ns < jw || s == 0.0 {
        if ns > 1 && s != 0.0 {
            // Reflect the spike back to a multiple of e1, then restore Hessenberg form of the
            // leading ns × ns block.
            let mut work: Vec<f64> = (0..ns).map(|j| s * v[j * jw]).collect();
            let (beta, tau) = larfg(work[0], &mut work[1..]);
            work[0] = 1.0;
            let _ = beta;
            if tau != 0.0 {
                // Left: rows 0..ns of T, all columns.
                for j in 0..jw {
                    let col = &mut t[j * jw..j * jw + ns];
                    let d: f64 = col.iter().zip(&work).map(|(a, b)| a * b).sum();
                    let f = tau * d;
                    col.iter_mut().zip(&work).for_each(|(a, b)| *a -= f * b);
                }
                // Right: columns 0..ns of T (rows 0..ns) and of V (all rows).
                for (m, rows) in [(&mut *t, ns), (&mut *v, jw)] {
                    let mut acc = vec![0.0; rows];
                    for (j, &wj) in work.iter().enumerate() {
                        let col = &m[j * jw..j * jw + rows];
                        acc.iter_mut().zip(col).for_each(|(a, c)| *a += wj * c);
                    }
                    for (j, &wj) in work.iter().enumerate() {
                        let f = tau * wj;
                        let col = &mut m[j * jw..j * jw + rows];
                        col.iter_mut().zip(&acc).for_each(|(c, a)| *c -= f * a);
                    }
                }
            }
            // Hessenberg reduction of T[0..ns, 0..ns] with Q (Q e1 = e1).
            let mut blk = vec![0.0; ns * ns];
            for j in 0..ns {
                blk[j * ns..(j + 1) * ns].copy_from_slice(&t[j * jw..j * jw + ns]);
            }
            // Cancelled during a blocked reduction: leave H and Z untouched (nothing of the
            // window has been written back yet); the caller stops at its next poll.
            let Ok(q) = hessenberg_reduce(&mut blk, ns) else {
                return (Vec::new(), 0);
            };
            for j in 0..ns {
                t[j * jw..j * jw + ns].copy_from_slice(&blk[j * ns..(j + 1) * ns]);
            }
            mul_left_t(t, jw, 0, ns, ns, jw - ns, &q, &mut w.tmp);
            mul_right(v, jw, 0, jw, 0, &q, ns, &mut w.tmp);
        }
        if kwtop > 0 && kwtop > ktop {
            h[kwtop + (kwtop - 1) * ld] = s * v[0];
        }
        // Copy the reduced window back (exact zeros below the subdiagonal).
        for j in 0..jw {
            for i in 0..jw {
                h[kwtop + i + (kwtop + j) * ld] = if i <= j + 1 { t[i + j * jw] } else { 0.0 };
            }
        }
        apply_far(h, z, n, kwtop, jw, v, &mut w.tmp);
    }
    (shifts, nd)
}

/// First column of `(H − s1)(H − s2)` at rows `k..k+nr` of the active block (LAPACK's dlaqr1),
/// scaled to avoid overflow.
fn first_column(h: &[f64], ld: usize, k: usize, nr: usize, b: &Bulge) -> [f64; 3] {
    let [(sr1, si1), (sr2, si2)] = *b;
    let h11 = h[k + k * ld];
    let h21 = h[k + 1 + k * ld];
    let h12 = h[k + (k + 1) * ld];
    let h22 = h[k + 1 + (k + 1) * ld];
    if nr == 2 {
        let s = (h11 - sr2).abs() + si2.abs() + h21.abs();
        if s == 0.0 {
            return [0.0; 3];
        }
        let h21s = h21 / s;
        [
            h21s * h12 + (h11 - sr1) * ((h11 - sr2) / s) - si1 * (si2 / s),
            h21s * (h11 + h22 - sr1 - sr2),
            0.0,
        ]
    } else {
        let h31 = h[k + 2 + k * ld];
        let h13 = h[k + (k + 2) * ld];
        let h23 = h[k + 1 + (k + 2) * ld];
        let h32 = h[k + 2 + (k + 1) * ld];
        let h33 = h[k + 2 + (k + 2) * ld];
        let s = (h11 - sr2).abs() + si2.abs() + h21.abs() + h31.abs();
        if s == 0.0 {
            return [0.0; 3];
        }
        let h21s = h21 / s;
        let h31s = h31 / s;
        [
            (h11 - sr1) * ((h11 - sr2) / s) - si1 * (si2 / s) + h12 * h21s + h13 * h31s,
            h21s * (h11 + h22 - sr1 - sr2) + h23 * h31s,
            h31s * (h11 + h33 - sr1 - sr2) + h21s * h32,
        ]
    }
}

/// One multishift QR sweep over the active block `ktop..=kbot` with the given bulges, chased as
/// a tightly packed chain (bulge `b` three rows behind bulge `b−1`). Time step `t` moves every
/// bulge one row; bulge `b` then acts at row `ktop + t − 3b`. Reflectors on disjoint rows and
/// columns commute, and each bulge only reads entries its predecessors have finished with, so
/// the result is that of the bulges chased one after another. The time steps are grouped into
/// slabs; inside a slab the reflectors are applied only to the diagonal window they touch and
/// accumulated in `U`, which is then applied to the rest of `H` and to `Z` by matrix products.
// Inlined so that it is compiled with the AVX2/FMA features of `multishift_avx2`.
#[inline(always)]
fn sweep(
    h: &mut [f64],
    z: &mut [f64],
    n: usize,
    ktop: usize,
    kbot: usize,
    bulges: &[Bulge],
    w: &mut Work,
) {
    let ld = n;
    let nb = bulges.len();
    if kbot <= ktop || nb == 0 {
        return;
    }
    let last_step = kbot - 1; // steps k = ktop..=kbot-1
    let t_end = (last_step - ktop) + 3 * (nb - 1) + 1; // time steps 0..t_end
    let slab = (3 * nb).max(6);
    let mut t0 = 0usize;
    while t0 < t_end {
        let t1 = (t0 + slab).min(t_end);
        // Positions touched in this slab.
        let kmin = (ktop + t0).saturating_sub(3 * (nb - 1)).max(ktop);
        let kmax = (ktop + t1 - 1).min(last_step);
        let w0 = if kmin > ktop { kmin - 1 } else { ktop };
        let w1 = (kmax + 3).min(kbot);
        let nw = w1 + 1 - w0;
        w.u.clear();
        w.u.resize(nw * nw, 0.0);
        for i in 0..nw {
            w.u[i + i * nw] = 1.0;
        }
        for t in t0..t1 {
            for (b, bulge) in bulges.iter().enumerate() {
                let Some(k) = (ktop + t).checked_sub(3 * b) else {
                    break;
                };
                if k < ktop {
                    break;
                }
                if k > last_step {
                    continue;
                }
                let nr = if k + 2 <= kbot { 3 } else { 2 };
                let mut v = if k == ktop {
                    first_column(h, ld, k, nr, bulge)
                } else {
                    let mut v = [0.0; 3];
                    for (r, x) in v.iter_mut().enumerate().take(nr) {
                        *x = h[k + r + (k - 1) * ld];
                    }
                    v
                };
                let (beta, tau) = larfg_short(v[0], &mut v[1..nr]);
                if k > ktop {
                    h[k + (k - 1) * ld] = beta;
                    h[k + 1 + (k - 1) * ld] = 0.0;
                    if nr == 3 {
                        h[k + 2 + (k - 1) * ld] = 0.0;
                    }
                }
                if tau == 0.0 {
                    continue;
                }
                let (v2, v3) = (v[1], if nr == 3 { v[2] } else { 0.0 });
                let (t1c, t2c, t3c) = (tau, tau * v2, tau * v3);
                // Left: rows k..k+nr, columns k..=w1.
                if nr == 3 {
                    for col in h[k * ld..(w1 + 1) * ld].chunks_exact_mut(ld) {
                        let c = &mut col[k..k + 3];
                        let sum = c[0] + v2 * c[1] + v3 * c[2];
                        c[0] -= sum * t1c;
                        c[1] -= sum * t2c;
                        c[2] -= sum * t3c;
                    }
                } else {
                    for col in h[k * ld..(w1 + 1) * ld].chunks_exact_mut(ld) {
                        let c = &mut col[k..k + 2];
                        let sum = c[0] + v2 * c[1];
                        c[0] -= sum * t1c;
                        c[1] -= sum * t2c;
                    }
                }
                // Right: columns k..k+nr, rows w0..=min(k+3, kbot) of H; all rows of U.
                let rmax = (k + 3).min(kbot) + 1;
                right_refl(h, ld, k, nr, w0..rmax, v2, v3, t1c, t2c, t3c);
                // U is a product of nb chains of consecutive reflectors, each of lower
                // bandwidth 2, so its entries below row c + 2·nb of column c are zero.
                let ku = k - w0;
                let urows = (ku + nr + 2 * nb).min(nw);
                right_refl(&mut w.u, nw, ku, nr, 0..urows, v2, v3, t1c, t2c, t3c);
            }
        }
        apply_far(h, z, n, w0, nw, &w.u, &mut w.tmp);
        t0 = t1;
    }
}

/// [`larfg`] for vectors of length 2 or 3 with a fast path when no entry is extreme (then the
/// squares cannot overflow and the norm is far above the underflow threshold).
#[inline(always)]
fn larfg_short(alpha: f64, x: &mut [f64]) -> (f64, f64) {
    let m = x.iter().fold(alpha.abs(), |acc, v| acc.max(v.abs()));
    if !(1e-150..=1e150).contains(&m) {
        return larfg(alpha, x);
    }
    let xn2: f64 = x.iter().map(|v| v * v).sum();
    if xn2 == 0.0 {
        return (alpha, 0.0);
    }
    let beta = -(alpha * alpha + xn2).sqrt().copysign(alpha);
    let tau = (beta - alpha) / beta;
    let scal = 1.0 / (alpha - beta);
    x.iter_mut().for_each(|v| *v *= scal);
    (beta, tau)
}

/// Applies the reflector `I − τ·v·vᵀ`, `v = (1, v2, v3)` (`nr = 2` ignores `v3`), from the right
/// to columns `k..k+nr`, rows `rows`, of the column-major `m` with leading dimension `ld`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn right_refl(
    m: &mut [f64],
    ld: usize,
    k: usize,
    nr: usize,
    rows: std::ops::Range<usize>,
    v2: f64,
    v3: f64,
    t1: f64,
    t2: f64,
    t3: f64,
) {
    if rows.is_empty() {
        return;
    }
    if nr == 3 {
        let (c0, rest) = m[k * ld..(k + 3) * ld].split_at_mut(ld);
        let (c1, c2) = rest.split_at_mut(ld);
        let (c0, c1, c2) = (&mut c0[rows.clone()], &mut c1[rows.clone()], &mut c2[rows]);
        for ((a, b), c) in c0.iter_mut().zip(c1.iter_mut()).zip(c2.iter_mut()) {
            let sum = *a + v2 * *b + v3 * *c;
            *a -= sum * t1;
            *b -= sum * t2;
            *c -= sum * t3;
        }
    } else {
        let (c0, c1) = m[k * ld..(k + 2) * ld].split_at_mut(ld);
        let (c0, c1) = (&mut c0[rows.clone()], &mut c1[rows]);
        for (a, b) in c0.iter_mut().zip(c1.iter_mut()) {
            let sum = *a + v2 * *b;
            *a -= sum * t1;
            *b -= sum * t2;
        }
    }
}
