//! Bindings for `crate::network` and `crate::cost`: the `CostModel` class, a validated network held
//! by Rust so that each evaluation converts only the rate vector, and the `CostPoint` class, one
//! evaluation point kept in Rust so that repeated Hessian-vector products reuse its factorisation.

use super::results::{CostEvaluation, NewtonAllocation, ValueGradient, ValueGradientBatch};
use super::{run, run_order, to_matrix, to_numpy, INLINE_ORDER};
use crate::allocation::newton_exact;
use crate::care::CareOptions;
use crate::cost::{self, with_context, CostOptions, CostPoint, Evaluation, Threads};
use crate::network::Network;
use crate::{Error, Result};
use nalgebra::DMatrix;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyModule;
use std::sync::Arc;

mod point;
pub(super) use point::PyCostPoint;

type Arr1<'py> = Bound<'py, PyArray1<f64>>;
type Arr1In<'py> = PyReadonlyArray1<'py, f64>;
type Arr2<'py> = Bound<'py, PyArray2<f64>>;

/// A network `(A, G, ĉ_1 … ĉ_N)` validated once (shapes and finiteness) and the
/// evaluators of `η(r) = tr Σ(r)` and its derivatives. Heavy work runs without the GIL.
#[pyclass(frozen, module = "capalloc_rs._core")]
pub struct CostModel {
    net: Arc<Network>,
    opts: CostOptions,
}

fn rows_of(rates: &PyReadonlyArray2<'_, f64>) -> Vec<Vec<f64>> {
    rates
        .as_array()
        .rows()
        .into_iter()
        .map(|row| row.to_vec())
        .collect()
}

/// `None` → every core (shared, fork-safe pool); `Some(t)` → `t` threads.
fn threads_of(threads: Option<usize>) -> Threads {
    match threads {
        None => Threads::All,
        Some(t) => Threads::Count(t),
    }
}

/// [`threads_of`] for the `N` solves of one Hessian of order `n`: a problem small enough to run
/// inline ([`INLINE_ORDER`]) runs them on the calling thread when no count is given (waking the
/// pool's sleeping threads costs more than the solves; the result does not depend on it).
fn hessian_threads(threads: Option<usize>, n: usize) -> Threads {
    match threads {
        None if n <= INLINE_ORDER => Threads::Sequential,
        t => threads_of(t),
    }
}

/// The first failing row's error (with its index), or all values.
fn first_error<T>(
    results: Vec<Result<T>>,
    nan_on_error: bool,
    nan: impl Fn() -> T,
) -> Result<Vec<T>> {
    results
        .into_iter()
        .enumerate()
        .map(|(k, res)| match res {
            Ok(v) => Ok(v),
            Err(_) if nan_on_error => Ok(nan()),
            Err(e) => Err(with_context(e, &format!("row {k}: "))),
        })
        .collect()
}

/// The columns of an `N × k` array, refused (shape error) unless it has `nn` rows.
fn columns_of(v: &PyReadonlyArray2<'_, f64>, nn: usize) -> Result<Vec<Vec<f64>>> {
    let v = v.as_array();
    if v.nrows() != nn {
        return Err(Error::Shape(format!(
            "v must have one entry per sensor ({nn}), got {}",
            v.nrows()
        )));
    }
    Ok(v.columns().into_iter().map(|c| c.to_vec()).collect())
}

/// The `nn × k` matrix with the given columns.
fn from_columns(nn: usize, cols: &[Vec<f64>]) -> DMatrix<f64> {
    DMatrix::from_fn(nn, cols.len(), |i, k| cols[k][i])
}

impl CostModel {
    fn check_batch(&self, rates: &PyReadonlyArray2<'_, f64>) -> Result<()> {
        let (_, cols) = rates.as_array().dim();
        if cols != self.net.num_sensors() {
            return Err(Error::Shape(format!(
                "rates must have shape (K, {}) (one rate per sensor in each row), got {} columns",
                self.net.num_sensors(),
                cols
            )));
        }
        Ok(())
    }
}

#[pymethods]
impl CostModel {
    /// Validates and stores the network. `scale` and `newton_steps` are the CARE options;
    /// `error_weight` is the matrix `M` of a weighted error `tr(M Σ)` (default `I`).
    #[new]
    #[pyo3(signature = (a, g, sensors, scale=true, newton_steps=8, error_weight=None))]
    fn new(
        a: PyReadonlyArray2<'_, f64>,
        g: PyReadonlyArray2<'_, f64>,
        sensors: Vec<PyReadonlyArray2<'_, f64>>,
        scale: bool,
        newton_steps: usize,
        error_weight: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<Self> {
        let sensors: Vec<DMatrix<f64>> = sensors.iter().map(to_matrix).collect();
        let mut net = Network::new(to_matrix(&a), to_matrix(&g), sensors)?;
        if let Some(m) = error_weight {
            net = net.with_error_weight(to_matrix(&m))?;
        }
        Ok(CostModel {
            net: Arc::new(net),
            opts: CostOptions {
                care: CareOptions {
                    scale,
                    newton_steps,
                    ..CareOptions::default()
                },
                ..CostOptions::default()
            },
        })
    }

    /// State dimension `n`.
    #[getter]
    fn n(&self) -> usize {
        self.net.order()
    }

    /// Number of sensors `N`.
    #[getter]
    fn num_sensors(&self) -> usize {
        self.net.num_sensors()
    }

    /// `W(r) = Σ r_i ĉ_i ĉ_iᵀ`.
    fn weight<'py>(&self, py: Python<'py>, r: PyReadonlyArray1<'py, f64>) -> PyResult<Arr2<'py>> {
        let r = r.as_array().to_vec();
        let w = self.net.weight(&r)?;
        Ok(to_numpy(py, w))
    }

    /// `η(r) = tr Σ(r)`.
    fn cost(&self, py: Python<'_>, r: PyReadonlyArray1<'_, f64>) -> PyResult<f64> {
        let r = r.as_array().to_vec();
        run_order(py, self.net.order(), || {
            cost::cost(&self.net, &r, &self.opts)
        })
    }

    /// `η` and `∇η` ([`ValueGradient`]).
    fn value_gradient<'py>(
        &self,
        py: Python<'py>,
        r: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<ValueGradient> {
        let r = r.as_array().to_vec();
        let (v, g) = run_order(py, self.net.order(), || {
            cost::value_gradient(&self.net, &r, &self.opts)
        })?;
        Ok(ValueGradient {
            value: v,
            gradient: g.into_pyarray(py).unbind(),
        })
    }

    /// A [`CostEvaluation`] (`η`, `Σ`, diagnostics; `∇η` from `order` 1, `∇²η` at `order` 2);
    /// the Hessian's solves use `threads` threads (default: every core).
    #[pyo3(signature = (r, order=0, threads=None))]
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        r: PyReadonlyArray1<'py, f64>,
        order: u8,
        threads: Option<usize>,
    ) -> PyResult<CostEvaluation> {
        if order > 2 {
            return Err(
                Error::InvalidInput(format!("order must be 0, 1 or 2, got {order}")).into(),
            );
        }
        let r = r.as_array().to_vec();
        let n = self.net.order();
        let out = run_order(py, n, || -> Result<_> {
            let ev = Evaluation::new(&self.net, &r, &self.opts)?;
            let (grad, hess) = if order >= 1 {
                let adj = ev.adjoint()?;
                let hess = if order == 2 {
                    Some(adj.hessian(hessian_threads(threads, n))?)
                } else {
                    None
                };
                (Some(adj.gradient().to_vec()), hess)
            } else {
                (None, None)
            };
            let value = ev.value();
            let (res, abs) = (ev.residual(), ev.closed_loop_abscissa());
            Ok((value, ev.sigma().clone(), res, abs, grad, hess))
        })?;
        let (value, sigma, res, abs, grad, hess) = out;
        Ok(CostEvaluation {
            value,
            sigma: to_numpy(py, sigma).unbind(),
            care_residual: res,
            closed_loop_abscissa: abs,
            gradient: grad.map(|g| g.into_pyarray(py).unbind()),
            hessian: hess.map(|h| to_numpy(py, h).unbind()),
        })
    }

    /// `∇²η(r) V` for an `N × k` matrix `V` (two Lyapunov solves per column after the gradient's).
    fn hvp<'py>(
        &self,
        py: Python<'py>,
        r: PyReadonlyArray1<'py, f64>,
        v: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Arr2<'py>> {
        let r = r.as_array().to_vec();
        let vs = columns_of(&v, self.net.num_sensors())?;
        let out = run(py, || cost::hvp(&self.net, &r, &vs, &self.opts))?;
        Ok(to_numpy(py, from_columns(self.net.num_sensors(), &out)))
    }

    /// The evaluation point at `r`: solves the CARE, factors `A_cl` and solves the adjoint equation
    /// once; the returned `CostPoint` keeps all of it for further products.
    fn at(&self, py: Python<'_>, r: PyReadonlyArray1<'_, f64>) -> PyResult<PyCostPoint> {
        let r = r.as_array().to_vec();
        let point = run_order(py, self.net.order(), || {
            CostPoint::at(Arc::clone(&self.net), &r, &self.opts)
        })?;
        Ok(PyCostPoint {
            point,
            opts: self.opts,
        })
    }

    /// Newton's method with the exact Hessian on the simplex `{γ ≥ 0, Σγ = sigma}` from
    /// `gamma0`, the whole loop in the core (`crate::allocation::newton`); points warm-started
    /// from the previous one when `warm`.
    #[pyo3(signature = (r_min, sigma, gamma0, tol, max_iter, warm))]
    #[allow(clippy::too_many_arguments)]
    fn newton_exact(
        &self,
        py: Python<'_>,
        r_min: f64,
        sigma: f64,
        gamma0: PyReadonlyArray1<'_, f64>,
        tol: f64,
        max_iter: usize,
        warm: bool,
    ) -> PyResult<NewtonAllocation> {
        let g0 = gamma0.as_array().to_vec();
        let out = run_order(py, self.net.order(), || {
            newton_exact(
                &self.net, r_min, sigma, &g0, tol, max_iter, warm, &self.opts,
            )
        })?;
        Ok(NewtonAllocation {
            gamma: out.gamma.into_pyarray(py).unbind(),
            iterations: out.iterations,
            value: out.value,
            gradient: out.gradient.into_pyarray(py).unbind(),
            value_error: out.value_error,
        })
    }

    /// The evaluation point at `r` reached by Newton–Kleinman from the symmetric `n × n` matrix
    /// `sigma0` (e.g. the block-diagonal `Σ` of the decoupled network), with the cold solve as the
    /// fallback; same accuracy and error bounds as `at(r)`.
    fn warm_at(
        &self,
        py: Python<'_>,
        r: PyReadonlyArray1<'_, f64>,
        sigma0: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<PyCostPoint> {
        let r = r.as_array().to_vec();
        let s0 = to_matrix(&sigma0);
        let point = run_order(py, self.net.order(), || {
            Evaluation::shared_warm(Arc::clone(&self.net), &r, &self.opts, &s0)?.into_adjoint()
        })?;
        Ok(PyCostPoint {
            point,
            opts: self.opts,
        })
    }

    /// `η` for each row of a `K × N` array, in parallel. A failing row raises its error (prefixed
    /// with the row index) unless `nan_on_error`, which gives NaN for it.
    #[pyo3(signature = (rates, nan_on_error=false, threads=None))]
    fn cost_many<'py>(
        &self,
        py: Python<'py>,
        rates: PyReadonlyArray2<'py, f64>,
        nan_on_error: bool,
        threads: Option<usize>,
    ) -> PyResult<Arr1<'py>> {
        self.check_batch(&rates)?;
        let rows = rows_of(&rates);
        let values = run(py, || {
            let res = cost::cost_many(&self.net, &rows, &self.opts, threads_of(threads))?;
            first_error(res, nan_on_error, || f64::NAN)
        })?;
        Ok(values.into_pyarray(py))
    }

    /// `η` and `∇η` for each row of a `K × N` array, in parallel ([`ValueGradientBatch`]: a
    /// `(K,)` and a `(K, N)` array).
    #[pyo3(signature = (rates, nan_on_error=false, threads=None))]
    fn value_gradient_many<'py>(
        &self,
        py: Python<'py>,
        rates: PyReadonlyArray2<'py, f64>,
        nan_on_error: bool,
        threads: Option<usize>,
    ) -> PyResult<ValueGradientBatch> {
        self.check_batch(&rates)?;
        let rows = rows_of(&rates);
        let nn = self.net.num_sensors();
        let out = run(py, || {
            let res = cost::value_gradient_many(&self.net, &rows, &self.opts, threads_of(threads))?;
            first_error(res, nan_on_error, || (f64::NAN, vec![f64::NAN; nn]))
        })?;
        let values: Vec<f64> = out.iter().map(|(v, _)| *v).collect();
        let grads = DMatrix::from_fn(out.len(), nn, |k, i| out[k].1[i]);
        Ok(ValueGradientBatch {
            values: values.into_pyarray(py).unbind(),
            gradients: to_numpy(py, grads).unbind(),
        })
    }
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<CostModel>()?;
    m.add_class::<PyCostPoint>()?;
    Ok(())
}
