//! The chute benchmark's two ratio targets from blocks of steps taken in turn in one
//! process: the 32,000-grain chute and its 512,000-grain replica (4 × 4), each stepped on
//! a pool of 1 thread and on a pool of 2, a block of 7 steps at a time. On a machine whose
//! speed drifts between minutes (and between seconds), whole runs compare only when taken
//! side by side; blocks a fraction of a second apart compare far more closely, and every
//! stage's time comes with them (`docs/performance.md`, "Measuring the ratios").
//!
//! A round steps the small chute in 8 blocks on each pool, alternating, then the replica
//! in one block on each pool; the pools' order turns every round. The first step of each
//! block is not timed: it pays for the state the other pool or the other packing left in
//! the caches. Blocks of 7 steps fall across the contact-table sort (every 20 steps) at
//! every phase, so no variant always gets the steps right after a sort.
//!
//! `cargo bench --bench chute_blocks` (40 rounds); `TALUS_ROUNDS=n` changes the rounds,
//! `TALUS_REPLICA=r` the large packing (`r` × `r` copies; 2 for 128,000 grains) and
//! `TALUS_BLOCK_STEPS=s` the steps of a block (7; an `s` that 20 divides would give one
//! pool the steps after each sort).

use std::time::Instant;

#[path = "support/chute_halves.rs"]
#[allow(dead_code)]
mod chute_halves;
use chute_halves::chute;
#[path = "support/rounds.rs"]
mod rounds;
use rounds::{env_count, median};
use talus::core::resources::StageTimings;
use talus::core::schedule::{Simulation, Stage};

/// The `talus` binary's allocator, as in the `chute` bench.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

/// Steps of a block unless `TALUS_BLOCK_STEPS` says otherwise; its first is not timed.
const BLOCK_STEPS: u64 = 7;

/// Blocks of the small chute on each pool in a round.
const SMALL_BLOCKS: usize = 8;

/// The time one variant (a packing on a pool) spent in its timed steps, whole and by
/// stage, the steps timed and the neighbour-list builds among them.
#[derive(Clone, Default)]
struct Tally {
    seconds: f64,
    stages: Vec<f64>,
    steps: u64,
    builds: u64,
}

impl Tally {
    /// Nanoseconds a grain-step, whole (`None`) or of one stage.
    fn ns(&self, grains: usize, stage: Option<usize>) -> f64 {
        let seconds = stage.map_or(self.seconds, |k| self.stages[k]);
        seconds / (grains as f64 * self.steps as f64) * 1e9
    }
}

/// Every stage's accumulated seconds.
fn stage_seconds(sim: &Simulation) -> Vec<f64> {
    let timings = sim.world.resource::<StageTimings>();
    Stage::ALL.iter().map(|&s| timings.get(s)).collect()
}

/// Neighbour-list builds so far.
fn builds(sim: &Simulation) -> u64 {
    sim.world
        .get_resource::<talus::collision::NeighbourList>()
        .map_or(0, |list| list.builds)
}

/// Steps `sim` one block on `pool`, adding the timed steps to `tally`. The pool's other
/// workers poll for work through the whole block, as through `talus run`'s loop of steps.
fn block(sim: &mut Simulation, pool: &rayon::ThreadPool, steps: u64, tally: &mut Tally) {
    pool.install(|| {
        talus::core::workers::with_workers_polling(|| {
            sim.step_before_another().expect("the chute steps");
            let (before, built) = (stage_seconds(sim), builds(sim));
            let start = Instant::now();
            for _ in 1..steps {
                sim.step_before_another().expect("the chute steps");
            }
            tally.seconds += start.elapsed().as_secs_f64();
            let after = stage_seconds(sim);
            tally.stages.resize(after.len(), 0.0);
            for (total, (a, b)) in tally.stages.iter_mut().zip(after.iter().zip(&before)) {
                *total += a - b;
            }
            tally.steps += steps - 1;
            tally.builds += builds(sim) - built;
        })
    });
}

/// `median (lower quartile–upper quartile)` of `values`.
fn spread(mut values: Vec<f64>) -> String {
    values.sort_by(f64::total_cmp);
    let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
    format!(
        "{:.3} ({:.3}–{:.3})",
        median(values.clone()),
        at(0.25),
        at(0.75)
    )
}

fn main() {
    let rounds = env_count("TALUS_ROUNDS", 40).max(1);
    let replica = env_count("TALUS_REPLICA", 4).max(1) as u32;
    let block_steps = env_count("TALUS_BLOCK_STEPS", BLOCK_STEPS as usize).max(2) as u64;
    let pools: Vec<rayon::ThreadPool> = [1, 2]
        .iter()
        .map(|&t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t)
                .build()
                .expect("a thread pool")
        })
        .collect();
    let (mut small, small_grains) = pools[1].install(|| chute(1, 1, |_| {}));
    let (mut large, large_grains) = pools[1].install(|| chute(replica, replica, |_| {}));
    // Warm up: the first steps build the neighbour lists and sort the tables.
    for sim in [&mut small, &mut large] {
        pools[1].install(|| sim.run_steps(20).expect("the chute steps"));
    }
    // Tallies: [small 1t, small 2t, large 1t, large 2t], whole and per round.
    let mut totals = vec![Tally::default(); 4];
    let mut per_round: Vec<Vec<Tally>> = Vec::with_capacity(rounds);
    for round in 0..rounds {
        let mut this = vec![Tally::default(); 4];
        let order = if round % 2 == 0 { [0, 1] } else { [1, 0] };
        for k in 0..SMALL_BLOCKS {
            // Within the round the order turns too, so that neither pool always follows
            // the large packing.
            let pair = if k % 2 == 0 {
                order
            } else {
                [order[1], order[0]]
            };
            for p in pair {
                block(&mut small, &pools[p], block_steps, &mut this[p]);
            }
        }
        for p in order {
            block(&mut large, &pools[p], block_steps, &mut this[2 + p]);
        }
        for (total, t) in totals.iter_mut().zip(&this) {
            total.seconds += t.seconds;
            total.steps += t.steps;
            total.builds += t.builds;
            total.stages.resize(t.stages.len(), 0.0);
            for (a, b) in total.stages.iter_mut().zip(&t.stages) {
                *a += b;
            }
        }
        per_round.push(this);
    }
    let grains = [small_grains, small_grains, large_grains, large_grains];
    println!(
        "{rounds} rounds; blocks of {block_steps} steps, the first untimed; ns a grain-step \
         over all rounds"
    );
    println!(
        "{:>22} {:>9} {:>9} {:>8} {:>9} {:>9} {:>8} {:>10}",
        "stage", "small 1t", "small 2t", "2t/1t", "large 1t", "large 2t", "2t/1t", "per-grain"
    );
    let row = |name: &str, stage: Option<usize>| {
        let ns: Vec<f64> = (0..4).map(|v| totals[v].ns(grains[v], stage)).collect();
        println!(
            "{name:>22} {:9.2} {:9.2} {:8.2} {:9.2} {:9.2} {:8.2} {:10.2}",
            ns[0],
            ns[1],
            ns[0] / ns[1],
            ns[2],
            ns[3],
            ns[2] / ns[3],
            ns[0] / ns[2]
        );
    };
    for (k, stage) in Stage::ALL.iter().enumerate() {
        if (0..4).any(|v| totals[v].ns(grains[v], Some(k)) > 0.05) {
            row(stage.name(), Some(k));
        }
    }
    row("step", None);
    // A list build is some 5–10 % of the steps' time between two builds; builds fall on
    // the variants' timed steps as they happen, which weighs on few blocks.
    println!(
        "{:>22} {:9} {:9} {:>8} {:9} {:9}",
        "list builds timed",
        totals[0].builds,
        totals[1].builds,
        "",
        totals[2].builds,
        totals[3].builds
    );
    // Each ratio: the variant whose time is divided, and the one it is divided by.
    let ratios = [
        (format!("2 threads against 1, {small_grains} grains"), 0, 1),
        (format!("2 threads against 1, {large_grains} grains"), 2, 3),
        (
            format!("per-grain rate of {large_grains} against {small_grains} grains, 1 thread"),
            0,
            2,
        ),
        ("the same, 2 threads".to_string(), 1, 3),
    ];
    println!("per round, median (quartiles):");
    for (label, over, under) in ratios {
        let per = per_round
            .iter()
            .map(|r| r[over].ns(grains[over], None) / r[under].ns(grains[under], None));
        println!("  {label}: {}", spread(per.collect()));
    }
    println!(
        "M grain-steps/s over all rounds: {:.2} and {:.2} ({small_grains} grains, 1 and 2 \
         threads), {:.2} and {:.2} ({large_grains})",
        1e3 / totals[0].ns(grains[0], None),
        1e3 / totals[1].ns(grains[1], None),
        1e3 / totals[2].ns(grains[2], None),
        1e3 / totals[3].ns(grains[3], None)
    );
}
