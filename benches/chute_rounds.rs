//! The chute benchmark in interleaved rounds: per round and size, the whole replica on 1
//! thread, on 2 threads, and its two halves exchanging their halo on a thread each
//! (`support/chute_halves.rs`), each run from the same starting state. On a machine whose
//! speed drifts between minutes, only runs taken side by side compare: this prints every
//! round and the medians of the rates and of each round's own ratios
//! (`docs/performance.md`, "What the unmet targets would take").
//!
//! `cargo bench --bench chute_rounds` (5 rounds of the 32,000-, 128,000- and 512,000-grain
//! replicas, 600, 200 and 100 steps a run); `TALUS_ROUNDS=n` and
//! `TALUS_REPLICAS=1,2,4` change the rounds and the replicas (`r` for `r` × `r` copies).

use std::path::Path;
use std::time::Instant;

#[path = "support/chute_halves.rs"]
mod chute_halves;
use chute_halves::{ExchangedHalves, chute};
#[path = "support/rounds.rs"]
mod rounds;
use rounds::{env_count, median};

/// The `talus` binary's allocator, as in the `chute` bench.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

/// Steps a run takes for the replica `r` × `r`: about 19 M grain-steps at 32,000 grains, 26 M
/// and 51 M at the larger sizes (a few seconds each, after a build that takes longer).
fn steps_for(r: u32) -> u64 {
    match r {
        1 => 600,
        2 => 200,
        _ => 100,
    }
}

/// M grain-steps per second of the whole replica `r` × `r` on `threads` threads.
fn whole(r: u32, threads: usize, steps: u64) -> f64 {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let (mut sim, grains) = pool.install(|| chute(r, r, |_| {}));
    let start = Instant::now();
    pool.install(|| sim.run_steps(steps).unwrap());
    grains as f64 * steps as f64 / start.elapsed().as_secs_f64() / 1e6
}

/// M grain-steps per second of the halves of the replica `r` × `r` exchanging their halo
/// (own grains only, over the wall time of both).
fn halves(atoms: &[talus::scene::lammps::Atom], r: u32, steps: u64) -> f64 {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let mut halves = ExchangedHalves::new(atoms, r, dir);
    let start = Instant::now();
    halves.run_steps(steps);
    halves.own_grains as f64 * steps as f64 / start.elapsed().as_secs_f64() / 1e6
}

fn main() {
    // `cargo bench` passes `--bench` (and any filter); this bench takes its settings from
    // the environment instead.
    let rounds = env_count("TALUS_ROUNDS", 5);
    let replicas: Vec<u32> = std::env::var("TALUS_REPLICAS")
        .ok()
        .map(|s| s.split(',').filter_map(|r| r.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![1, 2, 4]);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let atoms = talus::scene::lammps::read_data(&root.join("data.chute")).expect("data.chute");
    for r in replicas {
        let steps = steps_for(r);
        let grains = 32_000 * r * r;
        println!("{grains} grains, {steps} steps a run, M grain-steps/s:");
        println!("  round  1 thread  2 threads  halves exchanging  2t/1t  halves/1t  halves/2t");
        let mut runs = Vec::new();
        for round in 1..=rounds {
            let one = whole(r, 1, steps);
            let two = whole(r, 2, steps);
            let split = halves(&atoms, r, steps);
            println!(
                "  {round:5}  {one:8.2}  {two:9.2}  {split:17.2}  {:5.2}  {:9.2}  {:9.2}",
                two / one,
                split / one,
                split / two
            );
            runs.push((one, two, split));
        }
        let of = |f: fn(&(f64, f64, f64)) -> f64| median(runs.iter().map(f).collect());
        println!(
            "  median {:8.2}  {:9.2}  {:17.2}  {:5.2}  {:9.2}  {:9.2}",
            of(|r| r.0),
            of(|r| r.1),
            of(|r| r.2),
            of(|r| r.1 / r.0),
            of(|r| r.2 / r.0),
            of(|r| r.2 / r.1)
        );
    }
}
