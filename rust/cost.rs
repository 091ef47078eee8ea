//! The fast-sampling cost `η(r) = tr Σ(r)` of a [`Network`] with its exact gradient, Hessian and
//! Hessian-vector products.
//!
//! Notation (DESIGN.md §2, filter form): `W(r) = Σ r_i C_i`, `C_i = ĉ_i ĉ_iᵀ`, `Q = G Gᵀ`;
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
use crate::linalg::dense::{matmul, matmul_nt, matmul_tn, symmetrize};
use crate::linalg::sylvester::Lyapunov;
use crate::network::Network;
use crate::{Error, Result};
use nalgebra::DMatrix;
use rayon::prelude::*;
use rayon::{ThreadPool, ThreadPoolBuilder};
use std::ops::Deref;
use std::sync::{Arc, Mutex};

/// How parallel work (batches, the Hessian's per-sensor solves) is spread over threads. Results do
/// not depend on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Threads {
    /// On the calling thread only.
    Sequential,
    /// On a shared pool with one thread per core (created on first use, and again in a forked
    /// child process).
    #[default]
    All,
    /// On a dedicated pool of this many threads (created for the call).
    Count(usize),
}

/// The shared pool and the process it was created in.
static SHARED_POOL: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

fn build_pool(threads: usize) -> Result<ThreadPool> {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::InvalidInput(format!("could not start worker threads: {e}")))
}

/// The process's shared pool (rebuilt in a forked child). The bindings run every call on it too.
pub(crate) fn shared_pool() -> Result<Arc<ThreadPool>> {
    let pid = std::process::id();
    let mut guard = SHARED_POOL.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((owner, pool)) = guard.as_ref() {
        if *owner == pid {
            return Ok(Arc::clone(pool));
        }
    }
    // First use, or a forked child: the inherited pool's threads do not exist in this process.
    // Dropping it would signal threads that are not there, so it is leaked instead.
    if let Some(stale) = guard.take() {
        std::mem::forget(stale);
    }
    let pool = Arc::new(build_pool(0)?);
    *guard = Some((pid, Arc::clone(&pool)));
    Ok(pool)
}

/// Runs `f` inside the pool chosen by `threads` (`None` for [`Threads::Sequential`]).
/// `install` runs `f` on a pool thread: this thread's cancellation token goes with it (and the
/// parallel loops hand it on to their items, see [`crate::cancel`]).
fn in_pool<T: Send>(threads: Threads, f: impl FnOnce(bool) -> T + Send) -> Result<T> {
    let token = crate::cancel::current();
    let run = |parallel: bool| crate::cancel::with_token(token.as_ref(), || f(parallel));
    match threads {
        Threads::Sequential => Ok(run(false)),
        Threads::All => Ok(shared_pool()?.install(|| run(true))),
        Threads::Count(0) => Err(Error::InvalidInput("threads must be at least 1".into())),
        Threads::Count(1) => Ok(run(false)),
        Threads::Count(t) => Ok(build_pool(t)?.install(|| run(true))),
    }
}

/// `f(item)` with the cancellation token of the batch installed and polled first.
fn batch_item<T>(token: Option<&crate::cancel::Token>, f: impl FnOnce() -> Result<T>) -> Result<T> {
    crate::cancel::with_token(token, || {
        crate::cancel::check("a batch of cost evaluations")?;
        f()
    })
}

/// Options of the cost evaluation.
#[derive(Debug, Clone, Copy, Default)]
pub struct CostOptions {
    /// Options of the CARE solve.
    pub care: CareOptions,
}

/// Prefixes the message of an error, keeping its kind.
pub fn with_context(err: Error, prefix: &str) -> Error {
    match err {
        Error::Shape(m) => Error::Shape(format!("{prefix}{m}")),
        Error::NonFinite(m) => Error::NonFinite(format!("{prefix}{m}")),
        Error::InvalidInput(m) => Error::InvalidInput(format!("{prefix}{m}")),
        Error::NoStabilizingSolution(m) => Error::NoStabilizingSolution(format!("{prefix}{m}")),
        Error::Singular(m) => Error::Singular(format!("{prefix}{m}")),
        Error::ReorderFailed(m) => Error::ReorderFailed(format!("{prefix}{m}")),
        Error::NoConvergence(m) => Error::NoConvergence(format!("{prefix}{m}")),
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
    // A Σ + Σ Aᵀ − Σ W Σ + Q = 0 is the control form with A → Aᵀ; W = B Bᵀ with
    // B = [√r_1 ĉ_1 … √r_N ĉ_N] keeps the residual accurate at high rates (see `solve_care_factored`).
    let mut b = DMatrix::zeros(net.order(), net.total_outputs());
    for ((s, &ri), &off) in net.sensors().iter().zip(r).zip(net.offsets()) {
        let mut cols = b.columns_mut(off, s.outputs());
        cols.copy_from(s.matrix());
        cols *= ri.sqrt();
    }
    let sol = solve_care_factored(&net.a().transpose(), &b, net.q(), &opts.care)
        .map_err(|e| explain_extreme_rates(net, r, &w, e))?;
    Ok((sol, w))
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

fn trace(m: &DMatrix<f64>) -> f64 {
    m.diagonal().iter().sum()
}

/// `η(r) = tr Σ(r)`.
pub fn cost(net: &Network, r: &[f64], opts: &CostOptions) -> Result<f64> {
    let (sol, _) = solve_sigma(net, r, opts)?;
    let sigma = sol.x;
    Ok(trace(&sigma))
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
    sigma: DMatrix<f64>,
    u: DMatrix<f64>,
    a_cl: DMatrix<f64>,
    residual: f64,
    abscissa: f64,
    value_error: f64,
}

impl<'a> Evaluation<'a> {
    /// Solves the CARE at `r` (length `N`, entries finite and positive).
    pub fn new(net: &'a Network, r: &[f64], opts: &CostOptions) -> Result<Self> {
        Self::with_handle(Handle::Borrowed(net), r, opts)
    }

    fn with_handle(net: Handle<'a, Network>, r: &[f64], opts: &CostOptions) -> Result<Self> {
        let (sol, w) = solve_sigma(&net, r, opts)?;
        let (sigma, residual, abscissa, value_error) = (
            sol.x,
            sol.residual,
            sol.closed_loop_abscissa,
            sol.trace_error,
        );
        let n = net.order();
        let offsets = net.offsets();
        // U = Σ C̃ = [Σ ĉ_1 … Σ ĉ_N];  A_cl = A − Σ W = A − Σ_i r_i u_i ĉ_iᵀ.
        let mut u = DMatrix::zeros(n, net.total_outputs());
        let mut a_cl = net.a().clone();
        for (i, s) in net.sensors().iter().enumerate() {
            let ui = s.right_mul(&sigma);
            let rows = s.rows();
            if !rows.is_empty() {
                let mut cols = a_cl.columns_mut(rows.start, rows.len());
                cols.gemm(-r[i], &ui, &s.local().transpose(), 1.0);
            }
            u.columns_mut(offsets[i], s.outputs()).copy_from(&ui);
        }
        Ok(Evaluation {
            net,
            r: r.to_vec(),
            w,
            sigma,
            u,
            a_cl,
            residual,
            abscissa,
            value_error,
        })
    }

    /// The network evaluated.
    pub fn network(&self) -> &Network {
        &self.net
    }

    /// The rates.
    pub fn rates(&self) -> &[f64] {
        &self.r
    }

    /// `η = tr Σ`.
    pub fn value(&self) -> f64 {
        trace(&self.sigma)
    }

    /// The error covariance `Σ(r)`.
    pub fn sigma(&self) -> &DMatrix<f64> {
        &self.sigma
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
        self.residual
    }

    /// `max Re λ(A_cl) < 0`.
    pub fn closed_loop_abscissa(&self) -> f64 {
        self.abscissa
    }

    /// An upper bound on `|η − η_exact|`, the CARE's bound on `|tr Σ − tr Σ*|` (see
    /// [`crate::care::refine`]); `∞` when none can be established.
    pub fn value_error(&self) -> f64 {
        self.value_error
    }

    /// Factors `A_cl` (real Schur form) and solves the adjoint equation `A_clᵀ Y + Y A_cl = −I`:
    /// gives the gradient, and what the Hessian and Hessian-vector products need.
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

/// `Σ_{k ∈ cols} ⟨a[:, k], b[:, k]⟩`.
fn column_dots(a: &DMatrix<f64>, b: &DMatrix<f64>, cols: std::ops::Range<usize>) -> f64 {
    cols.map(|k| a.column(k).dot(&b.column(k))).sum()
}

/// The adjoint state at one rate vector: `Y`, the gradient, and the Schur form of `A_cl` for
/// further solves. Borrows its [`Evaluation`] ([`Evaluation::adjoint`]) or owns it
/// ([`Evaluation::into_adjoint`], [`CostPoint`]).
#[derive(Debug, Clone)]
pub struct Adjoint<'e, 'a> {
    eval: Handle<'e, Evaluation<'a>>,
    lyap: Lyapunov,
    y: DMatrix<f64>,
    yu: DMatrix<f64>,
    gradient: Vec<f64>,
}

impl<'e, 'a> Adjoint<'e, 'a> {
    fn with_handle(eval: Handle<'e, Evaluation<'a>>) -> Result<Self> {
        let n = eval.net.order();
        let lyap = Lyapunov::new(&eval.a_cl)?;
        let y = symmetrize(&lyap.solve_adjoint(&(-DMatrix::<f64>::identity(n, n)))?);
        let yu = matmul(&y, &eval.u);
        let offsets = eval.net.offsets();
        let gradient = (0..eval.net.num_sensors())
            .map(|i| -column_dots(&eval.u, &yu, offsets[i]..offsets[i + 1]))
            .collect();
        Ok(Adjoint {
            eval,
            lyap,
            y,
            yu,
            gradient,
        })
    }

    /// The evaluation (`Σ`, `η`, `A_cl`, the rates, the network).
    pub fn evaluation(&self) -> &Evaluation<'a> {
        &self.eval
    }

    /// `∇η(r)`, `∂η/∂r_i = −tr(ĉ_iᵀ Σ Y Σ ĉ_i)`.
    pub fn gradient(&self) -> &[f64] {
        &self.gradient
    }

    /// The adjoint solution `Y` of `A_clᵀ Y + Y A_cl = −I`.
    pub fn y(&self) -> &DMatrix<f64> {
        &self.y
    }

    /// `Σ'_i = ∂Σ/∂r_i`, the solution of `A_cl Σ'_i + Σ'_i A_clᵀ = Σ C_i Σ` (symmetric).
    pub fn sigma_derivative(&self, i: usize) -> Result<DMatrix<f64>> {
        let net: &Network = &self.eval.net;
        if i >= net.num_sensors() {
            return Err(Error::InvalidInput(format!(
                "sensor index {i} out of range (N = {})",
                net.num_sensors()
            )));
        }
        let off = net.offsets();
        let ui = self
            .eval
            .u
            .columns(off[i], off[i + 1] - off[i])
            .into_owned();
        let rhs = symmetrize(&matmul_nt(&ui, &ui));
        Ok(symmetrize(&self.lyap.solve(&rhs)?))
    }

    /// `C̃ᵀ S` (`P × n`), using the sensors' row supports.
    fn ct_times(&self, s: &DMatrix<f64>) -> DMatrix<f64> {
        let net: &Network = &self.eval.net;
        let off = net.offsets();
        let mut e = DMatrix::zeros(net.total_outputs(), s.ncols());
        for (k, sensor) in net.sensors().iter().enumerate() {
            e.rows_mut(off[k], sensor.outputs())
                .copy_from(&sensor.left_mul_t(s));
        }
        e
    }

    /// `Y = K Kᵀ`: Cholesky, or a symmetric square root if rounding made `Y` indefinite.
    fn y_factor(&self) -> Result<DMatrix<f64>> {
        match self.y.clone().cholesky() {
            Some(ch) => Ok(ch.l()),
            None => {
                // nalgebra's `symmetric_eigen()` iterates without bound (forever on NaN).
                let n = self.y.nrows();
                let eig = self
                    .y
                    .clone()
                    .try_symmetric_eigen(f64::EPSILON, 30 * n.max(10) * n.max(1))
                    .ok_or_else(|| {
                        Error::NoConvergence(
                            "the symmetric eigensolver for the adjoint Y did not converge within \
                             its bound of 30·max(10, n)·n sweeps (Y has non-finite entries?)"
                                .into(),
                        )
                    })?;
                let mut v = eig.eigenvectors;
                for (j, lambda) in eig.eigenvalues.iter().enumerate() {
                    let s = lambda.max(0.0).sqrt();
                    v.column_mut(j).scale_mut(s);
                }
                Ok(v)
            }
        }
    }

    /// The exact Hessian `∇²η(r)` (`N × N`, symmetric): `N` Lyapunov solves on the Schur form of
    /// `A_cl` already computed, spread over `threads` (the result does not depend on it).
    /// Memory: `O(N·P·n)` for the Gram factor.
    pub fn hessian(&self, threads: Threads) -> Result<DMatrix<f64>> {
        let net: &Network = &self.eval.net;
        let (n, nn, pp) = (net.order(), net.num_sensors(), net.total_outputs());
        let off = net.offsets();
        let k = self.y_factor()?;
        let sqrt_r: Vec<f64> = self.eval.r.iter().map(|v| v.sqrt()).collect();

        // For sensor i: Σ'_i, E_i = C̃ᵀ Σ'_i, T2[i, j] = tr(Y Σ'_i C_j Σ) = ⟨E_i[j-rows], (Y u_j)ᵀ⟩,
        // and M_i = R^{1/2} E_i K (flattened).
        // Column i of `gram` is vec(M_i); chunk i of `t2_data` is row i of T2. Filled in place
        // (in parallel over i when asked), so the Gram factor is the only O(N·P·n) allocation.
        let mut gram_data = vec![0.0; pp * n * nn];
        let mut t2_data = vec![0.0; nn * nn];
        let fill_column = |s: DMatrix<f64>, col: &mut [f64], t2row: &mut [f64]| {
            let mut e = self.ct_times(&s);
            for (j, t) in t2row.iter_mut().enumerate() {
                *t = (off[j]..off[j + 1])
                    .map(|c| e.row(c).transpose().dot(&self.yu.column(c)))
                    .sum();
            }
            for (j, sr) in sqrt_r.iter().enumerate() {
                e.rows_mut(off[j], off[j + 1] - off[j]).scale_mut(*sr);
            }
            col.copy_from_slice(matmul(&e, &k).as_slice());
        };
        // The columns may run on pool threads: each takes the caller's cancellation token.
        let token = crate::cancel::current();
        let fill = |(i, (col, t2row)): (usize, (&mut [f64], &mut [f64]))| -> Result<()> {
            let s = crate::cancel::with_token(token.as_ref(), || {
                crate::cancel::check("the Hessian's Lyapunov solves")?;
                self.sigma_derivative(i)
            })?;
            fill_column(s, col, t2row);
            Ok(())
        };
        // Not worth waking threads for a few small solves.
        let threads = if nn < 4 || n < 8 {
            Threads::Sequential
        } else {
            threads
        };
        in_pool(threads, |parallel| {
            if parallel {
                gram_data
                    .par_chunks_mut(pp * n)
                    .zip(t2_data.par_chunks_mut(nn))
                    .enumerate()
                    .try_for_each(fill)
            } else {
                gram_data
                    .chunks_mut(pp * n)
                    .zip(t2_data.chunks_mut(nn))
                    .enumerate()
                    .try_for_each(fill)
            }
        })??;
        let gram = DMatrix::from_vec(pp * n, nn, gram_data);
        // Column-major from row-major data: this is T2ᵀ, and only T2 + T2ᵀ is needed.
        let t2 = DMatrix::from_vec(nn, nn, t2_data);
        let t1 = matmul_tn(&gram, &gram);
        let h = (t1 + &t2 + t2.transpose()) * -2.0;
        Ok(symmetrize(&h))
    }

    /// Hessian-vector products `∇²η(r) v` for each `v` in `vs` (each of length `N`): two Lyapunov
    /// solves per vector on the Schur form of `A_cl` already computed.
    pub fn hvp(&self, vs: &[Vec<f64>]) -> Result<Vec<Vec<f64>>> {
        vs.iter().map(|v| self.hvp_one(v)).collect()
    }

    fn hvp_one(&self, v: &[f64]) -> Result<Vec<f64>> {
        let net: &Network = &self.eval.net;
        let nn = net.num_sensors();
        if v.len() != nn {
            return Err(Error::Shape(format!(
                "v must have one entry per sensor ({nn}), got {}",
                v.len()
            )));
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(Error::NonFinite(format!("v[{i}] = {} is not finite", v[i])));
        }
        let off = net.offsets();
        let (u, r) = (&self.eval.u, &self.eval.r);
        // Σ C_v Σ = U diag(v) Uᵀ.
        let mut uv = u.clone();
        for j in 0..nn {
            uv.columns_mut(off[j], off[j + 1] - off[j]).scale_mut(v[j]);
        }
        let rhs = symmetrize(&matmul_nt(&uv, u));
        let sv = symmetrize(&self.lyap.solve(&rhs)?);
        // B = W Σ'_v + C_v Σ: rows of sensor j get ĉ_j,loc (r_j ĉ_jᵀ Σ'_v + v_j u_jᵀ).
        let n = net.order();
        let mut b = DMatrix::zeros(n, n);
        for (j, s) in net.sensors().iter().enumerate() {
            let rows = s.rows();
            if rows.is_empty() {
                continue;
            }
            let mut inner = s.left_mul_t(&sv) * r[j];
            let uj = u.columns(off[j], s.outputs());
            inner += uj.transpose() * v[j];
            let mut target = b.rows_mut(rows.start, rows.len());
            target.gemm(1.0, s.local(), &inner, 1.0);
        }
        let m = matmul(&b, &self.y);
        let z = self.lyap.solve_adjoint(&(symmetrize(&m) * -1.0))?;
        let zu = matmul(&z, u);
        Ok((0..nn)
            .map(|i| {
                let cols = off[i]..off[i + 1];
                let svc = net.sensors()[i].right_mul(&sv);
                let third: f64 = cols
                    .clone()
                    .enumerate()
                    .map(|(c, k)| self.yu.column(k).dot(&svc.column(c)))
                    .sum();
                2.0 * column_dots(u, &zu, cols) - 2.0 * third
            })
            .collect())
    }
}

/// `(η, ∇η)`.
pub type ValueGradient = (f64, Vec<f64>);

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
