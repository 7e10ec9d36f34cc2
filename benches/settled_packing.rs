//! Throughput of a dense, settled packing: grain-steps per second at N = 1e3, 1e4,
//! 1e5 grains on 1 and 2 threads. Run: `cargo bench --bench settled_packing`.
//!
//! The packing is a simple cubic lattice compressed by 1 % (every grain has six
//! persistent contacts) inside a box of walls, without gravity, so the contact count
//! stays constant while it is timed.

use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

fn scene(per_side: usize) -> String {
    let r = 0.001;
    let spacing = 1.98 * r;
    let side = spacing * (per_side as f64 - 1.0) + 2.0 * r;
    format!(
        r#"Scene(
    name: "bench",
    steps: 1,
    initial_overlap_tolerance: 0.05,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.5, friction: 0.5))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: ({side}, {side}, {side}), material: "glass")],
    grains: [Lattice(material: "glass", radius: {r}, spacing: {spacing},
        region: (min: (0.0, 0.0, 0.0), max: ({side}, {side}, {side})))],
    output: (recording: false),
)"#
    )
}

fn settled_packing(c: &mut Criterion) {
    let mut group = c.benchmark_group("settled_packing");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    for per_side in [10usize, 22, 46] {
        let text = scene(per_side);
        let built = talus::scene::parse("bench.ron", &text)
            .unwrap()
            .build(&talus::registry())
            .unwrap();
        let n = built.grain_count;
        let mut sim = built.builder.build();
        sim.run_steps(20).unwrap();
        group.throughput(Throughput::Elements(n as u64));
        for threads in [1usize, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            group.bench_with_input(
                BenchmarkId::new(format!("{threads}_threads"), n),
                &n,
                |b, _| b.iter(|| pool.install(|| sim.step().unwrap())),
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
    targets = settled_packing
}
criterion_main!(benches);
