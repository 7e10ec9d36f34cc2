//! LAMMPS's chute algorithm written out as one plain Rust kernel, raced against Talus's step
//! on the same state: what a step with fewer passes — the overlap tests inside the force
//! loop, contact history kept per neighbour-list entry, no contact entities — buys when
//! compiled like Talus (`docs/performance.md`, "What the unmet targets would take").
//!
//! The kernel is `gran/hooke/history` with `newton on`, `nve/sphere`, `fix gravity` and
//! `fix freeze` as LAMMPS's sources write them, over a half neighbour list with a skin of
//! 0.1 that is rebuilt when a grain has moved more than half the skin (each step checked,
//! as `neigh_modify every 1 delay 0`), the tangential histories carried over from the old
//! list to the new by partner. It reads the state of `scenes/bench/chute.ron` after Talus
//! has built it (the same grains, in the same order in memory: rows of cells). Four
//! kernels ([`Variant`]): LAMMPS's algorithm as it stands; the same with Talus's staleness
//! test (fewer list builds, the same results); that one evaluating Talus's own linear law
//! through its lane form, with Talus's contact life cycle; and that one testing only the
//! pairs its blocks' moves can have closed, as Talus's narrow phase does. Each checks its
//! physics first, 100 steps from the data file: the first two against LAMMPS's output for
//! `bench/in.chute`, the others against Talus's own step (the run stops if one leaves
//! them).
//!
//! The race: blocks of 7 steps of the four kernels and of Talus's step in turn, 1 thread,
//! the first step of each block untimed (`benches/chute_blocks.rs`'s method), with each
//! kernel's time split into list builds, force loop, and kicks with drift, and its tests a
//! grain-step.
//!
//! `cargo bench --bench lammps_kernel` (40 rounds); `TALUS_ROUNDS=n` changes the rounds and
//! `TALUS_REPLICA=r` races `r` × `r` copies of the chute as well, in an eighth as many
//! rounds (0: the 32,000-grain chute alone, the default).

use std::time::Instant;

use glam::DVec3;

#[path = "support/chute_halves.rs"]
#[allow(dead_code)]
mod chute_halves;
use chute_halves::chute;
#[path = "support/rounds.rs"]
mod rounds;
use rounds::{env_count, median};
#[path = "support/lammps_kernel.rs"]
#[allow(dead_code)]
mod lammps_kernel;
use lammps_kernel::{Kernel, LAMMPS_STEP_100, TALUS_STEP_100, Variant};
use talus::core::schedule::Simulation;
use talus::core::snapshot::GrainSnapshot;

/// The `talus` binary's allocator, as in the other chute benches.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

/// Steps of a block; its first is not timed.
const BLOCK_STEPS: u64 = 7;

/// The chute of `replica` × `replica` copies, built and primed by Talus, with the
/// kernels made from the same state.
fn chute_and_kernels(replica: u32) -> (Simulation, [Kernel; Variant::ALL.len()], usize) {
    let (sim, grains) = chute(replica, replica, |_| {});
    let tilt = 26f64.to_radians();
    let gravity = DVec3::new(tilt.sin(), 0.0, -tilt.cos());
    let box_length = [40.0 * f64::from(replica), 20.0 * f64::from(replica)];
    let snapshot = sim.world.resource::<GrainSnapshot>();
    let kernels =
        Variant::ALL.map(|variant| Kernel::from_snapshot(snapshot, box_length, gravity, variant));
    (sim, kernels, grains)
}

/// Seconds of `BLOCK_STEPS − 1` timed steps, after one untimed.
fn timed_block(mut step: impl FnMut()) -> f64 {
    step();
    let start = Instant::now();
    for _ in 1..BLOCK_STEPS {
        step();
    }
    start.elapsed().as_secs_f64()
}

/// One block of Talus's step, the pool's other workers polling as in `talus run`.
fn talus_block(sim: &mut Simulation) -> f64 {
    talus::core::workers::with_workers_polling(|| {
        timed_block(|| sim.step_before_another().expect("the chute steps"))
    })
}

/// Races the kernels against Talus's step on `replica` × `replica` copies of the chute, all
/// in turn in each round, their order turning from round to round.
fn race(replica: u32, rounds: usize, pool: &rayon::ThreadPool) {
    let (mut sim, mut kernels, grains) = pool.install(|| chute_and_kernels(replica));
    // Warm up: lists built, tables sorted.
    for kernel in &mut kernels {
        for _ in 0..20 {
            kernel.step();
        }
    }
    pool.install(|| sim.run_steps(20).expect("the chute steps"));
    let builds_before = kernels.each_ref().map(|k| k.builds);
    let tested_before = kernels.each_ref().map(|k| k.tested);
    let split_before = kernels.each_ref().map(|k| k.seconds);
    // Seconds of the kernels and of Talus (last), in all and per round.
    const VARIANTS: usize = Variant::ALL.len() + 1;
    const TALUS: usize = VARIANTS - 1;
    let mut seconds = [0.0; VARIANTS];
    let mut per_round: Vec<[f64; VARIANTS]> = Vec::with_capacity(rounds);
    for round in 0..rounds {
        let mut this = [0.0; VARIANTS];
        for v in (0..VARIANTS).map(|k| (k + round) % VARIANTS) {
            this[v] = if v == TALUS {
                pool.install(|| talus_block(&mut sim))
            } else {
                timed_block(|| kernels[v].step())
            };
        }
        for v in 0..VARIANTS {
            seconds[v] += this[v];
        }
        per_round.push(this);
    }
    let grain_steps = grains as f64 * (rounds as u64 * (BLOCK_STEPS - 1)) as f64;
    let ns = |v: usize| seconds[v] / grain_steps * 1e9;
    println!("{grains} grains, {rounds} rounds, ns a grain-step over all rounds:");
    for (v, kernel) in kernels.iter().enumerate() {
        // The parts count every step, the untimed ones too.
        let steps = grains as f64 * (rounds as u64 * BLOCK_STEPS) as f64;
        let part = |k: usize| (kernel.seconds[k] - split_before[v][k]) / steps * 1e9;
        let against: Vec<f64> = per_round.iter().map(|r| r[TALUS] / r[v]).collect();
        println!(
            "  the {} kernel {:.1} ({:.2} M grain-steps/s): list builds {:.1} ({} builds), \
             force loop {:.1}, kicks, drift and staleness {:.1}; against Talus {:.3} over \
             all rounds, {:.3} by the rounds' median; {:.2} listed pairs a grain, {:.2} \
             tested a grain-step",
            kernel.variant.name(),
            ns(v),
            1e3 / ns(v),
            part(0),
            kernel.builds - builds_before[v],
            part(1),
            part(2),
            ns(TALUS) / ns(v),
            median(against),
            kernel.partner.len() as f64 / grains as f64,
            (kernel.tested - tested_before[v]) as f64 / steps,
        );
    }
    println!(
        "  Talus {:.1} ({:.2} M grain-steps/s)",
        ns(TALUS),
        1e3 / ns(TALUS)
    );
}

fn main() {
    let rounds = env_count("TALUS_ROUNDS", 40).max(1);
    let replica = env_count("TALUS_REPLICA", 0) as u32;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a thread pool");
    // The kernels' physics first: 100 steps from the data file's state, against LAMMPS's
    // output for LAMMPS's law and against Talus's own step for Talus's.
    let (_, kernels, _) = pool.install(|| chute_and_kernels(1));
    for mut kernel in kernels {
        let start = kernel.energies();
        for _ in 0..100 {
            kernel.step();
        }
        let (translational, rotational) = kernel.energies();
        let (reference, by) = if kernel.variant.talus_law() {
            (TALUS_STEP_100, "Talus")
        } else {
            (LAMMPS_STEP_100, "LAMMPS")
        };
        println!(
            "the {} kernel, 100 steps: Σ½mv² {:.4} → {translational:.10} ({by}: {}), \
             Σ½Iω² {rotational:.10} ({by}: {}); {} list builds",
            kernel.variant.name(),
            start.0,
            reference.0,
            reference.1,
            kernel.builds,
        );
        // LAMMPS prints 8 digits: a kernel outside them is not LAMMPS's algorithm, and
        // its race would say nothing. Talus's law must give Talus's step to rounding (its
        // forces are summed in another order).
        let tolerance = if kernel.variant.talus_law() {
            (1e-6, 1e-8)
        } else {
            (0.01, 1e-4)
        };
        assert!(
            (translational - reference.0).abs() < tolerance.0
                && (rotational - reference.1).abs() < tolerance.1,
            "the {} kernel left {by}'s energies",
            kernel.variant.name()
        );
    }
    race(1, rounds, &pool);
    if replica > 1 {
        race(replica, rounds.div_ceil(8), &pool);
    }
}
