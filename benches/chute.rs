//! LAMMPS's chute benchmark (`scenes/bench/chute.ron`) and its 2×2 and 4×4 replicas
//! (128,000 and 512,000 grains): grain-steps per second on 1 and 2 threads.
//!
//! `cargo bench --bench chute` prints, per size and thread count, criterion's time per
//! 10 steps and the throughput in grain-steps per second (criterion "elements").

use std::path::Path;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

/// The `talus` binary's allocator (large blocks on huge pages), so that the bench measures
/// what a run measures.
#[global_allocator]
static ALLOCATOR: talus::cli::alloc::HugePageAllocator = talus::cli::alloc::HugePageAllocator;

fn chute(replicate: u32) -> (talus::core::schedule::Simulation, usize) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let base = std::fs::read_to_string(root.join("chute.ron")).expect("scenes/bench/chute.ron");
    let text = base
        .replace(
            "periodic: (x: (0.0, 40.0), y: (0.0, 20.0)),",
            &format!("periodic: (x: (0.0, {}), y: (0.0, {})),", 40 * replicate, 20 * replicate),
        )
        .replace(
            "grains: [LammpsData(file: \"data.chute\",",
            &format!("grains: [LammpsData(file: \"data.chute\", replicate: ({replicate}, {replicate}, 1),"),
        );
    let scene = talus::scene::parse(root.join("chute-bench.ron"), &text).expect("valid scene");
    let built = scene.build(&talus::registry()).expect("valid scene");
    let n = built.grain_count;
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
            let (mut sim, n) = pool.install(|| chute(replicate));
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

criterion_group! {
    name = benches;
    // No plots: the workspace's plotters carries only the fonts talus-plot registers, so
    // criterion's own charts cannot draw text. The numbers are what matter here.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
