//! Block reordering of a real Schur form (Kressner, "Block algorithms for reordering standard
//! and generalized Schur forms", ACM TOMS 32, 2006): the selected eigenvalues are moved to the
//! top in chunks of up to [`CHUNK`] rows, each chunk through a sequence of diagonal windows of
//! order at most [`WINDOW`]. Inside a window the adjacent swaps of [`super::reorder`] act on a
//! copy of the window only and their product is accumulated into a small orthogonal `U`; the rows
//! and columns outside the window and `Z` are then updated by three matrix products with `U`.
//!
//! The swaps are exactly those of the unblocked ordering (dtrsen over dtrexc/dlaexc, with the
//! same rejection test), only their application to the far parts of `T` and `Z` is deferred and
//! batched: the rotations of an unblocked reordering touch whole rows and columns of `T` and `Z`
//! one at a time (memory bound), the products here run at matrix-multiply speed.

use super::multishift::apply_far;
use super::reorder::{block_size_at, move_block, SwapRejected};

/// Selected rows moved together through the windows.
const CHUNK: usize = 16;
/// Largest window order.
const WINDOW: usize = 32;
/// From this order on the blocked ordering is used: below it the unblocked one is as fast
/// (`reorder_window_timing`, ordering the Hamiltonian of a random CARE: order 200, 1.2 ms
/// unblocked and blocked; order 400: 8.3 / 5.6 ms; order 800: 68 / 40 ms; windows of 16 to 64
/// rows are within 20 % of each other, larger ones slower).
pub(super) const BLOCKED_MIN: usize = 256;

/// The ordering loop of LAPACK's dtrsen: each selected block in turn (rows with `sel[i]`) moved
/// to the top by adjacent swaps applied to the whole of `t` and `z`, `cancelled` polled once per
/// block. The rows a move shifts down are unselected, so the flags of the rows not yet visited
/// hold. Returns the number of selected rows.
pub(super) fn reorder_unblocked(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    sel: &[bool],
    cancelled: &dyn Fn() -> bool,
) -> Result<usize, Interrupt> {
    let mut ks = 0usize;
    let mut k = 0usize;
    while k < n {
        if cancelled() {
            return Err(Interrupt::Cancelled);
        }
        let bs = block_size_at(t, n, k);
        if sel[k] {
            if k != ks {
                move_block(t, z, n, k, ks).map_err(|(rej, at)| Interrupt::Rejected(rej, at))?;
            }
            ks += bs;
        }
        k += bs;
    }
    Ok(ks)
}

/// Moves every row `i` with `sel[i]` to the leading rows of the quasi-triangular `t`
/// (column-major `n × n`), updating `z`, keeping the selected blocks in their relative order;
/// both rows of a 2×2 block must carry the same flag. Returns the number of selected rows. On a
/// rejected swap returns the rejection and the row where it happened; `t` and `z` then hold a
/// valid but partially reordered Schur form (the caller restores them).
pub(super) fn reorder_selected(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    sel: &[bool],
    cancelled: &dyn Fn() -> bool,
) -> Result<usize, Interrupt> {
    if n < BLOCKED_MIN {
        return reorder_unblocked(t, z, n, sel, cancelled);
    }
    reorder_selected_with(t, z, n, sel, cancelled, WINDOW, CHUNK)
}

/// [`reorder_selected`] with the window order and chunk size given (`2 ≤ chunk ≤ window / 2`).
fn reorder_selected_with(
    t: &mut [f64],
    z: &mut [f64],
    n: usize,
    sel: &[bool],
    cancelled: &dyn Fn() -> bool,
    window: usize,
    chunk: usize,
) -> Result<usize, Interrupt> {
    debug_assert_eq!(sel.len(), n);
    let total = sel.iter().filter(|&&s| s).count();
    let mut sel = sel.to_vec();
    let mut tw: Vec<f64> = Vec::new();
    let mut u: Vec<f64> = Vec::new();
    let mut tmp: Vec<f64> = Vec::new();
    let mut ks = 0usize;
    // Each window either extends the ordered top (ks grows) or moves the first unordered
    // selected row up by at least window / 2 rows: at most n·(2n / WINDOW + 1) windows.
    let max_windows = n * (2 * n / window + 1) + 1;
    for _ in 0..max_windows {
        while ks < n && sel[ks] {
            ks += 1;
        }
        if ks >= total {
            return Ok(total);
        }
        if cancelled() {
            return Err(Interrupt::Cancelled);
        }
        let Some(j) = (ks..n).find(|&i| sel[i]) else {
            return Ok(total);
        };
        // The chunk: selected blocks from j on, at most CHUNK selected rows spanning at most
        // window / 2 rows (so the window reaches at least window / 2 rows above it).
        let (mut hi, mut end, mut count) = (j, j, 0usize);
        while hi < n {
            let bs = block_size_at(t, n, hi);
            if hi + bs - j > window / 2 && hi > j {
                break;
            }
            if sel[hi] {
                if count + bs > chunk && count > 0 {
                    break;
                }
                count += bs;
                end = hi + bs;
            }
            hi += bs;
        }
        let hi = end;
        let mut lo = hi.saturating_sub(window).max(ks);
        if lo > ks && t[lo + (lo - 1) * n] != 0.0 {
            lo += 1; // do not cut a 2×2 block
        }
        let w = hi - lo;
        tw.clear();
        for c in lo..hi {
            tw.extend_from_slice(&t[lo + c * n..hi + c * n]);
        }
        u.clear();
        u.resize(w * w, 0.0);
        for i in 0..w {
            u[i + i * w] = 1.0;
        }
        // The swaps of the unblocked ordering, on the window's copy, accumulated into U
        // (cancellation is polled once per window, above).
        let lks =
            reorder_unblocked(&mut tw, &mut u, w, &sel[lo..hi], &|| false).map_err(|stop| {
                match stop {
                    Interrupt::Rejected(rej, at) => Interrupt::Rejected(rej, lo + at),
                    other => other,
                }
            })?;
        for (c, col) in tw.chunks_exact(w).enumerate() {
            t[lo + (lo + c) * n..hi + (lo + c) * n].copy_from_slice(col);
        }
        apply_far(t, z, n, lo, w, &u, &mut tmp);
        for (i, s) in sel[lo..hi].iter_mut().enumerate() {
            *s = i < lks;
        }
    }
    // Not reached (see the bound above); should it ever be, finish with the unblocked ordering.
    reorder_unblocked(t, z, n, &sel, cancelled)
}

/// Why [`reorder_selected`] stopped early.
#[derive(Debug, Clone, Copy)]
pub(super) enum Interrupt {
    /// A swap was rejected at the given row.
    Rejected(SwapRejected, usize),
    /// The cancellation callback asked to stop (checked once per window).
    Cancelled,
}

#[cfg(test)]
mod tests {
    use super::super::tests::{check, eig_distance, rejected_pair};
    use super::super::RealSchur;
    use super::BLOCKED_MIN;
    use crate::linalg::testing::Rng;
    use crate::Error;
    use nalgebra::DMatrix;

    fn unblocked(s: &mut RealSchur, sel: &[bool]) -> usize {
        let n = s.t.nrows();
        super::reorder_unblocked(s.t.as_mut_slice(), s.z.as_mut_slice(), n, sel, &|| false).unwrap()
    }

    /// The blocked ordering (through `reorder`, and directly with small windows so that a moderate
    /// order crosses many windows) and the unblocked one agree on the same form: same selected
    /// count, the same eigenvalues in the same order on the diagonal, both backward stable.
    fn compare(a: &DMatrix<f64>, select: &dyn Fn(f64, f64) -> bool) {
        let n = a.nrows();
        let s0 = RealSchur::new(a).unwrap();
        let mut sel = vec![false; n];
        for (k, size) in s0.blocks() {
            let ev = s0.eigenvalues()[k];
            sel[k..k + size]
                .iter_mut()
                .for_each(|s| *s = select(ev.0, ev.1));
        }
        let mut plain = s0.clone();
        let sdim = unblocked(&mut plain, &sel);
        assert_eq!(sdim, sel.iter().filter(|&&s| s).count());
        let ep = plain.eigenvalues();
        let tol = 1e-9 * a.norm();
        let mut public = s0.clone();
        assert_eq!(public.reorder(select).unwrap(), sdim);
        let mut variants = vec![public];
        for &(window, chunk) in &[(8, 2), (16, 4), (24, 12), (64, 32)] {
            let mut s = s0.clone();
            let got = super::reorder_selected_with(
                s.t.as_mut_slice(),
                s.z.as_mut_slice(),
                n,
                &sel,
                &|| false,
                window,
                chunk,
            )
            .unwrap();
            assert_eq!(got, sdim, "window {window}, chunk {chunk}");
            variants.push(s);
        }
        for s in &variants {
            check(a, s, 20.0);
            let eb = s.eigenvalues();
            assert!(eig_distance(&eb, &ep) <= tol);
            // Same order, not only the same set: entrywise along the diagonal.
            for (x, y) in eb.iter().zip(&ep) {
                assert!(
                    (x.0 - y.0).abs() + (x.1.abs() - y.1.abs()).abs() <= tol,
                    "{x:?} vs {y:?}"
                );
            }
            assert!(eb[..sdim].iter().all(|e| select(e.0, e.1.abs())));
            assert!(sdim == n || sdim == 0 || s.t[(sdim, sdim - 1)] == 0.0);
        }
    }

    #[test]
    fn blocked_ordering_matches_the_unblocked_one() {
        let mut rng = Rng::new(21);
        for &n in &[37usize, 90, BLOCKED_MIN + 3] {
            let a = rng.matrix(n, n);
            compare(&a, &|re, _| re < 0.0);
            // Complex pairs first; a sparse selection far down (long moves through many windows).
            compare(&a, &|_, im| im != 0.0);
            compare(&a, &|re, _| re > 0.8 * (n as f64).sqrt());
            // Everything or nothing: nothing moves.
            compare(&a, &|_, _| true);
            compare(&a, &|_, _| false);
        }
        // A Hamiltonian, the CARE solver's case, with graded entries.
        let n = 45;
        let am = rng.matrix(n, n);
        let g = rng.psd(n, 4);
        let q = rng.psd(n, n);
        let mut h = DMatrix::zeros(2 * n, 2 * n);
        h.view_mut((0, 0), (n, n)).copy_from(&am);
        h.view_mut((0, n), (n, n)).copy_from(&(-&g * 1e3));
        h.view_mut((n, 0), (n, n)).copy_from(&(-&q * 1e-3));
        h.view_mut((n, n), (n, n)).copy_from(&(-am.transpose()));
        compare(&h, &|re, _| re < 0.0);
    }

    /// Timings of the ordering of a CARE Hamiltonian for several window / chunk sizes:
    /// `cargo test --release --lib reorder_window_timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn reorder_window_timing() {
        let mut rng = Rng::new(24);
        for &n in &[100usize, 200, 400] {
            let am = rng.matrix(n, n) * (1.0 / (n as f64).sqrt());
            let b = rng.matrix(n, n / 2);
            let q = rng.psd(n, n) * (1.0 / n as f64) + DMatrix::identity(n, n);
            let mut h = DMatrix::zeros(2 * n, 2 * n);
            h.view_mut((0, 0), (n, n)).copy_from(&am);
            h.view_mut((0, n), (n, n)).copy_from(&(-&b * b.transpose()));
            h.view_mut((n, 0), (n, n)).copy_from(&(-q));
            h.view_mut((n, n), (n, n)).copy_from(&(-am.transpose()));
            let s0 = RealSchur::new(&h).unwrap();
            let sel: Vec<bool> = {
                let mut v = vec![false; 2 * n];
                for (k, size) in s0.blocks() {
                    let neg = s0.eigenvalues()[k].0 < 0.0;
                    v[k..k + size].iter_mut().for_each(|x| *x = neg);
                }
                v
            };
            let time = |f: &mut dyn FnMut()| {
                let mut best = f64::INFINITY;
                for _ in 0..7 {
                    let t0 = std::time::Instant::now();
                    f();
                    best = best.min(t0.elapsed().as_secs_f64());
                }
                best * 1e3
            };
            let plain = time(&mut || {
                let mut s = s0.clone();
                unblocked(&mut s, &sel);
            });
            eprintln!("order {}: unblocked {plain:.2} ms", 2 * n);
            for &(w, c) in &[(16, 8), (24, 12), (32, 8), (32, 16), (40, 20), (64, 32)] {
                let ms = time(&mut || {
                    let mut s = s0.clone();
                    let nn = 2 * n;
                    super::reorder_selected_with(
                        s.t.as_mut_slice(),
                        s.z.as_mut_slice(),
                        nn,
                        &sel,
                        &|| false,
                        w,
                        c,
                    )
                    .unwrap();
                });
                eprintln!("  window {w:3} chunk {c:2}: {ms:.2} ms");
            }
        }
    }

    #[test]
    fn a_rejected_swap_in_a_window_restores_the_form() {
        // The coupled pair that dlaexc refuses, at the bottom of a large triangular form: moving
        // its second block to the top fails at the first swap, and T, Z are as on entry.
        let mut rng = Rng::new(22);
        let n = BLOCKED_MIN + 8;
        let mut t = rng.matrix(n, n);
        for j in 0..n {
            for i in j + 1..n {
                t[(i, j)] = 0.0;
            }
            t[(j, j)] = rng.uniform() - 0.5;
        }
        t.view_mut((n - 4, n - 4), (4, 4))
            .copy_from(&rejected_pair());
        let z = rng.orthogonal(n);
        let mut s = RealSchur {
            t: t.clone(),
            z: z.clone(),
        };
        let second = s.eigenvalues()[n - 2].0;
        let res = s.reorder(|re, _| re == second);
        assert!(matches!(res, Err(Error::Reorder(_))), "{res:?}");
        assert_eq!(s.t, t);
        assert_eq!(s.z, z);
    }

    #[test]
    fn a_cancelled_ordering_stops_and_restores_the_form() {
        let mut rng = Rng::new(23);
        let a = rng.matrix(BLOCKED_MIN + 10, BLOCKED_MIN + 10);
        let s0 = RealSchur::new(&a).unwrap();
        let mut s = s0.clone();
        let token = crate::cancel::Token::new();
        token.cancel();
        let res = crate::cancel::with_token(Some(&token), || s.reorder(|re, _| re < 0.0));
        assert!(matches!(res, Err(Error::Interrupted(_))), "{res:?}");
        assert_eq!(s.t, s0.t);
        assert_eq!(s.z, s0.z);
    }
}
