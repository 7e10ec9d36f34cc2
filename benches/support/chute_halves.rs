//! The chute benchmark's scenes for the benches: the replicas of `scenes/bench/chute.ron`, and
//! the replicas cut in two halves that step at once on two threads — whole periodic halves
//! (no halo) or halves cut across x whose halo of ghost grains is copied from the other half
//! every step ([`ExchangedHalves`]), the stand-in of a two-subdomain split.

use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use bevy_ecs::prelude::ResMut;
use glam::DVec3;
use talus::core::schedule::{Simulation, Stage};
use talus::core::snapshot::GrainSnapshot;

/// The chute replicated `x` × `y` times in x–y, primed, with its grain count; `extend`
/// may add systems before the simulation is built.
pub fn chute(
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
    build_primed(&root.join("chute-bench.ron"), &text, extend)
}

/// The scene `text` (read as if from `path`) built with `extend` and primed, with its grain
/// count.
fn build_primed(
    path: &Path,
    text: &str,
    extend: impl FnOnce(&mut talus::core::schedule::SimBuilder),
) -> (Simulation, usize) {
    let scene = talus::scene::parse(path, text).expect("valid scene");
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

/// Two rayon pools of one thread each, one a half.
pub fn pools_of_one() -> Vec<rayon::ThreadPool> {
    (0..2)
        .map(|_| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
        })
        .collect()
}

/// A barrier two halves meet at once a step, spinning (a parked
/// virtual CPU takes 50–75 µs to wake on the machines this is developed on), where a
/// subdomain would exchange its halo. Open until `armed`, so each half primes alone, and
/// opened again if a half stops early, so the other does not wait for it forever.
#[derive(Default)]
pub struct StepBarrier {
    /// Whether the halves wait for each other (open until set; cleared if a half stops).
    pub armed: AtomicBool,
    /// Arrivals so far, both halves together.
    pub arrived: AtomicUsize,
}

impl StepBarrier {
    /// Waits, on the half's `round`-th arrival, for the other half's.
    pub fn wait(&self, round: &mut usize) {
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

/// The width of a half's halo across each cut: a grain's diameter and the neighbour list's
/// skin (LAMMPS's communication cut-off for this benchmark).
pub const HALO: f64 = 1.1;

/// The period of `data.chute` along x and y.
pub const CHUTE_BOX: (f64, f64) = (40.0, 20.0);

/// Which grains of the replica `x` × `y` half `half` (0: x below the middle, 1: above)
/// holds: its own (type as in the file) and, after them, the ghosts (type 3, or 2 for the
/// frozen base), each with the shift along x that places it beside the half's cut; and the
/// count of its own.
pub fn half_atoms(
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
pub fn exchanged_half(
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
    // Each substitution must have found its text, or the halves would run another scene.
    assert!(
        text.contains("periodic: (y:")
            && text.contains("(name: \"ghost\"")
            && text.contains(&format!("file: \"{name}\""))
            && text.contains("\"ghost\", frozen: true"),
        "chute.ron changed: update the halves' scene"
    );
    build_primed(&dir.join("chute-half.ron"), &text, extend).0
}

/// The grains a half sends (dense indices in its snapshot, in the order of the other half's
/// ghosts) and the ghosts it receives (dense index and shift along x).
#[derive(Clone, Default)]
pub struct HaloPlan {
    /// Dense indices of the grains sent, in the order of the other half's ghosts.
    pub sends: Vec<usize>,
    /// Dense index of each ghost received, with its shift along x.
    pub receives: Vec<(usize, f64)>,
}

/// One ghost's state as sent: position, velocity, spin.
pub type GhostState = (DVec3, DVec3, DVec3);

/// The halves' exchange: each half's sent states, by the parity of the step (a half writes
/// the next step's while the other may still read this step's), and the barrier between
/// sending and receiving ([`StepBarrier`]).
#[derive(Default)]
pub struct HaloExchange {
    /// What each half sent, by the parity of its step.
    pub sent: [[Mutex<Vec<GhostState>>; 2]; 2],
    /// Where the halves meet between sending and receiving.
    pub barrier: StepBarrier,
    /// What each half sends and receives (set once both are primed).
    pub plans: [Mutex<HaloPlan>; 2],
}

impl HaloExchange {
    /// Half `half`'s step: send its grains' states, meet the other half, copy the other's
    /// into its ghosts' records. Idle until the barrier is armed.
    pub fn exchange(
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
pub fn match_ghosts(
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

/// The two halves of the chute replica `r` × `r` cut across x, each with its halo exchanged
/// every step ([`HaloExchange`]), primed, each with a rayon pool of one thread.
pub struct ExchangedHalves {
    /// The halves.
    pub halves: Vec<Simulation>,
    /// Their pools, one thread each.
    pub pools: Vec<rayon::ThreadPool>,
    /// Their exchange (and barrier).
    pub exchange: Arc<HaloExchange>,
    /// The grains the halves own (ghosts not counted).
    pub own_grains: usize,
}

impl ExchangedHalves {
    /// Builds and primes both halves of the replica `r` × `r` from `atoms` (`data.chute`'s),
    /// writing their data files under `dir`, and matches each half's ghosts to the other's
    /// grains.
    pub fn new(atoms: &[talus::scene::lammps::Atom], r: u32, dir: &Path) -> Self {
        let exchange = Arc::new(HaloExchange::default());
        let pools = pools_of_one();
        let mut own_grains = 0;
        let halves: Vec<Simulation> = (0..2)
            .map(|half| {
                let (half_atoms, own) = half_atoms(atoms, r, r, half);
                own_grains += own;
                let exchange = exchange.clone();
                let (mut step, mut plan) = (0, None);
                pools[half].install(|| {
                    exchanged_half(dir, r, r, half, &half_atoms, move |builder| {
                        builder.add_system(
                            Stage::BroadPhase,
                            "halo_exchange",
                            move |mut s: ResMut<GrainSnapshot>| {
                                exchange.exchange(half, &mut step, &mut plan, &mut s)
                            },
                        );
                    })
                })
            })
            .collect();
        let ghost_material = |sim: &Simulation| {
            let materials = sim.world.resource::<talus::core::resources::Materials>();
            materials
                .0
                .iter()
                .position(|m| m.name == "ghost")
                .expect("a ghost material") as u16
        };
        let period = CHUTE_BOX.0 * f64::from(r);
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
        Self {
            halves,
            pools,
            exchange,
            own_grains,
        }
    }

    /// Steps both halves `steps` steps at once.
    pub fn run_steps(&mut self, steps: u64) {
        step_halves(&mut self.halves, &self.pools, &self.exchange.barrier, steps);
    }
}

/// Steps both halves `steps` steps at once, each on its own pool; a half that stops early
/// opens the barrier so that the other does not wait for it forever.
pub fn step_halves(
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
