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
//! has built it (the same grains, in the same order in memory: rows of cells). Five
//! kernels ([`Variant`]): LAMMPS's algorithm as it stands; the same with Talus's staleness
//! test (fewer list builds, the same results); that one in three passes as Talus's step
//! takes them (overlap tests, force loop, sums: the same results); the second evaluating
//! Talus's own linear law through its lane form, with Talus's contact life cycle; and that
//! one testing only the pairs its blocks' moves can have closed, as Talus's narrow phase
//! does. Each checks its physics first, 100 steps from the data file: the first three
//! against LAMMPS's output for `bench/in.chute`, the others against Talus's own step (the
//! run stops if one leaves them).
//!
//! The race: blocks of 7 steps of the five kernels and of Talus's step in turn, 1 thread,
//! the first step of each block untimed (`benches/chute_blocks.rs`'s method), with each
//! kernel's time split into list builds, force loop, and kicks with drift, and its tests a
//! grain-step (and the three-pass kernel's time split into its passes).
//!
//! `cargo bench --bench lammps_kernel` (40 rounds); `TALUS_ROUNDS=n` changes the rounds and
//! `TALUS_REPLICA=r` then races `r` × `r` copies of the chute and a fresh 32,000-grain
//! chute in the same rounds, an eighth as many, for every kernel's and Talus's per-grain
//! rate over the same steps (0: the 32,000-grain chute alone, the default). Sizes must be
//! compared over the same steps: the LAMMPS-law kernels' rate drifts by some 9 % as the
//! flow goes on (`docs/performance-log.md`, session 61).

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

/// Seconds of the kernels and of Talus's step (last) in a round.
const VARIANTS: usize = Variant::ALL.len() + 1;
/// Talus's place among them.
const TALUS: usize = VARIANTS - 1;

/// The kernels and Talus's step on `replica` × `replica` copies of the chute, warmed up,
/// and the seconds of each round.
struct Race {
    sim: Simulation,
    kernels: [Kernel; Variant::ALL.len()],
    grains: usize,
    builds_before: [u64; Variant::ALL.len()],
    tested_before: [u64; Variant::ALL.len()],
    split_before: [[f64; 3]; Variant::ALL.len()],
    passes_before: [[f64; 3]; Variant::ALL.len()],
    out_of_order_before: [f64; Variant::ALL.len()],
    per_round: Vec<[f64; VARIANTS]>,
}

impl Race {
    fn new(replica: u32, pool: &rayon::ThreadPool) -> Self {
        let (mut sim, mut kernels, grains) = pool.install(|| chute_and_kernels(replica));
        // Warm up: lists built, tables sorted.
        for kernel in &mut kernels {
            for _ in 0..20 {
                kernel.step();
            }
        }
        pool.install(|| sim.run_steps(20).expect("the chute steps"));
        Self {
            builds_before: kernels.each_ref().map(|k| k.builds),
            tested_before: kernels.each_ref().map(|k| k.tested),
            split_before: kernels.each_ref().map(|k| k.seconds),
            passes_before: kernels.each_ref().map(|k| k.pass_seconds),
            out_of_order_before: kernels.each_ref().map(|k| k.out_of_order),
            sim,
            kernels,
            grains,
            per_round: Vec::new(),
        }
    }

    /// One block of each kernel and of Talus's step, in an order that turns with `round`.
    fn round(&mut self, round: usize, pool: &rayon::ThreadPool) {
        let mut this = [0.0; VARIANTS];
        for v in (0..VARIANTS).map(|k| (k + round) % VARIANTS) {
            this[v] = if v == TALUS {
                pool.install(|| talus_block(&mut self.sim))
            } else {
                timed_block(|| self.kernels[v].step())
            };
        }
        self.per_round.push(this);
    }

    /// Ns a grain-step of each variant (Talus last) over all rounds.
    fn ns(&self) -> [f64; VARIANTS] {
        self.ns_over(&self.per_round)
    }

    /// Ns a grain-step of each variant (Talus last) over `rounds`, some of this race's.
    fn ns_over(&self, rounds: &[[f64; VARIANTS]]) -> [f64; VARIANTS] {
        let grain_steps = self.grains as f64 * (rounds.len() as u64 * (BLOCK_STEPS - 1)) as f64;
        std::array::from_fn(|v| rounds.iter().map(|r| r[v]).sum::<f64>() / grain_steps * 1e9)
    }

    /// Each kernel's time, its parts and its ratio to Talus's.
    fn report(&self) {
        let rounds = self.per_round.len();
        let grains = self.grains;
        let ns = self.ns();
        println!("{grains} grains, {rounds} rounds, ns a grain-step over all rounds:");
        for (v, kernel) in self.kernels.iter().enumerate() {
            // The parts count every step, the untimed ones too.
            let steps = grains as f64 * (rounds as u64 * BLOCK_STEPS) as f64;
            let part = |k: usize| (kernel.seconds[k] - self.split_before[v][k]) / steps * 1e9;
            let against: Vec<f64> = self.per_round.iter().map(|r| r[TALUS] / r[v]).collect();
            println!(
                "  the {} kernel {:.1} ({:.2} M grain-steps/s): list builds {:.1} ({} builds), \
                 force loop {:.1}, kicks, drift and staleness {:.1}; against Talus {:.3} over \
                 all rounds, {:.3} by the rounds' median; {:.2} listed pairs a grain, {:.2} \
                 tested a grain-step, {:.1} % of the grains out of their cells' order ({:.1} \
                 before the rounds)",
                kernel.variant.name(),
                ns[v],
                1e3 / ns[v],
                part(0),
                kernel.builds - self.builds_before[v],
                part(1),
                part(2),
                ns[TALUS] / ns[v],
                median(against),
                kernel.partner.len() as f64 / grains as f64,
                (kernel.tested - self.tested_before[v]) as f64 / steps,
                100.0 * kernel.out_of_order,
                100.0 * self.out_of_order_before[v],
            );
            if kernel.variant == Variant::Passes {
                let pass =
                    |k: usize| (kernel.pass_seconds[k] - self.passes_before[v][k]) / steps * 1e9;
                println!(
                    "    its force loop's passes: overlap tests {:.1}, forces {:.1}, sums {:.1}",
                    pass(0),
                    pass(1),
                    pass(2)
                );
            }
        }
        println!(
            "  Talus {:.1} ({:.2} M grain-steps/s)",
            ns[TALUS],
            1e3 / ns[TALUS]
        );
        // Whether a rate drifts as the flow goes on: the first and the last eighth of the
        // rounds.
        let eighth = rounds / 8;
        if eighth > 0 {
            let early = self.ns_over(&self.per_round[..eighth]);
            let late = self.ns_over(&self.per_round[rounds - eighth..]);
            let drift: Vec<String> = (0..VARIANTS)
                .map(|v| format!("{:.1} → {:.1}", early[v], late[v]))
                .collect();
            println!(
                "  the first and the last {eighth} rounds, in the order above: {}",
                drift.join(", ")
            );
        }
    }
}

/// Races the kernels against Talus's step on `replica` × `replica` copies of the chute, all
/// in turn in each round, their order turning from round to round.
fn race(replica: u32, rounds: usize, pool: &rayon::ThreadPool) {
    let mut race = Race::new(replica, pool);
    for round in 0..rounds {
        race.round(round, pool);
    }
    race.report();
}

/// Each kernel's and Talus's per-grain rate at `replica` × `replica` copies of the chute
/// against the 32,000-grain chute's: both sizes raced in the same rounds, from the same
/// state and over the same steps (a kernel never sorts its grains in memory, so its rate
/// at a size depends on how far the flow has carried them from their first order), the
/// sizes' order turning from round to round.
fn per_grain(replica: u32, rounds: usize, pool: &rayon::ThreadPool) {
    let mut sizes = [Race::new(1, pool), Race::new(replica, pool)];
    for round in 0..rounds {
        for s in [round % 2, 1 - round % 2] {
            sizes[s].round(round, pool);
        }
    }
    for size in &sizes {
        size.report();
    }
    let (small, large) = (sizes[0].ns(), sizes[1].ns());
    println!(
        "per-grain rate, {} grains against {}, over all rounds (the rounds' median):",
        sizes[1].grains, sizes[0].grains
    );
    let names = Variant::ALL.map(|v| v.name());
    for v in 0..VARIANTS {
        let name = if v == TALUS { "Talus" } else { names[v] };
        let by_round: Vec<f64> = sizes[0]
            .per_round
            .iter()
            .zip(&sizes[1].per_round)
            .map(|(a, b)| (a[v] / sizes[0].grains as f64) / (b[v] / sizes[1].grains as f64))
            .collect();
        println!(
            "  {name}: {:.3} ({:.3})",
            small[v] / large[v],
            median(by_round)
        );
    }
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
    let mut after_100 = Vec::new();
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
        after_100.push((kernel.variant, translational, rotational));
    }
    // The three passes only part the refined kernel's work: the same sums in the same
    // order.
    let energies_of = |v: Variant| after_100.iter().find(|e| e.0 == v).map(|e| (e.1, e.2));
    assert_eq!(
        energies_of(Variant::Passes),
        energies_of(Variant::Refined),
        "the three-pass kernel left the refined kernel's bits"
    );
    race(1, rounds, &pool);
    if replica > 1 {
        per_grain(replica, rounds.div_ceil(8), &pool);
    }
}
