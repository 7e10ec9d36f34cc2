//! A servo wall holds a pressure: a packing squeezed by a servo-controlled lid settles with
//! the lid's load equal to the target, and the sampled stress equal to the target pressure.

mod common;

use talus::cli::ReportSample;

const PRESSURE: f64 = 2.0e4;

#[test]
fn a_servo_lid_holds_the_target_pressure() {
    let text = format!(
        r#"Scene(
    name: "servo",
    gravity: (0.0, 0.0, 0.0),
    duration: 0.15,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.2, friction: 0.3))],
    walls: [
        Box(min: (0.0, 0.0, 0.0), max: (0.01, 0.01, 0.1), material: "glass", omit: ["z_max"]),
        Plane(name: "lid", point: (0.0, 0.0, 0.0102), normal: (0.0, 0.0, -1.0), material: "glass",
            servo: (pressure: {PRESSURE:e}, area: 1e-4, gain: 0.05, max_speed: 0.05)),
    ],
    grains: [Lattice(material: "glass", radius: 0.001, region: (min: (0.0, 0.0, 0.0), max: (0.01, 0.01, 0.01)),
        spacing: 0.002)],
    sampling: (interval: 0.01),
    output: (recording: false),
)"#
    );
    let (mut sim, steps) = common::build(&text);
    assert!(
        sim.plan
            .stages
            .iter()
            .any(|(_, s)| s.iter().any(|n| n == "servo_walls"))
    );
    sim.run_steps(steps).unwrap();
    let sample = ReportSample::take(&sim.world);
    let mut q = sim
        .world
        .query::<(&talus::core::prelude::Wall, &talus::core::prelude::WallLoad)>();
    let (lid, load) = q.iter(&sim.world).find(|(w, _)| w.name == "lid").unwrap();
    let pushed = -load.0.dot(lid.normal);
    let target = PRESSURE * 1e-4;
    let stress = sample.stress.as_ref().expect("sampled");
    let domain = stress.regions.iter().find(|r| r.name == "domain").unwrap();
    let sigma_zz = domain.stress.0[2][2];
    eprintln!(
        "servo: lid load {pushed:.5} N (target {target} N), sampled σ_zz {sigma_zz:.2} Pa (target −{PRESSURE}), KE {:.2e} J",
        sample.kinetic()
    );
    assert!((pushed - target).abs() < 0.01 * target, "lid load {pushed}");
    assert!(
        (-sigma_zz - PRESSURE).abs() < 0.01 * PRESSURE,
        "σ_zz {sigma_zz}"
    );
}
