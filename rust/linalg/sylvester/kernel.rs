// Why this module is long: one algorithm, the recursive blocked quasi-triangular Sylvester/Lyapunov
// solver (LAPACK's dtrsyl/dlasy2 leaves with scaling against overflow and the pivot record).
//! Back substitution on the quasi-triangular (real Schur) form.
//!
//! Two kernels, both recursive and blocked so that almost all flops are level-3 products
//! (Jonsson–Kågström's RECSY splitting; the leaves follow LAPACK dtrsyl / SLICOT sb03my):
//!
//! * [`sylv`]: `T X + X op(S) = C` with `T`, `S` upper quasi-triangular and `op(S) = S` or `Sᵀ`
//!   (dtrsyl's `N,N` and `N,T`);
//! * [`lyap`]: `T Y + Y Tᵀ = C` with `C` symmetric: only the upper triangle of `C` is read, the full
//!   symmetric `Y` is written, and only the upper block triangle is solved for (half the flops).
//!
//! Matrices are column-major slices with a leading dimension. The row index of `C` is the index of
//! `T`, its column index the index of `S`, so one buffer serves a whole problem and sub-problems are
//! index ranges. Entries of `T`, `S` below the first subdiagonal are never read. A subdiagonal entry
//! `t[(k+1, k)] != 0` marks a 2×2 diagonal block; the blocks need not be standardised (a 2×2 block
//! with real eigenvalues is solved like any other), but two consecutive nonzero subdiagonal entries
//! are not allowed (the caller checks that).
//!
//! The leaves solve block column after block column of `X`. A block column whose `op(S)` diagonal
//! block is 1×1 is a shifted quasi-triangular back substitution; the small systems at 2×2 blocks of
//! `T` (order 2) are solved by Gaussian elimination with complete pivoting, as in dlasy2. A 2-column
//! block whose `op(S)` block has complex eigenvalues `μ, μ̄` and a well-conditioned eigenvector basis
//! (always so for the standardised blocks of a real Schur form, unless nearly defective) is solved
//! as one complex column `(T + μ I) w = g` (see [`ComplexColumn`]); otherwise the 2×2-by-2×2 blocks
//! are 4×4 real systems with complete pivoting, as in dlasy2. Where dtrsyl would replace a pivot
//! below `smin` by `smin` and carry on, these kernels stop with [`Error::SingularProblem`]:
//! `λ_i + μ_j ≈ 0` and the solution would be noise. Pivot magnitudes of complex pivots are measured
//! as `|re| + |im|` (within √2 of the modulus).

use crate::linalg::dense::axpy;
use crate::{Error, Result};
use faer::linalg::matmul::matmul;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::reborrow::*;
use faer::{Accum, MatMut, MatRef, Par};

/// Leaves of the recursion: problems with both dimensions at most this are solved directly.
const NB: usize = 32;

/// A read-only column-major matrix stored in a slice.
#[derive(Clone, Copy)]
pub(crate) struct View<'a> {
    pub a: &'a [f64],
    pub ld: usize,
}

impl<'a> View<'a> {
    pub fn new(a: &'a [f64], ld: usize) -> Self {
        debug_assert!(ld > 0 && a.len().is_multiple_of(ld));
        View { a, ld }
    }

    #[inline(always)]
    fn at(&self, i: usize, j: usize) -> f64 {
        self.a[i + j * self.ld]
    }

    /// Rows `r0..r1` of column `j`.
    #[inline(always)]
    fn col(&self, j: usize, r0: usize, r1: usize) -> &'a [f64] {
        &self.a[j * self.ld + r0..j * self.ld + r1]
    }

    fn faer(&self) -> MatRef<'a, f64> {
        MatRef::from_column_major_slice_with_stride(
            self.a,
            self.ld,
            self.a.len() / self.ld,
            self.ld,
        )
    }

    /// The diagonal block starting at `k` of size `size` as `[t00, t10, t01, t11]`.
    #[inline(always)]
    fn block(&self, k: usize, size: usize) -> [f64; 4] {
        if size == 1 {
            [self.at(k, k), 0.0, 0.0, 0.0]
        } else {
            [
                self.at(k, k),
                self.at(k + 1, k),
                self.at(k, k + 1),
                self.at(k + 1, k + 1),
            ]
        }
    }

    /// The diagonal block that ends just before `end` (its last index is `end - 1`), not starting
    /// before `start`.
    #[inline(always)]
    fn block_ending(&self, start: usize, end: usize) -> (usize, usize) {
        if end - 1 > start && self.at(end - 1, end - 2) != 0.0 {
            (end - 2, 2)
        } else {
            (end - 1, 1)
        }
    }

    /// The diagonal block that starts at `k`, not extending to `end` or beyond.
    #[inline(always)]
    fn block_starting(&self, k: usize, end: usize) -> usize {
        if k + 1 < end && self.at(k + 1, k) != 0.0 {
            2
        } else {
            1
        }
    }

    /// A split point near the middle of `r0..r1` that does not cut a 2×2 block.
    fn split(&self, r0: usize, r1: usize) -> usize {
        let h = r0 + (r1 - r0) / 2;
        if self.at(h, h - 1) != 0.0 {
            h + 1
        } else {
            h
        }
    }
}

fn faer_mut(c: &mut [f64], ld: usize) -> MatMut<'_, f64> {
    let ncols = c.len() / ld;
    MatMut::from_column_major_slice_with_stride_mut(c, ld, ncols, ld)
}

/// Which equation is being solved; only used to word error messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    /// `A X + X B = Q` (messages speak of `λ_i(A) + λ_j(B)`).
    Sylvester,
    /// `A X + X Aᵀ = Q` or its adjoint (messages speak of `λ_i(A) + λ_j(A)`).
    Lyapunov,
    /// `T X + X S = C` given directly in quasi-triangular form.
    QuasiTriangular,
}

/// State shared by one solve: the pivot threshold and the smallest pivot met.
pub(crate) struct Ctx {
    /// Pivots below this are treated as zero (the equation is singular or nearly so).
    pub smin: f64,
    /// The smallest pivot magnitude met so far.
    pub min_pivot: f64,
    pub kind: Kind,
}

impl Ctx {
    pub fn new(smin: f64, kind: Kind) -> Self {
        Ctx {
            smin,
            min_pivot: f64::INFINITY,
            kind,
        }
    }

    #[cold]
    #[inline(never)]
    fn singular(&self, tb: [f64; 4], mk: usize, sb: [f64; 4], nl: usize, pivot: f64) -> Error {
        let (eq, a, b) = match self.kind {
            Kind::Sylvester => ("Sylvester equation A X + X B = Q", "A", "B"),
            Kind::Lyapunov => ("Lyapunov equation", "A", "A"),
            Kind::QuasiTriangular => ("Sylvester equation T X + X S = C", "T", "S"),
        };
        Error::SingularProblem(format!(
            "{eq} is singular or nearly so: λ_i({a}) + λ_j({b}) ≈ 0 for λ_i ∈ {{{}}} and λ_j ∈ {{{}}} \
             (pivot {pivot:.3e} is below the tolerance {:.3e}); the solution is not unique or cannot \
             be computed accurately",
            fmt_eigs(tb, mk),
            fmt_eigs(sb, nl),
            self.smin
        ))
    }

    #[cold]
    #[inline(never)]
    fn overflow(&self) -> Error {
        Error::SingularProblem(format!(
            "{} solution overflows: the equation is too ill-conditioned (λ_i + λ_j too close to 0 \
             relative to the size of the right-hand side)",
            match self.kind {
                Kind::Sylvester | Kind::QuasiTriangular => "Sylvester equation",
                Kind::Lyapunov => "Lyapunov equation",
            }
        ))
    }
}

/// A number for messages: fixed notation in a readable range, scientific otherwise.
fn fmt_num(x: f64) -> String {
    if x == 0.0 || (1e-3..1e6).contains(&x.abs()) {
        let s = format!("{x:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s == "-0" {
            "0".to_string()
        } else {
            s.to_string()
        }
    } else {
        format!("{x:.6e}")
    }
}

/// Eigenvalues of a 1×1 or 2×2 block (`[t00, t10, t01, t11]`), formatted for messages.
fn fmt_eigs(b: [f64; 4], size: usize) -> String {
    if size == 1 {
        return fmt_num(b[0]);
    }
    let re = 0.5 * (b[0] + b[3]);
    let half = 0.5 * (b[0] - b[3]);
    let disc = half * half + b[1] * b[2];
    if disc >= 0.0 {
        let r = disc.sqrt();
        format!("{}, {}", fmt_num(re + r), fmt_num(re - r))
    } else {
        format!("{} ± {}i", fmt_num(re), fmt_num((-disc).sqrt()))
    }
}

/// `piv < smin`, or `piv` is NaN.
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn too_small(piv: f64, smin: f64) -> bool {
    !(piv >= smin)
}

/// Solves the `P×P` system `a x = b` (row-major `a`) in place in `b` by Gaussian elimination with
/// complete pivoting. Returns the smallest pivot magnitude, or `Err(pivot)` when a pivot falls below
/// `smin` (or is NaN).
#[inline(always)]
#[allow(clippy::needless_range_loop)]
fn solve_cp<const P: usize>(
    a: &mut [[f64; P]; P],
    b: &mut [f64; P],
    smin: f64,
) -> std::result::Result<f64, f64> {
    let mut colperm = [0usize; P];
    for (k, c) in colperm.iter_mut().enumerate() {
        *c = k;
    }
    let mut min_piv = f64::INFINITY;
    for k in 0..P {
        // Branch-free search: the pivot position is data dependent and would mispredict.
        let (mut ip, mut jp, mut big) = (k, k, -1.0);
        for (i, row) in a.iter().enumerate().skip(k) {
            for (j, v) in row.iter().enumerate().skip(k) {
                let v = v.abs();
                let gt = v > big;
                big = if gt { v } else { big };
                ip = if gt { i } else { ip };
                jp = if gt { j } else { jp };
            }
        }
        // NaN pivots fail the comparison as well.
        if too_small(big, smin) {
            return Err(big);
        }
        min_piv = min_piv.min(big);
        if ip != k {
            a.swap(ip, k);
            b.swap(ip, k);
        }
        if jp != k {
            for row in a.iter_mut() {
                row.swap(jp, k);
            }
            colperm.swap(jp, k);
        }
        let inv = 1.0 / a[k][k];
        for i in (k + 1)..P {
            let l = a[i][k] * inv;
            for j in (k + 1)..P {
                a[i][j] -= l * a[k][j];
            }
            b[i] -= l * b[k];
        }
    }
    let mut x = [0.0; P];
    for k in (0..P).rev() {
        let mut s = b[k];
        for j in (k + 1)..P {
            s -= a[k][j] * x[j];
        }
        x[k] = s / a[k][k];
    }
    for k in 0..P {
        b[colperm[k]] = x[k];
    }
    Ok(min_piv)
}

/// `op(Sb)` (`Sb` or `Sbᵀ`) of a block stored as `[s00, s10, s01, s11]`.
#[inline(always)]
fn op_block(sb: [f64; 4], trans: bool) -> [f64; 4] {
    if trans {
        [sb[0], sb[2], sb[1], sb[3]]
    } else {
        sb
    }
}

/// A complex number, for the complex-column path of [`column_backsub`].
#[derive(Clone, Copy, Debug)]
struct Cx {
    re: f64,
    im: f64,
}

impl Cx {
    #[inline(always)]
    fn new(re: f64, im: f64) -> Self {
        Cx { re, im }
    }

    /// `|re| + |im|`, within a factor √2 of the modulus (LAPACK's CABS1): pivot sizes need no more
    /// precision than that, and `hypot` would cost more than the rest of a 2×2 solve.
    #[inline(always)]
    fn abs1(self) -> f64 {
        self.re.abs() + self.im.abs()
    }

    #[inline(always)]
    fn mul(self, o: Cx) -> Cx {
        Cx::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }

    #[inline(always)]
    fn sub(self, o: Cx) -> Cx {
        Cx::new(self.re - o.re, self.im - o.im)
    }

    /// `1/self` without intermediate overflow or underflow (Smith's algorithm).
    #[inline(always)]
    fn recip(self) -> Cx {
        if self.re.abs() >= self.im.abs() {
            let r = self.im / self.re;
            let den = self.re + self.im * r;
            Cx::new(1.0 / den, -r / den)
        } else {
            let r = self.re / self.im;
            let den = self.re * r + self.im;
            Cx::new(r / den, -1.0 / den)
        }
    }
}

/// Solves the complex 2×2 system `a x = b` by elimination with complete pivoting; returns the
/// smallest pivot magnitude, or `Err(pivot)` when a pivot is below `smin`.
#[inline(always)]
fn solve_cx2(a: [[Cx; 2]; 2], b: [Cx; 2], smin: f64) -> std::result::Result<([Cx; 2], f64), f64> {
    let mags = [
        a[0][0].abs1(),
        a[0][1].abs1(),
        a[1][0].abs1(),
        a[1][1].abs1(),
    ];
    let mut best = 0;
    for q in 1..4 {
        if mags[q] > mags[best] {
            best = q;
        }
    }
    let (i, j) = (best / 2, best % 2);
    let (oi, oj) = (1 - i, 1 - j);
    let p1 = mags[best];
    if too_small(p1, smin) {
        return Err(p1);
    }
    let inv1 = a[i][j].recip();
    let l = a[oi][j].mul(inv1);
    let u = a[oi][oj].sub(l.mul(a[i][oj]));
    let p2 = u.abs1();
    if too_small(p2, smin) {
        return Err(p2);
    }
    let mut x = [Cx::new(0.0, 0.0); 2];
    x[oj] = b[oi].sub(l.mul(b[i])).mul(u.recip());
    x[j] = b[i].sub(a[i][oj].mul(x[oj])).mul(inv1);
    Ok((x, p1.min(p2)))
}

/// Largest condition number of the eigenvector basis accepted by the complex-column path.
const MAX_BASIS_COND: f64 = 8.0;

/// For a 2×2 block `S'` with complex eigenvalues `μ, μ̄`, `μ = α + iβ`: a real basis
/// `V = [Re v, Im v]` of an eigenvector `S' v = μ v`, and `V⁻¹`.
///
/// A block column `X` (m×2) of `T X + X S' = R` then satisfies `(T + μ I) w = R v` with `w = X v`,
/// i.e. `[Re w, Im w] = X V`: one complex back substitution instead of 2×2-by-2×2 block systems
/// (4×4 real with complete pivoting) at every diagonal block of `T`. The basis is only used when it
/// is well conditioned (`κ(V) ≤ MAX_BASIS_COND`), which holds unless `S'` is far from normal.
struct ComplexColumn {
    mu: Cx,
    v: [f64; 4],
    vinv: [f64; 4],
}

impl ComplexColumn {
    #[inline(always)]
    fn new(sp: [f64; 4]) -> Option<Self> {
        let (p, r, q, s) = (sp[0], sp[1], sp[2], sp[3]);
        let half = 0.5 * (p - s);
        let disc = half * half + q * r;
        if disc.is_nan() || disc >= 0.0 {
            return None;
        }
        let alpha = 0.5 * (p + s);
        let beta = (-disc).sqrt();
        // From the first row of (S' − μ I) v = 0: v = [q, μ − p]; from the second: v = [μ − s, r].
        let v1 = [q, alpha - p, 0.0, beta];
        let v2 = [alpha - s, r, beta, 0.0];
        let (k1, k2) = (cond2(v1), cond2(v2));
        let (v, k) = if k1 <= k2 { (v1, k1) } else { (v2, k2) };
        if k.is_nan() || k > MAX_BASIS_COND {
            return None;
        }
        let det = v[0] * v[3] - v[2] * v[1];
        let vinv = [v[3] / det, -v[1] / det, -v[2] / det, v[0] / det];
        Some(ComplexColumn {
            mu: Cx::new(alpha, beta),
            v,
            vinv,
        })
    }
}

/// 2-norm condition number of a 2×2 matrix `[m00, m10, m01, m11]` (infinite if singular).
#[inline(always)]
fn cond2(m: [f64; 4]) -> f64 {
    let f = m.iter().map(|v| v * v).sum::<f64>();
    let d = (m[0] * m[3] - m[2] * m[1]).abs();
    if d == 0.0 {
        return f64::INFINITY;
    }
    (f + (f * f - 4.0 * d * d).max(0.0).sqrt()) / (2.0 * d)
}

/// Solves `Tb X + X op(Sb) = R` for an `mk × nl` block (`mk, nl ∈ {1, 2}`), `R` column-major in `r`
/// (`r[i + mk·j]`), overwriting `r` with `X`. Returns the smallest pivot, or `Err(pivot)` when a pivot
/// is below `smin`.
///
/// With `S' = op(Sb)`, `vec(T X + X S') = (I ⊗ T + S'ᵀ ⊗ I) vec(X)`.
#[inline(always)]
fn block_solve(
    smin: f64,
    tb: [f64; 4],
    mk: usize,
    sb: [f64; 4],
    nl: usize,
    trans: bool,
    r: &mut [f64; 4],
) -> std::result::Result<f64, f64> {
    let sp = op_block(sb, trans);
    match (mk, nl) {
        (1, 1) => {
            let tau = tb[0] + sp[0];
            let piv = tau.abs();
            if piv >= smin {
                r[0] *= 1.0 / tau;
                Ok(piv)
            } else {
                Err(piv)
            }
        }
        (2, 1) => {
            // (T + s I) x = r.
            let s = sp[0];
            let mut a = [[tb[0] + s, tb[2]], [tb[1], tb[3] + s]];
            let mut b = [r[0], r[1]];
            let out = solve_cp::<2>(&mut a, &mut b, smin);
            r[0] = b[0];
            r[1] = b[1];
            out
        }
        (1, 2) => {
            // x (t + S') = r  ⇔  (t + S'ᵀ) xᵀ = rᵀ.
            let t = tb[0];
            let mut a = [[t + sp[0], sp[1]], [sp[2], t + sp[3]]];
            let mut b = [r[0], r[1]];
            let out = solve_cp::<2>(&mut a, &mut b, smin);
            r[0] = b[0];
            r[1] = b[1];
            out
        }
        _ => {
            // Unknowns x00, x10, x01, x11; row (i, j) = i + 2j.
            let (t00, t10, t01, t11) = (tb[0], tb[1], tb[2], tb[3]);
            let (s00, s10, s01, s11) = (sp[0], sp[1], sp[2], sp[3]);
            let mut a = [
                [t00 + s00, t01, s10, 0.0],
                [t10, t11 + s00, 0.0, s10],
                [s01, 0.0, t00 + s11, t01],
                [0.0, s01, t10, t11 + s11],
            ];
            solve_cp::<4>(&mut a, r, smin)
        }
    }
}

/// Solves the symmetric `T Y + Y Tᵀ = R` for a diagonal 2×2 block: unknowns `y00, y01, y11`.
/// `r = [r00, r01, r11]` is overwritten with the solution.
#[inline(always)]
fn lyap_block2(smin: f64, tb: [f64; 4], r: &mut [f64; 3]) -> std::result::Result<f64, f64> {
    let (a, c, b, d) = (tb[0], tb[1], tb[2], tb[3]);
    let mut m = [
        [2.0 * a, 2.0 * b, 0.0],
        [c, a + d, b],
        [0.0, 2.0 * c, 2.0 * d],
    ];
    solve_cp::<3>(&mut m, r, smin)
}

/// `c[:, dst] -= alpha · c[:, src]` on rows `r0..r1` (`src != dst`).
#[inline(always)]
fn axpy_cols(c: &mut [f64], ld: usize, src: usize, dst: usize, r0: usize, r1: usize, alpha: f64) {
    debug_assert_ne!(src, dst);
    let (x, y) = if src < dst {
        let (lo, hi) = c.split_at_mut(dst * ld);
        (&lo[src * ld + r0..src * ld + r1], &mut hi[r0..r1])
    } else {
        let (lo, hi) = c.split_at_mut(src * ld);
        (&hi[r0..r1], &mut lo[dst * ld + r0..dst * ld + r1])
    };
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi -= alpha * xi;
    }
}

/// Solves `T X + X op(S) = C` on rows `r0..r1` and columns `c0..c1` of `c` (leading dimension
/// `ldc`), where contributions of `X` outside that block have already been subtracted.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sylv(
    ctx: &mut Ctx,
    t: View<'_>,
    s: View<'_>,
    trans: bool,
    c: &mut [f64],
    ldc: usize,
    (r0, r1): (usize, usize),
    (c0, c1): (usize, usize),
) -> Result<()> {
    let (m, n) = (r1 - r0, c1 - c0);
    if m == 0 || n == 0 {
        return Ok(());
    }
    if m <= NB && n <= NB {
        return sylv_leaf(ctx, t, s, trans, c, ldc, (r0, r1), (c0, c1));
    }
    if m >= n {
        // T = [T11 T12; 0 T22]: X2 from the bottom rows first, then C1 -= T12 X2.
        let h = t.split(r0, r1);
        sylv(ctx, t, s, trans, c, ldc, (h, r1), (c0, c1))?;
        {
            let blk = faer_mut(c, ldc).submatrix_mut(r0, c0, m, n);
            let (top, bot) = blk.split_at_row_mut(h - r0);
            let t12 = t.faer().submatrix(r0, h, h - r0, r1 - h);
            matmul(top, Accum::Add, t12, bot.rb(), -1.0, Par::Seq);
        }
        sylv(ctx, t, s, trans, c, ldc, (r0, h), (c0, c1))
    } else {
        let h = s.split(c0, c1);
        let s12 = s.faer().submatrix(c0, h, h - c0, c1 - h);
        if !trans {
            // X S = [X1 S11, X1 S12 + X2 S22]: left columns first.
            sylv(ctx, t, s, trans, c, ldc, (r0, r1), (c0, h))?;
            {
                let blk = faer_mut(c, ldc).submatrix_mut(r0, c0, m, n);
                let (left, right) = blk.split_at_col_mut(h - c0);
                matmul(right, Accum::Add, left.rb(), s12, -1.0, Par::Seq);
            }
            sylv(ctx, t, s, trans, c, ldc, (r0, r1), (h, c1))
        } else {
            // X Sᵀ = [X1 S11ᵀ + X2 S12ᵀ, X2 S22ᵀ]: right columns first.
            sylv(ctx, t, s, trans, c, ldc, (r0, r1), (h, c1))?;
            {
                let blk = faer_mut(c, ldc).submatrix_mut(r0, c0, m, n);
                let (left, right) = blk.split_at_col_mut(h - c0);
                matmul(
                    left,
                    Accum::Add,
                    right.rb(),
                    s12.transpose(),
                    -1.0,
                    Par::Seq,
                );
            }
            sylv(ctx, t, s, trans, c, ldc, (r0, r1), (c0, h))
        }
    }
}

#[allow(clippy::too_many_arguments)]
fn sylv_leaf(
    ctx: &mut Ctx,
    t: View<'_>,
    s: View<'_>,
    trans: bool,
    c: &mut [f64],
    ldc: usize,
    rows: (usize, usize),
    cols: (usize, usize),
) -> Result<()> {
    crate::cancel::check("a Bartels–Stewart block solve")?;
    crate::linalg::dispatch_avx2!(
        sylv_leaf_avx2,
        sylv_leaf_body,
        (ctx: &mut Ctx, t: View<'_>, s: View<'_>, trans: bool, c: &mut [f64], ldc: usize, rows: (usize, usize), cols: (usize, usize)) -> Result<()>
    )
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn sylv_leaf_body(
    ctx: &mut Ctx,
    t: View<'_>,
    s: View<'_>,
    trans: bool,
    c: &mut [f64],
    ldc: usize,
    (r0, r1): (usize, usize),
    (c0, c1): (usize, usize),
) -> Result<()> {
    if !trans {
        // X S: column block l needs the solved columns to its left.
        let mut l = c0;
        while l < c1 {
            let nl = s.block_starting(l, c1);
            for j in c0..l {
                for jj in l..l + nl {
                    let sv = s.at(j, jj);
                    if sv != 0.0 {
                        axpy_cols(c, ldc, j, jj, r0, r1, sv);
                    }
                }
            }
            column_backsub(
                ctx,
                t,
                s.block(l, nl),
                nl,
                false,
                c,
                ldc,
                (r0, r1),
                l,
                false,
            )?;
            l += nl;
        }
    } else {
        // X Sᵀ: column block l needs the solved columns to its right.
        let mut e = c1;
        while e > c0 {
            let (l, nl) = s.block_ending(c0, e);
            for j in (l + nl)..c1 {
                for jj in l..l + nl {
                    let sv = s.at(jj, j);
                    if sv != 0.0 {
                        axpy_cols(c, ldc, j, jj, r0, r1, sv);
                    }
                }
            }
            column_backsub(ctx, t, s.block(l, nl), nl, true, c, ldc, (r0, r1), l, false)?;
            e = l;
        }
    }
    Ok(())
}

/// Back substitution for block column `l..l+nl` of `T X + X op(S_ll) = C` over the row blocks in
/// `r0..e`, bottom up, once every other contribution to those entries has been subtracted: solves
/// each block and subtracts its contribution from the rows above (down to `r0`). With `mirror`,
/// each solved block is also written transposed at the mirrored position (symmetric Lyapunov).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn column_backsub(
    ctx: &mut Ctx,
    t: View<'_>,
    sb: [f64; 4],
    nl: usize,
    trans: bool,
    c: &mut [f64],
    ldc: usize,
    (r0, e): (usize, usize),
    l: usize,
    mirror: bool,
) -> Result<()> {
    if nl == 2 {
        if let Some(cc) = ComplexColumn::new(op_block(sb, trans)) {
            return column_backsub_complex(ctx, t, sb, &cc, c, ldc, (r0, e), l, mirror);
        }
    }
    let smin = ctx.smin;
    let mut minp = ctx.min_pivot;
    let mut k_end = e;
    while k_end > r0 {
        let (k, mk) = t.block_ending(r0, k_end);
        if mk == 1 && nl == 1 {
            // The common case, kept free of the general block machinery. The reciprocal does not
            // depend on the right-hand side, so it is off the critical path of the substitution.
            let tau = t.at(k, k) + sb[0];
            let piv = tau.abs();
            if too_small(piv, smin) {
                return Err(ctx.singular(t.block(k, 1), 1, sb, 1, piv));
            }
            minp = minp.min(piv);
            let base = l * ldc;
            let x = c[base + k] * (1.0 / tau);
            c[base + k] = x;
            if mirror {
                c[l + k * ldc] = x;
            }
            axpy(-x, t.col(k, r0, k), &mut c[base + r0..base + k]);
        } else {
            let mut r = [0.0; 4];
            for j in 0..nl {
                for i in 0..mk {
                    r[i + mk * j] = c[(k + i) + (l + j) * ldc];
                }
            }
            let tb = t.block(k, mk);
            match block_solve(smin, tb, mk, sb, nl, trans, &mut r) {
                Ok(piv) => minp = minp.min(piv),
                Err(piv) => return Err(ctx.singular(tb, mk, sb, nl, piv)),
            }
            for j in 0..nl {
                let base = (l + j) * ldc;
                for i in 0..mk {
                    let x = r[i + mk * j];
                    c[base + k + i] = x;
                    if mirror {
                        c[(l + j) + (k + i) * ldc] = x;
                    }
                    axpy(-x, t.col(k + i, r0, k), &mut c[base + r0..base + k]);
                }
            }
        }
        k_end = k;
    }
    ctx.min_pivot = minp;
    for j in l..l + nl {
        if c[j * ldc + r0..j * ldc + e].iter().any(|v| !v.is_finite()) {
            return Err(ctx.overflow());
        }
    }
    Ok(())
}

/// [`column_backsub`] for a 2-column block whose `op(S_ll)` has complex eigenvalues, in complex
/// arithmetic (see [`ComplexColumn`]): `W = R V` in place of the two columns, `(T + μ I) w = g`
/// by back substitution with `w = Re W + i Im W`, then `X = W V⁻¹`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn column_backsub_complex(
    ctx: &mut Ctx,
    t: View<'_>,
    sb: [f64; 4],
    cc: &ComplexColumn,
    c: &mut [f64],
    ldc: usize,
    (r0, e): (usize, usize),
    l: usize,
    mirror: bool,
) -> Result<()> {
    let smin = ctx.smin;
    let mut minp = ctx.min_pivot;
    let mu = cc.mu;
    let (v, vi) = (cc.v, cc.vinv);
    {
        let (lo, hi) = c.split_at_mut((l + 1) * ldc);
        let re = &mut lo[l * ldc..l * ldc + e];
        let im = &mut hi[..e];
        for i in r0..e {
            let (x0, x1) = (re[i], im[i]);
            re[i] = x0 * v[0] + x1 * v[1];
            im[i] = x0 * v[2] + x1 * v[3];
        }
        let mut k_end = e;
        while k_end > r0 {
            let (k, mk) = t.block_ending(r0, k_end);
            if mk == 1 {
                let d = Cx::new(t.at(k, k) + mu.re, mu.im);
                let piv = d.abs1();
                if too_small(piv, smin) {
                    return Err(ctx.singular(t.block(k, 1), 1, sb, 2, piv));
                }
                minp = minp.min(piv);
                let w = Cx::new(re[k], im[k]).mul(d.recip());
                re[k] = w.re;
                im[k] = w.im;
                let tc = t.col(k, r0, k);
                axpy(-w.re, tc, &mut re[r0..k]);
                axpy(-w.im, tc, &mut im[r0..k]);
            } else {
                let tb = t.block(k, 2);
                let a = [
                    [Cx::new(tb[0] + mu.re, mu.im), Cx::new(tb[2], 0.0)],
                    [Cx::new(tb[1], 0.0), Cx::new(tb[3] + mu.re, mu.im)],
                ];
                let g = [Cx::new(re[k], im[k]), Cx::new(re[k + 1], im[k + 1])];
                let w = match solve_cx2(a, g, smin) {
                    Ok((w, piv)) => {
                        minp = minp.min(piv);
                        w
                    }
                    Err(piv) => return Err(ctx.singular(tb, 2, sb, 2, piv)),
                };
                for (i, wi) in w.iter().enumerate() {
                    re[k + i] = wi.re;
                    im[k + i] = wi.im;
                    let tc = t.col(k + i, r0, k);
                    axpy(-wi.re, tc, &mut re[r0..k]);
                    axpy(-wi.im, tc, &mut im[r0..k]);
                }
            }
            k_end = k;
        }
        for i in r0..e {
            let (w0, w1) = (re[i], im[i]);
            re[i] = w0 * vi[0] + w1 * vi[1];
            im[i] = w0 * vi[2] + w1 * vi[3];
        }
        if re[r0..e]
            .iter()
            .chain(im[r0..e].iter())
            .any(|x| !x.is_finite())
        {
            return Err(ctx.overflow());
        }
    }
    ctx.min_pivot = minp;
    if mirror {
        for i in r0..e {
            c[l + i * ldc] = c[i + l * ldc];
            c[(l + 1) + i * ldc] = c[i + (l + 1) * ldc];
        }
    }
    Ok(())
}

/// Solves the symmetric `T Y + Y Tᵀ = C` on the diagonal block `r0..r1` of `c`: reads the upper
/// triangle of that block, writes the full symmetric `Y` there. Contributions of `Y` outside the
/// block must have been subtracted from the upper triangle already.
pub(crate) fn lyap(
    ctx: &mut Ctx,
    t: View<'_>,
    c: &mut [f64],
    ldc: usize,
    (r0, r1): (usize, usize),
) -> Result<()> {
    let n = r1 - r0;
    if n == 0 {
        return Ok(());
    }
    if n <= NB {
        return lyap_leaf(ctx, t, c, ldc, (r0, r1));
    }
    // T = [T11 T12; 0 T22], Y = [Y11 Y12; Y12ᵀ Y22]:
    //   T22 Y22 + Y22 T22ᵀ = C22
    //   T11 Y12 + Y12 T22ᵀ = C12 − T12 Y22
    //   T11 Y11 + Y11 T11ᵀ = C11 − T12 Y12ᵀ − Y12 T12ᵀ   (upper triangle only)
    let h = t.split(r0, r1);
    let (n1, n2) = (h - r0, r1 - h);
    let t12 = t.faer().submatrix(r0, h, n1, n2);
    lyap(ctx, t, c, ldc, (h, r1))?;
    {
        let blk = faer_mut(c, ldc).submatrix_mut(r0, r0, n, n);
        let (_, c12, _, c22) = blk.split_at_mut(n1, n1);
        matmul(c12, Accum::Add, t12, c22.rb(), -1.0, Par::Seq);
    }
    sylv(ctx, t, t, true, c, ldc, (r0, h), (h, r1))?;
    {
        let blk = faer_mut(c, ldc).submatrix_mut(r0, r0, n, n);
        let (mut c11, c12, mut c21, _) = blk.split_at_mut(n1, n1);
        c21.copy_from(c12.rb().transpose());
        triangular::matmul(
            c11.rb_mut(),
            BlockStructure::TriangularUpper,
            Accum::Add,
            t12,
            BlockStructure::Rectangular,
            c21.rb(),
            BlockStructure::Rectangular,
            -1.0,
            Par::Seq,
        );
        triangular::matmul(
            c11,
            BlockStructure::TriangularUpper,
            Accum::Add,
            c12.rb(),
            BlockStructure::Rectangular,
            t12.transpose(),
            BlockStructure::Rectangular,
            -1.0,
            Par::Seq,
        );
    }
    lyap(ctx, t, c, ldc, (r0, h))
}

fn lyap_leaf(
    ctx: &mut Ctx,
    t: View<'_>,
    c: &mut [f64],
    ldc: usize,
    rows: (usize, usize),
) -> Result<()> {
    crate::cancel::check("a Bartels–Stewart block solve")?;
    crate::linalg::dispatch_avx2!(
        lyap_leaf_avx2,
        lyap_leaf_body,
        (ctx: &mut Ctx, t: View<'_>, c: &mut [f64], ldc: usize, rows: (usize, usize)) -> Result<()>
    )
}

#[inline(always)]
fn lyap_leaf_body(
    ctx: &mut Ctx,
    t: View<'_>,
    c: &mut [f64],
    ldc: usize,
    (r0, r1): (usize, usize),
) -> Result<()> {
    let mut e = r1;
    while e > r0 {
        let (l, nl) = t.block_ending(r0, e);
        let top = l + nl;
        // Block column l: subtract Σ_{j ≥ top} T[:, j] Y[j, l] + Y[:, j] T[l, j] on rows r0..top.
        // Y[j, l] (j ≥ top) lies in the lower triangle, mirrored when column j was solved.
        for j in top..r1 {
            let tcol = t.col(j, r0, top);
            for jj in l..top {
                let y = c[j + jj * ldc];
                let tv = t.at(jj, j);
                // jj < top ≤ j: column jj lies before column j.
                let (lo, hi) = c.split_at_mut(j * ldc);
                let (src, dst) = (&hi[r0..top], &mut lo[jj * ldc + r0..jj * ldc + top]);
                for ((d, sv), tc) in dst.iter_mut().zip(src).zip(tcol) {
                    *d -= y * tc + tv * sv;
                }
            }
        }
        // Diagonal block (only its upper triangle is read).
        let tb = t.block(l, nl);
        if nl == 1 {
            let tau = 2.0 * tb[0];
            let piv = tau.abs();
            if too_small(piv, ctx.smin) {
                return Err(ctx.singular(tb, 1, tb, 1, piv));
            }
            ctx.min_pivot = ctx.min_pivot.min(piv);
            c[l + l * ldc] *= 1.0 / tau;
        } else {
            let mut r = [
                c[l + l * ldc],
                c[l + (l + 1) * ldc],
                c[(l + 1) + (l + 1) * ldc],
            ];
            match lyap_block2(ctx.smin, tb, &mut r) {
                Ok(piv) => ctx.min_pivot = ctx.min_pivot.min(piv),
                Err(piv) => return Err(ctx.singular(tb, 2, tb, 2, piv)),
            }
            c[l + l * ldc] = r[0];
            c[l + (l + 1) * ldc] = r[1];
            c[(l + 1) + l * ldc] = r[1];
            c[(l + 1) + (l + 1) * ldc] = r[2];
        }
        for jj in l..top {
            for q in l..top {
                let y = c[q + jj * ldc];
                let base = jj * ldc;
                axpy(-y, t.col(q, r0, l), &mut c[base + r0..base + l]);
            }
        }
        // Off-diagonal blocks k < l of the block column, bottom up: T_kk Y_kl + Y_kl T_llᵀ = R_kl.
        column_backsub(ctx, t, tb, nl, true, c, ldc, (r0, l), l, true)?;
        for j in l..top {
            if c[j * ldc + l..j * ldc + top].iter().any(|v| !v.is_finite()) {
                return Err(ctx.overflow());
            }
        }
        e = l;
    }
    Ok(())
}
