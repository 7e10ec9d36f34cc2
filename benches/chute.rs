//! LAMMPS's chute benchmark (`scenes/bench/chute.ron`) and its 2×2 and 4×4 replicas
//! (128,000 and 512,000 grains): grain-steps per second on 1 and 2 threads.
//!
//! `cargo bench --bench chute` prints, per size and thread count, criterion's time per
//! 10 steps and the throughput in grain-steps per second (criterion "elements").
//!
//! A second group, `chute_two_halves`, times what a perfect split of each replica into two
//! subdomains would give on two cores: its two halves (the replica cut in two along y)
//! stepped at once as two independent simulations, one thread each, meeting once a step as
//! subdomains exchanging their halos would, and sharing nothing else — no halo, no exchange,
//! no serial bookkeeping. Set beside the replica's 1- and 2-thread rates it bounds what
//! owning each half on its own thread could buy (`docs/performance.md`, "What the unmet
//! targets would take").

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use talus::core::schedule::Stage;

/// The `talus` binary's allocator (large blocks on huge pages), so that the bench measures
/// what a run measures.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

/// The chute replicated `x` × `y` times in x–y, primed, with its grain count; `extend`
/// may add systems before the simulation is built.
fn chute(
    x: u32,
    y: u32,
    extend: impl FnOnce(&mut talus::core::schedule::SimBuilder),
) -> (talus::core::schedule::Simulation, usize) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let base = std::fs::read_to_string(root.join("chute.ron")).expect("scenes/bench/chute.ron");
    let text = base
        .replace(
            "periodic: (x: (0.0, 40.0), y: (0.0, 20.0)),",
            &format!("periodic: (x: (0.0, {}), y: (0.0, {})),", 40 * x, 20 * y),
        )
        .replace(
            "grains: [LammpsData(file: \"data.chute\",",
            &format!("grains: [LammpsData(file: \"data.chute\", replicate: ({x}, {y}, 1),"),
        );
    let scene = talus::scene::parse(root.join("chute-bench.ron"), &text).expect("valid scene");
    let mut built = scene.build(&talus::registry()).expect("valid scene");
    let n = built.grain_count;
    extend(&mut built.builder);
    let mut sim = built.builder.build();
    sim.prime().unwrap();
    // Nothing reads the energies between steps here: as `talus run` does between its
    // reports, the second kick does not sum them.
    sim.world
        .resource_mut::<talus::core::resources::KineticEnergyDue>()
        .0 = false;
    (sim, n)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("chute");
    group.sample_size(10);
    for replicate in [1u32, 2, 4] {
        for threads in [1usize, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let (mut sim, n) = pool.install(|| chute(replicate, replicate, |_| {}));
            // Warm the flow past its first neighbour-list builds.
            pool.install(|| sim.run_steps(20).unwrap());
            group.throughput(Throughput::Elements(10 * n as u64));
            group.bench_with_input(
                BenchmarkId::new(format!("{n} grains"), threads),
                &threads,
                |b, _| b.iter(|| pool.install(|| sim.run_steps(10).unwrap())),
            );
        }
    }
    group.finish();
}

/// A barrier the two halves of [`two_halves`] meet at once a step, spinning (a parked
/// virtual CPU takes 50–75 µs to wake on the machines this is developed on), where a
/// subdomain would exchange its halo. Open until `armed`, so each half primes alone, and
/// opened again if a half stops early, so the other does not wait for it forever.
#[derive(Default)]
struct StepBarrier {
    armed: AtomicBool,
    arrived: AtomicUsize,
}

impl StepBarrier {
    /// Waits, on the half's `round`-th arrival, for the other half's.
    fn wait(&self, round: &mut usize) {
        if !self.armed.load(Ordering::Acquire) {
            return;
        }
        *round += 1;
        self.arrived.fetch_add(1, Ordering::AcqRel);
        while self.arrived.load(Ordering::Acquire) < 2 * *round
            && self.armed.load(Ordering::Relaxed)
        {
            std::hint::spin_loop();
        }
    }
}

/// The two halves of the 128,000- and 512,000-grain replicas (2×1 and 4×2 copies: each
/// replica cut along y), stepped at once on two threads, each with a pool of one, meeting
/// at a [`StepBarrier`] at the end of every step's broad phase: what a two-subdomain split
/// could reach before any cost of its own (halo, exchange, migration), to set beside the
/// replica's 2-thread rate.
fn two_halves(c: &mut Criterion) {
    let mut group = c.benchmark_group("chute_two_halves");
    group.sample_size(10);
    for (x, y) in [(2u32, 1u32), (4, 2)] {
        let barrier = Arc::new(StepBarrier::default());
        let pools: Vec<rayon::ThreadPool> = (0..2)
            .map(|_| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(1)
                    .build()
                    .unwrap()
            })
            .collect();
        let mut halves: Vec<(talus::core::schedule::Simulation, usize)> = pools
            .iter()
            .map(|pool| {
                let barrier = barrier.clone();
                let mut round = 0;
                let (mut sim, n) = pool.install(|| {
                    chute(x, y, move |builder| {
                        builder.add_system(Stage::BroadPhase, "step_barrier", move || {
                            barrier.wait(&mut round)
                        });
                    })
                });
                pool.install(|| sim.run_steps(20).unwrap());
                (sim, n)
            })
            .collect();
        barrier.armed.store(true, Ordering::Release);
        let grains: usize = halves.iter().map(|(_, n)| n).sum();
        group.throughput(Throughput::Elements(10 * grains as u64));
        group.bench_function(BenchmarkId::new(format!("{grains} grains"), 2), |b| {
            // Both halves always step the same count, so their barrier rounds stay paired.
            b.iter_custom(|iters| {
                let start = Instant::now();
                std::thread::scope(|scope| {
                    for ((sim, _), pool) in halves.iter_mut().zip(&pools) {
                        let barrier = &barrier;
                        scope.spawn(move || {
                            let stepped = pool.install(|| sim.run_steps(10 * iters));
                            if stepped.is_err() {
                                barrier.armed.store(false, Ordering::Release);
                            }
                            stepped.unwrap()
                        });
                    }
                });
                start.elapsed()
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: the workspace's plotters carries only the fonts talus-plot registers, so
    // criterion's own charts cannot draw text. The numbers are what matter here.
    config = Criterion::default().without_plots();
    targets = bench, two_halves
}
criterion_main!(benches);
