//! Bindings for `crate::cost::CostPoint`: the `CostPoint` class, one evaluation point kept in Rust
//! so that repeated Hessian-vector products (and warm-started neighbours) reuse its factorisation.

use super::super::{run_order, to_numpy};
use super::{columns_of, from_columns, hessian_threads, Arr1, Arr1In, Arr2};
use crate::cost::{self, CostOptions, CostPoint};
use numpy::{IntoPyArray, PyReadonlyArray2};
use pyo3::prelude::*;
/// One evaluation point of `η`: the CARE solved at `r`, the Schur form of `A_cl = A − ΣW` and the
/// adjoint `Y` (with the gradient), all kept in Rust. Immutable. Each Hessian-vector product costs
/// two Lyapunov solves on the cached Schur form; the Hessian `N` solves. Heavy work runs without
/// the GIL.
#[pyclass(frozen, name = "CostPoint", module = "capalloc_rs._core")]
pub struct PyCostPoint {
    pub(super) point: CostPoint,
    /// The options of the model that made it (for warm-started neighbours).
    pub(super) opts: CostOptions,
}

impl PyCostPoint {
    fn warm_info(&self) -> Option<&cost::WarmInfo> {
        self.point.evaluation().warm_info()
    }
}

#[pymethods]
impl PyCostPoint {
    /// Number of sensors `N`.
    #[getter]
    fn num_sensors(&self) -> usize {
        self.point.evaluation().network().num_sensors()
    }

    /// The rates `r`.
    #[getter]
    fn rates<'py>(&self, py: Python<'py>) -> Arr1<'py> {
        self.point.evaluation().rates().to_vec().into_pyarray(py)
    }

    /// `η(r) = tr Σ(r)`.
    #[getter]
    fn value(&self) -> f64 {
        self.point.evaluation().value()
    }

    /// `Σ(r)` (a copy).
    #[getter]
    fn sigma<'py>(&self, py: Python<'py>) -> Arr2<'py> {
        to_numpy(py, self.point.evaluation().sigma().clone())
    }

    /// Relative residual of the CARE solution.
    #[getter]
    fn care_residual(&self) -> f64 {
        self.point.evaluation().residual()
    }

    /// An upper bound on `|η − η_exact|` from the CARE's error bound (`inf` when none).
    #[getter]
    fn value_error(&self) -> f64 {
        self.point.evaluation().value_error()
    }

    /// `max Re λ(A_cl) < 0`.
    #[getter]
    fn closed_loop_abscissa(&self) -> f64 {
        self.point.evaluation().closed_loop_abscissa()
    }

    /// An upper bound on the relative error `‖Σ − Σ*‖_F / ‖Σ*‖_F` (`inf` when none).
    #[getter]
    fn forward_error(&self) -> f64 {
        self.point.evaluation().forward_error()
    }

    /// Whether this point was computed by a warm start that was accepted (`False` for a cold
    /// point and for a warm start that fell back to the cold solve).
    #[getter]
    fn warm_started(&self) -> bool {
        self.warm_info().is_some_and(|w| w.fallback.is_none())
    }

    /// Why a warm start fell back to the cold solve (`None` for a cold point or an accepted warm
    /// start).
    #[getter]
    fn warm_fallback(&self) -> Option<String> {
        self.warm_info()?.fallback.as_ref().map(|f| f.to_string())
    }

    /// Schur forms of closed loops the warm start of this point computed (0: a cold point).
    #[getter]
    fn warm_factorizations(&self) -> usize {
        self.warm_info().map_or(0, |w| w.factorizations)
    }

    /// Chord corrections the warm start of this point applied (0: a cold point, or none).
    #[getter]
    fn warm_chord_steps(&self) -> usize {
        self.warm_info().map_or(0, |w| w.chord_steps)
    }

    /// The evaluation point at `r` of the same model, warm-started from this one: Newton–Kleinman
    /// from this point's `Σ` (a few `n × n` Schur forms instead of the `2n × 2n` Hamiltonian
    /// one), with the cold solve as the fallback; same accuracy and error bounds as
    /// `CostModel.at(r)`; first up to `chord_steps` chord corrections on this point's Schur form.
    /// `compensated=False`: a stalled iteration is not refined with double-double residuals; its
    /// error bounds are then those of the working-precision floor (a few times the cold solve's).
    #[pyo3(signature = (r, chord_steps=0, compensated=true))]
    fn warm(
        &self,
        py: Python<'_>,
        r: Arr1In<'_>,
        chord_steps: usize,
        compensated: bool,
    ) -> PyResult<Self> {
        let (r, mut opts) = (r.as_array().to_vec(), self.opts);
        opts.warm.chord_steps = chord_steps;
        opts.warm.compensated = compensated;
        let n = self.point.evaluation().network().order();
        let point = run_order(py, n, || self.point.warm(&r, &opts))?;
        Ok(PyCostPoint {
            point,
            opts: self.opts,
        })
    }

    /// `∇η(r)` (a copy).
    #[getter]
    fn gradient<'py>(&self, py: Python<'py>) -> Arr1<'py> {
        self.point.gradient().to_vec().into_pyarray(py)
    }

    /// `∇²η(r) V` for an `N × k` matrix `V`: two Lyapunov solves per column.
    fn hvp<'py>(&self, py: Python<'py>, v: PyReadonlyArray2<'py, f64>) -> PyResult<Arr2<'py>> {
        let nn = self.num_sensors();
        let vs = columns_of(&v, nn)?;
        let n = self.point.evaluation().network().order();
        let out = run_order(py, n, || self.point.hvp(&vs))?;
        Ok(to_numpy(py, from_columns(nn, &out)))
    }

    /// `∇²η(r)` (`N` Lyapunov solves over `threads` threads, default every core).
    #[pyo3(signature = (threads=None))]
    fn hessian<'py>(&self, py: Python<'py>, threads: Option<usize>) -> PyResult<Arr2<'py>> {
        let n = self.point.evaluation().network().order();
        let h = run_order(py, n, || self.point.hessian(hessian_threads(threads, n)))?;
        Ok(to_numpy(py, h))
    }

    /// The principal block `[∇²η(r)]_{JJ}` on the sensors `idx` (`|J|` Lyapunov solves).
    #[pyo3(signature = (idx, threads=None))]
    fn hessian_block<'py>(
        &self,
        py: Python<'py>,
        idx: Vec<usize>,
        threads: Option<usize>,
    ) -> PyResult<Arr2<'py>> {
        let n = self.point.evaluation().network().order();
        let h = run_order(py, n, || {
            self.point.hessian_block(&idx, hessian_threads(threads, n))
        })?;
        Ok(to_numpy(py, h))
    }
}
