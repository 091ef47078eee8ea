//! The fast-sampling cost `η(r) = tr Σ(r)` of a [`Network`] — `tr(M Σ(r))` when the network has
//! an error weight `M ⪰ 0` ([`Network::with_error_weight`]) — with its exact gradient, Hessian and
//! Hessian-vector products. The weight enters only the value and the adjoint's right-hand side
//! (`−M` for `−I` below); every other formula is unchanged.
//!
//! Notation (filter form): `W(r) = Σ r_i C_i`, `C_i = ĉ_i ĉ_iᵀ`, `Q = G Gᵀ`;
//! `Σ(r)` is the stabilising solution of `A Σ + Σ Aᵀ − Σ W Σ + Q = 0` and `A_cl = A − Σ W` is Hurwitz.
//! With `u_i = Σ ĉ_i`:
//!
//! * **gradient** (one adjoint solve): `A_clᵀ Y + Y A_cl = −I`, `∂η/∂r_i = −tr(u_iᵀ Y u_i) ≤ 0`;
//! * **Hessian** (`N` more solves, all on one real Schur form of `A_cl`):
//!   `A_cl Σ'_i + Σ'_i A_clᵀ = u_i u_iᵀ` and
//!   `∂²η/∂r_i∂r_j = −2[tr(Y Σ'_i W Σ'_j) + tr(Y Σ'_i C_j Σ) + tr(Y Σ'_j C_i Σ)]`;
//! * **Hessian-vector product** (two more solves): with `C_v = Σ v_j C_j`,
//!   `A_cl Σ'_v + Σ'_v A_clᵀ = Σ C_v Σ`, `M = (W Σ'_v + C_v Σ) Y`, `M_s = (M + Mᵀ)/2`,
//!   `A_clᵀ Z + Z A_cl = −M_s`; then `(∇²η v)_i = 2 tr(u_iᵀ Z u_i) − 2 tr((Y u_i)ᵀ Σ'_v ĉ_i)`.
//!
//! Derivation of the last one: `(∇²η v)_i = −2[tr(Σ'_i M) + tr(Y Σ'_v C_i Σ)]`, and for symmetric
//! `Σ'_i`, `tr(Σ'_i M) = tr(Σ'_i M_s) = −tr(Σ'_i (A_clᵀ Z + Z A_cl)) = −tr((A_cl Σ'_i + Σ'_i A_clᵀ) Z)
//! = −tr(u_iᵀ Z u_i)`.
//!
//! In the Hessian, the first term is a Gram matrix: with `Y = K Kᵀ`, `W = C̃ R C̃ᵀ`
//! (`C̃ = [ĉ_1 … ĉ_N]`, `R = diag(r_i I_{p_i})`), `tr(Y Σ'_i W Σ'_j) = ⟨M_i, M_j⟩_F` for
//! `M_i = R^{1/2} C̃ᵀ Σ'_i K` — it is assembled by one matrix product and is positive semidefinite
//! by construction.
//!
//! An [`Evaluation`] borrows its network and an [`Adjoint`] borrows its evaluation, so one point's
//! derivatives cost no copies. [`CostPoint`] is the same pair owning both (the network shared
//! through an [`Arc`]): it can be kept, moved to another thread or handed to Python, and every
//! further Hessian-vector product on it costs two Lyapunov solves on the cached Schur form. Both
//! are one type ([`Handle`] is either a borrow or an `Arc`), so the code is shared.
//!
//! Every evaluation is sequential and deterministic; the batched functions evaluate rows in
//! parallel (rayon), so their results are bitwise identical to one-at-a-time calls. Parallel work
//! runs on this module's own rayon pool, which is rebuilt after a `fork()` (rayon's global pool
//! hangs in a forked child, e.g. a `ProcessPoolExecutor` worker), never on the global pool.

use crate::care::{solve_care_factored, CareOptions, CareSolution};
use crate::network::Network;
use crate::{Error, Result};
use nalgebra::DMatrix;
use rayon::prelude::*;

mod adjoint;
mod pool;
mod warm;
use crate::linalg::sylvester::Lyapunov;
pub use adjoint::Adjoint;
#[cfg(feature = "python")]
pub(crate) use pool::shared_pool;
pub use pool::Threads;
use pool::{batch_item, in_pool};
use std::ops::Deref;
use std::sync::Arc;
pub use warm::{Fallback, WarmInfo, WarmParams, DEFAULT_WARM_STEPS};

/// `(η, ∇η)`.
pub type ValueGradient = (f64, Vec<f64>);

/// Options of the cost evaluation.
#[derive(Debug, Clone, Copy, Default)]
pub struct CostOptions {
    /// Options of the CARE solve.
    pub care: CareOptions,
    /// Parameters of warm-started evaluations ([`Evaluation::warm`]).
    pub warm: WarmParams,
}

/// Prefixes the message of an error, keeping its kind.
pub fn with_context(err: Error, prefix: &str) -> Error {
    match err {
        Error::Shape(m) => Error::Shape(format!("{prefix}{m}")),
        Error::NonFinite(m) => Error::NonFinite(format!("{prefix}{m}")),
        Error::InvalidInput(m) => Error::InvalidInput(format!("{prefix}{m}")),
        Error::NoStabilizingSolution(m) => Error::NoStabilizingSolution(format!("{prefix}{m}")),
        Error::SingularProblem(m) => Error::SingularProblem(format!("{prefix}{m}")),
        Error::Reorder(m) => Error::Reorder(format!("{prefix}{m}")),
        Error::Convergence(m) => Error::Convergence(format!("{prefix}{m}")),
        Error::Interrupted(m) => Error::Interrupted(m),
    }
}

/// Solves the filter-form CARE at `r` (checked) and returns `(CARE solution, W(r))`.
fn solve_sigma(
    net: &Network,
    r: &[f64],
    opts: &CostOptions,
) -> Result<(CareSolution, DMatrix<f64>)> {
    net.check_rates(r)?;
    let w = net.weight_unchecked(r);
    let b = rate_factor(net, r);
    let sol = solve_care_factored(&net.a().transpose(), &b, net.q(), &opts.care)
        .map_err(|e| explain_extreme_rates(net, r, &w, e))?;
    Ok((sol, w))
}

/// `B = [√r_1 ĉ_1 … √r_N ĉ_N]`, `W(r) = B Bᵀ`. `A Σ + Σ Aᵀ − Σ W Σ + Q = 0` is the control form
/// with `A → Aᵀ`; the factor keeps the residual accurate at high rates (see
/// `solve_care_factored`).
fn rate_factor(net: &Network, r: &[f64]) -> DMatrix<f64> {
    let mut b = DMatrix::zeros(net.order(), net.total_outputs());
    for ((s, &ri), &off) in net.sensors().iter().zip(r).zip(net.offsets()) {
        let mut cols = b.columns_mut(off, s.outputs());
        cols.copy_from(s.matrix());
        cols *= ri.sqrt();
    }
    b
}

/// `(A − Σ W, U)` with `U = Σ C̃ = [Σ ĉ_1 … Σ ĉ_N]`: `A_cl = A − Σ_i r_i u_i ĉ_iᵀ`, formed on the
/// sensors' row supports.
fn closed_loop_and_u(
    net: &Network,
    r: &[f64],
    sigma: &DMatrix<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = net.order();
    let offsets = net.offsets();
    let mut u = DMatrix::zeros(n, net.total_outputs());
    let mut a_cl = net.a().clone();
    for (i, s) in net.sensors().iter().enumerate() {
        let ui = s.right_mul(sigma);
        let rows = s.rows();
        if !rows.is_empty() {
            let mut cols = a_cl.columns_mut(rows.start, rows.len());
            cols.gemm(-r[i], &ui, &s.local().transpose(), 1.0);
        }
        u.columns_mut(offsets[i], s.outputs()).copy_from(&ui);
    }
    (a_cl, u)
}

/// A CARE failure at rates so large that `W(r)` overflows, or that the Hamiltonian's fast
/// eigenvalues `±sqrt(‖W‖‖Q‖)` dwarf `‖A‖` by more than `1/sqrt(eps)` (the slow ones then drown in
/// the rounding of the fast ones and look like eigenvalues on the imaginary axis), is reported as
/// what it is: rates out of double precision's reach, naming `r` — not as an internal matrix
/// overflow or a missing stabilising solution. Other errors pass through.
fn explain_extreme_rates(net: &Network, r: &[f64], w: &DMatrix<f64>, err: Error) -> Error {
    if matches!(err, Error::Interrupted(_)) {
        return err;
    }
    let (k, rmax) =
        r.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |b, (i, &v)| if v > b.1 { (i, v) } else { b },
        );
    let nw = crate::linalg::dense::norm_fro(w);
    let nq = crate::linalg::dense::norm_fro(net.q());
    let na = crate::linalg::dense::norm_fro(net.a()).max(f64::MIN_POSITIVE);
    let spread = nw.sqrt() * nq.sqrt() / na;
    if nw.is_finite() && !(spread > 1.0 / f64::EPSILON.sqrt()) {
        return err;
    }
    let why = if nw.is_finite() {
        format!(
            "the fastest filter mode, ~sqrt(‖W(r)‖·‖Q‖) = {:.2e}, exceeds ‖A‖_F = {na:.2e} by a \
             factor {spread:.1e} > 1/sqrt(eps), so the CARE cannot resolve the slow modes",
            nw.sqrt() * nq.sqrt()
        )
    } else {
        "W(r) = Σ r_i ĉ_i ĉ_iᵀ overflows double precision".to_string()
    };
    Error::InvalidInput(format!(
        "the rates are too large for the cost to be computed: r[{k}] = {rmax:.3e}; {why}. Use a \
         smaller capacity r_tot (or rescale the sensors ĉ_i: η is unchanged when r_i ĉ_iĉ_iᵀ is) \
         (solver: {err})"
    ))
}

/// `η(r) = tr Σ(r)`, or `tr(M Σ(r))` for a network with a weight `M`.
pub fn cost(net: &Network, r: &[f64], opts: &CostOptions) -> Result<f64> {
    let (sol, _) = solve_sigma(net, r, opts)?;
    Ok(net.weighted_trace(&sol.x))
}

/// A borrowed or shared reference: lets [`Evaluation`] and [`Adjoint`] either borrow what they
/// are computed from (no copy, lifetime-bound) or share ownership of it (`'static`).
#[derive(Debug)]
pub enum Handle<'a, T> {
    /// Borrowed for `'a`.
    Borrowed(&'a T),
    /// Shared ownership.
    Shared(Arc<T>),
}

impl<T> Clone for Handle<'_, T> {
    fn clone(&self) -> Self {
        match self {
            Handle::Borrowed(t) => Handle::Borrowed(t),
            Handle::Shared(t) => Handle::Shared(Arc::clone(t)),
        }
    }
}

impl<T> Deref for Handle<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        match self {
            Handle::Borrowed(t) => t,
            Handle::Shared(t) => t,
        }
    }
}

/// The solution of the CARE at one rate vector, with what every derivative needs. Borrows the
/// network ([`Evaluation::new`]) or shares it ([`Evaluation::shared`], `'static`).
#[derive(Debug, Clone)]
pub struct Evaluation<'a> {
    net: Handle<'a, Network>,
    r: Vec<f64>,
    w: DMatrix<f64>,
    /// The CARE solution (`x` is `Σ`) with its diagnostics.
    sol: CareSolution,
    u: DMatrix<f64>,
    a_cl: DMatrix<f64>,
    /// The real Schur form of the closed loop, when the solve computed it (warm starts): the
    /// adjoint uses it instead of factoring `A_cl` again.
    factor: Option<Arc<Lyapunov>>,
    warm: Option<WarmInfo>,
}

impl<'a> Evaluation<'a> {
    /// Solves the CARE at `r` (length `N`, entries finite and positive).
    pub fn new(net: &'a Network, r: &[f64], opts: &CostOptions) -> Result<Self> {
        Self::with_handle(Handle::Borrowed(net), r, opts)
    }

    fn with_handle(net: Handle<'a, Network>, r: &[f64], opts: &CostOptions) -> Result<Self> {
        let (sol, w) = solve_sigma(&net, r, opts)?;
        Ok(Self::assemble(net, r, w, sol, None, None))
    }

    fn assemble(
        net: Handle<'a, Network>,
        r: &[f64],
        w: DMatrix<f64>,
        sol: CareSolution,
        factor: Option<Arc<Lyapunov>>,
        warm: Option<WarmInfo>,
    ) -> Self {
        let (a_cl, u) = closed_loop_and_u(&net, r, &sol.x);
        Evaluation {
            net,
            r: r.to_vec(),
            w,
            sol,
            u,
            a_cl,
            factor,
            warm,
        }
    }

    /// The network evaluated.
    pub fn network(&self) -> &Network {
        &self.net
    }

    /// The rates.
    pub fn rates(&self) -> &[f64] {
        &self.r
    }

    /// `η = tr Σ` (`tr(M Σ)` with a weight `M`).
    pub fn value(&self) -> f64 {
        self.net.weighted_trace(&self.sol.x)
    }

    /// The error covariance `Σ(r)`.
    pub fn sigma(&self) -> &DMatrix<f64> {
        &self.sol.x
    }

    /// The CARE solution (`x = Σ`) with all its diagnostics; for a warm-started evaluation see
    /// the `warm` module documentation for the fields that have no meaning there (NaN).
    pub fn care(&self) -> &CareSolution {
        &self.sol
    }

    /// An upper bound on the relative error `‖Σ − Σ*‖_F / ‖Σ*‖_F` (`∞` when none).
    pub fn forward_error(&self) -> f64 {
        self.sol.forward_error
    }

    /// What the warm start did: `None` for an evaluation that did not try one
    /// ([`Evaluation::new`]); otherwise whether it was accepted or why it fell back.
    pub fn warm_info(&self) -> Option<&WarmInfo> {
        self.warm.as_ref()
    }

    /// `W(r)`.
    pub fn weight(&self) -> &DMatrix<f64> {
        &self.w
    }

    /// The closed loop `A_cl = A − Σ W` (Hurwitz).
    pub fn closed_loop(&self) -> &DMatrix<f64> {
        &self.a_cl
    }

    /// Relative residual of the CARE solution.
    pub fn residual(&self) -> f64 {
        self.sol.residual
    }

    /// `max Re λ(A_cl) < 0`.
    pub fn closed_loop_abscissa(&self) -> f64 {
        self.sol.closed_loop_abscissa
    }

    /// An upper bound on `|η − η_exact|`: the CARE's bound on `|tr Σ − tr Σ*|` (see
    /// [`crate::care::refine`]), times `‖M‖₂` with a weight `M` — valid since the bound is
    /// `|tr P|·e` for the semidefinite `P = Ω⁻¹(I)` and `|tr(M P)| ≤ ‖M‖₂ |tr P|` for `M ⪰ 0`;
    /// `∞` when none can be established.
    pub fn value_error(&self) -> f64 {
        self.sol.trace_error * self.net.error_weight_norm()
    }

    /// Factors `A_cl` (real Schur form; a warm-started evaluation already has it) and solves the
    /// adjoint equation `A_clᵀ Y + Y A_cl = −M` (`M = I` without a weight): gives the gradient, and
    /// what the Hessian and Hessian-vector products need.
    pub fn adjoint(&self) -> Result<Adjoint<'_, 'a>> {
        Adjoint::with_handle(Handle::Borrowed(self))
    }

    /// [`adjoint`](Self::adjoint), keeping the evaluation inside the result.
    pub fn into_adjoint(self) -> Result<Adjoint<'a, 'a>> {
        Adjoint::with_handle(Handle::Shared(Arc::new(self)))
    }
}

impl Evaluation<'static> {
    /// Solves the CARE at `r` for a shared network: the evaluation owns its share and can
    /// outlive every other handle to the network.
    pub fn shared(net: Arc<Network>, r: &[f64], opts: &CostOptions) -> Result<Self> {
        Self::with_handle(Handle::Shared(net), r, opts)
    }
}

/// An owned evaluation point: the CARE solved at `r`, `A_cl` in real Schur form, the adjoint `Y`
/// and the gradient, for a network shared through an [`Arc`]. Repeated Hessian-vector products
/// ([`Adjoint::hvp`]) cost two Lyapunov solves each; nothing is recomputed. `Send + Sync`.
pub type CostPoint = Adjoint<'static, 'static>;

impl CostPoint {
    /// Solves the CARE at `r`, factors `A_cl` and solves the adjoint equation.
    pub fn at(net: Arc<Network>, r: &[f64], opts: &CostOptions) -> Result<Self> {
        Evaluation::shared(net, r, opts)?.into_adjoint()
    }
}

/// `(η, ∇η)` at `r`.
pub fn value_gradient(net: &Network, r: &[f64], opts: &CostOptions) -> Result<(f64, Vec<f64>)> {
    let ev = Evaluation::new(net, r, opts)?;
    let adj = ev.adjoint()?;
    Ok((ev.value(), adj.gradient().to_vec()))
}

/// `(η, ∇η, ∇²η)` at `r`; the Hessian's solves are spread over `threads`.
pub fn value_gradient_hessian(
    net: &Network,
    r: &[f64],
    opts: &CostOptions,
    threads: Threads,
) -> Result<(f64, Vec<f64>, DMatrix<f64>)> {
    let ev = Evaluation::new(net, r, opts)?;
    let adj = ev.adjoint()?;
    let h = adj.hessian(threads)?;
    Ok((ev.value(), adj.gradient().to_vec(), h))
}

/// `∇²η(r) v` for each `v` in `vs`.
pub fn hvp(net: &Network, r: &[f64], vs: &[Vec<f64>], opts: &CostOptions) -> Result<Vec<Vec<f64>>> {
    let ev = Evaluation::new(net, r, opts)?;
    ev.adjoint()?.hvp(vs)
}

/// `η` at every rate vector of `rates`, spread over `threads`; entry `k` is exactly
/// `cost(net, &rates[k])`. The outer error is only for a thread pool that could not start.
pub fn cost_many(
    net: &Network,
    rates: &[Vec<f64>],
    opts: &CostOptions,
    threads: Threads,
) -> Result<Vec<Result<f64>>> {
    in_pool(threads, |parallel| {
        let token = crate::cancel::current();
        let one = |r: &Vec<f64>| batch_item(token.as_ref(), || cost(net, r, opts));
        if parallel {
            rates.par_iter().map(one).collect()
        } else {
            rates.iter().map(one).collect()
        }
    })
}

/// `(η, ∇η)` at every rate vector of `rates`, spread over `threads`; entry `k` is exactly
/// `value_gradient(net, &rates[k])`.
pub fn value_gradient_many(
    net: &Network,
    rates: &[Vec<f64>],
    opts: &CostOptions,
    threads: Threads,
) -> Result<Vec<Result<ValueGradient>>> {
    in_pool(threads, |parallel| {
        let token = crate::cancel::current();
        let one = |r: &Vec<f64>| batch_item(token.as_ref(), || value_gradient(net, r, opts));
        if parallel {
            rates.par_iter().map(one).collect()
        } else {
            rates.iter().map(one).collect()
        }
    })
}

#[cfg(test)]
mod tests;
