//! The lane form of the linear law (`ContactLaw::evaluate_lanes`) gives, lane by lane,
//! the bits of its scalar form (`ContactLaw::evaluate`): forces, energies and the updated
//! history, on four contacts with different parameters and phases of one path (a first
//! evaluation with its onset weight, loading, sticking, sliding, unloading, the release
//! pull after the bodies part, starting again) along turning normals, and on a lane whose
//! normal does not turn. It evaluates every lane it is offered, and only those.

use glam::DVec3;
use talus_contact::*;
use talus_linear_spring::{LinearSpring, LinearSpringLaw, TangentialSpring};

fn params(values: &[(&str, f64)]) -> <LinearSpring as ContactLaw>::Params {
    let pair = PairAssignment {
        materials: (0, 0),
        names: ("a".into(), "a".into()),
        values: ParamValues(values.iter().map(|(k, v)| (k.to_string(), *v)).collect()),
        min_effective_mass: 1e-3,
        min_effective_radius: 1e-3,
        dimension: talus_core::resources::Dimension::Three,
        material_values: None,
    };
    let (p, _) = LinearSpringLaw.resolve(&pair).unwrap();
    *p.downcast_ref::<<LinearSpring as ContactLaw>::Params>()
        .unwrap()
}

/// The normal (turning, unless `fixed`) and overlap (a train of impacts of period
/// 0.012 s, each lasting 0.01 s) of a contact path at time `t`.
fn normal_and_overlap(t: f64, fixed: bool) -> (DVec3, f64) {
    let angle = if fixed { 0.2 } else { 0.3 * (t * 40.0).sin() };
    let normal = DVec3::new(angle.sin(), 0.2 * angle, angle.cos()).normalize();
    let phase = t % 0.012;
    (normal, 2e-5 * (std::f64::consts::PI * phase / 0.01).sin())
}

/// Kinematics of the path at step `step` of lane `lane` (each lane its own phase).
fn kinematics(step: usize, lane: usize, dt: f64, previous_overlap: f64) -> ContactKinematics {
    let t = (step + 317 * lane) as f64 * dt;
    let fixed = lane == 3;
    let (normal, overlap) = normal_and_overlap(t, fixed);
    let (previous_normal, _) = normal_and_overlap(t - dt, fixed);
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
        // A contact is new when it did not overlap before: no previous normal.
        previous_normal: if previous_overlap > 0.0 {
            previous_normal
        } else {
            DVec3::ZERO
        },
        relative_omega: DVec3::new(1.0, -2.0, 0.5),
        effective_mass: 1e-3 * (1.0 + lane as f64),
        effective_radius: 5e-4,
        min_radius: 1e-3,
    };
    kin.displacement = kin.relative_velocity * dt;
    kin
}

fn bits(v: DVec3) -> [u64; 3] {
    v.to_array().map(f64::to_bits)
}

fn history_bits(h: &TangentialSpring) -> [u64; 8] {
    let [a, b, c] = bits(h.spring);
    let [d, e, f] = bits(h.tangential_dashpot);
    [
        a,
        b,
        c,
        d,
        e,
        f,
        h.normal_dashpot.to_bits(),
        h.normal_spring.to_bits(),
    ]
}

#[test]
fn lanes_give_the_scalar_bits() {
    let p = [
        params(&[("stiffness", 1e4), ("restitution", 0.5), ("friction", 0.3)]),
        params(&[("stiffness", 1e4), ("damping", 0.2), ("friction", 0.0)]),
        params(&[
            ("stiffness", 2e4),
            ("damping_rate", 50.0),
            ("friction", 0.5),
            ("tangential_damping_ratio", 0.5),
            ("tangential_stiffness_ratio", 0.5),
        ]),
        params(&[("stiffness", 1e4), ("restitution", 0.9), ("friction", 5.0)]),
    ];
    let dt = 1e-5;
    let mut history: [TangentialSpring; 4] = Default::default();
    let mut previous_overlap = [0.0; 4];
    let (mut evaluated, mut slid, mut stuck, mut onsets, mut releases) = (0, 0, 0, 0, 0);
    for step in 1..=3000 {
        let kin: [ContactKinematics; 4] =
            std::array::from_fn(|l| kinematics(step, l, dt, previous_overlap[l]));
        let lanes = ContactKinematicsLanes::from_scalar(kin);
        for book in [false, true] {
            let mut lane_history = history;
            // Lane 2 is not offered: it must be left alone.
            let offered = 0b1011;
            let (done, r) = LinearSpring::evaluate_lanes(
                [&p[0], &p[1], &p[2], &p[3]],
                &lanes,
                lane_history.each_mut(),
                offered,
                dt,
                book,
            );
            assert_eq!(done, offered, "step {step}");
            for l in 0..4 {
                let mut scalar_history = history[l];
                let s = LinearSpring::evaluate(&p[l], &kin[l], &mut scalar_history, dt);
                if done >> l & 1 == 0 {
                    assert_eq!(history_bits(&lane_history[l]), history_bits(&history[l]));
                    continue;
                }
                let at = format!("step {step}, lane {l}, book {book}");
                assert_eq!(bits(r.force.to_array()[l]), bits(s.force), "{at}");
                assert_eq!(bits(r.torque_a.to_array()[l]), bits(s.torque_a), "{at}");
                assert_eq!(bits(r.torque_b.to_array()[l]), bits(s.torque_b), "{at}");
                assert_eq!(
                    history_bits(&lane_history[l]),
                    history_bits(&scalar_history),
                    "{at}"
                );
                if book {
                    assert_eq!(
                        r.elastic_energy.to_array()[l].to_bits(),
                        s.elastic_energy.to_bits(),
                        "{at}"
                    );
                    assert_eq!(
                        r.integration_error.to_array()[l].to_bits(),
                        s.integration_error.to_bits(),
                        "{at}"
                    );
                    for (c, d) in r.dissipated.iter().zip(s.dissipated) {
                        assert_eq!(c.to_array()[l].to_bits(), d.to_bits(), "{at}");
                    }
                    if kin[l].overlap <= 0.0 {
                        releases += 1;
                    } else if kin[l].previous_overlap <= 0.0 {
                        onsets += 1;
                    } else if s.dissipated[2] > 0.0 {
                        slid += 1;
                    } else if l != 1 {
                        stuck += 1;
                    }
                }
            }
            if book {
                evaluated += done.count_ones();
            }
        }
        // Advance every lane with the scalar form (the reference).
        for l in 0..4 {
            LinearSpring::evaluate(&p[l], &kin[l], &mut history[l], dt);
            previous_overlap[l] = kin[l].overlap;
        }
    }
    eprintln!(
        "lanes evaluated {evaluated}: slid {slid}, stuck {stuck}, onsets {onsets}, releases {releases}"
    );
    assert_eq!(evaluated, 3 * 3000);
    assert!(
        slid > 100 && stuck > 100,
        "the path must both slide and stick"
    );
    assert!(onsets >= 8 && releases > 100, "contacts must start and end");
}
