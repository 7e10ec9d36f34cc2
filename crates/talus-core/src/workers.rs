//! Keeps the thread pool's other workers polling for work through a time step, so that
//! the step's many short parallel loops do not each wait for a sleeping thread to wake.
//!
//! Rayon parks a worker that has found nothing to do for a few tens of microseconds;
//! waking it again costs 50–75 µs on the virtual machines this project is developed on
//! (measured with a serial gap before a `join` of two 50 µs halves: 4 µs of overhead
//! after a 10 µs gap, 55–75 µs after gaps of 50 µs to 1 ms). A step has a dozen parallel
//! loops, several behind a serial stretch longer than that (entity spawns, sums), and a
//! 32,000-grain step on two threads takes about 5 ms: the wake-ups cost a tenth of it.
//! OpenMP codes meet the same cost with spinning barriers (`OMP_WAIT_POLICY=active`);
//! here each other worker runs a job that polls the pool for work until the step ends.
//! Which thread runs which piece of work never changes a result: every sum in a step is
//! taken in an order fixed by the data, not by the threads.

use std::cell::Cell;
use std::sync::atomic::{AtomicBool, Ordering};

thread_local! {
    /// Whether this thread is leading a step with polling workers or is one of them: a
    /// nested call runs its work directly.
    static ENGAGED: Cell<bool> = const { Cell::new(false) };
}

/// Runs `work` on this thread while every other worker of the current rayon pool polls
/// the pool for jobs (running those `work` makes) instead of parking, until `work`
/// returns. Runs `work` directly outside a pool, in a pool of one thread, or nested.
pub fn with_workers_polling<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    let threads = rayon::current_num_threads();
    let Some(leader) = rayon::current_thread_index() else {
        return work();
    };
    if threads < 2 || ENGAGED.get() {
        return work();
    }
    let done = AtomicBool::new(false);
    let done = &done;
    rayon::scope(|scope| {
        for _ in 1..threads {
            scope.spawn(move |_| poll_until(done, leader));
        }
        ENGAGED.set(true);
        let result = work();
        ENGAGED.set(false);
        done.store(true, Ordering::Release);
        result
    })
}

/// A polling worker's job: runs the pool's pending jobs one at a time until `done`. The
/// leader itself (which may pop this job while it waits inside `work`) and a worker
/// already polling return at once, so the leader never waits on its own poller.
fn poll_until(done: &AtomicBool, leader: usize) {
    if rayon::current_thread_index() == Some(leader) || ENGAGED.get() {
        return;
    }
    ENGAGED.set(true);
    while !done.load(Ordering::Acquire) {
        match rayon::yield_now() {
            Some(rayon::Yield::Executed) => {}
            Some(rayon::Yield::Idle) => {
                for _ in 0..32 {
                    std::hint::spin_loop();
                }
            }
            None => break,
        }
    }
    ENGAGED.set(false);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// Parallel loops inside the polled region run and give the same result as outside
    /// it, on pools of one to four threads, nested calls included.
    #[test]
    fn work_inside_runs_on_any_pool() {
        for threads in 1..=4 {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let expected: u64 = (0..100_000u64).map(|i| i * i % 7).sum();
            let got = pool.install(|| {
                with_workers_polling(|| {
                    let a: u64 = (0..100_000u64).into_par_iter().map(|i| i * i % 7).sum();
                    let b = with_workers_polling(|| {
                        (0..100_000u64)
                            .into_par_iter()
                            .map(|i| i * i % 7)
                            .sum::<u64>()
                    });
                    assert_eq!(a, b);
                    a
                })
            });
            assert_eq!(got, expected, "{threads} threads");
        }
        // Outside any pool.
        assert_eq!(with_workers_polling(|| 3), 3);
    }
}
