//! Stress sampling (`sampling:` in a scene): the sampled stresses against independent
//! references — wall tractions of a confined packing, the symmetry of the stress
//! without contact torques, the kinetic stress of a dilute gas computed from the grain
//! velocities, the inertial number of an imposed shear — and the plumbing: the stress
//! system only when asked for, located errors for bad input, the report and recording.

use crate::common;

use common::sampling::{region, regions};
use glam::DVec3;
use talus::core::prelude::*;
use talus::core::schedule::Simulation;
use talus_stress::{RegionStress, StressRecord, Tensor};

/// Load on a wall by name, N (force the grains exert on it).
fn wall_load(sim: &mut Simulation, name: &str) -> DVec3 {
    let mut q = sim.world.query::<(&Wall, &WallLoad)>();
    q.iter(&sim.world)
        .find(|(w, _)| w.name == name)
        .map(|(_, l)| l.0)
        .expect("wall exists")
}

/// Sets the prescribed velocity of a wall, by name.
fn set_wall_velocity(sim: &mut Simulation, name: &str, velocity: DVec3) {
    let mut q = sim.world.query::<&mut Wall>();
    for mut w in q.iter_mut(&mut sim.world) {
        if w.name == name {
            w.velocity = velocity;
        }
    }
}

/// Position of the lid along `axis`, m.
fn lid_position(sim: &mut Simulation, axis: usize) -> f64 {
    let mut q = sim.world.query::<&Wall>();
    q.iter(&sim.world)
        .find(|w| w.name == "lid")
        .map(|w| w.point[axis])
        .expect("lid exists")
}

/// Σ ½ m v² over the grains, J.
fn kinetic_energy(sim: &mut Simulation) -> f64 {
    common::grains(sim)
        .iter()
        .map(|g| 0.5 * g.mass * g.velocity.length_squared())
        .sum()
}

/// ‖½(T − Tᵀ)‖ / ‖T‖.
fn relative_asymmetry(t: &Tensor) -> f64 {
    t.antisymmetric_part().norm() / t.norm()
}

/// Side of the square box of the confined packing, m.
const SIDE: f64 = 0.012;
/// Initial height of the lid, m.
const LID_START: f64 = 0.03;
/// Time step of the confined packing, s: about 1/30 of the shortest contact time.
const TIME_STEP: f64 = 5e-6;
/// Steps between stress samples of the confined packing.
const SAMPLE_EVERY: u64 = 1000;
/// Time between stress samples of the confined packing, s.
const SAMPLE_INTERVAL: f64 = SAMPLE_EVERY as f64 * TIME_STEP;
/// Width of the 2-D confined packing, m.
const WIDTH_2D: f64 = 0.02;
/// Initial height of its lid, m.
const LID_START_2D: f64 = 0.07;
/// Its time step, s: about 1/30 of the shortest contact time of the disks.
const TIME_STEP_2D: f64 = 1.5e-4;
/// Steps between its stress samples.
const SAMPLE_EVERY_2D: u64 = 100;

/// 300 grains at rest, no gravity, in a square box whose lid moves down at `lid_speed`.
/// Walls are frictionless (the wall material has friction 0, and the geometric mixing
/// rule gives 0 for every grain–wall pair), so a wall's load is normal to it.
fn confined_scene(friction: f64, lid_speed: f64) -> String {
    let octants = octants()
        .iter()
        .enumerate()
        .map(|(k, (lo, hi))| {
            format!(
                "Box(name: \"octant{k}\", min: ({}, {}, {}), max: ({}, {}, {})),",
                lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
            )
        })
        .collect::<String>();
    format!(
        r#"Scene(
    name: "confined",
    steps: 1,
    time_step: {TIME_STEP},
    plugins: ["linear_spring"],
    materials: [
        (name: "glass", density: 2500.0,
         contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.2, friction: {friction})),
        (name: "wall", density: 2500.0,
         contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.2, friction: 0.0)),
    ],
    walls: [
        Box(min: (0.0, 0.0, 0.0), max: ({SIDE}, {SIDE}, 1.0), material: "wall", omit: ["z_max"]),
        Plane(name: "lid", point: (0.0, 0.0, {LID_START}), normal: (0.0, 0.0, -1.0),
              material: "wall", velocity: (0.0, 0.0, -{lid_speed})),
    ],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: ({SIDE}, {SIDE}, {LID_START})),
                    count: 300, radius: Uniform(min: 0.0008, max: 0.0012), seed: 7)],
    sampling: (interval: {SAMPLE_INTERVAL}, regions: [
        Slab(name: "lower", axis: "z", min: -1.0, max: 0.006),
        Slab(name: "upper", axis: "z", min: 0.006, max: 1.0),
        Box(name: "core", min: (0.003, 0.003, 0.003), max: (0.009, 0.009, 0.009)),
        {octants}
    ]),
    output: (recording: false),
)"#
    )
}

/// Eight boxes that split space at x = y = SIDE/2, z = 6 mm, reaching 1 m out on every
/// side: together they hold every branch segment of the confined packing, including the
/// parts of grain–wall branches past the wall planes.
fn octants() -> Vec<(DVec3, DVec3)> {
    let cut = DVec3::new(0.5 * SIDE, 0.5 * SIDE, 0.006);
    (0..8)
        .map(|k| {
            let mut lo = DVec3::splat(-1.0);
            let mut hi = DVec3::splat(1.0);
            for d in 0..3 {
                if k >> d & 1 == 0 {
                    hi[d] = cut[d];
                } else {
                    lo[d] = cut[d];
                }
            }
            (lo, hi)
        })
        .collect()
}

/// Runs to the next multiple of `every` steps, where a stress sample is taken.
fn run_to_next_sample(sim: &mut Simulation, every: u64) {
    let to_next = every - sim.step_count() % every;
    sim.run_steps(to_next).unwrap();
    assert_eq!(
        sim.world
            .resource::<StressRecord>()
            .latest
            .as_ref()
            .unwrap()
            .step,
        sim.step_count()
    );
}

/// How a confined packing is made: the lid moves along −`axis` towards the floor.
struct Protocol {
    /// 2 (z) in 3-D, 1 (y) in 2-D.
    axis: usize,
    /// Name of the floor wall.
    floor: &'static str,
    /// Lid position at which compression stops, m.
    compressed_to: f64,
    /// Speed at which the lid then backs off, m/s.
    unload_speed: f64,
    /// Lid load at which it stops, N.
    unload_to: f64,
    /// Steps between stress samples.
    sample_every: u64,
}

/// Compresses the confined packing well above jamming, then unloads it slowly until the
/// lid carries a small load (overlaps of order 1e-3 of a radius), holds the lid there and
/// lets the packing come to rest: until the floor and the lid carry the same load to
/// 1e-3 at two samples in a row. Returns the steps run.
fn compress_and_settle(sim: &mut Simulation, p: &Protocol) -> u64 {
    while lid_position(sim, p.axis) > p.compressed_to {
        sim.run_steps(10).unwrap();
        assert!(
            sim.step_count() < 100_000,
            "the lid never reached {} m",
            p.compressed_to
        );
    }
    let mut up = DVec3::ZERO;
    up[p.axis] = p.unload_speed;
    set_wall_velocity(sim, "lid", up);
    while wall_load(sim, "lid")[p.axis].abs() > p.unload_to {
        sim.run_steps(10).unwrap();
        assert!(sim.step_count() < 200_000, "the lid never unloaded");
    }
    set_wall_velocity(sim, "lid", DVec3::ZERO);
    let mut balanced = 0;
    while balanced < 2 {
        run_to_next_sample(sim, p.sample_every);
        let floor = wall_load(sim, p.floor)[p.axis].abs();
        let lid = wall_load(sim, "lid")[p.axis].abs();
        balanced = if (floor - lid).abs() < 1e-3 * lid {
            balanced + 1
        } else {
            0
        };
        assert!(sim.step_count() < 300_000, "the packing never came to rest");
    }
    sim.step_count()
}

#[test]
fn confined_packing_pressure_equals_wall_traction() {
    let (mut sim, _) = common::build(&confined_scene(0.3, 0.1));
    // To a solid fraction of 0.65, then back to a lid load of 0.1 N.
    let grain_volume: f64 = common::grains(&mut sim)
        .iter()
        .map(|g| g.mass / 2500.0)
        .sum();
    let steps = compress_and_settle(
        &mut sim,
        &Protocol {
            axis: 2,
            floor: "z_min",
            compressed_to: grain_volume / (0.65 * SIDE * SIDE),
            unload_speed: 0.02,
            unload_to: 0.1,
            sample_every: SAMPLE_EVERY,
        },
    );
    let all = regions(&sim);
    let domain = region(&all, "domain");
    let area = SIDE * SIDE;
    let bottom = wall_load(&mut sim, "z_min").z.abs();
    let lid = wall_load(&mut sim, "lid").z.abs();
    let traction_z = bottom / area;
    // Mean wall traction over the six faces (the lid stands for z_max). The side walls
    // span the floor-to-lid height.
    let height = lid_position(&mut sim, 2);
    let side_area = SIDE * height;
    let traction_x = 0.5
        * (wall_load(&mut sim, "x_min").x.abs() + wall_load(&mut sim, "x_max").x.abs())
        / side_area;
    let traction_y = 0.5
        * (wall_load(&mut sim, "y_min").y.abs() + wall_load(&mut sim, "y_max").y.abs())
        / side_area;
    let mean_traction = (traction_x + traction_y + traction_z) / 3.0;
    let szz = -domain.stress.0[2][2];
    println!(
        "{steps} steps; floor {bottom:.6e} N, lid {lid:.6e} N; KE {:.3e} J; solid fraction {:.4}",
        kinetic_energy(&mut sim),
        domain.solid_fraction
    );
    println!(
        "domain: -σzz {szz:.6e} Pa vs floor traction {traction_z:.6e} Pa ({:+.3e}); \
         p {:.6e} Pa vs mean wall traction {mean_traction:.6e} Pa ({:+.3e})",
        szz / traction_z - 1.0,
        domain.pressure,
        domain.pressure / mean_traction - 1.0
    );
    for name in ["lower", "upper", "core"] {
        let r = region(&all, name);
        println!(
            "{name}: -σzz {:.6e} Pa ({:+.3e}), p {:.6e} Pa, {} contacts, {} grains",
            -r.stress.0[2][2],
            -r.stress.0[2][2] / traction_z - 1.0,
            r.pressure,
            r.contacts,
            r.grains
        );
    }
    // The octants partition the domain: their grains add up, and so do their contact
    // stresses times their volumes, each contact cut by the octant faces counting in
    // every octant by the part of its branch segment there.
    let octant_regions: Vec<&RegionStress> = (0..8)
        .map(|k| region(&all, &format!("octant{k}")))
        .collect();
    let grains: usize = octant_regions.iter().map(|r| r.grains).sum();
    let summed = octant_regions.iter().fold(Tensor::ZERO, |acc, r| {
        acc.plus(r.contact_stress.scaled(r.volume))
    });
    let whole = domain.contact_stress.scaled(domain.volume);
    let cut_contacts: usize =
        octant_regions.iter().map(|r| r.contacts).sum::<usize>() - domain.contacts;
    let mismatch = summed.minus(whole).norm() / whole.norm();
    println!(
        "octants: {cut_contacts} contacts counted in two or more; Σ V σ mismatch {mismatch:.2e}"
    );
    assert_eq!(grains, domain.grains);
    assert!(cut_contacts > 0);
    assert!(mismatch < 1e-12);
    let volume: f64 = octant_regions.iter().map(|r| r.volume).sum();
    assert!((volume / domain.volume - 1.0).abs() < 1e-12);
    assert_eq!(domain.min[2], 0.0, "the floor bounds the domain");
    assert_eq!(domain.max[2], height, "the lid bounds the domain");
    assert!((szz / traction_z - 1.0).abs() < 0.01);
    assert!((domain.pressure / mean_traction - 1.0).abs() < 0.01);
    // No body force: every horizontal plane carries the floor's load, so each slab has
    // the same mean σzz; their contacts cut by the plane z = 6 mm count by the part of
    // the branch inside each.
    for name in ["lower", "upper"] {
        let r = region(&all, name);
        assert!(
            (-r.stress.0[2][2] / traction_z - 1.0).abs() < 0.01,
            "{name}"
        );
    }
}

#[test]
fn confined_disks_pressure_equals_wall_traction_in_2d() {
    // The same experiment with 200 disks in the xy-plane. A 2-D disk is a cylinder of
    // 1 m thickness (its mass is π ρ R² · 1 m), so wall loads are per metre of thickness
    // and the sampled volume is an area times 1 m: the traction is F / (width · 1 m).
    let (mut sim, _) = common::build(&format!(
        r#"Scene(
    name: "confined-2d",
    dimension: 2,
    steps: 1,
    time_step: {TIME_STEP_2D},
    plugins: ["linear_spring"],
    materials: [
        (name: "glass", density: 2500.0,
         contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.2, friction: 0.3)),
        (name: "wall", density: 2500.0,
         contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.2, friction: 0.0)),
    ],
    walls: [
        Box(min: (0.0, 0.0, 0.0), max: ({WIDTH_2D}, 1.0, 0.0), material: "wall", omit: ["y_max"]),
        Plane(name: "lid", point: (0.0, {LID_START_2D}, 0.0), normal: (0.0, -1.0, 0.0),
              material: "wall", velocity: (0.0, -0.01, 0.0)),
    ],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: ({WIDTH_2D}, {LID_START_2D}, 0.0)),
                    count: 200, radius: Uniform(min: 0.0008, max: 0.0012), seed: 3)],
    sampling: (interval: {interval}, regions: [Slab(name: "lower", axis: "y", min: -1.0, max: 0.01)]),
    output: (recording: false),
)"#,
        interval = SAMPLE_EVERY_2D as f64 * TIME_STEP_2D
    ));
    let disk_area: f64 = common::grains(&mut sim)
        .iter()
        .map(|g| std::f64::consts::PI * g.radius * g.radius)
        .sum();
    let steps = compress_and_settle(
        &mut sim,
        &Protocol {
            axis: 1,
            floor: "y_min",
            compressed_to: disk_area / (0.88 * WIDTH_2D),
            unload_speed: 0.001,
            unload_to: 0.05,
            sample_every: SAMPLE_EVERY_2D,
        },
    );
    let all = regions(&sim);
    let domain = region(&all, "domain");
    let floor = wall_load(&mut sim, "y_min").y.abs();
    let height = lid_position(&mut sim, 1);
    let traction_y = floor / (WIDTH_2D * 1.0);
    let traction_x = 0.5
        * (wall_load(&mut sim, "x_min").x.abs() + wall_load(&mut sim, "x_max").x.abs())
        / (height * 1.0);
    let mean_traction = 0.5 * (traction_x + traction_y);
    let syy = -domain.stress.0[1][1];
    let lower = -region(&all, "lower").stress.0[1][1];
    println!(
        "{steps} steps; floor {floor:.6e} N/m; area fraction {:.4}; volume {:.6e} m³ (area × 1 m)",
        domain.solid_fraction, domain.volume
    );
    println!(
        "domain: -σyy {syy:.6e} Pa vs floor traction {traction_y:.6e} Pa ({:+.3e}); \
         p {:.6e} Pa vs mean wall traction {mean_traction:.6e} Pa ({:+.3e}); lower slab ({:+.3e})",
        syy / traction_y - 1.0,
        domain.pressure,
        domain.pressure / mean_traction - 1.0,
        lower / traction_y - 1.0
    );
    assert!((domain.volume - WIDTH_2D * height * 1.0).abs() < 1e-12 * domain.volume);
    assert!((syy / traction_y - 1.0).abs() < 0.01);
    assert!((domain.pressure / mean_traction - 1.0).abs() < 0.01);
    assert!((lower / traction_y - 1.0).abs() < 0.01);
    assert_eq!(domain.stress.0[2][2], 0.0);
}

#[test]
fn settled_column_stress_is_the_weight_carried() {
    // 300 grains settled under gravity in a closed box with frictionless walls. The floor
    // carries the weight W, but the stress is not uniform: across a horizontal plane at
    // height z the packing transmits the weight of the grains above z (their centres
    // above it), so the mean σzz of a layer z₁ ≤ z < z₂ is
    //   −σzz = g Σ_p m_p clamp(z_p − z₁, 0, z₂ − z₁) / (A (z₂ − z₁)),
    // which for the whole box (height H) is g Σ m_p z_p / (A H), the weight times the
    // height of the centre of mass over the box volume, and only for a thin layer on the
    // floor tends to the floor traction W / A.
    let height = 0.03;
    let gravity = 9.81;
    let (mut sim, _) = common::build(&format!(
        r#"Scene(
    name: "column",
    gravity: (0.0, 0.0, -{gravity}),
    steps: 1,
    time_step: {TIME_STEP},
    plugins: ["linear_spring"],
    materials: [
        (name: "glass", density: 2500.0,
         contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.2, friction: 0.3)),
        (name: "wall", density: 2500.0,
         contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.2, friction: 0.0)),
    ],
    walls: [Box(min: (0.0, 0.0, 0.0), max: ({SIDE}, {SIDE}, {height}), material: "wall")],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: ({SIDE}, {SIDE}, {height})),
                    count: 300, radius: Uniform(min: 0.0008, max: 0.0012), seed: 7)],
    sampling: (interval: {SAMPLE_INTERVAL}, regions: [
        Slab(name: "floor_layer", axis: "z", min: -1.0, max: 0.001),
        Slab(name: "bottom_half", axis: "z", min: -1.0, max: 0.005),
        Slab(name: "middle", axis: "z", min: 0.003, max: 0.007),
    ]),
    output: (recording: false),
)"#
    ));
    let weight: f64 = common::grains(&mut sim)
        .iter()
        .map(|g| g.mass * gravity)
        .sum();
    let mut balanced = 0;
    while balanced < 2 {
        run_to_next_sample(&mut sim, SAMPLE_EVERY);
        let floor = wall_load(&mut sim, "z_min").z.abs();
        balanced = if (floor / weight - 1.0).abs() < 1e-3 {
            balanced + 1
        } else {
            0
        };
        assert!(sim.step_count() < 300_000, "the column never came to rest");
    }
    let all = regions(&sim);
    let grains = common::grains(&mut sim);
    let area = SIDE * SIDE;
    let floor = wall_load(&mut sim, "z_min").z.abs();
    let carried = |z1: f64, z2: f64| {
        let (lo, h) = (z1.max(0.0), z2 - z1.max(0.0));
        gravity
            * grains
                .iter()
                .map(|g| g.mass * (g.position.z - lo).clamp(0.0, h))
                .sum::<f64>()
            / (area * h)
    };
    println!(
        "{} steps; floor {floor:.6e} N vs weight {weight:.6e} N; KE {:.3e} J",
        sim.step_count(),
        kinetic_energy(&mut sim)
    );
    for (name, z1, z2) in [
        ("domain", 0.0, height),
        ("floor_layer", -1.0, 0.001),
        ("bottom_half", -1.0, 0.005),
        ("middle", 0.003, 0.007),
    ] {
        let szz = -region(&all, name).stress.0[2][2];
        let expected = carried(z1, z2);
        println!(
            "{name}: -σzz {szz:.6e} Pa vs weight carried {expected:.6e} Pa ({:+.3e}); floor traction W/A {:.6e} Pa ({:+.3e})",
            szz / expected - 1.0,
            floor / area,
            szz / (floor / area) - 1.0
        );
        assert!((szz / expected - 1.0).abs() < 0.01, "{name}");
    }
    // No grain centre lies below 0.8 mm (the smallest radius), so the 1 mm layer on the
    // floor carries nearly all the weight: there the sampled stress is the floor traction.
    let floor_layer = -region(&all, "floor_layer").stress.0[2][2];
    assert!((floor_layer / (floor / area) - 1.0).abs() < 0.01);
}

#[test]
fn without_contact_torques_the_stress_is_symmetric() {
    // Frictionless: every contact force lies along its branch vector, so each term
    // f ⊗ l is symmetric and so is the sum, while the packing is being compressed
    // (far from equilibrium, where only the balance of moments would symmetrise it).
    let (mut sim, _) = common::build(&confined_scene(0.0, 0.1));
    let mut worst: f64 = 0.0;
    let mut sampled = 0;
    for _ in 0..20 {
        run_to_next_sample(&mut sim, SAMPLE_EVERY);
        for r in regions(&sim).iter().filter(|r| r.contacts > 0) {
            worst = worst.max(relative_asymmetry(&r.stress));
            assert!(r.couple_stress.is_none());
            sampled += 1;
        }
    }
    println!("frictionless: worst ‖skew σ‖/‖σ‖ = {worst:.3e} over {sampled} region samples");
    assert!(sampled > 20, "contacts formed");
    assert!(worst < 1e-10);

    // The same compression with friction between grains is not symmetric while it is
    // out of equilibrium: the check above can fail. Friction adds no moment beyond
    // branch × force, so there is still no couple stress.
    let (mut sim, _) = common::build(&confined_scene(0.3, 0.1));
    let mut largest: f64 = 0.0;
    for _ in 0..20 {
        run_to_next_sample(&mut sim, SAMPLE_EVERY);
        for r in regions(&sim).iter().filter(|r| r.contacts > 0) {
            largest = largest.max(relative_asymmetry(&r.stress));
            assert!(r.couple_stress.is_none());
        }
    }
    println!("frictional: largest ‖skew σ‖/‖σ‖ = {largest:.3e}");
    assert!(largest > 1e-6);
}

/// Edge of the closed box of the gas, m.
const GAS_BOX: f64 = 0.1;
/// The gas cloud fills this cube (and the sampled region `cloud` is it), m.
const CLOUD: (f64, f64) = (0.01, 0.09);
/// Grains in the gas.
const GAS_GRAINS: usize = 1000;
/// Velocity components are uniform in [−v, v], m/s.
const SPREAD: f64 = 0.1;
/// Grain radius of the gas, m.
const GAS_RADIUS: f64 = 0.001;

fn gas_scene(sampling: &str) -> String {
    let (lo, hi) = CLOUD;
    format!(
        r#"Scene(
    name: "gas",
    steps: 1,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1000.0, restitution: 0.9))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: ({GAS_BOX}, {GAS_BOX}, {GAS_BOX}), material: "glass")],
    grains: [Random(material: "glass", region: (min: ({lo}, {lo}, {lo}), max: ({hi}, {hi}, {hi})),
                    count: {GAS_GRAINS}, radius: Fixed({GAS_RADIUS}), seed: 11, velocity_spread: {SPREAD})],
    {sampling}
    output: (recording: false),
)"#
    )
}

#[test]
fn kinetic_stress_of_a_dilute_gas_is_n_m_mean_vv() {
    let (lo, hi) = CLOUD;
    let (mut sim, _) = common::build(&gas_scene(&format!(
        "sampling: (interval: 1e-12, regions: [Box(name: \"cloud\", min: ({lo}, {lo}, {lo}), max: ({hi}, {hi}, {hi}))]),"
    )));
    sim.run_steps(20).unwrap();
    let all = regions(&sim);
    let cloud = region(&all, "cloud");
    assert_eq!(cloud.contacts, 0, "the gas stayed collision-free");
    assert_eq!(cloud.contact_stress, Tensor::ZERO);
    assert_eq!(cloud.kinetic_share, Some(1.0));

    // Directly from the grains: n m ⟨v′ ⊗ v′⟩ over the grains in the cloud, v′ about
    // their mass-weighted mean velocity.
    let grains: Vec<_> = common::grains(&mut sim)
        .into_iter()
        .filter(|g| (0..3).all(|d| lo <= g.position[d] && g.position[d] < hi))
        .collect();
    let volume = (hi - lo).powi(3);
    let mass: f64 = grains.iter().map(|g| g.mass).sum();
    let mean = grains.iter().map(|g| g.mass * g.velocity).sum::<DVec3>() / mass;
    let mut direct = [[0.0; 3]; 3];
    for g in &grains {
        let v = g.velocity - mean;
        for i in 0..3 {
            for j in 0..3 {
                direct[i][j] += g.mass * v[i] * v[j] / volume;
            }
        }
    }
    let direct = Tensor(direct);
    let sampled = cloud.kinetic_stress.scaled(-1.0);
    let difference = sampled.minus(direct).norm() / direct.norm();
    println!(
        "{} grains; n m <v'v'> diagonal ({:.6e}, {:.6e}, {:.6e}) Pa; sampled − direct: {difference:.2e} relative",
        grains.len(),
        direct.0[0][0],
        direct.0[1][1],
        direct.0[2][2]
    );
    assert_eq!(cloud.grains, grains.len());
    assert!(difference < 1e-12);
    assert!((cloud.volume / volume - 1.0).abs() < 1e-12);

    // Against the distribution: components uniform in [−v, v] have ⟨v_i²⟩ = v²/3 and
    // ⟨v_i v_j⟩ = 0. The standard error of the mean of N samples of v_i² is
    // √(4/45) v²/√N (Var v_i² = v⁴/5 − v⁴/9) and of v_i v_j it is (v²/3)/√N; we allow
    // four standard errors (removing the sample mean lowers ⟨v′²⟩ by (N−1)/N, well
    // inside that).
    let n = grains.len() as f64;
    let m = grains[0].mass;
    let expected = n / volume * m * SPREAD * SPREAD / 3.0;
    let diagonal_error = 4.0 * (4.0f64 / 45.0).sqrt() * SPREAD * SPREAD / n.sqrt() * n / volume * m;
    let off_diagonal_error = 4.0 * expected / n.sqrt();
    for i in 0..3 {
        for j in 0..3 {
            let (value, bound) = if i == j {
                (sampled.0[i][j] - expected, diagonal_error)
            } else {
                (sampled.0[i][j], off_diagonal_error)
            };
            println!("  ({i},{j}): deviation {value:+.3e} Pa, bound {bound:.3e} Pa");
            assert!(value.abs() < bound, "({i}, {j})");
        }
    }
    // An ideal gas: p = n m ⟨|v′|²⟩ / 3.
    assert!((cloud.pressure / (direct.trace(3) / 3.0) - 1.0).abs() < 1e-12);
}

#[test]
fn inertial_number_of_an_imposed_shear() {
    // The gas with its velocities replaced by a simple shear v = (γ̇ (z − 0.05), 0, 0):
    // the fitted shear rate is γ̇ in the slab and in the box, and I = γ̇ d √(ρ_s / p) with
    // p the kinetic pressure computed from the velocities here.
    let (lo, hi) = CLOUD;
    let rate = 3.0;
    let (mut sim, _) = common::build(&gas_scene(&format!(
        "sampling: (domain: false, regions: [
            Box(name: \"cloud\", min: ({lo}, {lo}, {lo}), max: ({hi}, {hi}, {hi})),
            Slab(name: \"layer\", axis: \"z\", min: 0.03, max: 0.07),
            Slab(name: \"given\", axis: \"z\", min: 0.03, max: 0.07, shear_rate: 1.0),
        ]),"
    )));
    {
        let mut q = sim.world.query::<(&Position, &mut Velocity)>();
        for (p, mut v) in q.iter_mut(&mut sim.world) {
            v.0 = DVec3::new(rate * (p.0.z - 0.05), 0.0, 0.0);
        }
    }
    // The initial-force pass samples step 0 with these velocities.
    sim.prime().unwrap();
    let all = regions(&sim);
    let grains = common::grains(&mut sim);
    for (name, z_range) in [
        ("cloud", (lo, hi)),
        ("layer", (0.03, 0.07)),
        ("given", (0.03, 0.07)),
    ] {
        let r = region(&all, name);
        let inside: Vec<_> = grains
            .iter()
            .filter(|g| {
                let in_z = z_range.0 <= g.position.z && g.position.z < z_range.1;
                in_z && (name != "cloud"
                    || (0..2).all(|d| lo <= g.position[d] && g.position[d] < hi))
            })
            .collect();
        let mass: f64 = inside.iter().map(|g| g.mass).sum();
        let mean = inside.iter().map(|g| g.mass * g.velocity).sum::<DVec3>() / mass;
        let volume = if name == "cloud" {
            (hi - lo).powi(3)
        } else {
            GAS_BOX * GAS_BOX * (z_range.1 - z_range.0)
        };
        let pressure: f64 = inside
            .iter()
            .map(|g| g.mass * (g.velocity - mean).length_squared())
            .sum::<f64>()
            / (3.0 * volume);
        let expected_rate = if name == "given" { 1.0 } else { rate };
        let expected = expected_rate * 2.0 * GAS_RADIUS * (2500.0 / pressure).sqrt();
        let i = r.inertial_number.expect("inertial number defined");
        println!(
            "{name}: γ̇ {:.12} ({:?}), p {pressure:.6e} Pa, I {i:.6e} vs {expected:.6e}, {:?}",
            r.shear_rate.unwrap(),
            r.shear_rate_source.unwrap(),
            r.regime.unwrap()
        );
        assert!(
            (r.shear_rate.unwrap() / expected_rate - 1.0).abs() < 1e-9,
            "{name}"
        );
        assert!((i / expected - 1.0).abs() < 1e-9, "{name}");
        assert_eq!(r.regime, Some(talus_stress::FlowRegime::of(expected)));
    }
    assert_eq!(
        region(&all, "given").shear_rate_source,
        Some(talus_stress::ShearRateSource::Scene)
    );
    assert_eq!(
        region(&all, "layer").shear_rate_source,
        Some(talus_stress::ShearRateSource::Fit)
    );
}

#[test]
fn couple_stress_of_a_rolling_resistance_torque() {
    // One sphere resting on a floor under a constant rolling torque M = μ_r F_n R
    // (`constant_torque`, F_n = m g at rest, R* = R against a wall) while it rolls along
    // +x: the couple stress is (1/V) M ⊗ b with b = −(R − δ/2) z the branch to the
    // contact point, V the domain box (floor to the top of the grain, 2R × 2R across).
    let (radius, density, stiffness, gravity, rolling_friction): (f64, f64, f64, f64, f64) =
        (0.005, 2500.0, 1e4, 9.81, 0.05);
    let mass = 4.0 / 3.0 * std::f64::consts::PI * density * radius.powi(3);
    let overlap = mass * gravity / stiffness;
    let z = radius - overlap;
    let speed = 0.05;
    let (mut sim, _) = common::build(&format!(
        r#"Scene(
    name: "rolling",
    gravity: (0.0, 0.0, -{gravity}),
    steps: 1,
    plugins: ["linear_spring"],
    materials: [(name: "steel", density: {density},
        contact: (law: "linear_spring", stiffness: {stiffness}, restitution: 0.5, friction: 0.5,
                  rolling: "constant_torque", rolling_friction: {rolling_friction}))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "steel")],
    grains: [List(material: "steel", grains: [(position: (0.0, 0.0, {z}), radius: {radius},
        velocity: ({speed}, 0.0, 0.0), angular_velocity: (0.0, {omega}, 0.0))])],
    sampling: (),
    initial_overlap_tolerance: 0.01,
    output: (recording: false),
)"#,
        omega = speed / (radius - 0.5 * overlap)
    ));
    sim.prime().unwrap();
    let all = regions(&sim);
    let domain = region(&all, "domain");
    let couple = domain
        .couple_stress
        .expect("the contact carries a rolling torque");
    let volume = (2.0 * radius) * (2.0 * radius) * (z + radius);
    let torque = rolling_friction * mass * gravity * radius;
    let expected = torque * (radius - 0.5 * overlap) / volume;
    println!(
        "couple stress (y, z) {:.6e} N/m vs M (R − δ/2) / V = {expected:.6e}; ‖skew σ‖ {:.3e} Pa",
        couple.0[1][2], domain.antisymmetric_norm
    );
    // Rolling along +x is resisted by a torque about −y; the branch points down (−z).
    assert!((couple.0[1][2] / expected - 1.0).abs() < 1e-6);
    let others: f64 = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .filter(|&(i, j)| (i, j) != (1, 2))
        .map(|(i, j)| couple.0[i][j].abs())
        .sum();
    assert!(others < 1e-9 * expected);
}

#[test]
fn stress_system_is_scheduled_only_when_the_scene_asks() {
    let plan_of = |text: &str| {
        let scene = talus::scene::parse("plan.ron", text).unwrap();
        let built = scene.build(&talus::registry()).unwrap();
        built.builder.plan().clone()
    };
    let sample_stage = |plan: &talus::core::schedule::Plan| {
        plan.stages
            .iter()
            .find(|(s, _)| *s == Stage::Sample)
            .unwrap()
            .1
            .clone()
    };
    let without = plan_of(&gas_scene(""));
    assert!(
        !sample_stage(&without)
            .iter()
            .any(|s| s == talus_stress::SYSTEM_NAME)
    );
    assert!(!without.plugins.iter().any(|p| p == "stress_sampling"));
    let (sim, _) = common::build(&gas_scene(""));
    assert!(sim.world.get_resource::<StressRecord>().is_none());

    let with = plan_of(&gas_scene("sampling: (),"));
    assert_eq!(
        sample_stage(&with),
        ["health_check", talus_stress::SYSTEM_NAME]
    );
    assert!(with.plugins.iter().any(|p| p == "stress_sampling"));
    assert!(
        with.notes
            .iter()
            .any(|n| n.starts_with("stress sampling every"))
    );
}

#[test]
fn bad_sampling_input_is_a_located_scene_error() {
    // (sampling section, field in the error, text at the error position, expected words)
    let cases = [
        (
            "sampling: (interval: -0.01),",
            "sampling.interval",
            "-0.01",
            "a positive interval",
        ),
        (
            "sampling: (regions: [Box(name: \"b\", min: (0.0, 0.0, 0.05), max: (0.1, 0.1, 0.05))]),",
            "sampling.regions[0].max",
            "(0.1, 0.1, 0.05)",
            "above that of `min`",
        ),
        (
            "sampling: (regions: [Slab(name: \"s\", axis: \"z\", min: 0.5, max: 0.2)]),",
            "sampling.regions[0].max",
            "0.2",
            "above `min`",
        ),
        (
            "sampling: (regions: [Slab(name: \"s\", axis: \"w\", min: 0.1, max: 0.2)]),",
            "sampling.regions[0].axis",
            "\"w\"",
            "\"x\", \"y\" or \"z\"",
        ),
        (
            "sampling: (regions: [Box(colour: 1.0, name: \"b\", min: (0.0, 0.0, 0.0), max: (0.1, 0.1, 0.1))]),",
            "sampling.regions[0].colour",
            "colour",
            "one of the fields",
        ),
        // After a tuple the RON error locator (`talus_scene::error::from_ron`) names the
        // field under the tuple's last element: `sampling.regions[0].max[2].colour`. The
        // position is right; the path prefix is a limitation of that shared locator.
        (
            "sampling: (regions: [Box(name: \"b\", min: (0.0, 0.0, 0.0), max: (0.1, 0.1, 0.1), colour: 1.0)]),",
            "sampling.regions[0].max[2].colour",
            "colour",
            "one of the fields",
        ),
        (
            "sampling: (intervall: 0.01),",
            "sampling.intervall",
            "intervall",
            "one of the fields",
        ),
        (
            "sampling: (regions: [Slab(name: \"domain\", axis: \"z\", min: 0.1, max: 0.2)]),",
            "sampling.regions[0].name",
            "\"domain\"",
            "a name not used by another region",
        ),
        (
            "sampling: (regions: [Slab(name: \"a b\", axis: \"z\", min: 0.1, max: 0.2)]),",
            "sampling.regions[0].name",
            "\"a b\"",
            "letters, digits",
        ),
        (
            "sampling: (regions: [Slab(name: \"s\", axis: \"z\", min: 0.1, max: 0.2, shear_rate: -1.0)]),",
            "sampling.regions[0].shear_rate",
            "-1.0",
            "non-negative shear rate",
        ),
        (
            "sampling: (domain: false),",
            "sampling",
            "(domain",
            "at least one region",
        ),
    ];
    for (section, field, at, words) in cases {
        let text = gas_scene(section);
        let result = talus::scene::parse("bad.ron", &text)
            .and_then(|s| s.build(&talus::registry()).map(|_| ()));
        let e = result.expect_err(section);
        println!("{e}");
        assert_eq!(e.field, field, "{section}");
        assert!(e.expected.contains(words), "{section}: {}", e.expected);
        // The position is where the offending text starts.
        let line = text.lines().nth(e.line - 1).expect("line in the text");
        let column = line
            .char_indices()
            .position(|_| true)
            .map(|_| e.column)
            .unwrap();
        let rest: String = line.chars().skip(column - 1).collect();
        assert!(
            rest.starts_with(at),
            "{section}: {}:{} is at `{rest}`",
            e.line,
            e.column
        );
    }
}

#[test]
fn report_and_recording_carry_the_stress_series() {
    let dir = common::temp_dir("stress-report");
    let (lo, hi) = CLOUD;
    let sampled = gas_scene(&format!(
        "sampling: (interval: 1e-4, regions: [Slab(name: \"middle\", axis: \"z\", min: {lo}, max: {hi})]),"
    ))
    .replace("steps: 1,", "steps: 40,")
    .replace("output: (recording: false),", "output: (report_interval: 1e-4, recording_interval: 1e-3),");
    let plain = gas_scene("").replace("steps: 1,", "steps: 40,").replace(
        "output: (recording: false),",
        "output: (report_interval: 1e-4, recording: false),",
    );
    let run = |name: &str, text: &str| {
        let path = dir.join(format!("{name}.ron"));
        std::fs::write(&path, text).unwrap();
        let options = talus::cli::RunOptions {
            out: Some(dir.join(name)),
            quiet: true,
            progress: false,
            ..Default::default()
        };
        talus::cli::run_scene(&path, &talus::registry(), &options).unwrap()
    };

    let summary = run("sampled", &sampled);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary.report_path).unwrap()).unwrap();
    let samples = json["samples"].as_array().unwrap();
    assert!(samples.len() > 2);
    for s in samples {
        let stress = &s["stress"];
        assert_eq!(stress["regions"][0]["name"], "domain");
        assert_eq!(stress["regions"][1]["name"], "middle");
        assert_eq!(stress["regions"][1]["shape"], "slab");
        assert!(stress["step"].as_u64().unwrap() <= s["step"].as_u64().unwrap());
        assert!(stress["regions"][0]["pressure"].as_f64().unwrap() > 0.0);
        assert_eq!(stress["regions"][0]["stress"].as_array().unwrap().len(), 3);
    }
    // The typed report reads back.
    let typed = &summary.report.samples.last().unwrap().stress;
    assert_eq!(typed.as_ref().unwrap().regions.len(), 2);

    let entities = talus::rerun_export::read_entities(summary.recording.unwrap()).unwrap();
    for path in [
        "/stress/domain/pressure",
        "/stress/middle/sigma_zz",
        "/stress/middle/shear_rate",
    ] {
        let e = entities
            .iter()
            .find(|e| e.path == path)
            .unwrap_or_else(|| panic!("{path}"));
        // One row per stress sample: steps 0, then every `interval`.
        assert!(
            e.temporal_rows >= samples.len() - 1,
            "{path}: {}",
            e.temporal_rows
        );
    }
    assert!(
        !entities
            .iter()
            .any(|e| e.path.starts_with("/stress/domain/couple"))
    );

    let summary = run("plain", &plain);
    let text = std::fs::read_to_string(&summary.report_path).unwrap();
    assert!(!text.contains("\"stress\""));
}
