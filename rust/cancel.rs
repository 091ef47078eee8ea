//! Cooperative cancellation of long computations (Ctrl-C from Python, time limits).
//!
//! A [`Token`] is a shared flag. The caller that wants to be able to stop a computation creates a
//! token, runs the computation inside [`with_token`] and calls [`Token::cancel`] from another
//! thread; the long loops of the crate (QR sweeps, Hessenberg panels, Bartels–Stewart blocks,
//! squarings, doubling steps, schedule-search candidates, batch items, Hessian columns) call
//! [`check`] once per iteration and return [`Error::Interrupted`] as soon as the flag is set. Without a token (the
//! default) [`check`] is a thread-local read and never fails.
//!
//! The token is installed per thread. Parallel code (rayon) captures [`current`] before it fans
//! out and re-installs it on the worker with [`with_token`], so a cancellation reaches every
//! thread of the computation. The crate has no Python in it: the bindings in `rust/python/` set
//! the flag when `Python::check_signals` reports a pending `KeyboardInterrupt`.

use crate::{Error, Result};
use std::cell::RefCell;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// A cancellation flag shared between the thread that may cancel and the threads that compute.
#[derive(Debug, Clone, Default)]
pub struct Token(Arc<AtomicBool>);

impl Token {
    /// A fresh token (not cancelled).
    pub fn new() -> Self {
        Token::default()
    }

    /// Asks every computation running under this token to stop at its next poll.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether [`Token::cancel`] has been called.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

thread_local! {
    static CURRENT: RefCell<Option<Token>> = const { RefCell::new(None) };
}

/// Runs `f` with `token` installed as this thread's cancellation token (restoring the previous
/// one afterwards, also on unwind). `None` runs `f` without a token.
pub fn with_token<R>(token: Option<&Token>, f: impl FnOnce() -> R) -> R {
    struct Restore(Option<Token>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let prev = self.0.take();
            CURRENT.with(|c| *c.borrow_mut() = prev);
        }
    }
    let prev = CURRENT.with(|c| c.replace(token.cloned()));
    let _restore = Restore(prev);
    f()
}

/// This thread's token, for handing to worker threads.
pub fn current() -> Option<Token> {
    CURRENT.with(|c| c.borrow().clone())
}

/// Whether this thread's computation has been asked to stop.
pub fn is_cancelled() -> bool {
    CURRENT.with(|c| c.borrow().as_ref().is_some_and(Token::is_cancelled))
}

/// `Err(Error::Interrupted)` naming `what` (the loop that noticed) if this thread's computation
/// has been asked to stop; `Ok(())` otherwise.
pub fn check(what: &str) -> Result<()> {
    if is_cancelled() {
        Err(interrupted(what))
    } else {
        Ok(())
    }
}

/// The error returned by a loop that stopped because its token was cancelled.
pub fn interrupted(what: &str) -> Error {
    Error::Interrupted(format!("interrupted during {what}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_without_token_never_fails() {
        assert!(check("x").is_ok());
        assert!(current().is_none());
    }

    #[test]
    fn token_is_scoped_and_restored() {
        let t = Token::new();
        with_token(Some(&t), || {
            assert!(check("loop").is_ok());
            t.cancel();
            let e = check("loop").unwrap_err();
            assert!(matches!(&e, Error::Interrupted(m) if m.contains("loop")));
            // Nested: no token inside.
            with_token(None, || assert!(check("inner").is_ok()));
            assert!(is_cancelled());
        });
        assert!(!is_cancelled());
    }

    #[test]
    fn token_reaches_other_threads_when_handed_over() {
        let t = Token::new();
        t.cancel();
        let tok = with_token(Some(&t), current);
        let r = std::thread::spawn(move || with_token(tok.as_ref(), || check("worker")))
            .join()
            .unwrap();
        assert!(matches!(r, Err(Error::Interrupted(_))));
    }

    /// With a cancelled token installed, every long loop of the crate stops with `Interrupted`
    /// (a pre-cancelled token reaches each poll deterministically, with no timing involved).
    mod every_long_loop_polls {
        use super::super::*;
        use crate::cost::{cost_many, CostOptions, Evaluation, Threads};
        use crate::linalg::expm::expm;
        use crate::linalg::schur::RealSchur;
        use crate::linalg::sylvester::{solve_lyapunov, solve_sylvester};
        use crate::linalg::testing::Rng;
        use crate::linalg::van_loan::van_loan;
        use crate::network::random_block_network;
        use crate::sampled::doubling::{doubling, fixed_point, DoublingOptions};
        use crate::sampled::search::{greedy_pass, neighbourhood, Objective};
        use crate::sampled::SampledSystem;
        use nalgebra::DMatrix;

        fn cancelled<T: std::fmt::Debug>(f: impl FnOnce() -> Result<T>) -> String {
            let t = Token::new();
            t.cancel();
            match with_token(Some(&t), f) {
                Err(Error::Interrupted(m)) => m,
                other => panic!("expected Interrupted, got {other:?}"),
            }
        }

        #[test]
        fn dense_linear_algebra() {
            let mut rng = Rng::new(1);
            let a = rng.matrix(30, 30);
            let q = rng.psd(30, 30);
            eprintln!("{}", cancelled(|| RealSchur::new(&a)));
            eprintln!(
                "{}",
                cancelled(|| solve_lyapunov(&(&a - DMatrix::identity(30, 30) * 9.0), &q))
            );
            eprintln!(
                "{}",
                cancelled(|| solve_sylvester(
                    &a,
                    &(&a * 2.0 + DMatrix::identity(30, 30) * 20.0),
                    &q
                ))
            );
            let mut s = RealSchur::new(&a).unwrap();
            let (t0, z0) = (s.t.clone(), s.z.clone());
            eprintln!("{}", cancelled(|| s.reorder(|re, _| re < 0.0)));
            // A cancelled reordering leaves the Schur form as it was.
            assert_eq!((s.t, s.z), (t0, z0));
            eprintln!("{}", cancelled(|| expm(&(&a * 50.0))));
            eprintln!("{}", cancelled(|| van_loan(&a, &q, 100.0)));
        }

        #[test]
        fn cost_batches_and_hessian() {
            let net = random_block_network(3, &[3, 3, 3, 3], &[1, 1, 1, 1], 0.1);
            let rates = vec![vec![2.0; 4]; 8];
            let opts = CostOptions::default();
            let res = with_token(
                Some(&{
                    let t = Token::new();
                    t.cancel();
                    t
                }),
                || cost_many(&net, &rates, &opts, Threads::Count(2)),
            )
            .unwrap();
            assert!(res.iter().all(|r| matches!(r, Err(Error::Interrupted(_)))));
            let ev = Evaluation::new(&net, &[2.0; 4], &opts).unwrap();
            let adj = ev.adjoint().unwrap();
            eprintln!("{}", cancelled(|| adj.hessian(Threads::Count(2))));
        }

        #[test]
        fn sampled_doubling_search_and_greedy() {
            let mut rng = Rng::new(2);
            let n = 4;
            let mut a = rng.matrix(n, n) * 0.3;
            for i in 0..n {
                a[(i, i)] -= 0.5;
            }
            let sys = SampledSystem::new(
                a,
                DMatrix::identity(n, n),
                (0..3).map(|_| rng.matrix(n, 1)).collect(),
            )
            .unwrap();
            let slots = [0usize, 1, 2, 0, 1, 2];
            let disc = sys.discretise(0.5, slots.len()).unwrap();
            let t = disc.period_triplet(&slots).unwrap();
            let opts = DoublingOptions::default();
            eprintln!("{}", cancelled(|| doubling(&t, &opts)));
            eprintln!("{}", cancelled(|| disc.period_triplet(&slots)));
            eprintln!(
                "{}",
                cancelled(|| fixed_point(&disc, &slots, &DMatrix::zeros(n, n), 1e-12, 1000))
            );
            eprintln!(
                "{}",
                cancelled(|| neighbourhood(&disc, &slots, Objective::Boundary, 1, &opts))
            );
            eprintln!(
                "{}",
                cancelled(|| greedy_pass(&disc, &DMatrix::zeros(n, n), 1))
            );
        }
    }
}
