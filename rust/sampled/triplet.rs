//! Riccati triplets and their composition (the star product).
//!
//! A triplet `(A, G, H)` with `G = Gᵀ ⪰ 0`, `H = Hᵀ ⪰ 0` stands for the map
//! `T(X) = H + A X (I + G X)⁻¹ Aᵀ` on positive semidefinite `X`. Every filter step is one:
//!
//! * predict over a slot, `X ↦ E X Eᵀ + H`, is `(E, 0, H)`;
//! * update with `c̄` (unit measurement noise), `X ↦ (X⁻¹ + c̄c̄ᵀ)⁻¹ = X (I + c̄c̄ᵀX)⁻¹`, is
//!   `(I, c̄c̄ᵀ, 0)`;
//!
//! and the composition of two triplets is again a triplet (Redheffer's star product):
//!
//! ```text
//! T₂ ∘ T₁ = (A₂ (I + H₁G₂)⁻¹ A₁,  G₁ + A₁ᵀ (I + G₂H₁)⁻¹ G₂ A₁,  H₂ + A₂ H₁ (I + G₂H₁)⁻¹ A₂ᵀ).
//! ```
//!
//! Composing triplets never forms products of symplectic matrices (which grow like `‖E‖^{2k}`
//! and lose the symmetric structure); every factor `I + G₂H₁` is similar to
//! `I + G₂^{1/2} H₁ G₂^{1/2}`, whose eigenvalues are at least 1, so it is always invertible.
//! The `H` of a composition of `m` period triplets is the covariance after `m` periods started
//! from `X = 0`; `A` is the transition of the error dynamics along that run and `G` the
//! information gathered, seen from the start.

use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, symmetrize, Lu};
use crate::{Error, Result};
use nalgebra::DMatrix;

/// From this order on, `Vᵀ` is factored again and its solves run blocked (many right-hand
/// sides, faer's triangular solves) instead of the column-by-column transposed solve of the LU of
/// `V`: one more factorisation (`2n³/3` flops, blocked) saves the unblocked `2n³` of every
/// transposed solve, which dominated the schedule search at `n = 100` (Lu::solve_transpose).
pub const TRANSPOSED_LU_MIN: usize = 32;

/// Solves with `Vᵀ` given `V` and its LU: by a factorisation of `Vᵀ` itself from order
/// [`TRANSPOSED_LU_MIN`] on, else by the transposed solve of the LU of `V`.
pub enum TransposedLu<'a> {
    /// The LU of `Vᵀ`.
    Own(Lu),
    /// The LU of `V` (its transposed solve).
    Of(&'a Lu),
}

impl<'a> TransposedLu<'a> {
    /// The solver of `Vᵀ x = b` for `v` with LU `lu`.
    pub fn new(v: &DMatrix<f64>, lu: &'a Lu) -> Result<Self> {
        if v.nrows() >= TRANSPOSED_LU_MIN {
            Ok(TransposedLu::Own(Lu::new(&v.transpose())?))
        } else {
            Ok(TransposedLu::Of(lu))
        }
    }

    /// `b ← V⁻ᵀ b`.
    pub fn solve_in_place(&self, b: &mut DMatrix<f64>) {
        match self {
            TransposedLu::Own(lu) => lu.solve_in_place(b),
            TransposedLu::Of(lu) => lu.solve_transpose_in_place(b),
        }
    }
}

/// A Riccati triplet `(A, G, H)`: the map `X ↦ H + A X (I + G X)⁻¹ Aᵀ`.
#[derive(Debug, Clone, PartialEq)]
pub struct Triplet {
    /// The transition part `A`.
    pub a: DMatrix<f64>,
    /// The (symmetric, positive semidefinite) information part `G`.
    pub g: DMatrix<f64>,
    /// The (symmetric, positive semidefinite) noise part `H` — the image of `X = 0`.
    pub h: DMatrix<f64>,
}

impl Triplet {
    /// The identity map `(I, 0, 0)`.
    pub fn identity(n: usize) -> Self {
        Triplet {
            a: DMatrix::identity(n, n),
            g: DMatrix::zeros(n, n),
            h: DMatrix::zeros(n, n),
        }
    }

    /// The prediction `X ↦ E X Eᵀ + H`: `(E, 0, H)`.
    pub fn predict(e: &DMatrix<f64>, h: &DMatrix<f64>) -> Self {
        Triplet {
            a: e.clone(),
            g: DMatrix::zeros(e.nrows(), e.nrows()),
            h: h.clone(),
        }
    }

    /// The measurement update with `c̄` (`n × p`, unit noise): `(I, c̄c̄ᵀ, 0)`.
    pub fn update(cbar: &DMatrix<f64>) -> Self {
        let n = cbar.nrows();
        Triplet {
            a: DMatrix::identity(n, n),
            g: matmul_nt(cbar, cbar),
            h: DMatrix::zeros(n, n),
        }
    }

    /// One slot, predict then update, in closed form: with `S = I_p + c̄ᵀHc̄ = LLᵀ` and the gain
    /// `K = H c̄ S⁻¹`,
    ///
    /// ```text
    /// A_s = (I − K c̄ᵀ) E                        (= (I + H g)⁻¹ E,  g = c̄c̄ᵀ)
    /// G_s = (L⁻¹ c̄ᵀ E)ᵀ (L⁻¹ c̄ᵀ E)               (= Eᵀ g (I + H g)⁻¹ E)
    /// H_s = (I − K c̄ᵀ) H (I − K c̄ᵀ)ᵀ + K Kᵀ       (= H (I + g H)⁻¹, Joseph form)
    /// ```
    ///
    /// Every part is computed in a form that is symmetric positive semidefinite by construction.
    pub fn slot(e: &DMatrix<f64>, h: &DMatrix<f64>, cbar: &DMatrix<f64>) -> Result<Self> {
        let n = e.nrows();
        let p = cbar.ncols();
        let hc = matmul(h, cbar); // n × p
        let mut s = matmul_tn(cbar, &hc); // p × p
        for i in 0..p {
            s[(i, i)] += 1.0;
        }
        let s = symmetrize(&s);
        let chol = s.cholesky().ok_or_else(|| {
            Error::SingularProblem("innovation covariance I + c̄ᵀHc̄ is not positive definite".into())
        })?;
        // K = H c̄ S⁻¹  ⇔  S Kᵀ = c̄ᵀ H.
        let k = chol.solve(&hc.transpose()).transpose(); // n × p
        let mut ikc = DMatrix::identity(n, n);
        ikc.gemm(-1.0, &k, &cbar.transpose(), 1.0); // I − K c̄ᵀ
        let a = matmul(&ikc, e);
        let l = chol.l();
        let ce = matmul_tn(cbar, e); // p × n
        let v = l.solve_lower_triangular(&ce).ok_or_else(|| {
            Error::SingularProblem("Cholesky factor of I + c̄ᵀHc̄ is singular".into())
        })?;
        let g = symmetrize(&matmul_tn(&v, &v));
        let mut hs = matmul_nt(&matmul(&ikc, h), &ikc);
        hs.gemm(1.0, &k, &k.transpose(), 1.0);
        Ok(Triplet {
            a,
            g,
            h: symmetrize(&hs),
        })
    }

    /// Order `n` of the matrices.
    pub fn order(&self) -> usize {
        self.a.nrows()
    }

    /// The composition `next ∘ self` (apply `self` first): the star product
    ///
    /// ```text
    /// W = I + G₂H₁,  A₃ = A₂ W⁻ᵀ A₁,  G₃ = G₁ + A₁ᵀ W⁻¹ G₂ A₁,  H₃ = H₂ + A₂ H₁ W⁻¹ A₂ᵀ
    /// ```
    ///
    /// with `(A₁, G₁, H₁) = self`, `(A₂, G₂, H₂) = next`; one LU of `W`, three solves. A
    /// non-finite result (overflow) is [`Error::Convergence`].
    pub fn then(&self, next: &Triplet) -> Result<Triplet> {
        let n = self.order();
        let (a1, g1, h1) = (&self.a, &self.g, &self.h);
        let (a2, g2, h2) = (&next.a, &next.g, &next.h);
        let mut w = matmul(g2, h1);
        for i in 0..n {
            w[(i, i)] += 1.0;
        }
        let err = |_| {
            Error::Convergence(
                "star product: I + G₂H₁ is singular (overflow or non-finite triplet)".into(),
            )
        };
        let lu = Lu::new(&w).map_err(err)?;
        let lut = TransposedLu::new(&w, &lu).map_err(err)?;
        // A₃ = A₂ W⁻ᵀ A₁.
        let mut x = a1.clone();
        lut.solve_in_place(&mut x);
        let a3 = matmul(a2, &x);
        // G₃ = G₁ + A₁ᵀ W⁻¹ (G₂ A₁).
        let mut y = matmul(g2, a1);
        lu.solve_in_place(&mut y);
        let g3 = symmetrize(&(g1 + matmul_tn(a1, &y)));
        // H₁ W⁻¹ = (W⁻ᵀ H₁)ᵀ; H₃ = H₂ + A₂ (H₁ W⁻¹) A₂ᵀ.
        let mut z = h1.clone();
        lut.solve_in_place(&mut z);
        let hw = z.transpose();
        let h3 = symmetrize(&(h2 + matmul_nt(&matmul(a2, &hw), a2)));
        let out = Triplet {
            a: a3,
            g: g3,
            h: h3,
        };
        if !out.is_finite() {
            return Err(Error::Convergence(
                "star product overflowed (the covariance grows without bound: an unstable mode \
                 is not detected by the schedule)"
                    .into(),
            ));
        }
        Ok(out)
    }

    /// Applies the map: `T(X) = H + A X (I + G X)⁻¹ Aᵀ` (symmetrised).
    pub fn apply(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        let n = self.order();
        let mut v = matmul(&self.g, x);
        for i in 0..n {
            v[(i, i)] += 1.0;
        }
        let lu = Lu::new(&v)?;
        // X V⁻¹ = (V⁻ᵀ Xᵀ)ᵀ = (V⁻ᵀ X)ᵀ for symmetric X.
        let mut z = x.clone();
        TransposedLu::new(&v, &lu)?.solve_in_place(&mut z);
        let xv = z.transpose();
        Ok(symmetrize(
            &(&self.h + matmul_nt(&matmul(&self.a, &xv), &self.a)),
        ))
    }

    /// Whether every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.a
            .iter()
            .chain(self.g.iter())
            .chain(self.h.iter())
            .all(|v| v.is_finite())
    }
}

/// Composes a sequence of triplets, first to last, by a balanced binary tree of star products
/// (`⌈log₂ m⌉` levels; the rounding errors of `m` compositions then grow with the depth rather
/// than with `m`). An empty sequence gives the identity of order `n`.
pub fn compose_all(items: &[&Triplet], n: usize) -> Result<Triplet> {
    match items.len() {
        0 => Ok(Triplet::identity(n)),
        1 => Ok(items[0].clone()),
        m => {
            crate::cancel::check("the composition of the period triplet")?;
            let (first, second) = items.split_at(m / 2);
            compose_all(first, n)?.then(&compose_all(second, n)?)
        }
    }
}
