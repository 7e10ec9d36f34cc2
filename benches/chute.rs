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
//!
//! A third group, `chute_halves_exchanged`, times that split with its halo: each replica
//! cut across x (the flow's direction) into two halves, each a simulation of its own grains
//! plus ghosts — frozen copies of the other half's grains within 1.1 d (a diameter and the
//! list's skin) of the two cuts — whose positions, velocities and spins are copied from the
//! other half at the same barrier every step, as a subdomain's ghost grains are refreshed by
//! a forward communication. A contact straddling a cut is evaluated on both sides (LAMMPS's
//! `newton off`); nothing migrates (the ghosts stay the grains that began within the halo,
//! which the flow carries along with their neighbours), so the halves keep the whole flow's
//! contacts (within 0.5 % of the whole replica's plus those straddling a cut, over 1,500
//! steps). A ghost is frozen (zero inverse mass), so a straddling contact's dashpot takes the
//! own grain's mass for the reduced mass, as against the frozen base: a simplification of
//! the physics that changes none of the work. The `chute_rounds` bench runs the same halves interleaved,
//! round by round, with the whole replica on 1 and 2 threads.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use talus::core::schedule::Stage;

#[path = "support/chute_halves.rs"]
mod chute_halves;
use chute_halves::{ExchangedHalves, StepBarrier, chute, pools_of_one, step_halves};

/// The `talus` binary's allocator (large blocks on huge pages), so that the bench measures
/// what a run measures.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

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
        let pools = pools_of_one();
        let halves: Vec<(talus::core::schedule::Simulation, usize)> = pools
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
        let mut halves: Vec<_> = halves.into_iter().map(|(sim, _)| sim).collect();
        group.bench_function(BenchmarkId::new(format!("{grains} grains"), 2), |b| {
            // Both halves always step the same count, so their barrier rounds stay paired.
            b.iter_custom(|iters| {
                let start = Instant::now();
                step_halves(&mut halves, &pools, &barrier, 10 * iters);
                start.elapsed()
            })
        });
    }
    group.finish();
}

/// The two halves of the 32,000-, 128,000- and 512,000-grain replicas cut across x, each
/// with its halo refreshed from the other every step ([`HaloExchange`]), stepped at once on
/// two threads with a pool of one each: a two-subdomain split with its halo's arithmetic
/// and communication (but no migration), to set beside the replica's 2-thread rate. The
/// throughput counts each half's own grains only.
fn halves_exchanged(c: &mut Criterion) {
    let mut group = c.benchmark_group("chute_halves_exchanged");
    group.sample_size(10);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let atoms = talus::scene::lammps::read_data(&root.join("data.chute")).expect("data.chute");
    for replicate in [1u32, 2, 4] {
        let mut halves =
            ExchangedHalves::new(&atoms, replicate, Path::new(env!("CARGO_TARGET_TMPDIR")));
        halves.run_steps(20);
        let own = halves.own_grains;
        group.throughput(Throughput::Elements(10 * own as u64));
        group.bench_function(BenchmarkId::new(format!("{own} grains"), 2), |b| {
            b.iter_custom(|iters| {
                let start = Instant::now();
                halves.run_steps(10 * iters);
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
    targets = bench, two_halves, halves_exchanged
}
criterion_main!(benches);
