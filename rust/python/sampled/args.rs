//! The checks of the arguments the `SampledModel` methods share, each turning a Python value into
//! the core's type or a package `InvalidInputError` naming the argument: a schedule (sensor index
//! per slot, each `≥ 0` and `< N`), the initial covariance `sigma0` (finite `n × n`), the per-sensor
//! count limits, the objective `which`, the doubling's stopping rule `(tol, max_steps)` and the
//! deadline `time_limit` seconds from now.

use super::model::PySampledModel;
use crate::python::to_matrix;
use crate::sampled::doubling::DoublingOptions;
use crate::sampled::search::{CountLimits, Objective};
use crate::Error;
use nalgebra::DMatrix;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use std::time::{Duration, Instant};

impl PySampledModel {
    /// The per-sensor count limits: `min_counts`/`max_counts` when given, else `min_count` for
    /// every sensor and no cap.
    pub(super) fn limits(
        &self,
        min_count: usize,
        min_counts: Option<Vec<usize>>,
        max_counts: Option<Vec<usize>>,
    ) -> crate::Result<CountLimits> {
        let n = self.sys.n_sensors();
        let mut l = CountLimits::common(min_count, n);
        if let Some(m) = min_counts {
            l.min = m;
        }
        if let Some(m) = max_counts {
            l.max = m;
        }
        l.check(n)?;
        Ok(l)
    }

    /// The schedule as sensor indices, checked against the model.
    pub(super) fn schedule(&self, slots: &PyReadonlyArray1<'_, i64>) -> crate::Result<Vec<usize>> {
        let slots = slots
            .as_array()
            .iter()
            .enumerate()
            .map(|(l, &i)| {
                usize::try_from(i).map_err(|_| {
                    Error::InvalidInput(format!("slot {l} names sensor {i}: indices must be ≥ 0"))
                })
            })
            .collect::<crate::Result<Vec<usize>>>()?;
        self.sys.check_schedule(&slots)?;
        Ok(slots)
    }

    /// `sigma0` as a finite `n × n` matrix.
    pub(super) fn initial_covariance(
        &self,
        sigma0: &PyReadonlyArray2<'_, f64>,
    ) -> crate::Result<DMatrix<f64>> {
        let n = self.sys.order();
        let s0 = to_matrix(sigma0);
        crate::linalg::dense::check_shape("sigma0", &s0, n, n)?;
        crate::linalg::dense::check_finite("sigma0", &s0)?;
        Ok(s0)
    }
}

pub(super) fn objective(which: &str) -> crate::Result<Objective> {
    match which {
        "boundary" => Ok(Objective::Boundary),
        "average" => Ok(Objective::Average),
        other => Err(Error::InvalidInput(format!(
            "which must be 'boundary' or 'average', got {other:?}"
        ))),
    }
}

/// The deadline `time_limit` seconds from now: a past deadline evaluates no candidate; one beyond
/// what `Instant` holds is no deadline.
pub(super) fn deadline_of(time_limit: Option<f64>) -> crate::Result<Option<Instant>> {
    if time_limit.is_some_and(f64::is_nan) {
        return Err(Error::InvalidInput(
            "time_limit must be a number of seconds, got nan".into(),
        ));
    }
    Ok(time_limit
        .map(|t| Duration::try_from_secs_f64(t.max(0.0)).unwrap_or(Duration::MAX))
        .and_then(|d| Instant::now().checked_add(d)))
}

/// The checked common arguments of the search kernels (`neighbourhood`, `screen`,
/// `candidate_costs`): the objective, the doubling's stopping rule and the deadline.
pub(super) struct SearchArgs {
    pub(super) obj: Objective,
    pub(super) opts: DoublingOptions,
    pub(super) deadline: Option<Instant>,
}

impl SearchArgs {
    /// Checks `which`, `tol`, `max_steps` and `time_limit` (seconds from now; `None`: none).
    pub(super) fn new(
        which: &str,
        tol: f64,
        max_steps: usize,
        time_limit: Option<f64>,
    ) -> crate::Result<Self> {
        Ok(SearchArgs {
            obj: objective(which)?,
            opts: options(tol, max_steps)?,
            deadline: deadline_of(time_limit)?,
        })
    }
}

pub(super) fn options(tol: f64, max_steps: usize) -> crate::Result<DoublingOptions> {
    if !(tol.is_finite() && tol > 0.0) {
        return Err(Error::InvalidInput(format!(
            "tol must be positive and finite, got {tol}"
        )));
    }
    Ok(DoublingOptions { tol, max_steps })
}
