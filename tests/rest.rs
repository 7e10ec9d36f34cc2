//! Long rest: a settled grain on a floor stays put (no creep) over a million steps.

use crate::common;

#[test]
fn settled_grain_moves_less_than_1e_minus_9_radius_in_a_million_steps() {
    let (mut sim, _) = common::build(
        r#"Scene(
    name: "rest",
    gravity: (0.0, 0.0, -9.81),
    steps: 1,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.5, friction: 0.5))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "glass")],
    grains: [List(material: "glass", grains: [(position: (0.0, 0.0, 0.005), radius: 0.005)])],
    output: (recording: false),
)"#,
    );
    sim.run_steps(100_000).unwrap();
    let start = common::grains(&mut sim)[0];
    // Settled: the overlap carries the weight, δ = m g / k.
    let expected_overlap = start.mass * 9.81 / 1e4;
    let overlap = start.radius - start.position.z;
    assert!(
        (overlap - expected_overlap).abs() < 1e-6 * expected_overlap,
        "{overlap} vs {expected_overlap}"
    );
    sim.run_steps(1_000_000).unwrap();
    let end = common::grains(&mut sim)[0];
    let moved = (end.position - start.position).length();
    assert!(moved < 1e-9 * start.radius, "moved {moved} m");
}
