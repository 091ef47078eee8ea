//! Bindings for `crate::sampled`: the sampled system at a finite period.
//!
//! Why this module is long: one pyclass, `SampledModel`, whose methods each bind one core
//! function, and the caches (discretisation, star-product tree, pending candidate) they share;
//! at the end, the exact schedule search's function and record (`sampled_exact_schedule`).
//!
//! [`PySampledModel`] (`_core.SampledModel`) holds the model `(A, Q = GGᵀ, [ĉ_i])` validated once
//! (shapes, finiteness, symmetry of `Q`) and the discretisation of the last `(tau, r_tot)` it was
//! asked for; its methods take the period `tau` and a schedule `slots` (int64 sensor index per
//! slot), so the schedule search converts and validates the model once, not on every candidate.
//! The Python layer (`capalloc_rs.sampled`) validates schedules and the hypotheses of
//! Proposition 1 and raises the specific exceptions. The two existence tests, which take `(A, C)`
//! rather than the model, stay free functions.

use super::results::{
    AliasingPair, CandidateCosts, FixedPoint, GreedyPass, Neighbourhood, PeriodTriplet,
    Propagation, Screen, SlotDiscretisation, SteadyState,
};
use super::{run, to_matrix, to_numpy};
use crate::sampled::doubling::{fixed_point, propagate, steady_state, DoublingOptions};
use crate::sampled::existence::{aliasing_pair, unobservable_dimension};
use crate::sampled::search::SteadyCost;
use crate::sampled::search::{
    greedy_pass_limits, neighbourhood_until, schedule_cost, CountLimits, Objective,
};
use crate::sampled::sensitivity::{screen_at_until, screen_with_until};
use crate::sampled::star_tree::{candidate_costs, past, Delta, StarTree};
use crate::sampled::{Discretisation, SampledSystem};
use crate::Error;
use nalgebra::DMatrix;
use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray1, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyList;
use pyo3::types::{PyComplex, PyModule};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

type Arr3<'py> = Bound<'py, PyArray3<f64>>;

// Literal defaults in the signatures (shown by Python's text signatures, checked against
// `_core.pyi` by stubtest) equal to the core's constants:
const _: () = assert!(crate::sampled::existence::OBSERVABILITY_RTOL == 1e-10);
const _: () = assert!(crate::sampled::existence::ALIASING_TOL == 1e-8);

/// The last discretisation computed, keyed by `(tau.to_bits(), budget.to_bits())`.
type Cached = Option<((u64, u64), Arc<Discretisation>)>;

/// A star-product tree's key: `(tau, budget)` as bits and the schedule's length.
type TreeKey = (u64, u64, usize);

/// The star-product tree of the last schedule screened.
type CachedTree = Option<(TreeKey, StarTree)>;

/// The cheapest candidate of the last `candidate_costs` on the kept tree: the tree's schedule
/// then (`base`), the candidate, the segments it recomposed and its steady state — so that the
/// screen of the accepted candidate neither recomposes nor doubles again.
struct Pending {
    key: TreeKey,
    base: Vec<usize>,
    slots: Vec<usize>,
    delta: Delta,
    steady: SteadyCost,
}

/// The sampled model, validated once, with the discretisation of the last `(tau, r_tot)` kept.
/// Immutable from Python; the cache is an implementation detail (results never depend on it: a
/// discretisation is a pure function of `(A, Q, [ĉ_i], tau, r_tot)`).
#[pyclass(frozen, name = "SampledModel", module = "capalloc_rs._core")]
pub struct PySampledModel {
    sys: SampledSystem,
    last: Mutex<Cached>,
    tree: Mutex<CachedTree>,
    pending: Mutex<Option<Pending>>,
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
    fn disc_for(
        &self,
        tau: f64,
        slots: &[usize],
        budget: Option<f64>,
    ) -> crate::Result<Arc<Discretisation>> {
        self.discretisation(tau, self.budget(slots, budget))
    }

    /// The per-sensor count limits: `min_counts`/`max_counts` when given, else `min_count` for
    /// every sensor and no cap.
    fn limits(
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

    fn pending_lock(&self) -> std::sync::MutexGuard<'_, Option<Pending>> {
        self.pending.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The screen of `slots` when they are the pending cheapest candidate of the last
    /// `candidate_costs` on the kept tree: the tree adopts its segments and its steady state is
    /// reused. `None` otherwise (the pending candidate is dropped either way).
    fn screen_pending(
        &self,
        disc: &Discretisation,
        tau: f64,
        slots: &[usize],
        obj: Objective,
        limits: &CountLimits,
        deadline: Option<Instant>,
    ) -> Option<crate::Result<Option<crate::sampled::sensitivity::Screen>>> {
        let key = (tau.to_bits(), disc.budget.to_bits(), slots.len());
        let p = self.pending_lock().take()?;
        let mut guard = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        match guard.as_mut() {
            Some((k, tree))
                if *k == key && p.key == key && p.slots == slots && tree.slots() == p.base =>
            {
                tree.adopt(slots, p.delta);
                let st = &p.steady;
                Some(screen_at_until(
                    disc,
                    slots,
                    &st.sigma,
                    &st.monodromy,
                    st.rho,
                    obj,
                    limits,
                    deadline,
                ))
            }
            _ => None,
        }
    }

    /// Runs `f` on the star-product tree of `(tau, slots)`: the kept tree moved to `slots` when
    /// it was made for the same `(tau, r_tot)`, else a new one (kept for the next call). A tree
    /// whose update failed half-way (or reached `deadline`: `Error::Interrupted`, see
    /// `star_tree::check_deadline`) is dropped, never reused.
    fn with_tree<T>(
        &self,
        disc: &Discretisation,
        tau: f64,
        slots: &[usize],
        deadline: Option<Instant>,
        f: impl FnOnce(&StarTree) -> crate::Result<T>,
    ) -> crate::Result<T> {
        let key = (tau.to_bits(), disc.budget.to_bits(), slots.len());
        let mut guard = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        let tree = match guard.take() {
            Some((k, mut t)) if k == key => {
                t.update_until(disc, slots, deadline)?;
                t
            }
            _ => StarTree::new_until(disc, slots, deadline)?.ok_or_else(|| {
                Error::Interrupted("the time limit of the schedule search".into())
            })?,
        };
        let out = f(&tree);
        *guard = Some((key, tree));
        out
    }

    /// The schedule as sensor indices, checked against the model.
    fn schedule(&self, slots: &PyReadonlyArray1<'_, i64>) -> crate::Result<Vec<usize>> {
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
    fn initial_covariance(
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

fn stack<'py>(py: Python<'py>, ms: &[DMatrix<f64>], n: usize) -> Arr3<'py> {
    Array3::from_shape_fn((ms.len(), n, n), |(l, i, j)| ms[l][(i, j)]).into_pyarray(py)
}

fn objective(which: &str) -> crate::Result<Objective> {
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
fn deadline_of(time_limit: Option<f64>) -> crate::Result<Option<Instant>> {
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
struct SearchArgs {
    obj: Objective,
    opts: DoublingOptions,
    deadline: Option<Instant>,
}

impl SearchArgs {
    /// Checks `which`, `tol`, `max_steps` and `time_limit` (seconds from now; `None`: none).
    fn new(
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

fn options(tol: f64, max_steps: usize) -> crate::Result<DoublingOptions> {
    if !(tol.is_finite() && tol > 0.0) {
        return Err(Error::InvalidInput(format!(
            "tol must be positive and finite, got {tol}"
        )));
    }
    Ok(DoublingOptions { tol, max_steps })
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
        let SearchArgs {
            obj,
            opts,
            deadline,
        } = SearchArgs::new(which, tol, max_steps, time_limit)?;
        let limits = self.limits(min_count, min_counts, max_counts)?;
        let sc = run(py, || {
            let disc = self.disc_for(tau, &slots, budget)?;
            disc.check_schedule(&slots)?;
            if let Some(sc) = self.screen_pending(&disc, tau, &slots, obj, &limits, deadline) {
                return sc;
            }
            let sc = past(self.with_tree(&disc, tau, &slots, deadline, |tree| {
                screen_with_until(
                    &disc,
                    &slots,
                    &tree.root(&disc)?,
                    obj,
                    &limits,
                    &opts,
                    deadline,
                )
            }))?;
            Ok(sc.flatten())
        })?;
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
        let SearchArgs {
            obj,
            opts,
            deadline,
        } = SearchArgs::new(which, tol, max_steps, time_limit)?;
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
            let disc = self.disc_for(tau, first, budget)?;
            let key = (tau.to_bits(), disc.budget.to_bits(), r);
            let guard = self.tree.lock().unwrap_or_else(|e| e.into_inner());
            let mut cc = match &*guard {
                Some((k, tree)) if *k == key => {
                    let mut cc =
                        candidate_costs(&disc, tree, &cands, obj, &opts, deadline, incumbent)?;
                    *self.pending_lock() = cc.best.take().map(|(j, delta, steady)| Pending {
                        key,
                        base: tree.slots().to_vec(),
                        slots: cands[j].clone(),
                        delta,
                        steady,
                    });
                    cc
                }
                _ => {
                    drop(guard);
                    *self.pending_lock() = None;
                    let tree = StarTree::new(&disc, first)?;
                    candidate_costs(&disc, &tree, &cands, obj, &opts, deadline, incumbent)?
                }
            };
            cc.best = None;
            Ok(cc)
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

/// Dimension of the unobservable subspace of `(A, C)`, output `y = Cᵀx`.
#[pyfunction]
#[pyo3(signature = (a, c, rtol=1e-10))]
fn sampled_unobservable_dimension(
    py: Python<'_>,
    a: PyReadonlyArray2<'_, f64>,
    c: PyReadonlyArray2<'_, f64>,
    rtol: f64,
) -> PyResult<usize> {
    let (a, c) = (to_matrix(&a), to_matrix(&c));
    run(py, || {
        crate::linalg::dense::check_finite("A", &a)?;
        crate::linalg::dense::check_finite("C", &c)?;
        unobservable_dimension(&a, &c, rtol)
    })
}

/// The [`AliasingPair`] of eigenvalues of `A` aliased by the period `tau`, or `None`.
#[pyfunction]
#[pyo3(signature = (a, tau, tol=1e-8))]
fn sampled_aliasing_pair(
    py: Python<'_>,
    a: PyReadonlyArray2<'_, f64>,
    tau: f64,
    tol: f64,
) -> PyResult<Option<AliasingPair>> {
    let a = to_matrix(&a);
    let pair = run(py, || aliasing_pair(&a, tau, tol))?;
    Ok(pair.map(|((r1, i1), (r2, i2))| AliasingPair {
        first: PyComplex::from_doubles(py, r1, i1).unbind(),
        second: PyComplex::from_doubles(py, r2, i2).unbind(),
    }))
}

pub(super) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySampledModel>()?;
    m.add_function(wrap_pyfunction!(sampled_unobservable_dimension, m)?)?;
    m.add_function(wrap_pyfunction!(sampled_aliasing_pair, m)?)?;
    m.add_class::<ExactSchedule>()?;
    m.add_function(wrap_pyfunction!(sampled_exact_schedule, m)?)?;
    Ok(())
}

// ---- The exact schedule search of equal-cost slots (crate::sampled::exact_dfs). ----

/// The outcome of `sampled_exact_schedule`: the best schedule found below the incumbent
/// (`None`: never beaten), its exact cost, the proven lower bound over the schedules of that
/// length, the nodes bounded and whether the tree was exhausted.
#[pyclass(frozen, get_all, module = "capalloc_rs._core")]
pub(crate) struct ExactSchedule {
    pub slots: Option<Vec<usize>>,
    pub eta_bar: f64,
    pub lower_bound: f64,
    pub nodes: usize,
    pub complete: bool,
}

/// The branch-and-bound over the schedules of `length` equal-cost slots of `model`
/// (`crate::sampled::exact_dfs`): `relaxed[mask − 1]` is the relaxed sensor `ĉ_𝒜` (n×k,
/// `τ ĉ_𝒜ĉ_𝒜ᵀ ⪰ c̄_ic̄_iᵀ` for every sensor `i` in the bit mask), `incumbent` the exact cost to
/// beat, `symmetric` keeps `R_l ≥ R_1` (the average figure without idle time); stops after
/// `node_limit` nodes or `time_limit` seconds.
#[pyfunction]
#[pyo3(signature = (model, tau, length, which, relaxed, min_counts, max_counts, incumbent, symmetric, node_limit, time_limit=None, budget=None))]
#[allow(clippy::too_many_arguments)]
fn sampled_exact_schedule(
    py: Python<'_>,
    model: &Bound<'_, PySampledModel>,
    tau: f64,
    length: usize,
    which: &str,
    relaxed: Vec<PyReadonlyArray2<'_, f64>>,
    min_counts: Vec<usize>,
    max_counts: Vec<usize>,
    incumbent: f64,
    symmetric: bool,
    node_limit: usize,
    time_limit: Option<f64>,
    budget: Option<f64>,
) -> PyResult<ExactSchedule> {
    use crate::sampled::exact_dfs::{exact_schedule, ExactProblem};
    let objective = objective(which)?;
    let deadline = deadline_of(time_limit)?;
    let factors: Vec<DMatrix<f64>> = relaxed.iter().map(to_matrix).collect();
    let model = model.get();
    if model.sys.costs().iter().any(|&b| b != model.sys.costs()[0]) {
        return Err(Error::InvalidInput(
            "the exact schedule kernel needs equal sample costs".into(),
        )
        .into());
    }
    if length == 0 || length > crate::sampled::MAX_SLOTS_PER_PERIOD {
        return Err(
            Error::InvalidInput(format!("length must be in 1..=2^24, got {length}")).into(),
        );
    }
    let out = run(py, || {
        let slots = vec![0; length];
        let disc = model.disc_for(tau, &slots, budget)?;
        let sq = tau.sqrt();
        let problem = ExactProblem {
            disc: &disc,
            objective,
            len: length,
            lo: min_counts,
            hi: max_counts,
            relaxed: factors.iter().map(|c| c * sq).collect(),
            symmetric,
            incumbent,
            node_limit,
            deadline,
        };
        exact_schedule(&problem)
    })?;
    Ok(ExactSchedule {
        slots: out.slots,
        eta_bar: out.cost,
        lower_bound: out.lower_bound,
        nodes: out.nodes,
        complete: out.complete,
    })
}
