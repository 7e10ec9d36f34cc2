//! The ceiling of temporal blocking on the chute benchmark, on one thread: a packing of
//! 128,000 or 512,000 grains made of independent simulations — copies of the 32,000-grain
//! chute (22 MB, inside the 32 MB L3) or of its 64,000-grain replica — stepped one step each
//! in turn, so that every stage of a step runs over one region while the region is in cache;
//! in interleaved rounds with the 32,000-grain chute alone and the whole replicas. The copies
//! share no halo and exchange nothing, so their rates bound what a step run region by region
//! could reach (`docs/performance.md`, "What the unmet targets would take").
//!
//! `cargo bench --bench chute_regions` (5 rounds: the 32,000-grain chute 600 steps, the
//! 128,000-grain packings 200, the 512,000-grain ones 100); `TALUS_ROUNDS=n` changes the
//! rounds.

use std::time::Instant;

use talus::core::schedule::Simulation;

#[path = "support/chute_halves.rs"]
#[allow(dead_code)] // the halves themselves are the other benches'
mod chute_halves;
use chute_halves::chute;
#[path = "support/rounds.rs"]
mod rounds;
use rounds::{env_count, median};

/// The `talus` binary's allocator, as in the `chute` bench.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

/// M grain-steps per second of the whole replica `r` × `r`, `steps` steps.
fn whole(r: u32, steps: u64) -> f64 {
    let (mut sim, grains) = chute(r, r, |_| {});
    let start = Instant::now();
    sim.run_steps(steps).unwrap();
    grains as f64 * steps as f64 / start.elapsed().as_secs_f64() / 1e6
}

/// M grain-steps per second of `sims`, `grains` own grains in all, stepped one step each in
/// turn, `steps` steps each. As `run_steps` does, every step but the last leaves its end
/// unobserved (its second kick folded into the next step's first), and each simulation's
/// state is written back to its components at the end.
fn in_turn(mut sims: Vec<Simulation>, grains: usize, steps: u64) -> f64 {
    let start = Instant::now();
    for step in 0..steps {
        for sim in sims.iter_mut() {
            if step + 1 < steps {
                sim.step_before_another().unwrap();
            } else {
                sim.step().unwrap();
            }
        }
    }
    for sim in sims.iter_mut() {
        sim.synchronize();
    }
    grains as f64 * steps as f64 / start.elapsed().as_secs_f64() / 1e6
}

/// `count` copies of the replica `x` × `y` of the chute, with their grains in all.
fn copies(count: usize, x: u32, y: u32) -> (Vec<Simulation>, usize) {
    (0..count)
        .map(|_| chute(x, y, |_| {}))
        .fold((Vec::new(), 0), |(mut sims, grains), (sim, n)| {
            sims.push(sim);
            (sims, grains + n)
        })
}

fn main() {
    let rounds = env_count("TALUS_ROUNDS", 5);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    const COLUMNS: [&str; 6] = [
        "32,000 alone",
        "128,000 whole",
        "4 x 32,000 in turn",
        "512,000 whole",
        "16 x 32,000 in turn",
        "8 x 64,000 in turn",
    ];
    println!("1 thread, M grain-steps/s; in brackets, against 32,000 alone:");
    println!("  round  {}", COLUMNS.join(" | "));
    let mut runs: Vec<[f64; 6]> = Vec::new();
    for round in 1..=rounds {
        let run = pool.install(|| {
            [
                whole(1, 600),
                whole(2, 200),
                {
                    let (sims, n) = copies(4, 1, 1);
                    in_turn(sims, n, 200)
                },
                whole(4, 100),
                {
                    let (sims, n) = copies(16, 1, 1);
                    in_turn(sims, n, 100)
                },
                {
                    let (sims, n) = copies(8, 2, 1);
                    in_turn(sims, n, 100)
                },
            ]
        });
        print_row(&format!("{round:5}"), &run, &COLUMNS);
        runs.push(run);
    }
    let medians: [f64; 6] = std::array::from_fn(|c| median(runs.iter().map(|r| r[c]).collect()));
    print_row("median", &medians, &COLUMNS);
    println!("  medians of each round's ratio to 32,000 alone:");
    for (c, name) in COLUMNS.iter().enumerate().skip(1) {
        let ratio = median(runs.iter().map(|r| r[c] / r[0]).collect());
        println!("    {name}: {ratio:.3}");
    }
    println!("  medians of each round's ratio of the regions in turn to the whole replica:");
    for (c, whole) in [(2, 1), (4, 3), (5, 3)] {
        let ratio = median(runs.iter().map(|r| r[c] / r[whole]).collect());
        println!("    {} / {}: {ratio:.3}", COLUMNS[c], COLUMNS[whole]);
    }
}

/// One round's rates (or their medians), each with its ratio to the first, in columns as
/// wide as their names.
fn print_row(label: &str, rates: &[f64; 6], columns: &[&str; 6]) {
    let cells: Vec<String> = rates
        .iter()
        .zip(columns)
        .map(|(rate, name)| {
            let cell = format!("{rate:.2} ({:.3})", rate / rates[0]);
            format!("{cell:>width$}", width = name.len())
        })
        .collect();
    println!("  {label}  {}", cells.join(" | "));
}
