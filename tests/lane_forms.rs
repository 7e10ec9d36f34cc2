//! The lane form of the linear law (four persistent contacts at once,
//! `plugins/linear-spring/src/lanes.rs`) gives its scalar form's results bit for bit: the
//! same scenes run with the lane forms on and off (`talus::contact::LaneForms`) end with
//! the same grains, the same contacts (geometry, force, torques, tangential spring and the
//! rest of the history) and the same energies, on a flow (the LAMMPS chute), on a pile
//! settling in a walled box (grain–wall contacts go through the scalar form, and a pile
//! near rest keeps some normals unturned), without friction, and without the energy ledger.

mod common;

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
                g.point,
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

/// Runs `steps` steps of a scene with the lane forms on or off; returns the grains, the
/// contacts and the energies at the end, and the number of active contacts.
fn run(text: &str, steps: u64, lanes: bool) -> (impl PartialEq + std::fmt::Debug, usize) {
    let (mut sim, _) = common::build(text);
    sim.world.insert_resource(LaneForms(lanes));
    sim.prime().unwrap();
    sim.run_steps(steps).unwrap();
    let contacts = sim.world.resource::<EnergySnapshot>().contacts;
    let state = (
        grain_bits(&mut sim.world),
        contact_bits(&mut sim.world),
        energy_bits(&sim.world),
    );
    (state, contacts)
}

/// Asserts that a scene ends the same with and without the lane forms.
fn same_with_and_without_lanes(what: &str, text: &str, steps: u64) {
    let (with, contacts) = run(text, steps, true);
    let (without, _) = run(text, steps, false);
    assert!(contacts > 0, "{what}: the grains must touch");
    assert!(with == without, "{what}: the lane form changed the results");
}

fn chute_text() -> String {
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
    let text = common::settling_box_scene("lanes-frictionless", 6000).replace("friction: 0.5", "friction: 0.0");
    assert!(text.contains("friction: 0.0"));
    same_with_and_without_lanes("frictionless box", &text, 6000);
}
