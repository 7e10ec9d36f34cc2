//! Talus's step against an independent reference on LAMMPS's chute: a plain kernel that
//! holds no contact entities, tables, narrow phase, sorts or recycled rows, only LAMMPS's
//! half neighbour list with each contact's history in its entry
//! (`benches/support/lammps_kernel.rs`), evaluating Talus's linear law with Talus's contact
//! life cycle. After 100 steps of the flowing chute the two must hold the same grains in
//! the same state to rounding: every contact made, kept, released and ended at the same
//! step, with its history carried through the tables' sorts and reuses.

#[path = "../benches/support/lammps_kernel.rs"]
#[allow(dead_code)]
mod lammps_kernel;

use std::path::Path;

use glam::DVec3;
use lammps_kernel::{Kernel, Variant};
use talus::core::components::{AngularVelocity, Position, Velocity};
use talus::core::snapshot::GrainSnapshot;

#[test]
fn talus_steps_the_chute_as_a_plain_reference_kernel_does() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench/chute.ron");
    let text = std::fs::read_to_string(&path).unwrap();
    let scene = talus::scene::parse(&path, &text).unwrap_or_else(|e| panic!("{e}"));
    let built = scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    let steps = built.stop.steps;
    assert_eq!(steps, 100);
    let mut sim = built.builder.build();
    sim.prime().unwrap();
    let tilt = 26f64.to_radians();
    let mut kernel = Kernel::from_snapshot(
        sim.world.resource::<GrainSnapshot>(),
        [40.0, 20.0],
        DVec3::new(tilt.sin(), 0.0, -tilt.cos()),
        Variant::TalusLaw,
    );
    let order = sim.world.resource::<GrainSnapshot>().entity.clone();
    sim.run_steps(steps).unwrap();
    for _ in 0..steps {
        kernel.step();
    }
    // Talus's grains, in the snapshot's order of step 0 (the kernel's).
    let state = |e: bevy_ecs::entity::Entity| {
        let grain = sim.world.entity(e);
        (
            grain.get::<Position>().unwrap().0,
            grain.get::<Velocity>().unwrap().0,
            grain.get::<AngularVelocity>().unwrap().0,
        )
    };
    let (mut worst_position, mut worst_velocity, mut worst_spin) = (0.0f64, 0.0f64, 0.0f64);
    for (i, &e) in order.iter().enumerate() {
        let (x, v, w) = state(e);
        // Both wrap into the box, at different steps: compare by the nearest image.
        let mut d = x - kernel.position[i];
        d.x -= 40.0 * (d.x / 40.0).round();
        d.y -= 20.0 * (d.y / 20.0).round();
        worst_position = worst_position.max(d.length());
        worst_velocity = worst_velocity.max((v - kernel.velocity[i]).length());
        worst_spin = worst_spin.max((w - kernel.omega[i]).length());
    }
    // The two sum each grain's forces in other orders, and 100 steps of the flow grow that
    // rounding to 3e-14 in position, 7e-12 in velocity and 2e-11 in spin (measured). A
    // contact made, kept or ended at another step, or with another history, changes its
    // grains' velocities by some 1e-4 in that one step (a force of order the grains'
    // weight, 0.5, for dt over a mass of 0.5): the kernel without the release evaluation
    // parts from Talus by 1e-2 in velocity.
    assert!(
        worst_position < 1e-10 && worst_velocity < 1e-9 && worst_spin < 1e-8,
        "the grains part from the reference: position {worst_position:e}, velocity \
         {worst_velocity:e}, spin {worst_spin:e}"
    );
    let contacts = talus::cli::ReportSample::take(&sim.world).contacts;
    assert_eq!(
        Some(contacts),
        kernel.active_contacts(),
        "Talus's contacts carrying a force, and the reference's"
    );
}
