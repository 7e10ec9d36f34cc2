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
//! plus ghosts — frozen copies of the other half's grains within [`HALO`] of the two cuts —
//! whose positions, velocities and spins are copied from the other half at the same barrier
//! every step, as a subdomain's ghost grains are refreshed by a forward communication. A
//! contact straddling a cut is evaluated on both sides (LAMMPS's `newton off`); nothing
//! migrates (the ghosts stay the grains that began within the halo, which the flow carries
//! along with their neighbours), so the halves keep the whole flow's contacts (within
//! 0.5 % of the whole replica's plus those straddling a cut, over 1,500 steps). A ghost is
//! frozen (zero inverse mass), so a straddling contact's dashpot takes the own grain's mass
//! for the reduced mass, as against the frozen base: a simplification of the physics that
//! changes none of the work.

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use bevy_ecs::prelude::ResMut;
use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use glam::DVec3;
use talus::core::schedule::Stage;
use talus::core::snapshot::GrainSnapshot;

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

/// The width of a half's halo across each cut: a grain's diameter and the neighbour list's
/// skin (LAMMPS's communication cut-off for this benchmark).
const HALO: f64 = 1.1;

/// The period of `data.chute` along x and y.
const CHUTE_BOX: (f64, f64) = (40.0, 20.0);

/// Which grains of the replica `x` × `y` half `half` (0: x below the middle, 1: above)
/// holds: its own (type as in the file) and, after them, the ghosts (type 3, or 2 for the
/// frozen base), each with the shift along x that places it beside the half's cut; and the
/// count of its own.
fn half_atoms(
    atoms: &[talus::scene::lammps::Atom],
    x: u32,
    y: u32,
    half: usize,
) -> (Vec<talus::scene::lammps::Atom>, usize) {
    let (lx, ly) = CHUTE_BOX;
    let period = lx * f64::from(x);
    let (lo, hi) = if half == 0 {
        (0.0, period / 2.0)
    } else {
        (period / 2.0, period)
    };
    let replica = (0..x)
        .flat_map(|i| (0..y).map(move |j| (i, j)))
        .flat_map(|(i, j)| {
            atoms.iter().map(move |a| {
                let mut a = *a;
                a.position += DVec3::new(f64::from(i) * lx, f64::from(j) * ly, 0.0);
                a
            })
        });
    let (mut own, mut ghosts) = (Vec::new(), Vec::new());
    for mut a in replica {
        if (lo..hi).contains(&a.position.x) {
            own.push(a);
            continue;
        }
        let beside = [0.0, period, -period].into_iter().find(|shift| {
            let x = a.position.x + shift;
            (lo - HALO..lo).contains(&x) || (hi..hi + HALO).contains(&x)
        });
        if let Some(shift) = beside {
            a.position.x += shift;
            if a.atom_type != 2 {
                a.atom_type = 3;
            }
            ghosts.push(a);
        }
    }
    let count = own.len();
    own.extend(ghosts);
    (own, count)
}

/// One half of [`half_atoms`] as a scene (periodic in y only, the ghosts a frozen material
/// of their own), written with its data file under `dir`, built with `extend`, primed.
fn exchanged_half(
    dir: &Path,
    x: u32,
    y: u32,
    half: usize,
    atoms: &[talus::scene::lammps::Atom],
    extend: impl FnOnce(&mut talus::core::schedule::SimBuilder),
) -> talus::core::schedule::Simulation {
    use std::fmt::Write;
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let base = std::fs::read_to_string(root.join("chute.ron")).expect("scenes/bench/chute.ron");
    let period_y = CHUTE_BOX.1 * f64::from(y);
    let name = format!("chute-{x}x{y}-half{half}.data");
    let mut data = format!(
        "half {half} of the chute {x}x{y} with its halo\n\n{} atoms\n3 atom types\n\nAtoms\n\n",
        atoms.len()
    );
    for (n, a) in atoms.iter().enumerate() {
        let p = a.position;
        writeln!(
            data,
            "{} {} {:?} {:?} {:?} {:?} {:?}",
            n + 1,
            a.atom_type,
            a.diameter,
            a.density,
            p.x,
            p.y,
            p.z
        )
        .unwrap();
    }
    data.push_str("\nVelocities\n\n");
    for (n, a) in atoms.iter().enumerate() {
        let (v, w) = (a.velocity, a.angular_velocity);
        writeln!(
            data,
            "{} {:?} {:?} {:?} {:?} {:?} {:?}",
            n + 1,
            v.x,
            v.y,
            v.z,
            w.x,
            w.y,
            w.z
        )
        .unwrap();
    }
    std::fs::write(dir.join(&name), data).expect("a writable bench directory");
    let text = base
        .replace(
            "periodic: (x: (0.0, 40.0), y: (0.0, 20.0)),",
            &format!("periodic: (y: (0.0, {period_y:?})),"),
        )
        .replace(
            "            contact: (law: \"linear_spring\", stiffness: 2e5, damping_rate: 50.0, friction: 0.5)),\n    ],",
            "            contact: (law: \"linear_spring\", stiffness: 2e5, damping_rate: 50.0, friction: 0.5)),\n        (name: \"ghost\", density: 1.0,\n            contact: (law: \"linear_spring\", stiffness: 2e5, damping_rate: 50.0, friction: 0.5)),\n    ],",
        )
        .replace("file: \"data.chute\"", &format!("file: \"{name}\""))
        .replace(
            "(type: 2, material: \"base\", frozen: true),",
            "(type: 2, material: \"base\", frozen: true),\n        (type: 3, material: \"ghost\", frozen: true),",
        );
    assert!(
        text.contains("\"ghost\", frozen: true"),
        "chute.ron changed: update the halves' scene"
    );
    let scene = talus::scene::parse(dir.join("chute-half.ron"), &text).expect("valid scene");
    let mut built = scene.build(&talus::registry()).expect("valid scene");
    extend(&mut built.builder);
    let mut sim = built.builder.build();
    sim.prime().unwrap();
    sim.world
        .resource_mut::<talus::core::resources::KineticEnergyDue>()
        .0 = false;
    sim
}

/// The grains a half sends (dense indices in its snapshot, in the order of the other half's
/// ghosts) and the ghosts it receives (dense index and shift along x).
#[derive(Clone, Default)]
struct HaloPlan {
    sends: Vec<usize>,
    receives: Vec<(usize, f64)>,
}

/// One ghost's state as sent: position, velocity, spin.
type GhostState = (DVec3, DVec3, DVec3);

/// The halves' exchange: each half's sent states, by the parity of the step (a half writes
/// the next step's while the other may still read this step's), and the barrier between
/// sending and receiving ([`StepBarrier`]).
#[derive(Default)]
struct HaloExchange {
    sent: [[Mutex<Vec<GhostState>>; 2]; 2],
    barrier: StepBarrier,
    plans: [Mutex<HaloPlan>; 2],
}

impl HaloExchange {
    /// Half `half`'s step: send its grains' states, meet the other half, copy the other's
    /// into its ghosts' records. Idle until the barrier is armed.
    fn exchange(
        &self,
        half: usize,
        step: &mut usize,
        plan: &mut Option<HaloPlan>,
        s: &mut GrainSnapshot,
    ) {
        if !self.barrier.armed.load(Ordering::Acquire) {
            return;
        }
        let plan = plan.get_or_insert_with(|| self.plans[half].lock().unwrap().clone());
        let parity = *step % 2;
        {
            let mut sent = self.sent[half][parity].lock().unwrap();
            sent.clear();
            sent.extend(
                plan.sends
                    .iter()
                    .map(|&i| (s.records[i].position, s.records[i].velocity, s.omega[i])),
            );
        }
        self.barrier.wait(step);
        let received = self.sent[1 - half][parity].lock().unwrap();
        for (&(i, shift), &(p, v, w)) in plan.receives.iter().zip(received.iter()) {
            s.records[i].position = p + DVec3::new(shift, 0.0, 0.0);
            s.records[i].velocity = v;
            s.omega[i] = w;
        }
    }
}

/// Which grains of `from` the ghosts (material `ghost`) of `to` copy, found by position
/// (a ghost is its grain shifted along x by 0 or a period).
fn match_ghosts(
    to: &GrainSnapshot,
    ghost: u16,
    from: &GrainSnapshot,
    from_ghost: u16,
    period: f64,
) -> (Vec<usize>, Vec<(usize, f64)>) {
    let mut by_height: HashMap<(u64, u64), Vec<usize>> = HashMap::new();
    for i in (0..from.len()).filter(|&i| from.material[i] != from_ghost) {
        let p = from.records[i].position;
        by_height
            .entry((p.y.to_bits(), p.z.to_bits()))
            .or_default()
            .push(i);
    }
    let (mut sends, mut receives) = (Vec::new(), Vec::new());
    for g in (0..to.len()).filter(|&g| to.material[g] == ghost) {
        let p = to.records[g].position;
        let (source, shift) = by_height[&(p.y.to_bits(), p.z.to_bits())]
            .iter()
            .find_map(|&i| {
                let dx = p.x - from.records[i].position.x;
                [0.0, period, -period]
                    .into_iter()
                    .find(|s| (dx - s).abs() < 1e-9)
                    .map(|s| (i, s))
            })
            .expect("every ghost is a grain of the other half");
        sends.push(source);
        receives.push((g, shift));
    }
    (sends, receives)
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
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    for replicate in [1u32, 2, 4] {
        let exchange = Arc::new(HaloExchange::default());
        let pools: Vec<rayon::ThreadPool> = (0..2)
            .map(|_| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(1)
                    .build()
                    .unwrap()
            })
            .collect();
        let mut own = 0;
        let mut halves: Vec<talus::core::schedule::Simulation> = (0..2)
            .map(|half| {
                let (half_atoms, own_atoms) = half_atoms(&atoms, replicate, replicate, half);
                own += own_atoms;
                let exchange = exchange.clone();
                let (mut step, mut plan) = (0, None);
                pools[half].install(|| {
                    exchanged_half(
                        dir,
                        replicate,
                        replicate,
                        half,
                        &half_atoms,
                        move |builder| {
                            builder.add_system(
                                Stage::BroadPhase,
                                "halo_exchange",
                                move |mut s: ResMut<GrainSnapshot>| {
                                    exchange.exchange(half, &mut step, &mut plan, &mut s)
                                },
                            );
                        },
                    )
                })
            })
            .collect();
        let ghost_material = |sim: &talus::core::schedule::Simulation| {
            let materials = sim.world.resource::<talus::core::resources::Materials>();
            materials
                .0
                .iter()
                .position(|m| m.name == "ghost")
                .expect("a ghost material") as u16
        };
        let period = CHUTE_BOX.0 * f64::from(replicate);
        for half in 0..2 {
            let (to, from) = (&halves[half], &halves[1 - half]);
            let (sends, receives) = match_ghosts(
                to.world.resource::<GrainSnapshot>(),
                ghost_material(to),
                from.world.resource::<GrainSnapshot>(),
                ghost_material(from),
                period,
            );
            exchange.plans[1 - half].lock().unwrap().sends = sends;
            exchange.plans[half].lock().unwrap().receives = receives;
        }
        exchange.barrier.armed.store(true, Ordering::Release);
        step_halves(&mut halves, &pools, &exchange.barrier, 20);
        group.throughput(Throughput::Elements(10 * own as u64));
        group.bench_function(BenchmarkId::new(format!("{own} grains"), 2), |b| {
            b.iter_custom(|iters| {
                let start = Instant::now();
                step_halves(&mut halves, &pools, &exchange.barrier, 10 * iters);
                start.elapsed()
            })
        });
    }
    group.finish();
}

/// Steps both halves `steps` steps at once, each on its own pool; a half that stops early
/// opens the barrier so that the other does not wait for it forever.
fn step_halves(
    halves: &mut [talus::core::schedule::Simulation],
    pools: &[rayon::ThreadPool],
    barrier: &StepBarrier,
    steps: u64,
) {
    std::thread::scope(|scope| {
        for (sim, pool) in halves.iter_mut().zip(pools) {
            scope.spawn(move || {
                let stepped = pool.install(|| sim.run_steps(steps));
                if stepped.is_err() {
                    barrier.armed.store(false, Ordering::Release);
                }
                stepped.unwrap()
            });
        }
    });
}

criterion_group! {
    name = benches;
    // No plots: the workspace's plotters carries only the fonts talus-plot registers, so
    // criterion's own charts cannot draw text. The numbers are what matter here.
    config = Criterion::default().without_plots();
    targets = bench, two_halves, halves_exchanged
}
criterion_main!(benches);
