//! The general Sylvester operator `X ↦ A X + X B` (`A` m×m, `B` n×n): both factored once by real
//! Schur forms, then each solve is two congruences and one quasi-triangular solve (the recursive
//! kernel shared with the Lyapunov operator).

use super::kernel::{self, Ctx, Kind, View};
use super::{
    check_rtol, check_solution, pivot_ratio, product, product_into, sep_by_estimator, smin, Factor,
    Solution, DEFAULT_SINGULAR_RTOL,
};
use crate::linalg::dense::{check_finite, check_shape, check_square, norm_fro};
use crate::linalg::schur::RealSchur;
use crate::Result;
use nalgebra::DMatrix;

/// A Sylvester operator `X ↦ A X + X B` (`A` m×m, `B` n×n, `X` m×n) with `A` and `B` factored once.
#[derive(Debug, Clone)]
pub struct Sylvester {
    fa: Factor,
    fb: Factor,
    rtol: f64,
}

impl Sylvester {
    /// Factors `A` and `B` (square, finite, non-empty).
    pub fn new(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Result<Self> {
        check_square("A", a)?;
        check_square("B", b)?;
        let sa = RealSchur::new(a)?;
        let sb = RealSchur::new(b)?;
        Ok(Sylvester {
            fa: Factor::new(sa, Some(a)),
            fb: Factor::new(sb, Some(b)),
            rtol: DEFAULT_SINGULAR_RTOL,
        })
    }

    /// Uses existing Schur forms of `A` and `B`.
    pub fn from_schur(a: RealSchur, b: RealSchur) -> Self {
        Sylvester {
            fa: Factor::new(a, None),
            fb: Factor::new(b, None),
            rtol: DEFAULT_SINGULAR_RTOL,
        }
    }

    /// Sets the relative singularity tolerance (default [`DEFAULT_SINGULAR_RTOL`]).
    pub fn with_singular_rtol(mut self, rtol: f64) -> Result<Self> {
        check_rtol(rtol)?;
        self.rtol = rtol;
        Ok(self)
    }

    /// Solves `A X + X B = Q`.
    pub fn solve(&self, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        self.solve_impl(q, false).map(|(x, _)| x)
    }

    /// Solves the adjoint equation `Aᵀ X + X Bᵀ = Q`.
    pub fn solve_adjoint(&self, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        self.solve_impl(q, true).map(|(x, _)| x)
    }

    /// Solves `A X + X B = Q` and reports the residual and pivot ratio.
    pub fn solve_with_info(&self, q: &DMatrix<f64>) -> Result<Solution> {
        self.with_info(q, false)
    }

    /// Solves `Aᵀ X + X Bᵀ = Q` and reports the residual and pivot ratio.
    pub fn solve_adjoint_with_info(&self, q: &DMatrix<f64>) -> Result<Solution> {
        self.with_info(q, true)
    }

    fn with_info(&self, q: &DMatrix<f64>, adjoint: bool) -> Result<Solution> {
        let (x, ratio) = self.solve_impl(q, adjoint)?;
        let (a, b) = (self.fa.a(), self.fb.a());
        let ax = product(a, adjoint, &x, false);
        let xb = product(&x, false, b, adjoint);
        let r = &ax + &xb - q;
        let denom = (norm_fro(a) + norm_fro(b)) * norm_fro(&x) + norm_fro(q);
        let residual = if denom > 0.0 {
            norm_fro(&r) / denom
        } else {
            0.0
        };
        Ok(Solution {
            x,
            residual,
            pivot_ratio: ratio,
        })
    }

    fn solve_impl(&self, q: &DMatrix<f64>, adjoint: bool) -> Result<(DMatrix<f64>, f64)> {
        self.fa.usable()?;
        self.fb.usable()?;
        let (m, n) = (self.fa.order(), self.fb.order());
        check_shape("Q", q, m, n)?;
        check_finite("Q", q)?;
        // A X + X B = Q with A = Za Ta Zaᵀ, B = Zb Tb Zbᵀ, X = Za Y Zbᵀ: Ta Y + Y Tb = Zaᵀ Q Zb.
        // The adjoint uses the Schur forms of Aᵀ and Bᵀ.
        let (ta, za) = self.fa.tz(adjoint);
        let (tb, zb) = self.fb.tz(adjoint);
        let scale = self.fa.norm.max(self.fb.norm);
        let mut ctx = Ctx::new(smin(self.rtol, scale), Kind::Sylvester);
        let mut w = product(q, false, zb, false);
        let mut c = product(za, true, &w, false);
        kernel::sylv(
            &mut ctx,
            View::new(ta.as_slice(), m),
            View::new(tb.as_slice(), n),
            false,
            c.as_mut_slice(),
            m,
            (0, m),
            (0, n),
        )?;
        product_into(&mut w, za, false, &c, false);
        product_into(&mut c, &w, false, zb, true);
        check_solution(&c, Kind::Sylvester)?;
        Ok((c, pivot_ratio(ctx.min_pivot, scale)))
    }

    /// Hager–Higham estimate of `sep = 1/‖L⁻¹‖₁` for `L: X ↦ Ta X + X Tb` on `m×n` matrices (the
    /// Sylvester operator in Schur coordinates, as LAPACK's dtrsna/dtrsen); within a factor
    /// `√(mn)` of the Frobenius-norm separation. Returns `0.0` when the equation is singular.
    pub fn sep_estimate(&self) -> Result<f64> {
        self.fa.usable()?;
        self.fb.usable()?;
        let (m, n) = (self.fa.order(), self.fb.order());
        let smin = smin(self.rtol, self.fa.norm.max(self.fb.norm));
        Ok(sep_by_estimator(m, n, |c, transpose| {
            // L*: Taᵀ Y + Y Tbᵀ = C ⇔ Ua Ŷ + Ŷ Ub = Ĉ with Ŷ = Ja Y Jb, i.e. vec reversed.
            let (ta, _) = self.fa.tz(transpose);
            let (tb, _) = self.fb.tz(transpose);
            let mut ctx = Ctx::new(smin, Kind::Sylvester);
            kernel::sylv(
                &mut ctx,
                View::new(ta.as_slice(), m),
                View::new(tb.as_slice(), n),
                false,
                c,
                m,
                (0, m),
                (0, n),
            )
        }))
    }
}

/// Solves `A X + X B = Q` (scipy's `solve_sylvester`).
pub fn solve_sylvester(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    q: &DMatrix<f64>,
) -> Result<DMatrix<f64>> {
    let m = check_square("A", a)?;
    let n = check_square("B", b)?;
    check_shape("Q", q, m, n)?;
    Sylvester::new(a, b)?.solve(q)
}
