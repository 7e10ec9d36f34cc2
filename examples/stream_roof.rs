//! Measures how fast one core streams the arrays the chute's kick stage reads and writes,
//! at the packing sizes of the chute benchmark: the floor under the stage's time at each
//! size, against which `docs/performance.md` ("The per-grain rate at 512,000 grains")
//! reads the stage's per-grain loss between 32,000 and 512,000 grains.
//!
//! `cargo run --release --example stream_roof` runs, for 32,000, 128,000 and 512,000
//! grains, a stand-in of the kick with the kick's own arrays and nothing else: the
//! translation pass (each grain's 64-byte snapshot record read and written, its force,
//! mass and position at the last list build read; velocity kicked, position drifted, the
//! largest move since the build kept) and the spin pass (spin read and written, torque
//! and moment of inertia read). It prints the time a grain and the bytes a grain over
//! that time, on one thread and, for the shared caches' and memory's share, on two cores
//! each streaming arrays of its own at once; then on one thread again with the rest of a
//! step's bytes read between two kicks, so that the kick finds in the caches what a step
//! leaves there (the floor that compares with the stage's time in a run). A plain
//! `a += b · c` over two arrays of the same total size gives the core's streaming rate
//! without the kick's arithmetic.

use std::hint::black_box;
use std::time::Instant;

use glam::DVec3;

/// A snapshot record: position, radius, velocity, inverse mass (64 bytes, as
/// `talus::core::snapshot::GrainRecord`).
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Record {
    position: DVec3,
    radius: f64,
    velocity: DVec3,
    inverse_mass: f64,
}

/// The kick stage's arrays for `n` grains.
struct KickArrays {
    records: Vec<Record>,
    force: Vec<DVec3>,
    mass: Vec<f64>,
    reference: Vec<DVec3>,
    spin: Vec<DVec3>,
    torque: Vec<DVec3>,
    inertia: Vec<f64>,
}

/// Bytes a grain the two passes move between the core and its caches or memory: each
/// array read once, and the two it writes (records and spins) written back once.
const KICK_BYTES: usize = (64 + 24 + 8 + 24) + (24 + 24 + 8) + 64 + 24;

impl KickArrays {
    fn new(n: usize) -> Self {
        let record = |k: usize| Record {
            position: DVec3::new(k as f64 * 1e-3, 1.0, 2.0),
            radius: 0.5,
            velocity: DVec3::new(0.1, 0.0, -0.1),
            inverse_mass: 1.0,
        };
        Self {
            records: (0..n).map(record).collect(),
            force: vec![DVec3::new(0.0, 0.0, -1.0); n],
            mass: vec![1.0; n],
            reference: (0..n).map(|k| record(k).position).collect(),
            spin: vec![DVec3::splat(0.01); n],
            torque: vec![DVec3::splat(1e-3); n],
            inertia: vec![0.1; n],
        }
    }

    /// One kick: the translation pass, then the spin pass; returns the largest squared
    /// move since the reference (so that nothing is optimised away).
    fn kick(&mut self, dt: f64) -> f64 {
        let mut largest = 0.0f64;
        for (((r, f), m), x0) in self
            .records
            .iter_mut()
            .zip(&self.force)
            .zip(&self.mass)
            .zip(&self.reference)
        {
            r.velocity += *f * (dt / m);
            r.position += r.velocity * dt;
            largest = largest.max((r.position - *x0).length_squared());
        }
        for ((w, t), i) in self.spin.iter_mut().zip(&self.torque).zip(&self.inertia) {
            *w += *t * (dt / i);
        }
        largest
    }
}

/// Bytes a grain the rest of a step reads between two kicks (the contact tables, the
/// neighbour list, the grain tables' other columns: the resident set of a 512,000-grain
/// run is about 700 bytes a grain, `docs/performance.md`, "Memory per grain"), read between
/// two timed kicks when the kick is timed as in a step, so that it finds in the caches only
/// what a step would leave there.
const REST_OF_STEP_BYTES: usize = 700 - KICK_BYTES + 64 + 24;

/// Reads `rest` a cache line at a time: the other stages of a step, as far as the caches see.
fn read_through(rest: &[u64]) -> u64 {
    rest.iter().step_by(8).fold(0, |sum, &x| sum ^ x)
}

/// Nanoseconds a grain of the median of `passes` kicks over `n` grains, after a warm-up;
/// with `in_step`, the rest of a step's bytes are read between two kicks (untimed).
fn time_kick(n: usize, passes: usize, in_step: bool) -> f64 {
    let rest = if in_step {
        vec![1u64; n * REST_OF_STEP_BYTES / 8]
    } else {
        Vec::new()
    };
    let mut arrays = KickArrays::new(n);
    // Tiny steps, alternating in sign, so that the state stays bounded however many passes.
    for _ in 0..3 {
        black_box(arrays.kick(1e-9));
    }
    let mut times: Vec<f64> = (0..passes)
        .map(|k| {
            let dt = if k % 2 == 0 { 1e-9 } else { -1e-9 };
            black_box(read_through(&rest));
            let start = Instant::now();
            black_box(arrays.kick(dt));
            start.elapsed().as_secs_f64() * 1e9 / n as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[passes / 2]
}

/// Bytes a pair of elements of `a += b · c` moves: two read, one written back.
const PLAIN_BYTES: usize = 24;

/// Nanoseconds a pair of elements of the median of `passes` passes of `a += b · c` over
/// arrays of `bytes` bytes together.
fn time_plain(bytes: usize, passes: usize) -> f64 {
    let len = bytes / 16;
    let (mut a, b) = (vec![1.0f64; len], vec![1e-12f64; len]);
    let mut times: Vec<f64> = (0..passes)
        .map(|k| {
            let c = if k % 2 == 0 { 1.0 } else { -1.0 };
            let start = Instant::now();
            for (a, b) in a.iter_mut().zip(&b) {
                *a += b * c;
            }
            black_box(&a);
            start.elapsed().as_secs_f64() * 1e9 / len as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[passes / 2]
}

fn main() {
    println!(
        "kick stand-in: {KICK_BYTES} bytes a grain (arrays read, records and spins written back)"
    );
    println!(
        "| grains | working set (MB) | 1 core: ns a grain | GB/s | 2 cores at once: ns a grain | GB/s | 1 core, the rest of a step read between kicks: ns a grain | GB/s | plain a += b, 1 core: GB/s |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for (n, passes) in [(32_000usize, 2001usize), (128_000, 501), (512_000, 101)] {
        let alone = time_kick(n, passes, false);
        let together = std::thread::scope(|scope| {
            let other = scope.spawn(|| time_kick(n, passes, false));
            let mine = time_kick(n, passes, false);
            let theirs = other.join().expect("the other core's run");
            (mine + theirs) / 2.0
        });
        let in_step = time_kick(n, passes, true);
        let working_set = n * (KICK_BYTES - 64 - 24);
        let plain = time_plain(working_set, passes);
        println!(
            "| {n} | {:.1} | {alone:.2} | {:.1} | {together:.2} | {:.1} | {in_step:.2} | {:.1} | {:.1} |",
            working_set as f64 / 1e6,
            KICK_BYTES as f64 / alone,
            KICK_BYTES as f64 / together,
            KICK_BYTES as f64 / in_step,
            PLAIN_BYTES as f64 / plain,
        );
    }
}
