//! The Riccati residual `R(X) = AᵀX + XA − XGX + Q` accumulated in double-double arithmetic
//! (error-free products and sums: Ogita, Rump and Oishi's `Dot2`), rounded once at the end.
//!
//! A residual computed in working precision has a rounding floor `γ·(|Aᵀ||X| + |X||A| + |X||G||X| +
//! |Q|)`, `γ ≈ 2n·eps`; on a stiff or badly scaled problem that floor, mapped through the
//! closed-loop Lyapunov operator, is far above `eps·‖X‖` and Newton refinement stalls there. With
//! the compensated residual the floor is `eps·|R| + γ²·(…)`: refinement reaches the accuracy
//! that the representation of `X` allows.
//!
//! Each dot product `Σ a_k b_k` is accumulated as `s + c` with `(p, e) = TwoProduct(a_k, b_k)`,
//! `(s, t) = TwoSum(s, p)`, `c += t + e`; the result's error is at most `eps·|Σ| + γ_n²·Σ|a_k||b_k|`
//! (Ogita–Rump–Oishi 2005, Prop. 4.5). Products with a double-double operand `b = b_h + b_l` add
//! `a_k·b_l` to `c`, a term of relative size `eps` inside the `γ²` bound.

use super::quadratic::Quadratic;
use super::refine::Operator;
use crate::linalg::dense::{norm_fro, symmetrize};
use crate::Result;
use nalgebra::DMatrix;

/// A matrix in double-double: `hi + lo` entrywise.
pub(super) struct Dd {
    pub(super) hi: DMatrix<f64>,
    pub(super) lo: DMatrix<f64>,
}

/// `a·b` exactly as `p + e` (needs a fused multiply-add; `f64::mul_add` is exact everywhere).
#[inline(always)]
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    (p, a.mul_add(b, -p))
}

/// `a + b` exactly as `s + t` (Knuth).
#[inline(always)]
pub(super) fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// `Σ x_k (y_k + z_k)` in double-double (`z` may be absent).
#[inline(always)]
pub(super) fn dot2(x: &[f64], y: &[f64], z: Option<&[f64]>) -> (f64, f64) {
    let (mut s, mut c) = (0.0f64, 0.0f64);
    for (k, (&a, &b)) in x.iter().zip(y).enumerate() {
        let (p, e) = two_prod(a, b);
        let (s2, t) = two_sum(s, p);
        s = s2;
        c += t + e;
        if let Some(z) = z {
            c += a * z[k];
        }
    }
    two_sum(s, c)
}

/// `Σ (x_k + u_k)(y_k + v_k)` in double-double.
#[inline(always)]
fn dot2_dd(x: &[f64], u: &[f64], y: &[f64], v: &[f64]) -> (f64, f64) {
    let (mut s, mut c) = (0.0f64, 0.0f64);
    for k in 0..x.len() {
        let (p, e) = two_prod(x[k], y[k]);
        let (s2, t) = two_sum(s, p);
        s = s2;
        c += t + e + (x[k] * v[k] + u[k] * y[k]);
    }
    two_sum(s, c)
}

/// `Mᵀ N` for column-major `M` (`k × r`) and `N` (`k × c`, optionally double-double with `N_lo`).
#[inline(always)]
fn tn(m: &DMatrix<f64>, n: &DMatrix<f64>, n_lo: Option<&DMatrix<f64>>) -> Dd {
    let (r, c) = (m.ncols(), n.ncols());
    let mut hi = DMatrix::zeros(r, c);
    let mut lo = DMatrix::zeros(r, c);
    for j in 0..c {
        let nj = n.column(j);
        let nl = n_lo.map(|l| l.column(j));
        for i in 0..r {
            let (h, l) = dot2(
                m.column(i).as_slice(),
                nj.as_slice(),
                nl.as_ref().map(|v| v.as_slice()),
            );
            hi[(i, j)] = h;
            lo[(i, j)] = l;
        }
    }
    Dd { hi, lo }
}

/// `Mᵀ M` for a double-double `M`.
fn tn_self(m: &Dd) -> Dd {
    let r = m.hi.ncols();
    let mut hi = DMatrix::zeros(r, r);
    let mut lo = DMatrix::zeros(r, r);
    for j in 0..r {
        for i in 0..=j {
            let (h, l) = dot2_dd(
                m.hi.column(i).as_slice(),
                m.lo.column(i).as_slice(),
                m.hi.column(j).as_slice(),
                m.lo.column(j).as_slice(),
            );
            hi[(i, j)] = h;
            lo[(i, j)] = l;
            hi[(j, i)] = h;
            lo[(j, i)] = l;
        }
    }
    Dd { hi, lo }
}

/// `AᵀX + XA − XGX + Q` for symmetric `X`, with `XGX` from `G` (`factor = None`) or from the
/// factor `B` of `G = BBᵀ`, accumulated in double-double and rounded once.
pub(super) fn residual(
    a: &DMatrix<f64>,
    g: Option<&DMatrix<f64>>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> DMatrix<f64> {
    crate::linalg::dispatch_fma!(
        residual_fma,
        residual_impl,
        (a: &DMatrix<f64>, g: Option<&DMatrix<f64>>, factor: Option<&DMatrix<f64>>, q: &DMatrix<f64>, x: &DMatrix<f64>) -> DMatrix<f64>
    )
}

#[inline(always)]
fn residual_impl(
    a: &DMatrix<f64>,
    g: Option<&DMatrix<f64>>,
    factor: Option<&DMatrix<f64>>,
    q: &DMatrix<f64>,
    x: &DMatrix<f64>,
) -> DMatrix<f64> {
    let n = a.nrows();
    // AᵀX (XA is its transpose: X is symmetric).
    let p = tn(a, x, None);
    // XGX: X (G X) with G symmetric, or (XB)(XB)ᵀ = ((XB)ᵀ)ᵀ (XB)ᵀ.
    let xgx = match (factor, g) {
        (Some(b), _) => {
            let xb_t = tn(b, x, None); // Bᵀ X = (XB)ᵀ, m × n
            tn_self(&xb_t)
        }
        (None, Some(g)) => {
            let gx = tn(g, x, None);
            tn(x, &gx.hi, Some(&gx.lo))
        }
        (None, None) => Dd {
            hi: DMatrix::zeros(n, n),
            lo: DMatrix::zeros(n, n),
        },
    };
    DMatrix::from_fn(n, n, |i, j| {
        // (P_ij + P_ji) − XGX_ij + Q_ij in double-double, then rounded.
        let (s, t) = two_sum(p.hi[(i, j)], p.hi[(j, i)]);
        let (s, t2) = two_sum(s, -xgx.hi[(i, j)]);
        let (s, t3) = two_sum(s, q[(i, j)]);
        let lo = t + t2 + t3 + (p.lo[(i, j)] + p.lo[(j, i)] - xgx.lo[(i, j)]);
        s + lo
    })
}

/// `(Eᵀ(XM₁), Eᵀ(XM₂))` for symmetric `X`, each in double-double (the inner product kept in
/// double-double too): the products of the generalised residual (module `generalized`).
pub(super) fn pencil_products(
    e: &DMatrix<f64>,
    x: &DMatrix<f64>,
    m1: &DMatrix<f64>,
    m2: &DMatrix<f64>,
) -> (Dd, Dd) {
    crate::linalg::dispatch_fma!(
        pencil_products_fma,
        pencil_products_impl,
        (e: &DMatrix<f64>, x: &DMatrix<f64>, m1: &DMatrix<f64>, m2: &DMatrix<f64>) -> (Dd, Dd)
    )
}

#[inline(always)]
fn pencil_products_impl(
    e: &DMatrix<f64>,
    x: &DMatrix<f64>,
    m1: &DMatrix<f64>,
    m2: &DMatrix<f64>,
) -> (Dd, Dd) {
    let xm1 = tn(x, m1, None); // XᵀM₁ = XM₁
    let xm2 = tn(x, m2, None);
    (tn(e, &xm1.hi, Some(&xm1.lo)), tn(e, &xm2.hi, Some(&xm2.lo)))
}

/// Up to this order a solution whose refinement stalled at the rounding floor of the
/// working-precision residual is refined with the compensated one.
pub(crate) const COMPENSATED_MAX_ORDER: usize = 64;

/// Up to this order a near-axis solution is refined with compensated residuals and certified
/// (above it, near-axis problems are refused as before).
pub(super) const CERTIFY_MAX_ORDER: usize = 400;

/// Newton steps with the compensated residual, at most.
const COMPENSATED_STEPS: usize = 4;

/// A solution refined with compensated residuals: the residual of `x` (accurate to `rounding`).
pub(super) struct Compensated {
    pub(super) x: DMatrix<f64>,
    pub(super) r: DMatrix<f64>,
    pub(super) rounding: f64,
    pub(super) steps: usize,
    /// `‖Ω⁻¹(R(x))‖_F` as computed: the Newton correction at the final `x` (∞ if not available).
    pub(super) eta: f64,
    /// The arithmetic part of `rounding` (without the data's representation).
    pub(super) arith: f64,
    /// `Ω⁻¹(I)` of the closed loop of `x` when the operator was factored afresh.
    pub(super) p: Option<DMatrix<f64>>,
}

/// Newton refinement of `x` with residuals accumulated in double-double ([`compensated`]), a
/// step kept when the next correction contracts, until the corrections are below 4 ulps of `X`.
/// `None` when the compensated residual is not finite (entries near the overflow threshold);
/// [`Error::Interrupted`] when cancelled (checked before every step).
pub(super) fn compensated_refinement<'o>(
    a: &DMatrix<f64>,
    q: &DMatrix<f64>,
    quad: Quadratic<'_>,
    op: &'o Operator<'o>,
    fresh: &dyn Fn(&DMatrix<f64>) -> Option<Operator<'o>>,
    x0: &DMatrix<f64>,
) -> Result<Option<Compensated>> {
    let res = |x: &DMatrix<f64>| {
        let r = quad.residual_compensated(a, q, x);
        r.iter().all(|v| v.is_finite()).then_some(r)
    };
    let mut x = x0.clone();
    let Some(mut r) = res(&x) else {
        return Ok(None);
    };
    // The operator: the frozen one first; when its corrections stop contracting, the closed loop
    // of the current X factored afresh (once).
    let mut own: Option<Operator<'o>> = None;
    let mut delta = op.solve(&(-&r)).ok();
    let mut eta = delta.as_ref().map_or(f64::INFINITY, norm_fro);
    let mut steps = 0;
    for _ in 0..2 * COMPENSATED_STEPS {
        // A compensated residual costs ~10 plain ones (a quarter second at n = 400).
        crate::cancel::check("the compensated refinement of the Riccati solution")?;
        let cur = own.as_ref().unwrap_or(op);
        let Some(dl) = delta.take() else { break };
        let dn = norm_fro(&dl);
        if !(dn > 4.0 * f64::EPSILON * norm_fro(&x)) {
            break;
        }
        let candidate = symmetrize(&(&x + &dl));
        let Some(cr) = res(&candidate) else { break };
        let next = cur.solve(&(-&cr)).ok();
        if let Some(nd) = next.as_ref().map(norm_fro).filter(|&nd| nd <= 0.5 * dn) {
            (x, r, delta, eta) = (candidate, cr, next, nd);
            steps += 1;
            continue;
        }
        if own.is_some() {
            break;
        }
        let Some(f) = fresh(&x) else { break };
        delta = f.solve(&(-&r)).ok();
        eta = delta.as_ref().map_or(f64::INFINITY, norm_fro);
        own = Some(f);
    }
    let p = match &own {
        Some(f) => f.solve(&DMatrix::identity(x.nrows(), x.nrows())).ok(),
        None => None,
    };
    let (arith, w) = arith_bound(a, q, quad, &x, &r);
    Ok(Some(Compensated {
        x,
        r,
        rounding: arith + f64::EPSILON * w,
        steps,
        eta,
        arith,
        p,
    }))
}

/// The arithmetic error bound of the compensated residual `r` of `x` and the weight `W` of the
/// plain evaluation (Ogita–Rump–Oishi, Prop. 4.5): eps·|R| from the final rounding, γ_k²·W for
/// the accumulation (W the entrywise bound of the plain evaluation; every dot product is of
/// length at most k = max(n, m), γ_k = k·eps/(1 − k·eps), taken at k + 2 for the few sums that
/// combine the products), and products that fell below the normal range. The data's own
/// representation (A, G, Q each within eps of the intended values) moves R by up to eps·W more
/// (`rounding` of [`Compensated`] includes it, so that the bound covers the solution of the
/// intended data, as the working-precision bound γ·W does).
pub(super) fn arith_bound(
    a: &DMatrix<f64>,
    q: &DMatrix<f64>,
    quad: Quadratic<'_>,
    x: &DMatrix<f64>,
    r: &DMatrix<f64>,
) -> (f64, f64) {
    let n = a.nrows() as f64;
    let w = quad.rounding(a, q, x) / ((2.0 * n + 4.0) * f64::EPSILON);
    let k = (quad.inner().max(x.nrows()) + 2) as f64 * f64::EPSILON;
    let gamma = k / (1.0 - k);
    let arith =
        2.0 * f64::EPSILON * norm_fro(r) + 2.0 * gamma * gamma * w + n * n * f64::MIN_POSITIVE;
    (arith, w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::testing::Rng;

    #[test]
    fn two_prod_and_two_sum_are_exact() {
        let (p, e) = two_prod(1.0 + f64::EPSILON, 1.0 - f64::EPSILON);
        assert_eq!(p, 1.0);
        assert_eq!(e, -f64::EPSILON * f64::EPSILON);
        let (s, t) = two_sum(1.0, 1e-20);
        assert_eq!((s, t), (1.0, 1e-20));
    }

    #[test]
    fn cancellation_is_resolved_where_plain_sums_lose_everything() {
        // x·y = 1e16 + 1 − 1e16 = 1 exactly; the plain dot product gives 0 or 2.
        let x = [1e16, 1.0, -1e16];
        let y = [1.0, 1.0, 1.0];
        let (h, l) = dot2(&x, &y, None);
        assert_eq!(h + l, 1.0);
        let (h, l) = dot2_dd(&x, &[0.0; 3], &y, &[0.0, 0.5, 0.0]);
        assert_eq!(h + l, 1.5);
    }

    #[test]
    fn residual_matches_the_plain_one_and_sees_below_its_rounding() {
        let mut rng = Rng::new(5);
        let n = 6;
        let a = rng.matrix(n, n);
        let b = rng.matrix(n, 2);
        let g = &b * b.transpose();
        let q = rng.psd(n, n);
        let x = rng.psd(n, n);
        let plain = a.transpose() * &x + &x * &a - &x * &g * &x + &q;
        let r1 = residual(&a, Some(&g), None, &q, &x);
        let r2 = residual(&a, None, Some(&b), &q, &x);
        let scale = plain.norm() + 1.0;
        assert!((&r1 - &plain).norm() <= 1e-13 * scale);
        assert!((&r2 - &plain).norm() <= 1e-13 * scale);
        // Small integers: every product below is exact in f64. With Q = −(AᵀX + XA − XGX),
        // R(X) = 0 exactly, and R(X + δP) = δ(AᵀP + PA − XGP − PGX) − δ²PGP for δ = 2⁻⁴⁶,
        // a residual 1e12 times below the rounding floor of the plain evaluation.
        let ai = DMatrix::from_fn(n, n, |i, j| ((i * 7 + j * 3) % 5) as f64 - 2.0);
        let bi = DMatrix::from_fn(n, 1, |i, _| (i % 3) as f64 + 1.0);
        let xi = DMatrix::from_fn(n, n, |i, j| {
            ((i + j) % 4) as f64 + if i == j { 8.0 } else { 0.0 }
        });
        let pi = DMatrix::from_fn(n, n, |i, j| ((i * j) % 3) as f64 + 1.0);
        let gi = &bi * bi.transpose();
        let q0 = -(ai.transpose() * &xi + &xi * &ai - &xi * &gi * &xi);
        assert_eq!(residual(&ai, None, Some(&bi), &q0, &xi).amax(), 0.0);
        assert_eq!(residual(&ai, Some(&gi), None, &q0, &xi).amax(), 0.0);
        let d = 2f64.powi(-46);
        let xd = &xi + &pi * d;
        let lin = ai.transpose() * &pi + &pi * &ai - &xi * &gi * &pi - &pi * &gi * &xi;
        let expect = lin * d - &pi * &gi * &pi * (d * d);
        for r in [
            residual(&ai, None, Some(&bi), &q0, &xd),
            residual(&ai, Some(&gi), None, &q0, &xd),
        ] {
            let err = (&r - &expect).norm() / expect.norm();
            assert!(err <= 4.0 * f64::EPSILON, "{err:e}");
        }
        let plain_d = ai.transpose() * &xd + &xd * &ai - &xd * &gi * &xd + &q0;
        assert!((&plain_d - &expect).norm() > 1e-6 * expect.norm());
    }
}
