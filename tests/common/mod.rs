//! Helpers shared by the workspace-level tests: build scenes from text, read grains.
#![allow(dead_code)]

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus::core::prelude::*;
use talus::core::schedule::Simulation;

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

/// A fresh temporary folder for a test.
pub fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("talus-test-{name}-{}", std::process::id()));
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

    /// Contact time of f = k δ^{3/2} for the pair's reduced mass at normal speed v (the
    /// Hertz formula 2.943 δ_max / v, δ_max = (5 m* v²/(4k))^{2/5}).
    pub fn contact_time(v: f64) -> f64 {
        let m = 0.5 * grain_mass();
        2.943 * (5.0 * m * v * v / (4.0 * STIFFNESS)).powf(0.4) / v
    }
}
