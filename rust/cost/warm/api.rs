//! The warm-started constructors: [`Evaluation::warm`], [`Evaluation::warm_from_sigma`],
//! [`Evaluation::shared_warm`], [`Adjoint::warm_evaluation`] and [`CostPoint::warm`].

use super::{solve, Problem, WarmInfo};
use crate::cost::{rate_factor, solve_sigma, Adjoint, CostOptions, CostPoint, Evaluation, Handle};
use crate::linalg::sylvester::Lyapunov;
use crate::network::Network;
use crate::{Error, Result};
use nalgebra::DMatrix;
use std::sync::Arc;

impl<'a> Evaluation<'a> {
    /// Solves the CARE at `r` starting from the solution of a nearby evaluation `from` (of the
    /// same network): Newton–Kleinman from `from.sigma()`, each step one real Schur form of the
    /// `n × n` closed loop and one Lyapunov solve, falling back to the cold solve of
    /// [`Evaluation::new`] when the start is not stabilising, the corrections do not contract, the
    /// result cannot be certified, or after [`WarmParams::max_steps`](super::WarmParams::max_steps) steps (see the `warm`
    /// module documentation). Same accuracy and error bounds as [`Evaluation::new`];
    /// [`warm_info`](Self::warm_info) says what happened. The closed loop's Schur form is kept for
    /// the [`adjoint`](Self::adjoint).
    pub fn warm(
        net: &'a Network,
        r: &[f64],
        opts: &CostOptions,
        from: &Evaluation<'_>,
    ) -> Result<Self> {
        Self::warm_with_handle(
            Handle::Borrowed(net),
            r,
            opts,
            from.sigma(),
            from.factor.as_deref(),
        )
    }

    /// [`warm`](Self::warm) from any symmetric `n × n` starting matrix `sigma0` (e.g. a
    /// prediction). A start that is not finite or not stabilising falls back to the cold solve.
    pub fn warm_from_sigma(
        net: &'a Network,
        r: &[f64],
        opts: &CostOptions,
        sigma0: &DMatrix<f64>,
    ) -> Result<Self> {
        Self::warm_with_handle(Handle::Borrowed(net), r, opts, sigma0, None)
    }

    fn warm_with_handle(
        net: Handle<'a, Network>,
        r: &[f64],
        opts: &CostOptions,
        sigma0: &DMatrix<f64>,
        start_factor: Option<&Lyapunov>,
    ) -> Result<Self> {
        net.check_rates(r)?;
        let n = net.order();
        if sigma0.shape() != (n, n) {
            return Err(Error::Shape(format!(
                "the warm start must be {n}×{n} (the network's order), got {}×{}",
                sigma0.nrows(),
                sigma0.ncols()
            )));
        }
        let w = net.weight_unchecked(r);
        let b = rate_factor(&net, r);
        let mut info = WarmInfo {
            fallback: None,
            steps: 0,
            factorizations: 0,
            predicted: false,
            chord_steps: 0,
        };
        let problem = Problem {
            net: &net,
            r,
            w: &w,
            b: &b,
        };
        match solve(&problem, sigma0, start_factor, &opts.warm, &mut info)? {
            Ok(ws) => Ok(Self::assemble(
                net,
                r,
                w,
                ws.sol,
                Some(Arc::new(ws.factor)),
                Some(info),
            )),
            Err(reason) => {
                info.fallback = Some(reason);
                let (sol, w) = solve_sigma(&net, r, opts)?;
                Ok(Self::assemble(net, r, w, sol, None, Some(info)))
            }
        }
    }
}

impl Evaluation<'static> {
    /// [`Evaluation::warm_from_sigma`] for a shared network.
    pub fn shared_warm(
        net: Arc<Network>,
        r: &[f64],
        opts: &CostOptions,
        sigma0: &DMatrix<f64>,
    ) -> Result<Self> {
        Self::warm_with_handle(Handle::Shared(net), r, opts, sigma0, None)
    }
}

impl<'a> Adjoint<'_, 'a> {
    /// The evaluation at `r` of the same network, warm-started from this point
    /// ([`Evaluation::warm`]) with the tangent predictor: the first correction uses this point's
    /// factored closed loop (one solve, no factorisation), so that from a point 1 % away one
    /// Schur form fewer is needed.
    pub fn warm_evaluation(&self, r: &[f64], opts: &CostOptions) -> Result<Evaluation<'a>> {
        let ev = self.evaluation();
        Evaluation::warm_with_handle(
            ev.net.clone(),
            r,
            opts,
            ev.sigma(),
            Some(self.closed_loop_factor()),
        )
    }
}

impl CostPoint {
    /// The evaluation point at `r` of the same network, warm-started from this one
    /// ([`Adjoint::warm_evaluation`]); then the adjoint on the kept Schur form.
    pub fn warm(&self, r: &[f64], opts: &CostOptions) -> Result<Self> {
        self.warm_evaluation(r, opts)?.into_adjoint()
    }
}
