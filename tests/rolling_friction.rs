//! Friction: a grain launched sliding without spin on a floor ends rolling without
//! slipping at v = 5/7 v₀ (sphere) or 2/3 v₀ (disk), the rigid-body Coulomb result.

use crate::common;

fn scene(dimension: u8) -> String {
    // A disk of unit thickness weighs πρR²·1 m = 2.45 kg: stiffer contact, so that the
    // overlap (and the lever arm R − δ/2 of the contact point) stays below 1e-4 R.
    let (gravity, normal, z, stiffness) = if dimension == 3 {
        ("(0.0, 0.0, -9.81)", "(0.0, 0.0, 1.0)", "0.0, 0.01", 1e5)
    } else {
        ("(0.0, -9.81, 0.0)", "(0.0, 1.0, 0.0)", "0.01, 0.0", 1e8)
    };
    format!(
        r#"Scene(
    name: "rolling",
    dimension: {dimension},
    gravity: {gravity},
    duration: 0.4,
    plugins: ["linear_spring"],
    materials: [(name: "steel", density: 7800.0,
        contact: (law: "linear_spring", stiffness: {stiffness:e}, restitution: 0.5, friction: 0.3))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: {normal}, material: "steel")],
    grains: [List(material: "steel", grains: [
        (position: (0.0, {z}), radius: 0.01, velocity: (1.0, 0.0, 0.0)),
    ])],
    output: (recording: false),
)"#
    )
}

fn final_speed(dimension: u8) -> (f64, f64) {
    let (mut sim, steps) = common::build(&scene(dimension));
    assert!(
        sim.config().rotation,
        "friction torques the grain: rotation is on"
    );
    let window = steps / 4;
    let (mut v_sum, mut slip_sum) = (0.0, 0.0);
    for step in 1..=steps {
        sim.step().unwrap();
        if step > steps - window {
            let g = common::grains(&mut sim)[0];
            v_sum += g.velocity.x;
            // Rolling: the contact point is at rest, v = ω × R (ω about −z or +y).
            let omega = if dimension == 3 {
                g.omega.y
            } else {
                -g.omega.z
            };
            slip_sum += g.velocity.x - omega * g.radius;
        }
    }
    (v_sum / window as f64, slip_sum / window as f64)
}

#[test]
fn sphere_rolls_at_five_sevenths() {
    let (v, slip) = final_speed(3);
    assert!((v - 5.0 / 7.0).abs() / (5.0 / 7.0) < 0.01, "v = {v}");
    assert!(slip.abs() < 0.01 * v, "slip velocity {slip}");
}

#[test]
fn disk_rolls_at_two_thirds() {
    let (v, slip) = final_speed(2);
    assert!((v - 2.0 / 3.0).abs() / (2.0 / 3.0) < 0.01, "v = {v}");
    assert!(slip.abs() < 0.01 * v, "slip velocity {slip}");
}
