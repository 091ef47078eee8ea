//! The proven optimal schedule of `L` equal-cost slots: depth-first branch-and-bound over the
//! slot assignments, each node bounded by relaxing its free slots (the Python module
//! `capalloc_rs.sampled.exact` states the tree and proves the bound; this is its kernel).
//!
//! **Maps.** Every slot is a Riccati triplet (`φ_i`, predict over `bτ₀` then update with `c̄_i`);
//! the relaxed slot of an allowed set `𝒜` is `ρ_𝒜 = U_J ∘ P_{bτ₀}` with `J ⪰ c̄_ic̄_iᵀ` for all
//! `i ∈ 𝒜` (its factor is given by the caller, one per allowed set as a bit mask), so
//! `ρ_𝒜 ⪯ φ_i` pointwise. A node keeps the composition of its fixed slots and the powers
//! `ρ_𝒜^k` are composed once per allowed set.
//!
//! **Order of the slots.** For the boundary figure the node fixes the *last* `d` slots
//! `R_{L−d+1} … R_L` (a suffix): its relaxed period is `Ψ = T ∘ φ_{R_L} ∘ … ∘ φ_{R_{L−d+1}} ∘
//! ρ^{L−d}`, so the slots nearest the period boundary, which weigh most on `Σ̄`, are exact
//! from the first levels on. For the average figure it fixes the first `d` slots (a prefix),
//! `Ψ = T ∘ ρ^{L−d} ∘ φ_{R_d} ∘ … ∘ φ_{R_1}`, and with the rotation symmetry keeps
//! `R_l ≥ R_1`. Both trees hold every schedule (with the symmetry, one of each rotation class).
//!
//! **Bound from the parent.** By the relaxation theorem every fixed point `Σ̄_R` of a
//! completion `R` of a node satisfies `Σ̄_R ⪰ X` for the node's bound state `X`; a child's
//! completions are completions of its parent (its allowed set is a subset), so the parent's `X_p`
//! is `⪯ Σ̄_R` for them, and by induction (`Ψ ⪯ Φ_R` and monotonicity)
//! `Ψ^k(X_p) ⪯ Φ_R^k(Σ̄_R) = Σ̄_R` for every `k`: **every iterate from `X_p` is a lower bound**.
//! The root starts from `X = 0`. The iterates `Ψ^{2^k}(X_p)` (doubling of `Ψ`'s triplet) are
//! computed until they settle; the node is pruned as soon as one reaches the incumbent, so most
//! pruned nodes cost one application of `Ψ`. An overflowing doubling stops at the last finite
//! iterate (still a bound). The average figure's bound is the mean of `tr(M ·)` of the
//! posteriors of `Ψ`'s slots from `X` (each `⪯` the same posterior of `R`).
//!
//! **Leaves** (all slots fixed) are costed exactly ([`schedule_cost`], `+∞` without a steady
//! state). Every bound is lowered by the relative `BOUND_RTOL` before it is compared.

use super::doubling::DoublingOptions;
use super::search::{schedule_cost, Objective};
use super::{Discretisation, Triplet};
use crate::linalg::dense::norm_fro;
use crate::{Error, Result};
use nalgebra::DMatrix;
use std::collections::HashMap;
use std::time::Instant;

/// Relative margin subtracted from every bound (rounding of the maps), as in the Python layer.
pub const BOUND_RTOL: f64 = 1e-9;
/// Most doubling steps of a node's bound.
const MAX_DOUBLINGS: usize = 64;
/// A node's iterates have settled when they change by less than this, relatively.
const SETTLED: f64 = 1e-10;
/// Most sensors (allowed sets are bit masks of a `u32`).
pub const MAX_SENSORS: usize = 16;

/// `X ↦ (X + Xᵀ)/2`.
fn sym(x: DMatrix<f64>) -> DMatrix<f64> {
    (&x + x.transpose()) * 0.5
}

/// The star product `t2 ∘ t1` of [`Triplet::then`] written with `V = I + H₁G₂ = Wᵀ` and the
/// push-through identities (`W⁻ᵀ = V⁻¹`, `H₁W⁻¹ = V⁻¹H₁`, `W⁻¹G₂ = G₂V⁻¹`): one LU of `V`, one
/// solve with `2n` right-hand sides, no transposed solve (the kernel's matrices are small).
fn star(t1: &Triplet, t2: &Triplet) -> Result<Triplet> {
    let n = t1.order();
    let v = DMatrix::identity(n, n) + &t1.h * &t2.g;
    let lu = v.lu();
    let mut rhs = DMatrix::zeros(n, 2 * n);
    rhs.columns_mut(0, n).copy_from(&t1.a);
    rhs.columns_mut(n, n).copy_from(&t1.h);
    if !lu.solve_mut(&mut rhs) {
        return Err(Error::Convergence(
            "star product: I + H₁G₂ is singular (overflow or non-finite triplet)".into(),
        ));
    }
    let ya = rhs.columns(0, n);
    let yh = rhs.columns(n, n);
    let a = &t2.a * ya;
    let g = sym(&t1.g + t1.a.transpose() * (&t2.g * ya));
    let h = sym(&t2.h + &t2.a * (yh * t2.a.transpose()));
    let out = Triplet { a, g, h };
    if !out.is_finite() {
        return Err(Error::Convergence("star product overflowed".into()));
    }
    Ok(out)
}

/// `T(X) = H + A X (I + G X)⁻¹ Aᵀ = H + A (I + X G)⁻¹ X Aᵀ` (symmetric `X`): one LU, one solve.
fn apply(t: &Triplet, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
    let n = t.order();
    let v = DMatrix::identity(n, n) + x * &t.g;
    let y = v.lu().solve(x).ok_or_else(|| {
        Error::Convergence("I + XG is singular (overflow or non-finite state)".into())
    })?;
    Ok(sym(&t.h + &t.a * (y * t.a.transpose())))
}

/// The problem of one length `L`.
pub struct ExactProblem<'a> {
    /// The discretisation (every sensor of the same cost).
    pub disc: &'a Discretisation,
    /// The figure minimised.
    pub objective: Objective,
    /// The number of slots `L`.
    pub len: usize,
    /// Least count of each sensor.
    pub lo: Vec<usize>,
    /// Largest count of each sensor.
    pub hi: Vec<usize>,
    /// The relaxed slot's scaled factor `c̄_𝒜` (`c̄_𝒜c̄_𝒜ᵀ ⪰ J ⪰ c̄_ic̄_iᵀ`, `i ∈ 𝒜`) by mask − 1.
    pub relaxed: Vec<DMatrix<f64>>,
    /// Keep only `R_l ≥ R_1` (the average figure without idle time).
    pub symmetric: bool,
    /// The incumbent's exact cost.
    pub incumbent: f64,
    /// Most nodes bounded.
    pub node_limit: usize,
    /// Stop at this time.
    pub deadline: Option<Instant>,
}

/// The outcome of [`exact_schedule`].
#[derive(Debug, Clone)]
pub struct ExactOutcome {
    /// The best schedule found below the incumbent (`None`: the incumbent was never beaten).
    pub slots: Option<Vec<usize>>,
    /// Its exact cost (the incumbent's if `slots` is `None`).
    pub cost: f64,
    /// `min(cost, bounds of the open nodes)`: no schedule of `L` slots costs less.
    pub lower_bound: f64,
    /// Nodes bounded or costed.
    pub nodes: usize,
    /// Whether the tree was exhausted (then the best schedule is optimal among `L` slots).
    pub complete: bool,
}

/// A node: its fixed slots (in the order they were fixed), counts, the composition of its
/// fixed slots, its bound state `X` and its bound.
struct Node {
    fixed: Vec<usize>,
    counts: Vec<usize>,
    map: Triplet,
    x: DMatrix<f64>,
    bound: f64,
}

/// The search's state: the problem, the slot and relaxed triplets, the tail, the powers of the
/// relaxed slots, the incumbent and the nodes counted.
struct Search<'a> {
    p: &'a ExactProblem<'a>,
    tail: Option<Triplet>,
    relaxed: Vec<Triplet>,
    powers: HashMap<u32, Vec<Triplet>>,
    backward: bool,
    best: Option<Vec<usize>>,
    best_cost: f64,
    nodes: usize,
}

/// Whether an error means "no finite limit" (the bound is then the last finite iterate, or a
/// leaf has no steady state) rather than a failure to report.
fn overflow(e: &Error) -> bool {
    matches!(e, Error::Convergence(_) | Error::NonFinite(_))
}

impl<'a> Search<'a> {
    fn new(p: &'a ExactProblem<'a>) -> Result<Self> {
        let n_sensors = p.disc.n_sensors();
        if n_sensors > MAX_SENSORS || p.relaxed.len() != (1usize << n_sensors) - 1 {
            return Err(Error::InvalidInput(format!(
                "relaxed must hold one factor per non-empty set of the {n_sensors} sensors \
                 (at most {MAX_SENSORS} sensors), got {}",
                p.relaxed.len()
            )));
        }
        if p.lo.len() != n_sensors || p.hi.len() != n_sensors || p.len == 0 {
            return Err(Error::InvalidInput(
                "min_counts and max_counts need one entry per sensor, and length ≥ 1".into(),
            ));
        }
        let (e, h) = (p.disc.e_of(0), p.disc.h_of(0));
        let relaxed = p
            .relaxed
            .iter()
            .map(|c| Triplet::slot(e, h, c))
            .collect::<Result<Vec<_>>>()?;
        let tail = p.disc.tail(&vec![0; p.len])?;
        Ok(Search {
            p,
            tail,
            relaxed,
            powers: HashMap::new(),
            backward: p.objective == Objective::Boundary,
            best: None,
            best_cost: p.incumbent,
            nodes: 0,
        })
    }

    /// `ρ_𝒜^k` for the allowed set `mask`.
    fn power(&mut self, mask: u32, k: usize) -> Result<&Triplet> {
        let rho = &self.relaxed[mask as usize - 1];
        let n = self.p.disc.order();
        let pw = self
            .powers
            .entry(mask)
            .or_insert_with(|| vec![Triplet::identity(n)]);
        while pw.len() <= k {
            let next = star(&pw[pw.len() - 1], rho)?;
            pw.push(next);
        }
        Ok(&pw[k])
    }

    /// The allowed set of a node: sensors below their cap (from `first` on).
    fn allowed(&self, counts: &[usize], first: usize) -> u32 {
        (first..counts.len())
            .filter(|&i| counts[i] < self.p.hi[i])
            .fold(0, |m, i| m | (1 << i))
    }

    /// The node's relaxed period `Ψ` (module docstring) from the composition of its fixed slots.
    fn psi(&mut self, map: &Triplet, free: usize, mask: u32) -> Result<Triplet> {
        let core = if free == 0 {
            map.clone()
        } else if self.backward {
            star(self.power(mask, free)?, map)?
        } else {
            star(map, self.power(mask, free)?)?
        };
        match &self.tail {
            None => Ok(core),
            Some(t) => star(&core, t),
        }
    }

    /// The figure's value at the bound state `x`: `tr(M x)` for the boundary; for the average
    /// the mean of `tr(M ·)` over the posteriors of `Ψ`'s slots started from `x`.
    fn value(&self, x: &DMatrix<f64>, fixed: &[usize], mask: u32) -> Result<f64> {
        if self.p.objective == Objective::Boundary {
            return Ok(self.p.disc.weighted_trace(x));
        }
        let free = self.p.len - fixed.len();
        let rho = (free > 0).then(|| &self.relaxed[mask as usize - 1]);
        let exact = fixed.iter().map(|&i| &self.p.disc.slots[i]);
        let relaxed = (0..free).filter_map(|_| rho);
        let mut s = x.clone();
        let mut sum = 0.0;
        for t in exact.chain(relaxed) {
            s = apply(t, &s)?;
            sum += self.p.disc.weighted_trace(&s);
        }
        Ok(sum / self.p.len as f64)
    }

    /// The node's bound and bound state from the parent's state `x0` (module docstring),
    /// lowered by `BOUND_RTOL`, given the first iterate `x1 = Ψ(x0)`: `Ψ` is composed and
    /// doubled only if `x1` does not already reach the incumbent.
    fn bound(
        &mut self,
        map: &Triplet,
        fixed: &[usize],
        mask: u32,
        x0: &DMatrix<f64>,
        x1: DMatrix<f64>,
    ) -> Result<(f64, DMatrix<f64>)> {
        let lowered = |v: f64| v * (1.0 - BOUND_RTOL);
        let v1 = lowered(self.value(&x1, fixed, mask)?);
        if v1 >= self.best_cost {
            return Ok((v1, x1));
        }
        let free = self.p.len - fixed.len();
        let mut t = match self.psi(map, free, mask) {
            Ok(t) => t,
            Err(e) if overflow(&e) => return Ok((v1, x1)),
            Err(e) => return Err(e),
        };
        let boundary = self.p.objective == Objective::Boundary;
        let mut x = x1;
        for _ in 0..MAX_DOUBLINGS {
            let next = match star(&t, &t) {
                Ok(nt) => nt,
                Err(e) if overflow(&e) => break,
                Err(e) => return Err(e),
            };
            let nx = apply(&next, x0)?;
            let settled = norm_fro(&(&nx - &x)) <= SETTLED * norm_fro(&nx);
            t = next;
            x = nx;
            if settled {
                break;
            }
            // The boundary figure's value is one trace: test every iterate against the incumbent.
            if boundary && lowered(self.value(&x, fixed, mask)?) >= self.best_cost {
                break;
            }
        }
        let v = lowered(self.value(&x, fixed, mask)?);
        Ok((v.max(v1), x))
    }

    /// `Ψ(x0)` of the child fixing sensor `i` (`pre`: `ρ^{free}(x0)` backwards, the parent's
    /// fixed slots applied to `x0` forwards), by applying the maps one after the other.
    fn first_iterate(
        &mut self,
        node: &Node,
        i: usize,
        pre: &DMatrix<f64>,
        free: usize,
        mask: u32,
    ) -> Result<DMatrix<f64>> {
        let phi = &self.p.disc.slots[i];
        let core = if self.backward {
            apply(&node.map, &apply(phi, pre)?)?
        } else if free == 0 {
            apply(phi, pre)?
        } else {
            let y = apply(phi, pre)?;
            apply(self.power(mask, free)?, &y)?
        };
        Ok(match &self.tail {
            None => core,
            Some(t) => apply(t, &core)?,
        })
    }

    /// The slots of a full node in time order.
    fn schedule(&self, fixed: &[usize]) -> Vec<usize> {
        let mut s = fixed.to_vec();
        if self.backward {
            s.reverse();
        }
        s
    }

    /// Costs a full node exactly (its first iterate `x1 = Φ_R(x0)` bounds its cost: it is
    /// costed only below the incumbent) and keeps it if it beats the incumbent.
    fn leaf(&mut self, fixed: &[usize], x1: &DMatrix<f64>) -> Result<()> {
        let v1 = self.value(x1, fixed, 0)? * (1.0 - BOUND_RTOL);
        if v1 >= self.best_cost {
            return Ok(());
        }
        let slots = self.schedule(fixed);
        let opts = DoublingOptions::default();
        let cost = match schedule_cost(self.p.disc, &slots, self.p.objective, &opts) {
            Ok(c) => c,
            Err(e) if overflow(&e) => f64::INFINITY,
            Err(e) => return Err(e),
        };
        if cost < self.best_cost {
            self.best_cost = cost;
            self.best = Some(slots);
        }
        Ok(())
    }

    /// Whether the minima can still be met with `free` slots left.
    fn can_meet_minima(&self, counts: &[usize], free: usize) -> bool {
        let owed: usize = (0..counts.len())
            .map(|i| self.p.lo[i].saturating_sub(counts[i]))
            .sum();
        owed <= free
    }

    /// The state every child's first iterate starts from: `ρ^{free}(x)` of the allowed set
    /// `mask` backwards (kept per mask in `pre`), the parent's fixed slots applied to `x`
    /// forwards (one for all children).
    fn pre(
        &mut self,
        node: &Node,
        free: usize,
        mask: u32,
        pre: &mut HashMap<u32, DMatrix<f64>>,
    ) -> Result<DMatrix<f64>> {
        let key = if self.backward { mask } else { 0 };
        if let Some(y) = pre.get(&key) {
            return Ok(y.clone());
        }
        let y = if self.backward {
            if free == 0 {
                node.x.clone()
            } else {
                apply(self.power(mask, free)?, &node.x)?
            }
        } else {
            apply(&node.map, &node.x)?
        };
        pre.insert(key, y.clone());
        Ok(y)
    }

    /// The children of a node still below the incumbent, the least bound last (full children
    /// are costed as leaves).
    fn children(&mut self, node: &Node) -> Result<Vec<Node>> {
        let d = node.fixed.len();
        let sym = self.p.symmetric;
        let first = if sym && d > 0 { node.fixed[0] } else { 0 };
        let free = self.p.len - d - 1;
        let mut pre = HashMap::new();
        let mut out = Vec::new();
        for i in first..node.counts.len() {
            if node.counts[i] >= self.p.hi[i] {
                continue;
            }
            let mut counts = node.counts.clone();
            counts[i] += 1;
            if !self.can_meet_minima(&counts, free) {
                continue;
            }
            let mut fixed = node.fixed.clone();
            fixed.push(i);
            let mask = self.allowed(&counts, if sym { fixed[0] } else { 0 });
            if free > 0 && mask == 0 {
                continue;
            }
            self.nodes += 1;
            let y = self.pre(node, free, mask, &mut pre)?;
            let x1 = self.first_iterate(node, i, &y, free, mask)?;
            if free == 0 {
                self.leaf(&fixed, &x1)?;
                continue;
            }
            let phi = &self.p.disc.slots[i];
            let map = if self.backward {
                star(phi, &node.map)?
            } else {
                star(&node.map, phi)?
            };
            let (bound, x) = self.bound(&map, &fixed, mask, &node.x, x1)?;
            if bound < self.best_cost {
                out.push(Node {
                    fixed,
                    counts,
                    map,
                    x,
                    bound,
                });
            }
        }
        out.sort_by(|a, b| b.bound.total_cmp(&a.bound));
        Ok(out)
    }

    fn stopped(&self) -> bool {
        self.nodes >= self.p.node_limit || self.p.deadline.is_some_and(|d| Instant::now() >= d)
    }
}

/// The branch-and-bound of the module docstring over the schedules of `p.len` slots.
///
/// Errors: invalid input (factor count, limits), cancellation ([`Error::Interrupted`]), and
/// the failures of the maps other than overflow.
pub fn exact_schedule(p: &ExactProblem<'_>) -> Result<ExactOutcome> {
    let mut s = Search::new(p)?;
    let n = p.disc.order();
    let counts = vec![0; p.disc.n_sensors()];
    let root_mask = s.allowed(&counts, 0);
    let zero = DMatrix::zeros(n, n);
    let mut stack = Vec::new();
    if root_mask != 0 && s.can_meet_minima(&counts, p.len) {
        let id = Triplet::identity(n);
        s.nodes += 1;
        let (bound, x) = match s.psi(&id, p.len, root_mask) {
            Ok(t) => {
                let x1 = apply(&t, &zero)?;
                s.bound(&id, &[], root_mask, &zero, x1)?
            }
            Err(e) if overflow(&e) => (f64::INFINITY, zero.clone()),
            Err(e) => return Err(e),
        };
        stack.push(Node {
            fixed: Vec::new(),
            counts,
            map: id,
            x,
            bound,
        });
    }
    // Each pop fixes one more slot of a node; the node limit bounds the pops.
    while let Some(node) = stack.pop() {
        crate::cancel::check("the exact schedule search")?;
        if s.stopped() {
            stack.push(node);
            break;
        }
        if node.bound >= s.best_cost {
            continue;
        }
        let kids = s.children(&node)?;
        let best = s.best_cost;
        stack.extend(kids.into_iter().filter(|c| c.bound < best));
    }
    let open: Vec<f64> = stack
        .iter()
        .map(|nd| nd.bound)
        .filter(|&b| b < s.best_cost)
        .collect();
    Ok(ExactOutcome {
        slots: s.best,
        cost: s.best_cost,
        lower_bound: open.iter().copied().fold(s.best_cost, f64::min),
        nodes: s.nodes,
        complete: open.is_empty(),
    })
}
