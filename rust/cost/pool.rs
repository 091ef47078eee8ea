//! Where the cost layer's parallel work runs: the choice of threads ([`Threads`]) and the
//! process's shared rayon pool, rebuilt after a `fork()` (rayon's global pool hangs in a forked
//! child, e.g. a `ProcessPoolExecutor` worker). The calling thread's cancellation token is carried
//! into the pool.

use crate::{Error, Result};
use rayon::{ThreadPool, ThreadPoolBuilder};
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
pub(super) fn in_pool<T: Send>(threads: Threads, f: impl FnOnce(bool) -> T + Send) -> Result<T> {
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
pub(super) fn batch_item<T>(
    token: Option<&crate::cancel::Token>,
    f: impl FnOnce() -> Result<T>,
) -> Result<T> {
    crate::cancel::with_token(token, || {
        crate::cancel::check("a batch of cost evaluations")?;
        f()
    })
}
