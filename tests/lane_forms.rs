//! The lane form of the linear law (four persistent contacts at once,
//! `plugins/linear-spring/src/lanes.rs`) gives its scalar form's results bit for bit: the
//! same scenes run with the lane forms on and off (`talus::contact::LaneForms`) end with
//! the same grains, the same contacts (geometry, force, torques, tangential spring and the
//! rest of the history) and the same energies, on a flow (the LAMMPS chute), on a pile
//! settling in a walled box (grain–wall contacts go through the scalar form, and a pile
//! near rest keeps some normals unturned), without friction, and without the energy ledger.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use bevy_ecs::prelude::*;
use talus::contact::{Contact, ContactForce, ContactGeometry, LaneForms, LawState};
use talus::core::prelude::*;
use talus_linear_spring::TangentialSpring;

/// Every grain's position, velocity and spin, by entity, as bits.
fn grain_bits(world: &mut World) -> BTreeMap<u64, Vec<u64>> {
    let mut q =
        world.query_filtered::<(Entity, &Position, &Velocity, &AngularVelocity), With<Grain>>();
    q.iter(world)
        .map(|(e, p, v, w)| {
            let bits = [p.0, v.0, w.0]
                .iter()
                .flat_map(|x| x.to_array())
                .map(f64::to_bits)
                .collect();
            (e.to_bits(), bits)
        })
        .collect()
}

/// Every contact's geometry, force, torques and history, by pair, as bits.
fn contact_bits(world: &mut World) -> BTreeMap<(u64, u64), Vec<u64>> {
    let mut q = world.query::<(
        &Contact,
        &ContactGeometry,
        &ContactForce,
        &LawState<TangentialSpring>,
    )>();
    q.iter(world)
        .map(|(c, g, f, h)| {
            let h = &h.0;
            let values = [
                g.normal,
                f.force,
                f.torque_a,
                f.torque_b,
                h.spring,
                h.tangential_dashpot,
            ]
            .iter()
            .flat_map(|x| x.to_array())
            .chain([g.overlap, h.normal_dashpot, h.normal_spring])
            .map(f64::to_bits)
            .collect();
            ((c.a.to_bits(), c.b.to_bits()), values)
        })
        .collect()
}

/// The energies and ledger of the last step, as bits.
fn energy_bits(world: &World) -> Vec<u64> {
    let e = world.resource::<EnergySnapshot>();
    let l = world.resource::<EnergyLedger>();
    [
        e.translational_kinetic,
        e.rotational_kinetic,
        e.elastic,
        e.max_overlap_ratio,
        l.gravity_work,
        l.wall_work,
        l.integration_error,
    ]
    .into_iter()
    .chain(l.dissipated.iter().copied())
    .map(f64::to_bits)
    .collect()
}

/// Runs `steps` steps of a scene whose world `setup` has changed; returns the grains, the
/// contacts, the energies and the number of active contacts at the end, and that number.
pub(crate) fn run_with(
    text: &str,
    steps: u64,
    setup: impl FnOnce(&mut World),
) -> (impl PartialEq + std::fmt::Debug, usize) {
    let (mut sim, _) = common::build(text);
    setup(&mut sim.world);
    sim.prime().unwrap();
    sim.run_steps(steps).unwrap();
    let contacts = sim.world.resource::<EnergySnapshot>().contacts;
    let state = (
        grain_bits(&mut sim.world),
        contact_bits(&mut sim.world),
        energy_bits(&sim.world),
        contacts,
    );
    (state, contacts)
}

/// Runs `steps` steps of a scene with the lane forms on or off ([`run_with`]).
fn run(text: &str, steps: u64, lanes: bool) -> (impl PartialEq + std::fmt::Debug, usize) {
    run_with(text, steps, move |world| {
        world.insert_resource(LaneForms(lanes))
    })
}

/// Asserts that a scene ends the same with and without the lane forms.
fn same_with_and_without_lanes(what: &str, text: &str, steps: u64) {
    let (with, contacts) = run(text, steps, true);
    let (without, _) = run(text, steps, false);
    assert!(contacts > 0, "{what}: the grains must touch");
    assert!(with == without, "{what}: the lane form changed the results");
}

pub(crate) fn chute_text() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    std::fs::read_to_string(root.join("chute.ron"))
        .unwrap()
        .replace("\"data.chute\"", &format!("{:?}", root.join("data.chute")))
}

#[test]
fn the_chute_flow_is_the_same_with_lanes() {
    let text = chute_text().replace("energy_ledger: false", "energy_ledger: true");
    assert!(text.contains("energy_ledger: true"));
    same_with_and_without_lanes("chute", &text, 60);
}

#[test]
fn the_chute_flow_without_the_ledger_is_the_same_with_lanes() {
    let text = chute_text();
    assert!(text.contains("energy_ledger: false"));
    same_with_and_without_lanes("chute without the ledger", &text, 60);
}

#[test]
fn a_settling_pile_in_a_box_is_the_same_with_lanes() {
    same_with_and_without_lanes(
        "settling box",
        &common::settling_box_scene("lanes-box", 6000),
        6000,
    );
}

#[test]
fn a_frictionless_pile_is_the_same_with_lanes() {
    let text = common::settling_box_scene("lanes-frictionless", 6000)
        .replace("friction: 0.5", "friction: 0.0");
    assert!(text.contains("friction: 0.0"));
    same_with_and_without_lanes("frictionless box", &text, 6000);
}

/// The Hertz–Mindlin law with constant-torque rolling resistance, assembled from parts
/// that each have a lane form, as a scene selects it (`rolling: "constant_torque"`).
type HertzRolling = talus::contact::Composed<
    talus_hertz_mindlin::HertzNormal,
    talus_hertz_mindlin::HertzDamping,
    talus_hertz_mindlin::MindlinTangential,
    talus_rolling_resistance::ConstantTorque,
>;

/// The parameters of [`HertzRolling`] for one pair from scene values.
fn hertz_rolling_params(values: &[(&str, f64)]) -> <HertzRolling as ContactLaw>::Params {
    use talus::contact::{ComposedLaw, LawDescriptor, PairAssignment, ParamValues};
    let pair = PairAssignment {
        materials: (0, 0),
        names: ("a".into(), "a".into()),
        values: ParamValues(values.iter().map(|(k, v)| (k.to_string(), *v)).collect()),
        min_effective_mass: 1e-3,
        min_effective_radius: 5e-4,
        dimension: talus::core::resources::Dimension::Three,
        material_values: None,
    };
    let law = ComposedLaw::<
        talus_hertz_mindlin::HertzNormal,
        talus_hertz_mindlin::HertzDamping,
        talus_hertz_mindlin::MindlinTangential,
        talus_rolling_resistance::ConstantTorque,
    >::new("hertz_mindlin", "test");
    let (p, _) = law.resolve(&pair).unwrap();
    p.downcast_ref::<<HertzRolling as ContactLaw>::Params>()
        .unwrap()
        .clone()
}

use talus::contact::{ContactKinematics, ContactKinematicsLanes, ContactLaw};

/// A contact path for lane `lane`: a train of impacts (overlap rising and falling
/// through zero, so that contacts start, persist and end), a turning normal, sliding and
/// sticking tangential motion, a turning spin.
fn path(step: usize, lane: usize, dt: f64, previous_overlap: f64) -> ContactKinematics {
    let t = (step + 317 * lane) as f64 * dt;
    let shape = |t: f64| {
        let angle = 0.3 * (t * 40.0).sin();
        let normal = glam::DVec3::new(angle.sin(), 0.2 * angle, angle.cos()).normalize();
        let phase = t % 0.012;
        (normal, 2e-5 * (std::f64::consts::PI * phase / 0.01).sin())
    };
    let (normal, overlap) = shape(t);
    let (previous_normal, _) = shape(t - dt);
    let tangent = normal.cross(glam::DVec3::Y).normalize();
    let vt = tangent * (0.05 * (t * 300.0).cos()) + normal.cross(tangent) * 0.01;
    let vn = 2e-5 * std::f64::consts::PI / 0.01 * (std::f64::consts::PI * t / 0.01).cos();
    let relative_velocity = vt - normal * vn;
    ContactKinematics {
        normal,
        overlap,
        point: glam::DVec3::ZERO,
        branch_a: -normal * 1e-3,
        branch_b: normal * 1e-3,
        relative_velocity,
        normal_velocity: relative_velocity.dot(normal),
        tangential_velocity: relative_velocity - normal * relative_velocity.dot(normal),
        displacement: relative_velocity * dt,
        previous_overlap,
        previous_normal: if previous_overlap > 0.0 {
            previous_normal
        } else {
            glam::DVec3::ZERO
        },
        relative_omega: glam::DVec3::new((t * 90.0).sin(), -2.0, 0.5 * (t * 30.0).cos()),
        effective_mass: 1e-3 * (1.0 + lane as f64),
        effective_radius: 5e-4,
        min_radius: 1e-3,
    }
}

/// Drives four lanes of law `L` along [`path`] for `steps` steps and checks, at every
/// step, that the lane form evaluates exactly the offered lanes and gives each of them
/// the scalar form's force, torques, energies and history, bit for bit.
fn lanes_match_scalar<L: ContactLaw>(params: [L::Params; 4], steps: usize) {
    let bits = |v: glam::DVec3| v.to_array().map(f64::to_bits);
    // Histories compared through their text (RON writes every f64 so that it reads back
    // to the same bits, signed zeros included).
    let text = |h: &L::History| ron::to_string(h).unwrap();
    let dt = 1e-5;
    let mut history: [L::History; 4] = Default::default();
    let mut previous_overlap = [0.0; 4];
    let (mut onsets, mut releases) = (0, 0);
    for step in 1..=steps {
        let kin: [ContactKinematics; 4] =
            std::array::from_fn(|l| path(step, l, dt, previous_overlap[l]));
        let lanes = ContactKinematicsLanes::from_scalar(kin);
        for book in [false, true] {
            let mut lane_history = history.clone();
            let offered = 0b1101;
            let (done, r) = L::evaluate_lanes(
                std::array::from_fn(|l| &params[l]),
                &lanes,
                lane_history.each_mut(),
                offered,
                dt,
                book,
            );
            assert_eq!(done, offered, "step {step}");
            for l in 0..4 {
                let mut scalar_history = history[l].clone();
                let s = L::evaluate(&params[l], &kin[l], &mut scalar_history, dt);
                if offered >> l & 1 == 0 {
                    assert_eq!(
                        text(&lane_history[l]),
                        text(&history[l]),
                        "step {step}: lane {l}"
                    );
                    continue;
                }
                let at = format!("step {step}, lane {l}, book {book}");
                assert_eq!(bits(r.force.to_array()[l]), bits(s.force), "{at}");
                assert_eq!(bits(r.torque_a.to_array()[l]), bits(s.torque_a), "{at}");
                assert_eq!(bits(r.torque_b.to_array()[l]), bits(s.torque_b), "{at}");
                assert_eq!(text(&lane_history[l]), text(&scalar_history), "{at}");
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
                }
            }
        }
        for l in 0..4 {
            onsets += usize::from(kin[l].overlap > 0.0 && previous_overlap[l] <= 0.0);
            releases += usize::from(kin[l].overlap <= 0.0 && previous_overlap[l] > 0.0);
            L::evaluate(&params[l], &kin[l], &mut history[l], dt);
            previous_overlap[l] = kin[l].overlap;
        }
    }
    assert!(
        onsets >= 8 && releases >= 8,
        "contacts must start and end ({onsets}, {releases})"
    );
}

#[test]
fn hertz_mindlin_with_rolling_lanes_give_the_scalar_bits() {
    let params = [
        hertz_rolling_params(&[
            ("youngs_modulus", 1e8),
            ("poisson_ratio", 0.3),
            ("restitution", 0.5),
            ("friction", 0.5),
            ("rolling_friction", 0.1),
        ]),
        hertz_rolling_params(&[
            ("youngs_modulus", 5e7),
            ("poisson_ratio", 0.25),
            ("restitution", 0.8),
            ("friction", 0.0),
            ("rolling_friction", 0.05),
        ]),
        hertz_rolling_params(&[
            ("youngs_modulus", 2e8),
            ("poisson_ratio", 0.3),
            ("restitution", 0.3),
            ("friction", 5.0),
            ("tangential_damping_ratio", 0.5),
            ("rolling_friction", 0.2),
        ]),
        hertz_rolling_params(&[
            ("youngs_modulus", 1e8),
            ("poisson_ratio", 0.3),
            ("restitution", 0.5),
            ("friction", 0.1),
            ("tangential_damping_ratio", 1.0),
            ("rolling_friction", 0.1),
        ]),
    ];
    const { assert!(<HertzRolling as ContactLaw>::LANES) };
    lanes_match_scalar::<HertzRolling>(params, 3000);
}

#[test]
fn the_hertz_chute_flow_is_the_same_with_lanes() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let text = std::fs::read_to_string(root.join("chute-hertz.ron"))
        .unwrap()
        .replace("\"data.chute\"", &format!("{:?}", root.join("data.chute")));
    let run = |lanes: bool| {
        let (mut sim, _) = common::build(&text);
        sim.world.insert_resource(LaneForms(lanes));
        sim.prime().unwrap();
        sim.run_steps(60).unwrap();
        let mut q = sim
            .world
            .query::<(&Contact, &ContactGeometry, &ContactForce)>();
        let contacts: BTreeMap<(u64, u64), Vec<u64>> = q
            .iter(&sim.world)
            .map(|(c, g, f)| {
                let values = [g.normal, f.force, f.torque_a, f.torque_b]
                    .iter()
                    .flat_map(|x| x.to_array())
                    .chain([g.overlap])
                    .map(f64::to_bits)
                    .collect();
                ((c.a.to_bits(), c.b.to_bits()), values)
            })
            .collect();
        (
            grain_bits(&mut sim.world),
            contacts,
            energy_bits(&sim.world),
        )
    };
    assert!(
        run(true) == run(false),
        "the lane form changed the Hertz chute"
    );
}
