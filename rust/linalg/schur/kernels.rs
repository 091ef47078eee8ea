//! Scalar kernels shared by the QR iteration and the reordering: the standardised 2×2 Schur
//! factorisation (as LAPACK's dlanv2), Householder reflector generation (dlarfg), Givens rotation
//! generation (dlartg) and plane rotations / 3-element reflectors applied to column-major storage.

/// Machine epsilon (LAPACK's `dlamch('P')`).
pub(super) const EPS: f64 = f64::EPSILON;
/// Smallest positive normal number (LAPACK's `dlamch('S')`).
pub(super) const SAFMIN: f64 = f64::MIN_POSITIVE;

/// `sqrt(x² + y²)` without spurious overflow or underflow. Unlike libm's `hypot` it does not
/// guarantee correct rounding (a few ulps), which is all the callers need, and it is much faster.
#[inline]
pub(super) fn hypot(x: f64, y: f64) -> f64 {
    let (ax, ay) = (x.abs(), y.abs());
    let m = ax.max(ay);
    if m > 1e-150 && m < 1e150 {
        (x * x + y * y).sqrt()
    } else if m == 0.0 || !m.is_finite() {
        // Zero, infinite or NaN arguments: defer to libm for the IEEE special cases.
        x.hypot(y)
    } else {
        let (a, b) = (ax / m, ay / m);
        m * (a * a + b * b).sqrt()
    }
}

/// Euclidean norm of a short vector, without spurious overflow or underflow.
#[inline]
fn norm_short(x: &[f64]) -> f64 {
    let m = x.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
    if m > 1e-150 && m < 1e150 {
        x.iter().map(|v| v * v).sum::<f64>().sqrt()
    } else if m == 0.0 || !m.is_finite() {
        x.iter().fold(0.0f64, |acc, &v| acc.hypot(v))
    } else {
        m * x.iter().map(|v| (v / m) * (v / m)).sum::<f64>().sqrt()
    }
}

/// Result of [`lanv2`]: the standardised block `[[a, b], [c, d]]` and the rotation `(cs, sn)` with
/// `[[A, B], [C, D]] = [[cs, -sn], [sn, cs]] · [[a, b], [c, d]] · [[cs, sn], [-sn, cs]]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Lanv2 {
    pub a: f64,
    pub b: f64,
    pub c: f64,
    pub d: f64,
    pub cs: f64,
    pub sn: f64,
}

impl Lanv2 {
    /// The two eigenvalues `(re, im)`; for a complex pair the one with positive imaginary part first.
    pub fn eigenvalues(&self) -> [(f64, f64); 2] {
        if self.c == 0.0 {
            [(self.a, 0.0), (self.d, 0.0)]
        } else {
            let im = self.b.abs().sqrt() * self.c.abs().sqrt();
            [(self.a, im), (self.d, -im)]
        }
    }
}

/// Schur factorisation of a real 2×2 matrix in standard form (the algorithm of LAPACK's dlanv2):
/// either `c = 0` (two real eigenvalues `a`, `d`), or `a = d` and `b·c < 0` (complex pair
/// `a ± i·sqrt(|b|)·sqrt(|c|)`).
pub(super) fn lanv2(a: f64, b: f64, c: f64, d: f64) -> Lanv2 {
    const MULTPL: f64 = 4.0;
    let (mut a, mut b, mut c, mut d) = (a, b, c, d);
    let (mut cs, mut sn);
    if c == 0.0 {
        cs = 1.0;
        sn = 0.0;
    } else if b == 0.0 {
        // Swap rows and columns.
        cs = 0.0;
        sn = 1.0;
        std::mem::swap(&mut a, &mut d);
        b = -c;
        c = 0.0;
    } else if a - d == 0.0 && b.signum() != c.signum() {
        // Already standardised complex block.
        cs = 1.0;
        sn = 0.0;
    } else {
        let temp = a - d;
        let mut p = 0.5 * temp;
        let bcmax = b.abs().max(c.abs());
        let bcmis = b.abs().min(c.abs()) * b.signum() * c.signum();
        let scale = p.abs().max(bcmax);
        let mut z = (p / scale) * p + (bcmax / scale) * bcmis;
        if z >= MULTPL * EPS {
            // Real eigenvalues: compute a and d.
            z = p + (scale.sqrt() * z.sqrt()).copysign(p);
            a = d + z;
            d -= (bcmax / z) * bcmis;
            let tau = hypot(c, z);
            cs = z / tau;
            sn = c / tau;
            b -= c;
            c = 0.0;
        } else {
            // Complex eigenvalues, or real (almost) equal ones: make the diagonal equal. Scale
            // (b + c, a − d) by a power of two so that neither overflows nor underflows.
            let mut sigma = b + c;
            let mut temp = temp;
            let big = sigma.abs().max(temp.abs());
            let m = b.abs().max(c.abs()).max(a.abs()).max(d.abs());
            if !(big.is_finite() && big < 2f64.powi(500)) && m.is_finite() && m > 0.0 {
                // Rescale from the original entries (b + c or a − d may have overflowed).
                let f = 2f64.powi(-(m.log2().floor() as i32) - 2);
                sigma = b * f + c * f;
                temp = a * f - d * f;
            }
            p = 0.5 * temp;
            let tau = hypot(sigma, temp);
            cs = (0.5 * (1.0 + sigma.abs() / tau)).sqrt();
            sn = -(p / (tau * cs)) * if sigma >= 0.0 { 1.0 } else { -1.0 };
            // [aa bb; cc dd] = [a b; c d] [cs -sn; sn cs]
            let aa = a * cs + b * sn;
            let bb = -a * sn + b * cs;
            let cc = c * cs + d * sn;
            let dd = -c * sn + d * cs;
            // [a b; c d] = [cs sn; -sn cs] [aa bb; cc dd]
            b = bb * cs + dd * sn;
            c = -aa * sn + cc * cs;
            let mid = 0.5 * ((aa * cs + cc * sn) + (-bb * sn + dd * cs));
            a = mid;
            d = mid;
            if c != 0.0 {
                if b != 0.0 {
                    if b.signum() == c.signum() {
                        // Real eigenvalues after all: reduce to upper triangular form.
                        let sab = b.abs().sqrt();
                        let sac = c.abs().sqrt();
                        p = (sab * sac).copysign(c);
                        let tau = 1.0 / (b + c).abs().sqrt();
                        a = mid + p;
                        d = mid - p;
                        b -= c;
                        c = 0.0;
                        let cs1 = sab * tau;
                        let sn1 = sac * tau;
                        let t = cs * cs1 - sn * sn1;
                        sn = cs * sn1 + sn * cs1;
                        cs = t;
                    }
                } else {
                    b = -c;
                    c = 0.0;
                    let t = cs;
                    cs = -sn;
                    sn = t;
                }
            }
        }
    }
    Lanv2 { a, b, c, d, cs, sn }
}

/// Generates an elementary reflector `H = I − τ·v·vᵀ` with `v = (1, x')` such that
/// `H·(alpha, x) = (beta, 0)` (LAPACK's dlarfg). Overwrites `x` with `x'` and returns `(beta, τ)`.
pub(super) fn larfg(alpha: f64, x: &mut [f64]) -> (f64, f64) {
    // Fast path (the bulge chase calls this for every 3-vector): when no square can overflow
    // or underflow, one square root gives beta and the two divisions are independent.
    let mx = x.iter().fold(0.0f64, |acc, v| acc.max(v.abs()));
    if mx == 0.0 {
        return (alpha, 0.0);
    }
    if mx > 1e-150 && mx < 1e150 && alpha.abs() < 1e150 {
        let xsq: f64 = x.iter().map(|v| v * v).sum();
        let beta = -(alpha * alpha + xsq).sqrt().copysign(alpha);
        let tau = (beta - alpha) / beta;
        let scal = 1.0 / (alpha - beta);
        x.iter_mut().for_each(|v| *v *= scal);
        return (beta, tau);
    }
    let mut xnorm = norm_short(x);
    if xnorm == 0.0 {
        return (alpha, 0.0);
    }
    let mut alpha = alpha;
    let mut beta = -hypot(alpha, xnorm).copysign(alpha);
    let safmin = SAFMIN / EPS;
    let mut knt = 0;
    if beta.abs() < safmin {
        // beta may be inaccurate: scale x and recompute (at most 20 times).
        let rsafmn = 1.0 / safmin;
        loop {
            knt += 1;
            x.iter_mut().for_each(|v| *v *= rsafmn);
            beta *= rsafmn;
            alpha *= rsafmn;
            if beta.abs() >= safmin || knt >= 20 {
                break;
            }
        }
        xnorm = norm_short(x);
        beta = -hypot(alpha, xnorm).copysign(alpha);
    }
    let tau = (beta - alpha) / beta;
    let scal = 1.0 / (alpha - beta);
    x.iter_mut().for_each(|v| *v *= scal);
    for _ in 0..knt {
        beta *= safmin;
    }
    (beta, tau)
}

/// A plane rotation `(cs, sn, r)` with `[cs sn; −sn cs]·(f, g) = (r, 0)` (LAPACK's dlartg).
pub(super) fn lartg(f: f64, g: f64) -> (f64, f64, f64) {
    if g == 0.0 {
        (1.0, 0.0, f)
    } else if f == 0.0 {
        (0.0, g.signum(), g.abs())
    } else {
        // Like LAPACK's dlartg: bring f, g into the normal range by an exact power of two first,
        // or c = |f|/hypot(f, g) would carry only the few significant bits of subnormal inputs.
        let m = f.abs().max(g.abs());
        let e = if !(m >= LARTG_LO) || m > LARTG_HI {
            -(m.log2().floor() as i32)
        } else {
            0
        };
        let (fs, gs) = (pow2(f, e), pow2(g, e));
        let d = hypot(fs, gs);
        let rs = d.copysign(fs);
        (fs.abs() / d, gs / rs, pow2(rs, -e))
    }
}

const LARTG_LO: f64 = 1.0 / (1u64 << 60) as f64 / (1u64 << 60) as f64; // 2^-120
const LARTG_HI: f64 = ((1u64 << 60) as f64) * ((1u64 << 60) as f64); // 2^120

/// `v·2^e` in two exact power-of-two steps (2^e alone may overflow).
#[inline]
fn pow2(v: f64, e: i32) -> f64 {
    if e == 0 {
        v
    } else {
        (v * 2f64.powi(e / 2)) * 2f64.powi(e - e / 2)
    }
}

/// Applies the rotation `(x, y) ← (cs·x + sn·y, cs·y − sn·x)` element-wise to two slices.
#[inline(always)]
pub(super) fn rot(x: &mut [f64], y: &mut [f64], cs: f64, sn: f64) {
    for (a, b) in x.iter_mut().zip(y.iter_mut()) {
        let t = cs * *a + sn * *b;
        *b = cs * *b - sn * *a;
        *a = t;
    }
}

/// Two distinct columns `j < k` of a column-major `n`-row matrix, restricted to rows `r`.
#[inline(always)]
pub(super) fn two_cols(
    m: &mut [f64],
    n: usize,
    j: usize,
    k: usize,
    r: std::ops::Range<usize>,
) -> (&mut [f64], &mut [f64]) {
    debug_assert!(j < k);
    let (lo, hi) = m.split_at_mut(k * n);
    (&mut lo[j * n + r.start..j * n + r.end], &mut hi[r])
}

/// Rotation applied to rows `i` and `i + 1` of a column-major `n`-row matrix, columns `cols`.
#[inline(always)]
pub(super) fn rot_rows(
    m: &mut [f64],
    n: usize,
    i: usize,
    cols: std::ops::Range<usize>,
    cs: f64,
    sn: f64,
) {
    if cols.is_empty() {
        return;
    }
    for col in m[cols.start * n..cols.end * n].chunks_exact_mut(n) {
        let (a, b) = (col[i], col[i + 1]);
        col[i] = cs * a + sn * b;
        col[i + 1] = cs * b - sn * a;
    }
}

/// Rotation applied to columns `j` and `j + 1` of a column-major `n`-row matrix, rows `rows`.
#[inline(always)]
pub(super) fn rot_cols(
    m: &mut [f64],
    n: usize,
    j: usize,
    rows: std::ops::Range<usize>,
    cs: f64,
    sn: f64,
) {
    if rows.is_empty() {
        return;
    }
    let (x, y) = two_cols(m, n, j, j + 1, rows);
    rot(x, y, cs, sn);
}

/// Applies `H = I − τ·v·vᵀ` (`v` of length 3) from the left to rows `i..i+3`, columns `cols`.
#[inline(always)]
pub(super) fn refl3_rows(
    m: &mut [f64],
    n: usize,
    i: usize,
    cols: std::ops::Range<usize>,
    v: [f64; 3],
    tau: f64,
) {
    if tau == 0.0 || cols.is_empty() {
        return;
    }
    let (t1, t2, t3) = (tau * v[0], tau * v[1], tau * v[2]);
    for col in m[cols.start * n..cols.end * n].chunks_exact_mut(n) {
        let c = &mut col[i..i + 3];
        let s = v[0] * c[0] + v[1] * c[1] + v[2] * c[2];
        c[0] -= s * t1;
        c[1] -= s * t2;
        c[2] -= s * t3;
    }
}

/// Applies `H = I − τ·v·vᵀ` (`v` of length 3) from the right to columns `j..j+3`, rows `rows`.
#[inline(always)]
pub(super) fn refl3_cols(
    m: &mut [f64],
    n: usize,
    j: usize,
    rows: std::ops::Range<usize>,
    v: [f64; 3],
    tau: f64,
) {
    if tau == 0.0 || rows.is_empty() {
        return;
    }
    let (t1, t2, t3) = (tau * v[0], tau * v[1], tau * v[2]);
    let (c0, rest) = m[j * n..(j + 3) * n].split_at_mut(n);
    let (c1, c2) = rest.split_at_mut(n);
    let (c0, c1, c2) = (&mut c0[rows.clone()], &mut c1[rows.clone()], &mut c2[rows]);
    for ((a, b), c) in c0.iter_mut().zip(c1.iter_mut()).zip(c2.iter_mut()) {
        let s = v[0] * *a + v[1] * *b + v[2] * *c;
        *a -= s * t1;
        *b -= s * t2;
        *c -= s * t3;
    }
}
