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
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

thread_local! {
    /// Whether this thread is leading a step with polling workers or is one of them: a
    /// nested call runs its work directly.
    static ENGAGED: Cell<bool> = const { Cell::new(false) };
}

/// Where the polling workers book the time they find no job, part by part of the work
/// (the stages of a step): the load imbalance and the serial stretches of each part, as
/// the other threads see them, where the part's wall-clock time shows neither. Each idle
/// spin of a worker is booked to the part that was running when the spin began, so an
/// idle stretch across two parts is split between them. Shared between the thread that
/// marks the parts ([`IdleBook::enter`]) and the workers; booking costs a clock read per
/// idle spin (a few µs), none while there is work.
#[derive(Debug)]
pub struct IdleBook {
    /// The part now running, or [`IdleBook::NONE`] between parts.
    current: AtomicUsize,
    /// Nanoseconds booked per part.
    nanos: [AtomicU64; IdleBook::PARTS],
}

impl Default for IdleBook {
    fn default() -> Self {
        Self {
            current: AtomicUsize::new(Self::NONE),
            nanos: std::array::from_fn(|_| AtomicU64::new(0)),
        }
    }
}

impl IdleBook {
    /// How many parts a book holds (a step has ten stages).
    pub const PARTS: usize = 16;
    /// No part: idle time is not booked (between steps).
    pub const NONE: usize = usize::MAX;

    /// Books the idle time from now on to `part` (below [`Self::PARTS`]; [`Self::NONE`]:
    /// to no part).
    pub fn enter(&self, part: usize) {
        self.current.store(part, Ordering::Relaxed);
    }

    /// Seconds of idle worker time booked to `part` so far, summed over the workers.
    pub fn seconds(&self, part: usize) -> f64 {
        self.nanos
            .get(part)
            .map_or(0.0, |n| n.load(Ordering::Relaxed) as f64 * 1e-9)
    }

    /// Forgets what was booked (the part being run stays current).
    pub fn clear(&self) {
        for n in &self.nanos {
            n.store(0, Ordering::Relaxed);
        }
    }

    /// Adds `nanos` to `part` (nothing for [`Self::NONE`]).
    fn book(&self, part: usize, nanos: u64) {
        if let Some(n) = self.nanos.get(part) {
            n.fetch_add(nanos, Ordering::Relaxed);
        }
    }
}

/// Runs `work` on this thread while every other worker of the current rayon pool polls
/// the pool for jobs (running those `work` makes) instead of parking, until `work`
/// returns. Runs `work` directly outside a pool, in a pool of one thread, or nested.
pub fn with_workers_polling<R: Send>(work: impl FnOnce() -> R + Send) -> R {
    with_workers_polling_booked(None, work)
}

/// [`with_workers_polling`], the workers booking the time they find no job in `book`
/// (when given and when they poll: not nested, not on one thread).
pub fn with_workers_polling_booked<R: Send>(
    book: Option<&IdleBook>,
    work: impl FnOnce() -> R + Send,
) -> R {
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
            scope.spawn(move |_| poll_until(done, leader, book));
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
fn poll_until(done: &AtomicBool, leader: usize, book: Option<&IdleBook>) {
    if rayon::current_thread_index() == Some(leader) || ENGAGED.get() {
        return;
    }
    ENGAGED.set(true);
    // When the last idle spin ended, while the worker has found no job since: the
    // fruitless search between two spins is idle time too.
    let mut idle_since: Option<Instant> = None;
    while !done.load(Ordering::Acquire) {
        match rayon::yield_now() {
            Some(rayon::Yield::Executed) => idle_since = None,
            Some(rayon::Yield::Idle) => {
                // Booked to the part running as the spin begins.
                let start = book.map(|book| {
                    let part = book.current.load(Ordering::Relaxed);
                    (idle_since.unwrap_or_else(Instant::now), part)
                });
                for _ in 0..32 {
                    std::hint::spin_loop();
                }
                if let (Some(book), Some((since, part))) = (book, start) {
                    let now = Instant::now();
                    book.book(part, (now - since).as_nanos() as u64);
                    idle_since = Some(now);
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

    /// A book adds what is booked to each part, drops what is booked to no part, and
    /// forgets everything when cleared.
    #[test]
    fn idle_book_adds_by_part() {
        let book = IdleBook::default();
        book.book(2, 1_500);
        book.book(2, 500);
        book.book(IdleBook::NONE, 7_000);
        book.book(IdleBook::PARTS, 7_000);
        assert!((book.seconds(2) - 2e-6).abs() < 1e-15);
        assert_eq!(book.seconds(0), 0.0);
        assert_eq!(book.seconds(IdleBook::NONE), 0.0);
        book.clear();
        assert_eq!(book.seconds(2), 0.0);
    }

    /// The workers' idle time booked to a part cannot exceed the part's wall-clock time
    /// times the number of workers that poll, nothing is booked between parts, and a pool
    /// of one thread books nothing.
    #[test]
    fn idle_time_is_bounded_by_the_parts_wall_clock() {
        for threads in 1..=3 {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let book = IdleBook::default();
            let (serial, parallel) = pool.install(|| {
                with_workers_polling_booked(Some(&book), || {
                    // Part 0: serial work on the leader alone.
                    book.enter(0);
                    let start = Instant::now();
                    let mut x = 0u64;
                    while start.elapsed().as_millis() < 20 {
                        x = std::hint::black_box(x.wrapping_mul(31).wrapping_add(7));
                    }
                    let serial = start.elapsed().as_secs_f64();
                    // Part 1: a parallel loop.
                    book.enter(1);
                    let start = Instant::now();
                    let sum: u64 = (0..2_000_000u64).into_par_iter().map(|i| i % 13).sum();
                    std::hint::black_box(sum);
                    let parallel = start.elapsed().as_secs_f64();
                    // Between parts.
                    book.enter(IdleBook::NONE);
                    std::thread::sleep(std::time::Duration::from_millis(5));
                    (serial, parallel)
                })
            });
            let workers = (threads - 1) as f64;
            // A spin booked to a part may end a clock read after the part does.
            let slack = 1e-3;
            assert!(
                book.seconds(0) <= workers * serial + slack,
                "{threads} threads"
            );
            assert!(
                book.seconds(1) <= workers * parallel + slack,
                "{threads} threads"
            );
            for part in 2..IdleBook::PARTS {
                assert_eq!(book.seconds(part), 0.0);
            }
            if threads == 1 {
                assert_eq!(book.seconds(0) + book.seconds(1), 0.0);
            }
        }
    }
}
