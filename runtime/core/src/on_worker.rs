//! [`on_worker`]: run a piece of work made of many parallel loops on a
//! worker of the rayon pool, so its loops split work among workers instead
//! of each handing its job across threads.
//!
//! A parallel loop started from a thread outside the pool (the CLI's main
//! thread, the host's thread calling into a plugin library, which links
//! its own copy of rayon) injects its job into the pool and blocks the
//! caller on a lock until a worker has run it: two context switches per
//! loop. An iterative solve runs hundreds of short loops, so that cost
//! adds up (the four-cavity pendulum: 98 k context switches in 40 frames,
//! 7 k with its entry points on a worker). Started on a worker, the loops
//! split by work stealing with no hand-over.

/// Runs `f` on a worker of the current rayon pool and waits for it; on a
/// worker already, runs `f` in place.
pub fn on_worker<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        f()
    } else {
        rayon::join(f, || ()).0
    }
}

#[cfg(test)]
mod tests {
    use super::on_worker;

    #[test]
    fn calls_run_on_a_worker_of_the_pool_and_nested_calls_in_place() {
        assert_eq!(rayon::current_thread_index(), None, "the test thread");
        let (outer, inner) = on_worker(|| {
            let outer = std::thread::current().id();
            let inner = on_worker(|| std::thread::current().id());
            (rayon::current_thread_index().map(|_| outer), inner)
        });
        assert!(outer.is_some(), "the call ran on a pool worker");
        assert_eq!(outer, Some(inner), "a nested call stays on its worker");
    }
}
