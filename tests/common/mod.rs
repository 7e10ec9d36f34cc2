//! Helpers shared by the workspace-level tests: build scenes from text, read grains.
#![allow(dead_code)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus::core::prelude::*;
use talus::core::schedule::Simulation;

/// 120 frictional glass beads of 3–5 mm dropped into a 2 cm box (seed 9): a small pile
/// that settles with persistent, loaded contacts, run for `steps` steps.
pub fn settling_box_scene(name: &str, steps: u64) -> String {
    format!(
        r#"Scene(
    name: "{name}",
    gravity: (0.0, 0.0, -9.81),
    steps: {steps},
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 2000.0, restitution: 0.5, friction: 0.5))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.06), material: "glass")],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.03)),
        count: 120, radius: Uniform(min: 0.0015, max: 0.0025), seed: 9, velocity_spread: 0.05)],
    output: (recording: false),
)"#
    )
}

/// Builds a simulation from scene text; returns it with its step count.
pub fn build(text: &str) -> (Simulation, u64) {
    let scene = talus::scene::parse("test-scene.ron", text).unwrap_or_else(|e| panic!("{e}"));
    let built = scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    let steps = built.stop.steps;
    (built.builder.build(), steps)
}

/// State of one grain.
#[derive(Clone, Copy, Debug)]
pub struct GrainState {
    pub position: DVec3,
    pub velocity: DVec3,
    pub omega: DVec3,
    pub radius: f64,
    pub mass: f64,
}

/// All grains, in query order.
pub fn grains(sim: &mut Simulation) -> Vec<GrainState> {
    let mut q = sim
        .world
        .query_filtered::<(&Position, &Velocity, &AngularVelocity, &Radius, &Mass), With<Grain>>();
    q.iter(&sim.world)
        .map(|(p, v, w, r, m)| GrainState {
            position: p.0,
            velocity: v.0,
            omega: w.0,
            radius: r.0,
            mass: m.0,
        })
        .collect()
}

/// Instantaneous energies and ledger.
pub fn energies(sim: &Simulation) -> (EnergySnapshot, EnergyLedger) {
    (
        sim.world.resource::<EnergySnapshot>().clone(),
        sim.world.resource::<EnergyLedger>().clone(),
    )
}

/// A fresh temporary folder for a test, never the same twice in one process (the tests
/// share one binary and run on several threads).
pub fn temp_dir(name: &str) -> std::path::PathBuf {
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("talus-test-{name}-{}-{call}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Builds a simulation from scene text, resumed from a saved state when one is given
/// (then marked primed: its forces are the state's).
pub fn build_or_resume(text: &str, resume: Option<&talus::scene::state::SavedState>) -> Simulation {
    let scene = talus::scene::parse("test-scene.ron", text).unwrap_or_else(|e| panic!("{e}"));
    let built = match resume {
        Some(state) => scene.resume(&talus::registry(), state),
        None => scene.build(&talus::registry()),
    }
    .unwrap_or_else(|e| panic!("{e}"));
    let resumed = built.resumed;
    let mut sim = built.builder.build();
    if resumed {
        sim.mark_primed();
    }
    sim
}

/// The glass-like Jiang–Liu grain pair of the law's tests: density, radius and spring
/// constant k ≈ (4/3) E* √R* (E* ≈ 35 GPa).
pub mod jiang_liu_glass {
    /// Density, kg/m³.
    pub const DENSITY: f64 = 2500.0;
    /// Radius, m.
    pub const RADIUS: f64 = 0.005;
    /// Spring constant k of f = k δ^{3/2}, N/m^{3/2}.
    pub const STIFFNESS: f64 = 2.0e9;

    /// Mass of one grain, kg.
    pub fn grain_mass() -> f64 {
        DENSITY * 4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3)
    }

    /// The scene's `grains:` entry for the pair: centres at ∓x along x and ∓offset/2
    /// along y, approaching at relative speed `v` along x, the first spinning at `spin`
    /// rad/s about z.
    pub fn pair_grains(x: f64, offset: f64, v: f64, spin: f64) -> String {
        format!(
            r#"grains: [List(material: "glass", grains: [
        (position: ({nx:e}, {ny:e}, 0.0), radius: {RADIUS}, velocity: ({hv:e}, 0.0, 0.0), angular_velocity: (0.0, 0.0, {spin:e})),
        (position: ({x:e}, {y:e}, 0.0), radius: {RADIUS}, velocity: ({nhv:e}, 0.0, 0.0)),
    ])],"#,
            nx = -x,
            ny = -0.5 * offset,
            y = 0.5 * offset,
            hv = 0.5 * v,
            nhv = -0.5 * v,
        )
    }

    /// Contact time of f = k δ^{3/2} for the pair's reduced mass at normal speed v (the
    /// Hertz formula 2.943 δ_max / v, δ_max = (5 m* v²/(4k))^{2/5}).
    pub fn contact_time(v: f64) -> f64 {
        let m = 0.5 * grain_mass();
        2.943 * (5.0 * m * v * v / (4.0 * STIFFNESS)).powf(0.4) / v
    }
}

/// A gas of 800 glass grains (radii 0.7–0.9 mm, speeds up to 1 m/s, soft frictional
/// contacts) filling a cube of edge `cube` that is periodic along every axis, without
/// gravity. `shear` is appended inside `periodic:` (empty, or `,\n        shear: (...)` for
/// a Lees–Edwards cell); `sampling` is the scene's sampling section.
pub fn glass_gas(name: &str, steps: u64, cube: f64, shear: &str, sampling: &str) -> String {
    let (lo, hi) = (0.001, cube - 0.001);
    format!(
        r#"Scene(
    name: "{name}",
    gravity: (0.0, 0.0, 0.0),
    steps: {steps},
    periodic: (x: (0.0, {cube}), y: (0.0, {cube}), z: (0.0, {cube}){shear}),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 200.0, restitution: 0.8, friction: 0.3))],
    grains: [Random(material: "glass", region: (min: ({lo}, {lo}, {lo}), max: ({hi}, {hi}, {hi})),
        count: 800, radius: Uniform(min: 0.0007, max: 0.0009), seed: 5, velocity_spread: 1.0)],
    {sampling}
    output: (recording: false),
)"#
    )
}

/// The latest samples of stress regions and coarse-grained fields.
pub mod sampling {
    use talus::core::schedule::Simulation;
    use talus_stress::{FieldRecord, FieldSample, RegionStress, StressRecord};

    /// The latest stress sample's regions.
    pub fn regions(sim: &Simulation) -> Vec<RegionStress> {
        sim.world
            .resource::<StressRecord>()
            .latest
            .clone()
            .expect("a stress sample was taken")
            .regions
    }

    /// The region of that name.
    pub fn region<'a>(all: &'a [RegionStress], name: &str) -> &'a RegionStress {
        all.iter().find(|r| r.name == name).expect("region sampled")
    }

    /// The latest field sample.
    pub fn field(sim: &Simulation) -> FieldSample {
        sim.world
            .resource::<FieldRecord>()
            .latest
            .clone()
            .expect("a field sample was taken")
    }
}
