//! `_core.SampledModel`: the sampled model `(A, Q = GGᵀ, [ĉ_i], [b_i], M)` validated once, the
//! discretisation of the last `(tau, r_tot)` it was asked for, and its methods, each binding one
//! function of `crate::sampled` at the period `tau` on a schedule `slots`: the slot maps and the
//! period's triplet (`crate::sampled::Discretisation`), the periodic steady state by doubling, one
//! period's propagation and the plain fixed-point iteration (`crate::sampled::doubling`), the
//! exact cost, the neighbourhood and a greedy pass (`crate::sampled::search`), the screen
//! (`crate::sampled::sensitivity`) and the costs of candidate schedules
//! (`crate::sampled::star_tree`; the tree they share is kept by [`super::star_tree`]).

use super::args::{objective, options, SearchArgs};
use super::star_tree::{CachedTree, Pending};
use crate::python::results::{
    CandidateCosts, FixedPoint, GreedyPass, Neighbourhood, PeriodTriplet, Propagation, Screen,
    SlotDiscretisation, SteadyState,
};
use crate::python::{run, to_matrix, to_numpy};
use crate::sampled::doubling::{fixed_point, propagate, steady_state};
use crate::sampled::search::{greedy_pass_limits, neighbourhood_until, schedule_cost};
use crate::sampled::{Discretisation, SampledSystem};
use crate::Error;
use nalgebra::DMatrix;
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::sync::{Arc, Mutex};

type Arr3<'py> = Bound<'py, PyArray3<f64>>;

/// The last discretisation computed, keyed by `(tau.to_bits(), budget.to_bits())`.
type Cached = Option<((u64, u64), Arc<Discretisation>)>;

/// The sampled model, validated once, with the discretisation of the last `(tau, r_tot)` kept.
/// Immutable from Python; the cache is an implementation detail (results never depend on it: a
/// discretisation is a pure function of `(A, Q, [ĉ_i], tau, r_tot)`).
#[pyclass(frozen, name = "SampledModel", module = "capalloc_rs._core")]
pub struct PySampledModel {
    pub(super) sys: SampledSystem,
    last: Mutex<Cached>,
    pub(super) tree: Mutex<CachedTree>,
    pub(super) pending: Mutex<Option<Pending>>,
}

impl PySampledModel {
    /// The discretisation for `(tau, budget)`: the cached one when the key matches, else
    /// computed (and kept). Called inside [`run`], off the GIL.
    fn discretisation(&self, tau: f64, budget: f64) -> crate::Result<Arc<Discretisation>> {
        let key = (tau.to_bits(), budget.to_bits());
        if let Some((k, d)) = &*self.lock() {
            if *k == key {
                return Ok(Arc::clone(d));
            }
        }
        let d = Arc::new(self.sys.discretise_budget(tau, budget)?);
        *self.lock() = Some((key, Arc::clone(&d)));
        Ok(d)
    }

    /// The cache's lock; a panic while it was held leaves only a cache behind, still valid.
    fn lock(&self) -> std::sync::MutexGuard<'_, Cached> {
        self.last.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The budget of a call: `budget` when given, else what the schedule uses (`Σ_l b_{R_l}`;
    /// with unit costs the number of slots, the paper's `r_tot`).
    fn budget(&self, slots: &[usize], budget: Option<f64>) -> f64 {
        budget.unwrap_or_else(|| self.sys.used(slots))
    }

    /// The discretisation of a call on `slots` (see [`Self::budget`]).
    pub(super) fn disc_for(
        &self,
        tau: f64,
        slots: &[usize],
        budget: Option<f64>,
    ) -> crate::Result<Arc<Discretisation>> {
        self.discretisation(tau, self.budget(slots, budget))
    }
}

fn stack<'py>(py: Python<'py>, ms: &[DMatrix<f64>], n: usize) -> Arr3<'py> {
    Array3::from_shape_fn((ms.len(), n, n), |(l, i, j)| ms[l][(i, j)]).into_pyarray(py)
}

#[pymethods]
impl PySampledModel {
    /// Validates and stores `A` (n×n), `Q = GGᵀ` (n×n, symmetric), the sensors `ĉ_i` (n×p_i),
    /// the sample costs `b_i > 0` (default 1 each) and the error weight `M` (default: the plain
    /// trace).
    #[new]
    #[pyo3(signature = (a, q, sensors, costs=None, weight=None))]
    fn new(
        a: PyReadonlyArray2<'_, f64>,
        q: PyReadonlyArray2<'_, f64>,
        sensors: Vec<PyReadonlyArray2<'_, f64>>,
        costs: Option<Vec<f64>>,
        weight: Option<PyReadonlyArray2<'_, f64>>,
    ) -> PyResult<Self> {
        let mut sys = SampledSystem::new(
            to_matrix(&a),
            to_matrix(&q),
            sensors.iter().map(to_matrix).collect(),
        )?;
        if let Some(c) = costs {
            sys = sys.with_costs(c)?;
        }
        sys = sys.with_weight(weight.as_ref().map(to_matrix))?;
        Ok(PySampledModel {
            sys,
            last: Mutex::new(None),
            tree: Mutex::new(None),
            pending: Mutex::new(None),
        })
    }

    /// State dimension `n`.
    #[getter]
    fn n(&self) -> usize {
        self.sys.order()
    }

    /// Number of sensors `N`.
    #[getter]
    fn num_sensors(&self) -> usize {
        self.sys.n_sensors()
    }

    /// The sample cost `b_i` of every sensor.
    #[getter]
    fn costs<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.sys.costs().to_vec())
    }

    /// The [`SlotDiscretisation`] of a period `tau` of `budget` channel units (for unit costs the
    /// number of slots `r_tot`): one channel unit `(e, h)`, every sensor's slot `(es, hs)` and
    /// `cbar`.
    fn discretise(&self, py: Python<'_>, tau: f64, budget: f64) -> PyResult<SlotDiscretisation> {
        let d = run(py, || self.discretisation(tau, budget))?;
        let m = |x: &DMatrix<f64>| to_numpy(py, x.clone()).unbind();
        let nsens = d.n_sensors();
        Ok(SlotDiscretisation {
            e: m(&d.e),
            h: m(&d.h),
            cbar: d.cbar.iter().map(m).collect(),
            es: (0..nsens).map(|i| m(d.e_of(i))).collect(),
            hs: (0..nsens).map(|i| m(d.h_of(i))).collect(),
            tau0: d.tau0,
        })
    }

    /// The [`PeriodTriplet`] `(a, g, h)` of a schedule (its idle tail included).
    #[pyo3(signature = (tau, slots, budget=None))]
    fn period_triplet(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        budget: Option<f64>,
    ) -> PyResult<PeriodTriplet> {
        let slots = self.schedule(&slots)?;
        let t = run(py, || {
            self.disc_for(tau, &slots, budget)?.period_triplet(&slots)
        })?;
        Ok(PeriodTriplet {
            a: to_numpy(py, t.a).unbind(),
            g: to_numpy(py, t.g).unbind(),
            h: to_numpy(py, t.h).unbind(),
        })
    }

    /// The periodic [`SteadyState`] of a schedule (structure-preserving doubling).
    #[pyo3(signature = (tau, slots, tol=1e-12, max_steps=64, budget=None))]
    fn steady_state(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        tol: f64,
        max_steps: usize,
        budget: Option<f64>,
    ) -> PyResult<SteadyState> {
        let slots = self.schedule(&slots)?;
        let opts = options(tol, max_steps)?;
        let (ss, tail) = run(py, || {
            let disc = self.disc_for(tau, &slots, budget)?;
            let ss = steady_state(&disc, &slots, &opts)?;
            let idle = disc.idle(disc.used(&slots))?;
            Ok((ss, (idle, disc.idle_triplet(idle)?)))
        })?;
        let n = self.sys.order();
        let (idle, tail) = tail;
        let tail = tail.unwrap_or_else(|| crate::sampled::Triplet::identity(n));
        Ok(SteadyState {
            boundary: to_numpy(py, ss.boundary).unbind(),
            posteriors: stack(py, &ss.posteriors, n).unbind(),
            priors: stack(py, &ss.priors, n).unbind(),
            steps: ss.steps,
            rel_change: ss.rel_change,
            spectral_radius: ss.spectral_radius,
            residual: ss.residual,
            idle,
            tail_e: to_numpy(py, tail.a).unbind(),
            tail_h: to_numpy(py, tail.h).unbind(),
        })
    }

    /// The [`Propagation`] (priors, posteriors) of one period of slot maps applied to `sigma0`
    /// (the idle tail, if any, follows the last posterior).
    #[pyo3(signature = (tau, slots, sigma0, budget=None))]
    fn propagate(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        sigma0: PyReadonlyArray2<'_, f64>,
        budget: Option<f64>,
    ) -> PyResult<Propagation> {
        let slots = self.schedule(&slots)?;
        let s0 = self.initial_covariance(&sigma0)?;
        let (priors, posts) = run(py, || {
            let disc = self.disc_for(tau, &slots, budget)?;
            disc.check_schedule(&slots)?;
            propagate(&disc, &slots, &s0)
        })?;
        let n = self.sys.order();
        Ok(Propagation {
            priors: stack(py, &priors, n).unbind(),
            posteriors: stack(py, &posts, n).unbind(),
        })
    }

    /// The [`FixedPoint`] `(sigma, periods, rel_change)` of the plain iteration `Σ ← Φ_R(Σ)` from
    /// `sigma0`.
    #[pyo3(signature = (tau, slots, sigma0, tol, max_periods, budget=None))]
    #[allow(clippy::too_many_arguments)]
    fn fixed_point(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        sigma0: PyReadonlyArray2<'_, f64>,
        tol: f64,
        max_periods: usize,
        budget: Option<f64>,
    ) -> PyResult<FixedPoint> {
        let slots = self.schedule(&slots)?;
        let s0 = self.initial_covariance(&sigma0)?;
        let fp = run(py, || {
            let disc = self.disc_for(tau, &slots, budget)?;
            fixed_point(&disc, &slots, &s0, tol, max_periods)
        })?;
        Ok(FixedPoint {
            sigma: to_numpy(py, fp.sigma).unbind(),
            periods: fp.periods,
            rel_change: fp.rel_change,
        })
    }

    /// The exact cost of a schedule (`which` = "boundary" or "average"; `tr(MΣ)` with a weight).
    #[pyo3(signature = (tau, slots, which="boundary", tol=1e-12, max_steps=64, budget=None))]
    #[allow(clippy::too_many_arguments)]
    fn cost(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        which: &str,
        tol: f64,
        max_steps: usize,
        budget: Option<f64>,
    ) -> PyResult<f64> {
        let slots = self.schedule(&slots)?;
        let (obj, opts) = (objective(which)?, options(tol, max_steps)?);
        run(py, || {
            let disc = self.disc_for(tau, &slots, budget)?;
            schedule_cost(&disc, &slots, obj, &opts)
        })
    }

    /// The [`Neighbourhood`] `(current, reassign[r_tot, N], swap[r_tot − 1], rotate[r_tot],
    /// complete, evaluated)` — see `crate::sampled::search::Neighbourhood`; with `time_limit`
    /// (seconds) candidates that would start later are skipped (`+∞`, `complete = False`, not
    /// counted in `evaluated`). `min_counts`/`max_counts` (per sensor) replace `min_count`, and
    /// reassignments beyond the budget cost `+∞`.
    #[pyo3(signature = (tau, slots, which="boundary", min_count=1, tol=1e-12, max_steps=64, time_limit=None, budget=None, min_counts=None, max_counts=None))]
    #[allow(clippy::too_many_arguments)]
    fn neighbourhood(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        which: &str,
        min_count: usize,
        tol: f64,
        max_steps: usize,
        time_limit: Option<f64>,
        budget: Option<f64>,
        min_counts: Option<Vec<usize>>,
        max_counts: Option<Vec<usize>>,
    ) -> PyResult<Neighbourhood> {
        let slots = self.schedule(&slots)?;
        let args = SearchArgs::new(which, tol, max_steps, time_limit)?;
        let limits = self.limits(min_count, min_counts, max_counts)?;
        let nb = run(py, || {
            let disc = self.disc_for(tau, &slots, budget)?;
            neighbourhood_until(&disc, &slots, args.obj, &limits, &args.opts, args.deadline)
        })?;
        Ok(Neighbourhood {
            current: nb.current,
            reassign: to_numpy(py, nb.reassign).unbind(),
            swap: PyArray1::from_vec(py, nb.swap).unbind(),
            rotate: PyArray1::from_vec(py, nb.rotate).unbind(),
            complete: nb.complete,
            evaluated: nb.evaluated,
        })
    }

    /// The [`Screen`] `(current, spectral_radius, reassign[r_tot, N], swap[r_tot − 1],
    /// rotate[r_tot], stein_steps)` of a schedule — see `crate::sampled::sensitivity::Screen`:
    /// the exact cost, the first-order predicted change of every reassignment and adjacent swap
    /// (`+∞`: no-op, a sensor left outside its count limits, or beyond the budget) and the exact
    /// cost of every rotation (`+∞` with idle time). The schedule's star-product tree is kept for
    /// [`Self::candidate_costs`]. With `time_limit` (seconds): `None` once it has passed (checked
    /// before every star product of the tree and between the parts of the screen).
    #[pyo3(signature = (tau, slots, which="boundary", min_count=1, tol=1e-12, max_steps=64, budget=None, min_counts=None, max_counts=None, time_limit=None))]
    #[allow(clippy::too_many_arguments)]
    fn screen(
        &self,
        py: Python<'_>,
        tau: f64,
        slots: PyReadonlyArray1<'_, i64>,
        which: &str,
        min_count: usize,
        tol: f64,
        max_steps: usize,
        budget: Option<f64>,
        min_counts: Option<Vec<usize>>,
        max_counts: Option<Vec<usize>>,
        time_limit: Option<f64>,
    ) -> PyResult<Option<Screen>> {
        let slots = self.schedule(&slots)?;
        let args = SearchArgs::new(which, tol, max_steps, time_limit)?;
        let limits = self.limits(min_count, min_counts, max_counts)?;
        let sc = run(py, || self.screen_kept(tau, &slots, budget, args, &limits))?;
        let Some(sc) = sc else {
            return Ok(None);
        };
        Ok(Some(Screen {
            current: sc.current,
            spectral_radius: sc.spectral_radius,
            reassign: to_numpy(py, sc.reassign).unbind(),
            swap: PyArray1::from_vec(py, sc.swap).unbind(),
            rotate: PyArray1::from_vec(py, sc.rotate).unbind(),
            stein_steps: sc.stein_steps,
        }))
    }

    /// The [`CandidateCosts`] `(costs, complete, evaluated)`: the exact cost of each schedule of
    /// `candidates` (a list of int64 arrays of `r_tot` slots), `+∞` when its steady state does
    /// not exist, evaluated in parallel on the star-product tree of the last schedule screened
    /// (segments it shares are not recomposed; the costs equal [`Self::cost`]'s). With
    /// `time_limit` (seconds) candidates that would start later are skipped (`+∞`). Without
    /// `budget`, the budget is what the first candidate uses. With `incumbent` (boundary
    /// objective) a candidate whose doubling proves its cost above it is cut short (`+∞`).
    #[pyo3(signature = (tau, candidates, which="boundary", tol=1e-12, max_steps=64, time_limit=None, budget=None, incumbent=None))]
    #[allow(clippy::too_many_arguments)]
    fn candidate_costs(
        &self,
        py: Python<'_>,
        tau: f64,
        candidates: &Bound<'_, PyList>,
        which: &str,
        tol: f64,
        max_steps: usize,
        time_limit: Option<f64>,
        budget: Option<f64>,
        incumbent: Option<f64>,
    ) -> PyResult<CandidateCosts> {
        let cands = candidates
            .iter()
            .map(|c| {
                let arr: PyReadonlyArray1<'_, i64> = c.extract()?;
                Ok(self.schedule(&arr)?)
            })
            .collect::<PyResult<Vec<Vec<usize>>>>()?;
        let args = SearchArgs::new(which, tol, max_steps, time_limit)?;
        let Some(first) = cands.first() else {
            return Ok(CandidateCosts {
                costs: PyArray1::from_vec(py, Vec::new()).unbind(),
                complete: true,
                evaluated: 0,
            });
        };
        let r = first.len();
        if let Some((k, c)) = cands.iter().enumerate().find(|(_, c)| c.len() != r) {
            return Err(Error::InvalidInput(format!(
                "candidate {k} has {} slots, candidate 0 has {r}",
                c.len()
            ))
            .into());
        }
        let cc = run(py, || {
            self.candidate_costs_kept(tau, first, &cands, budget, args, incumbent)
        })?;
        Ok(CandidateCosts {
            costs: PyArray1::from_vec(py, cc.costs).unbind(),
            complete: cc.complete,
            evaluated: cc.evaluated,
        })
    }

    /// The [`GreedyPass`] `(slots, sigma)`: one greedy pass over a period of `budget` channel
    /// units (for unit costs the number of slots `r_tot`) from the posterior `sigma0`, with at
    /// least `min_count` samples of every sensor (or `min_counts`, and at most `max_counts`).
    #[pyo3(signature = (tau, budget, sigma0, min_count, min_counts=None, max_counts=None))]
    #[allow(clippy::too_many_arguments)]
    fn greedy_pass(
        &self,
        py: Python<'_>,
        tau: f64,
        budget: f64,
        sigma0: PyReadonlyArray2<'_, f64>,
        min_count: usize,
        min_counts: Option<Vec<usize>>,
        max_counts: Option<Vec<usize>>,
    ) -> PyResult<GreedyPass> {
        let s0 = self.initial_covariance(&sigma0)?;
        let limits = self.limits(min_count, min_counts, max_counts)?;
        let (slots, s) = run(py, || {
            greedy_pass_limits(&*self.discretisation(tau, budget)?, &s0, &limits)
        })?;
        let slots: Vec<i64> = slots.into_iter().map(|i| i as i64).collect();
        Ok(GreedyPass {
            slots: PyArray1::from_vec(py, slots).unbind(),
            sigma: to_numpy(py, s).unbind(),
        })
    }
}
