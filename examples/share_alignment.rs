//! Measures what it costs two threads to take each other's shares of an array between
//! two parallel loops: the cost a step pays when one stage's thread reads or writes the
//! grains or contacts that another stage's other thread last wrote. `docs/performance.md`
//! ("Measuring the ratios") uses it to explain why the threads' shares must stay aligned
//! from stage to stage.
//!
//! `cargo run --release --example share_alignment` times a simple update of every record
//! of an array (64 bytes each) in chunks on 1 and 2 threads, the chunks' halves taken by
//! the same thread every pass ("aligned") or by the other thread every other pass
//! ("swapped"), for an array that fits in the two cores' L2 caches (32,000 records,
//! 2 MB) and one that does not (256,000 records, 16 MB).

use rayon::prelude::*;
use std::time::Instant;

/// A record the size of a cache line.
type Record = [f64; 8];

/// One pass over `records` in `chunks` chunks; with `swap` the chunks are handed out last
/// first, so that each thread takes the half the other took in a plain pass.
fn pass(records: &mut [Record], chunk: usize, swap: bool) {
    let update = |c: &mut [Record]| {
        for r in c {
            r[0] += r[1] * 0.5 + r[2];
            r[3] += r[0];
        }
    };
    if swap {
        records.par_chunks_mut(chunk).rev().for_each(update);
    } else {
        records.par_chunks_mut(chunk).for_each(update);
    }
}

/// Microseconds a pass, over `passes` passes, every other one swapped if `alternate`.
fn time(records: &mut [Record], chunk: usize, passes: usize, alternate: bool) -> f64 {
    let start = Instant::now();
    for k in 0..passes {
        pass(records, chunk, alternate && k % 2 == 1);
    }
    start.elapsed().as_secs_f64() / passes as f64 * 1e6
}

fn main() {
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        pool.install(|| {
            talus::core::workers::with_workers_polling(|| {
                for (len, passes) in [(32_000, 4000), (256_000, 500)] {
                    let mut records = vec![[0.0; 8]; len];
                    let chunk = len / 8;
                    time(&mut records, chunk, passes, true);
                    let aligned = time(&mut records, chunk, passes, false);
                    let swapped = time(&mut records, chunk, passes, true);
                    println!(
                        "{threads} thread(s), {len} records ({} MB): aligned {aligned:.1} µs a \
                         pass, swapped every other pass {swapped:.1} µs",
                        len * 64 / 1_000_000
                    );
                }
            })
        });
    }
}
