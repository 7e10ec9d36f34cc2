//! Measures how long a cache line takes to travel between two cores and back: the cost a
//! parallel step pays whenever one thread reads what another wrote (a contact force, a
//! grain's force total, a contact entity's row). `docs/performance-log.md` uses it to
//! explain how far two threads can scale on a given machine (session 18 on).
//!
//! `cargo run --release --example core_latency` prints the mean round trip in
//! nanoseconds. The two threads spin, so on an idle machine the scheduler keeps them on
//! two different cores; on a busy one the figure includes time slices lost to others.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// Round trips timed.
const ROUND_TRIPS: u64 = 1_000_000;

/// One counter on a line of its own, so the line holds nothing else.
#[repr(align(128))]
struct Line(AtomicU64);

fn main() {
    let line = Line(AtomicU64::new(0));
    let flag = &line.0;
    let seconds = std::thread::scope(|scope| {
        // The other thread answers each odd value with the next even one.
        scope.spawn(|| {
            for k in 0..ROUND_TRIPS {
                while flag.load(Ordering::Acquire) != 2 * k + 1 {
                    std::hint::spin_loop();
                }
                flag.store(2 * k + 2, Ordering::Release);
            }
        });
        let start = Instant::now();
        for k in 0..ROUND_TRIPS {
            flag.store(2 * k + 1, Ordering::Release);
            while flag.load(Ordering::Acquire) != 2 * k + 2 {
                std::hint::spin_loop();
            }
        }
        start.elapsed().as_secs_f64()
    });
    let round_trip_ns = seconds / ROUND_TRIPS as f64 * 1e9;
    println!(
        "cache-line round trip between two threads: {round_trip_ns:.0} ns \
         (one way about {:.0} ns)",
        round_trip_ns / 2.0
    );
}
