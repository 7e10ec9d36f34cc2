//! A law assembled from sub-models gives bit-identical forces, torques and energies to
//! the same law written whole, step after step, through loading, sliding, unloading and
//! separation along a rotating contact normal.

use glam::DVec3;
use talus_contact::*;
use talus_linear_spring::parts::ComposedLinearSpring;
use talus_linear_spring::{LinearSpring, LinearSpringLaw};

fn pair(values: &[(&str, f64)]) -> PairAssignment {
    PairAssignment {
        materials: (0, 0),
        names: ("a".into(), "a".into()),
        values: ParamValues(values.iter().map(|(k, v)| (k.to_string(), *v)).collect()),
        min_effective_mass: 1e-3,
        min_effective_radius: 1e-3,
        dimension: talus_core::resources::Dimension::Three,
        material_values: None,
    }
}

/// A contact path: overlap rising then falling through zero, normal turning, sliding
/// and sticking tangential motion (a deterministic sequence, no random numbers).
fn kinematics(step: usize, dt: f64) -> ContactKinematics {
    let (normal, overlap) = normal_and_overlap(step, dt);
    // The contact is new at step 1: no previous normal, and it starts mid-step.
    let (previous_normal, previous_overlap) = if step > 1 {
        normal_and_overlap(step - 1, dt)
    } else {
        (DVec3::ZERO, 0.0)
    };
    let t = step as f64 * dt;
    let tangent = normal.cross(DVec3::Y).normalize();
    let vt = tangent * (0.05 * (t * 300.0).cos()) + normal.cross(tangent) * 0.01;
    let vn = 2e-5 * std::f64::consts::PI / 0.01 * (std::f64::consts::PI * t / 0.01).cos();
    let relative_velocity = vt - normal * vn;
    let mut kin = ContactKinematics {
        normal,
        overlap,
        point: DVec3::ZERO,
        branch_a: -normal * 1e-3,
        branch_b: normal * 1e-3,
        relative_velocity,
        normal_velocity: relative_velocity.dot(normal),
        tangential_velocity: relative_velocity - normal * relative_velocity.dot(normal),
        displacement: DVec3::ZERO,
        previous_overlap,
        previous_normal,
        relative_omega: DVec3::new(1.0, -2.0, 0.5),
        effective_mass: 1e-3,
        effective_radius: 5e-4,
        min_radius: 1e-3,
    };
    kin.displacement = kin.relative_velocity * dt;
    kin
}

/// The normal and overlap of the path at `step`.
fn normal_and_overlap(step: usize, dt: f64) -> (DVec3, f64) {
    let t = step as f64 * dt;
    let angle = 0.3 * (t * 40.0).sin();
    let normal = DVec3::new(angle.sin(), 0.2 * angle, angle.cos()).normalize();
    (normal, 2e-5 * (std::f64::consts::PI * t / 0.01).sin())
}

fn compare(values: &[(&str, f64)]) {
    let pair = pair(values);
    let whole = LinearSpringLaw;
    let parts = talus_linear_spring::parts::composed_descriptor();
    let (pw, _) = whole.resolve(&pair).unwrap();
    let (pc, _) = parts.resolve(&pair).unwrap();
    let pw = pw
        .downcast_ref::<<LinearSpring as ContactLaw>::Params>()
        .unwrap();
    let pc = pc
        .downcast_ref::<<ComposedLinearSpring as ContactLaw>::Params>()
        .unwrap();
    assert_eq!(
        LinearSpring::dissipation(),
        ComposedLinearSpring::dissipation()
    );
    let mut hw = Default::default();
    let mut hc = Default::default();
    let dt = 1e-5;
    let mut slid = false;
    let mut in_contact = 0;
    // 0.01 s of contact, then separation (overlap < 0) at step 1000.
    for step in 1..=1001 {
        let kin = kinematics(step, dt);
        let a = LinearSpring::evaluate(pw, &kin, &mut hw, dt);
        let b = ComposedLinearSpring::evaluate(pc, &kin, &mut hc, dt);
        for (x, y) in [
            (a.force, b.force),
            (a.torque_a, b.torque_a),
            (a.torque_b, b.torque_b),
        ] {
            assert_eq!(
                x.to_array().map(f64::to_bits),
                y.to_array().map(f64::to_bits),
                "step {step}"
            );
        }
        assert_eq!(
            a.elastic_energy.to_bits(),
            b.elastic_energy.to_bits(),
            "step {step}"
        );
        assert_eq!(
            a.integration_error.to_bits(),
            b.integration_error.to_bits(),
            "step {step}"
        );
        assert_eq!(
            a.dissipated.map(f64::to_bits),
            b.dissipated.map(f64::to_bits),
            "step {step}"
        );
        slid |= a.dissipated[2] > 0.0;
        in_contact += usize::from(kin.overlap > 0.0);
    }
    assert!(in_contact > 900, "the path must load the contact");
    if values.iter().any(|(k, v)| *k == "friction" && *v > 0.0) {
        assert!(slid, "the path must make the contact slide");
    }
}

#[test]
fn composed_linear_law_is_bit_identical_to_the_whole_law() {
    compare(&[("stiffness", 1e4), ("restitution", 0.5), ("friction", 0.3)]);
    compare(&[("stiffness", 1e4), ("damping", 0.2), ("friction", 0.0)]);
    compare(&[
        ("collision_time", 1e-3),
        ("restitution", 0.8),
        ("friction", 0.5),
        ("tangential_damping_ratio", 0.5),
        ("tangential_stiffness_ratio", 0.5),
    ]);
}
