//! The Lyapunov operator `X ↦ A X + X Aᵀ` with `A` factored once by a real Schur form, for many
//! right-hand sides (and its adjoint `X ↦ Aᵀ X + X A`), and scipy's `solve_continuous_lyapunov`.

use super::kernel::{self, Ctx, Kind, View};
use super::*;

/// A Lyapunov operator `X ↦ A X + X Aᵀ` with `A` factored once (real Schur form), for many
/// right-hand sides.
///
/// Each solve costs two congruences with the Schur vectors (`3n³` flop-pairs for symmetric `Q`,
/// `4n³` otherwise) plus the triangular solve (`n³/2` for symmetric `Q`, `n³` otherwise). `Q` is
/// treated as symmetric when it is exactly symmetric (bitwise); then the solution is exactly
/// symmetric too.
#[derive(Debug, Clone)]
pub struct Lyapunov {
    factor: Factor,
    rtol: f64,
}

impl Lyapunov {
    /// Factors `A` (square, finite, non-empty).
    pub fn new(a: &DMatrix<f64>) -> Result<Self> {
        let schur = RealSchur::new(a)?;
        Ok(Lyapunov {
            factor: Factor::new(schur, Some(a)),
            rtol: DEFAULT_SINGULAR_RTOL,
        })
    }

    /// Uses an existing Schur form `A = Z T Zᵀ`. A malformed factor (shapes, non-finite entries,
    /// a 3×3 unreduced block) is reported by the first solve.
    pub fn from_schur(schur: RealSchur) -> Self {
        Lyapunov {
            factor: Factor::new(schur, None),
            rtol: DEFAULT_SINGULAR_RTOL,
        }
    }

    /// Sets the relative singularity tolerance (default [`DEFAULT_SINGULAR_RTOL`]); see the
    /// module documentation. `0.0` only rejects zero and subnormal pivots.
    pub fn with_singular_rtol(mut self, rtol: f64) -> Result<Self> {
        check_rtol(rtol)?;
        self.rtol = rtol;
        Ok(self)
    }

    /// The Schur form of `A`.
    pub fn schur(&self) -> &RealSchur {
        &self.factor.schur
    }

    /// The order `n` of `A`.
    pub fn order(&self) -> usize {
        self.factor.order()
    }

    /// Solves `A X + X Aᵀ = Q`.
    pub fn solve(&self, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        self.solve_impl(q, false).map(|(x, _)| x)
    }

    /// Solves the adjoint equation `Aᵀ X + X A = Q`.
    pub fn solve_adjoint(&self, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        self.solve_impl(q, true).map(|(x, _)| x)
    }

    /// Solves `A X + X Aᵀ = Q` and reports the residual and pivot ratio (the residual costs one or
    /// two extra `n×n` products).
    pub fn solve_with_info(&self, q: &DMatrix<f64>) -> Result<Solution> {
        self.with_info(q, false)
    }

    /// Solves `Aᵀ X + X A = Q` and reports the residual and pivot ratio.
    pub fn solve_adjoint_with_info(&self, q: &DMatrix<f64>) -> Result<Solution> {
        self.with_info(q, true)
    }

    fn with_info(&self, q: &DMatrix<f64>, adjoint: bool) -> Result<Solution> {
        let (x, ratio) = self.solve_impl(q, adjoint)?;
        let a = self.factor.a();
        // A X + X Aᵀ (or Aᵀ X + X A).
        let ax = product(a, adjoint, &x, false);
        let xa = product(&x, false, a, !adjoint);
        let r = &ax + &xa - q;
        let denom = 2.0 * norm_fro(a) * norm_fro(&x) + norm_fro(q);
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

    /// The Schur vectors `Z` of `A = Z T Zᵀ`: the coordinates of
    /// [`solve_schur_coordinates`](Self::solve_schur_coordinates).
    pub fn schur_vectors(&self) -> &DMatrix<f64> {
        &self.factor.schur.z
    }

    /// Solves `A X + X Aᵀ = Q` (or, when `adjoint`, `Aᵀ X + X A = Q`) for symmetric `Q` given and
    /// returned in Schur coordinates: `c = Zᵀ Q Z` in, `Zᵀ X Z` out — only the triangular solve,
    /// no congruence with `Z` (a caller that keeps its matrices in these coordinates saves the
    /// `3n³` of each solve). Only the upper triangle of `c` is read; the solution is exactly
    /// symmetric. The adjoint equation's Schur form is that of `Aᵀ` in the reversed basis `Z J`,
    /// so its data are reversed (`J c J`) before and after the solve.
    pub fn solve_schur_coordinates(
        &self,
        mut c: DMatrix<f64>,
        adjoint: bool,
    ) -> Result<DMatrix<f64>> {
        self.factor.usable()?;
        let n = self.order();
        check_shape("Q", &c, n, n)?;
        check_finite("Q", &c)?;
        let (t, _) = self.factor.tz(adjoint);
        let mut ctx = Ctx::new(smin(self.rtol, self.factor.norm), Kind::Lyapunov);
        let tv = View::new(t.as_slice(), n);
        mirror_upper(&mut c);
        if adjoint {
            c = DMatrix::from_fn(n, n, |i, j| c[(n - 1 - i, n - 1 - j)]);
        }
        kernel::lyap(&mut ctx, tv, c.as_mut_slice(), n, (0, n))?;
        mirror_upper(&mut c);
        if adjoint {
            c = DMatrix::from_fn(n, n, |i, j| c[(n - 1 - i, n - 1 - j)]);
        }
        check_solution(&c, Kind::Lyapunov)?;
        Ok(c)
    }

    fn solve_impl(&self, q: &DMatrix<f64>, adjoint: bool) -> Result<(DMatrix<f64>, f64)> {
        self.factor.usable()?;
        let n = self.order();
        check_shape("Q", q, n, n)?;
        check_finite("Q", q)?;
        let (t, z) = self.factor.tz(adjoint);
        let scale = self.factor.norm;
        let mut ctx = Ctx::new(smin(self.rtol, scale), Kind::Lyapunov);
        let tv = View::new(t.as_slice(), n);
        // Two n×n buffers: W = Q Z, C = Zᵀ W, solve in C, W = Z Y, C = W Zᵀ.
        let mut w = product(q, false, z, false);
        let x = if is_exactly_symmetric(q) {
            // Only the upper triangles of C = Zᵀ Q Z and of X = Z Y Zᵀ are formed; X is mirrored.
            let mut c = product_upper(z, true, &w, false);
            kernel::lyap(&mut ctx, tv, c.as_mut_slice(), n, (0, n))?;
            product_into(&mut w, z, false, &c, false);
            product_upper_into(&mut c, &w, false, z, true);
            mirror_upper(&mut c);
            c
        } else {
            let mut c = product(z, true, &w, false);
            kernel::sylv(&mut ctx, tv, tv, true, c.as_mut_slice(), n, (0, n), (0, n))?;
            product_into(&mut w, z, false, &c, false);
            product_into(&mut c, &w, false, z, true);
            c
        };
        check_solution(&x, Kind::Lyapunov)?;
        Ok((x, pivot_ratio(ctx.min_pivot, scale)))
    }

    /// Hager–Higham estimate of `sep = 1/‖L⁻¹‖₁` for `L: X ↦ T X + X Tᵀ` on `n×n` matrices (the
    /// Lyapunov operator in Schur coordinates), as LAPACK's dtrsna/dtrsen estimate `sep`. It lies
    /// within a factor `n` of the Frobenius-norm separation `σ_min(I⊗A + A⊗I)`; `‖A‖_F / sep` is a
    /// condition number for the equation. Costs about ten triangular solves. Returns `0.0` when the
    /// equation is singular (to the tolerance in use).
    pub fn sep_estimate(&self) -> Result<f64> {
        self.factor.usable()?;
        let n = self.order();
        let (t, u) = (&self.factor.schur.t, &self.factor.adj_t);
        let smin = smin(self.rtol, self.factor.norm);
        Ok(sep_by_estimator(n, n, |c, transpose| {
            // L*: Tᵀ Y + Y T = C  ⇔  U Ŷ + Ŷ Uᵀ = Ĉ with Ŷ = J Y J, i.e. vec reversed.
            let tm = if transpose { u } else { t };
            let mut ctx = Ctx::new(smin, Kind::Lyapunov);
            let tv = View::new(tm.as_slice(), n);
            kernel::sylv(&mut ctx, tv, tv, true, c, n, (0, n), (0, n))
        }))
    }
}

/// Solves `A X + X Aᵀ = Q` (scipy's `solve_continuous_lyapunov`).
pub fn solve_lyapunov(a: &DMatrix<f64>, q: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let n = check_square("A", a)?;
    check_shape("Q", q, n, n)?;
    Lyapunov::new(a)?.solve(q)
}
