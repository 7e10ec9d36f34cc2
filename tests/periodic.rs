//! Periodic boundaries: a collision through the seam is the same collision as one in the
//! middle of the box (translation invariance), and a frictional gas in a fully periodic
//! box conserves momentum exactly and energy to the integrator's error.

use crate::common;

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus::cli::ReportSample;
use talus::contact::{Contact, ContactKind};
use talus::core::prelude::*;

/// Two glass spheres of radius 1 cm approaching head-on along x at 0.5 m/s each, centred
/// on `x_mid` in a box periodic in x over [0, 0.2).
fn pair_scene(x_a: f64, x_b: f64) -> String {
    format!(
        r#"Scene(
    name: "seam",
    duration: 0.008,
    steps_per_collision: 2000,
    periodic: (x: (0.0, 0.2)),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.7, friction: 0.3))],
    grains: [List(material: "glass", grains: [
        (position: ({x_a:e}, 0.0, 0.0), radius: 0.01, velocity: (0.5, 0.0, 0.0)),
        (position: ({x_b:e}, 0.0, 0.0), radius: 0.01, velocity: (-0.5, 0.0, 0.0)),
    ])],
    output: (recording: false),
)"#
    )
}

fn run_pair(x_a: f64, x_b: f64) -> (Vec<common::GrainState>, usize) {
    let (mut sim, steps) = common::build(&pair_scene(x_a, x_b));
    let mut contact_steps = 0;
    for _ in 0..steps {
        sim.step().unwrap();
        contact_steps += common::energies(&sim).0.contacts;
    }
    (common::grains(&mut sim), contact_steps)
}

#[test]
fn a_collision_through_the_seam_is_the_collision_in_the_middle() {
    // In the middle: centres at 0.0895 and 0.1105. Through the seam: a at 0.1895 moving
    // right meets b at 0.0105 (its image at 0.2105) moving left.
    let (middle, steps_middle) = run_pair(0.0895, 0.1105);
    let (seam, steps_seam) = run_pair(0.1895, 0.0105);
    assert!(steps_middle > 100, "the grains collided in the middle");
    assert_eq!(
        steps_middle, steps_seam,
        "same contact duration through the seam"
    );
    let e = -(middle[0].velocity.x - middle[1].velocity.x) / 1.0;
    assert!((e - 0.7).abs() < 0.005 * 0.7, "restitution {e}");
    for (m, s) in middle.iter().zip(&seam) {
        assert!(
            (m.velocity - s.velocity).length() < 1e-9,
            "velocities {:?} vs {:?}",
            m.velocity,
            s.velocity
        );
        // Positions agree modulo the box (the seam pair started 0.1 m further right).
        let shift = s.position - m.position - DVec3::new(0.1, 0.0, 0.0);
        let wrapped = shift.x - 0.2 * (shift.x / 0.2).round();
        assert!(
            wrapped.abs() < 1e-12 && shift.y.abs() < 1e-12,
            "shift {shift:?}"
        );
        assert!(
            (0.0..0.2).contains(&s.position.x),
            "wrapped into the box: {}",
            s.position.x
        );
    }
}

const GAS: &str = r#"Scene(
    name: "periodic-gas",
    gravity: (0.0, 0.0, 0.0),
    steps: 20000,
    periodic: (x: (0.0, 0.02), y: (0.0, 0.02), z: (0.0, 0.02)),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e3, restitution: 1.0, friction: 0.3))],
    grains: [Random(material: "glass", region: (min: (0.001, 0.001, 0.001), max: (0.019, 0.019, 0.019)),
        count: 150, radius: Uniform(min: 0.0008, max: 0.001), seed: 11, velocity_spread: 0.2)],
    output: (recording: false),
)"#;

fn momentum(sim: &mut talus::core::schedule::Simulation) -> (DVec3, f64) {
    common::grains(sim)
        .iter()
        .fold((DVec3::ZERO, 0.0), |(p, s), g| {
            (p + g.mass * g.velocity, s + g.mass * g.velocity.length())
        })
}

/// Contacts whose two grains sit on opposite sides of a seam (more than half a box apart).
fn seam_contacts(sim: &mut talus::core::schedule::Simulation) -> usize {
    let mut q = sim.world.query::<&Contact>();
    let pairs: Vec<(Entity, Entity)> = q
        .iter(&sim.world)
        .filter(|c| c.kind == ContactKind::GrainGrain)
        .map(|c| (c.a, c.b))
        .collect();
    pairs
        .iter()
        .filter(|(a, b)| {
            let pa = sim.world.get::<Position>(*a).unwrap().0;
            let pb = sim.world.get::<Position>(*b).unwrap().0;
            ((pa - pb).abs().max_element()) > 0.01
        })
        .count()
}

#[test]
fn a_frictional_gas_in_a_periodic_box_conserves_momentum_and_energy() {
    let (mut sim, steps) = common::build(GAS);
    sim.prime().unwrap();
    let first = ReportSample::take(&sim.world);
    let (p0, scale) = momentum(&mut sim);
    let mut seams = 0;
    let mut wrapped = 0;
    let mut previous: Vec<DVec3> = common::grains(&mut sim)
        .iter()
        .map(|g| g.position)
        .collect();
    for step in 1..=steps {
        sim.step().unwrap();
        if step % 20 == 0 {
            seams += seam_contacts(&mut sim);
            let now: Vec<DVec3> = common::grains(&mut sim)
                .iter()
                .map(|g| g.position)
                .collect();
            wrapped += now
                .iter()
                .zip(&previous)
                .filter(|(a, b)| (**a - **b).abs().max_element() > 0.01)
                .count();
            previous = now;
        }
    }
    let last = ReportSample::take(&sim.world);
    let (p1, _) = momentum(&mut sim);
    let grains = common::grains(&mut sim);
    assert!(seams > 0, "no contact formed across a seam");
    assert!(wrapped > 0, "no grain crossed a face");
    for g in &grains {
        assert!(g.position.cmpge(DVec3::ZERO).all() && g.position.cmplt(DVec3::splat(0.02)).all());
    }
    // Contact forces come in equal and opposite pairs, also through the seam.
    let drift = (p1 - p0).length() / scale;
    assert!(drift < 1e-12, "momentum drift {drift:e}");
    let e0 = first.kinetic() + first.elastic;
    let book = (last.bookkeeping_balance - first.bookkeeping_balance).abs() / e0;
    let physical = (last.energy_balance - first.energy_balance).abs() / e0;
    eprintln!(
        "periodic gas: {seams} seam contacts sampled, {wrapped} face crossings, momentum drift {drift:.2e}, bookkeeping {book:.2e}, physical {physical:.2e}, friction {:.3e} J",
        last.dissipated_total
    );
    assert!(book < 1e-6, "bookkeeping drift {book:e}");
    assert!(physical < 1e-3, "physical drift {physical:e}");
}

fn error_of(text: &str) -> talus::scene::SceneError {
    match talus::scene::parse("bad.ron", text).and_then(|s| s.build(&talus::registry()).map(|_| ()))
    {
        Err(e) => e,
        Ok(()) => panic!("accepted:\n{text}"),
    }
}

#[test]
fn bad_periodic_boxes_are_scene_errors() {
    let short = GAS.replace("x: (0.0, 0.02), y", "x: (0.0, 0.003), y");
    let e = error_of(&short);
    assert_eq!(e.field, "grains[0]", "{e}"); // grains outside [0, 0.003) first
    // One grain of radius 1 mm in a box 3.5 mm long: it would touch its own image.
    let tiny = pair_scene(0.001, 0.05)
        .replace("x: (0.0, 0.2)", "x: (0.0, 0.0035)")
        .replace(
            "(position: (5e-2, 0.0, 0.0), radius: 0.01, velocity: (-0.5, 0.0, 0.0)),",
            "",
        )
        .replace("radius: 0.01", "radius: 0.001");
    let e = error_of(&tiny);
    assert_eq!(e.field, "periodic.x", "{e}");
    assert!(e.expected.contains("twice the largest reach"), "{e}");
    let inverted = GAS.replace("y: (0.0, 0.02)", "y: (0.02, 0.0)");
    assert_eq!(error_of(&inverted).field, "periodic.y");
    let unknown = GAS.replace("z: (0.0, 0.02)", "w: (0.0, 0.02)");
    assert!(
        error_of(&unknown).expected.contains("x"),
        "lists the fields"
    );
}
