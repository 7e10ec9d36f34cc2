//! Sorting the contact table into the order of its grains (the narrow phase does it every
//! `CONTACT_SORT_INTERVAL` steps, so that the force loop reads the grains nearly in
//! order) moves whole contacts: every pair keeps its geometry, force and tangential spring
//! bit for bit, the narrow phase's index finds each pair at the entity that now holds it,
//! and the run goes on as without the sort, up to the order in which each grain's contact
//! forces are summed. On LAMMPS's chute (32,000 grains, about 16,000 contacts made and
//! broken all along) and on grains falling into a walled box (contacts with walls).
//!
//! The narrow phase also hands the entity of a contact that ended to a new pair of the
//! same law instead of despawning one and spawning another: the new pair starts exactly
//! as a freshly spawned contact would, so a run does the same with and without it, up to
//! the same order of sums.

use crate::common;

use std::collections::BTreeMap;
use std::path::Path;

use bevy_ecs::prelude::*;
use talus::collision::narrow::{CONTACT_SORT_INTERVAL, ContactIndex, sort_contacts};
use talus::contact::{Contact, ContactBodies, ContactForce, ContactGeometry, LawState};
use talus::core::components::{Grain, Position, Velocity};
use talus::core::schedule::Simulation;
use talus::core::snapshot::GrainSnapshot;
use talus_linear_spring::TangentialSpring;

/// A contact's geometry, force and spring, bit for bit (4 + 9 + 3 numbers).
type Record = Vec<u64>;

/// Where the spring's three numbers start in a [`Record`].
const SPRING: usize = 13;

/// Every contact by its pair (entity bits of `a` and `b`), with the entity that holds it.
type Contacts = BTreeMap<(u64, u64), (Entity, Record)>;

/// The contacts of a world ([`Contacts`]), vacant rows left out.
fn contacts(world: &mut World) -> Contacts {
    let mut q = world.query::<(
        Entity,
        &Contact,
        &ContactGeometry,
        &ContactForce,
        &LawState<TangentialSpring>,
    )>();
    q.iter(world)
        .filter(|(_, c, _, _, _)| !c.is_vacant())
        .map(|(e, c, g, f, h)| {
            let numbers = g
                .normal
                .to_array()
                .into_iter()
                .chain([g.overlap])
                .chain(f.force.to_array())
                .chain(f.torque_a.to_array())
                .chain(f.torque_b.to_array())
                .chain(h.0.spring.to_array());
            (
                (c.a.to_bits(), c.b.to_bits()),
                (e, numbers.map(f64::to_bits).collect()),
            )
        })
        .collect()
}

/// The chute after `steps` steps.
fn chute(steps: u64) -> Simulation {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench/chute.ron");
    let scene = talus::scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let built = scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    run(built.builder.build(), steps)
}

/// The walled settling box of the other tests after `steps` steps: grains still falling
/// onto the pile, contacts with the six walls made and broken.
fn settling_box(steps: u64) -> Simulation {
    let (sim, _) = common::build(&common::settling_box_scene("sort", steps));
    run(sim, steps)
}

fn run(mut sim: Simulation, steps: u64) -> Simulation {
    sim.prime().unwrap();
    sim.run_steps(steps).unwrap();
    sim
}

/// Sorts the contact tables as the narrow phase does; returns how many contacts moved.
fn sort(sim: &mut Simulation) -> usize {
    sim.world
        .resource_scope(|world, mut index: Mut<ContactIndex>| {
            world.resource_scope(|world, snapshot: Mut<GrainSnapshot>| {
                sort_contacts(world, &mut index, &snapshot)
            })
        })
}

/// Grain velocities by entity.
fn velocities(world: &mut World) -> BTreeMap<Entity, glam::DVec3> {
    let mut q = world.query_filtered::<(Entity, &Velocity), With<Grain>>();
    q.iter(world).map(|(e, v)| (e, v.0)).collect()
}

/// Grain positions by entity, bit for bit.
fn positions(world: &mut World) -> BTreeMap<Entity, [u64; 3]> {
    let mut q = world.query_filtered::<(Entity, &Position), With<Grain>>();
    q.iter(world)
        .map(|(e, p)| (e, p.0.to_array().map(f64::to_bits)))
        .collect()
}

#[test]
fn sorting_the_contact_table_moves_whole_contacts_and_keeps_their_springs() {
    // The narrow phase last sorted at a multiple of the interval; since then despawns
    // have refilled rows from the table's end and new contacts went to its end.
    check_sort(&chute, 2 * CONTACT_SORT_INTERVAL - 1, 5_000);
}

#[test]
fn sorting_a_table_with_wall_contacts_moves_them_whole() {
    check_sort(&settling_box, 500 * CONTACT_SORT_INTERVAL - 1, 20);
    // Wall contacts are there: the box's floor carries the falling grains.
    let mut sim = settling_box(500 * CONTACT_SORT_INTERVAL - 1);
    let mut q = sim.world.query::<&Contact>();
    let walls = q
        .iter(&sim.world)
        .filter(|c| c.kind == talus::contact::ContactKind::GrainWall)
        .count();
    assert!(walls > 5, "wall contacts: {walls}");
}

#[test]
fn a_new_pair_given_an_ended_contacts_entity_starts_as_a_spawned_one() {
    let steps = 2 * CONTACT_SORT_INTERVAL + 4;
    assert_ne!(
        (steps + 1) % CONTACT_SORT_INTERVAL,
        0,
        "the step compared must not sort the contact tables"
    );
    let mut recycled = chute(steps);
    let mut spawned = chute(steps);
    spawned.world.resource_mut::<ContactIndex>().never_recycle = true;
    let before = contacts(&mut recycled.world);
    assert_eq!(before, contacts(&mut spawned.world), "the two runs agree");
    // Every row's entity, vacant rows' too, in each run.
    let entities = |world: &mut World| -> std::collections::BTreeSet<Entity> {
        world
            .query_filtered::<Entity, With<Contact>>()
            .iter(world)
            .collect()
    };
    let rows_before = [entities(&mut recycled.world), entities(&mut spawned.world)];
    let (recycled_after, spawned_after) = check_twins(&mut recycled, &mut spawned);
    // In the compared step, entities that held an ended pair or a vacant row now hold a
    // new pair.
    let handed_over = |after: &Contacts, rows_before: &std::collections::BTreeSet<Entity>| {
        after
            .iter()
            .filter(|(pair, (e, _))| !before.contains_key(*pair) && rows_before.contains(e))
            .count()
    };
    let new_pairs = recycled_after
        .keys()
        .filter(|p| !before.contains_key(p))
        .count();
    let (handed, handed_plain) = (
        handed_over(&recycled_after, &rows_before[0]),
        handed_over(&spawned_after, &rows_before[1]),
    );
    eprintln!("{new_pairs} new pairs; {handed} of them given an ended contact's entity");
    assert!(
        handed > new_pairs / 2 && handed <= new_pairs,
        "{handed} of {new_pairs} new pairs given an ended contact's entity"
    );
    assert_eq!(handed_plain, 0, "no hand-over when it is turned off");
}

/// Sorts the contact table of the scene `make` gives after `steps` steps (which must leave
/// it out of order) and checks the sort against a twin run without it; at least
/// `min_loaded` contacts must hold a tangential spring.
fn check_sort(make: &dyn Fn(u64) -> Simulation, steps: u64, min_loaded: usize) {
    let mut sorted = make(steps);
    let mut plain = make(steps);
    let before = contacts(&mut sorted.world);
    assert_eq!(before, contacts(&mut plain.world), "the two runs agree");
    let loaded = before
        .values()
        .filter(|(_, r)| r[SPRING..].iter().any(|&x| x != 0))
        .count();
    assert!(loaded >= min_loaded, "contacts holding a spring: {loaded}");

    let moved = sort(&mut sorted);
    eprintln!(
        "{} contacts, {loaded} holding a spring; the sort moved {moved}",
        before.len()
    );
    assert!(
        moved > before.len() / 10,
        "the table was out of order: {moved} of {} contacts moved",
        before.len()
    );
    let after = contacts(&mut sorted.world);
    // The same pairs with the same numbers; many held by another entity now.
    assert_eq!(
        before.keys().collect::<Vec<_>>(),
        after.keys().collect::<Vec<_>>()
    );
    let mut new_holder = 0;
    for (pair, (entity, record)) in &before {
        let (now, record_now) = &after[pair];
        assert_eq!(
            record, record_now,
            "contact {pair:?} is whole after the sort"
        );
        new_holder += usize::from(now != entity);
    }
    assert!(new_holder > 0, "the sort moved contacts among entities");
    // The table is in the order of its bodies' dense indices.
    let mut q = sorted.world.query::<&ContactBodies>();
    let keys: Vec<(u32, u32)> = q.iter(&sorted.world).map(|b| (b.a, b.b)).collect();
    assert!(keys.is_sorted(), "rows in the order of their bodies");
    // The index finds every pair at the entity that holds it now.
    {
        let index = sorted.world.resource::<ContactIndex>();
        let snapshot = sorted.world.resource::<GrainSnapshot>();
        let mut q = sorted.world.try_query::<(Entity, &Contact)>().unwrap();
        for (entity, c) in q.iter(&sorted.world).filter(|(_, c)| !c.is_vacant()) {
            assert_eq!(
                index.contact_between(snapshot, c.a, c.b),
                Some(entity),
                "the index holds pair {:?} at its new entity",
                (c.a, c.b)
            );
        }
    }
    assert_eq!(sort(&mut sorted), 0, "a sorted table stays as it is");

    check_twins(&mut sorted, &mut plain);
}

/// Steps two runs that hold the same contacts, each pair perhaps at another entity and
/// row (`moved`, `plain`), and checks that they go on alike: the next step bit for bit up
/// to the order in which each grain's contact forces are summed, and the springs equal up
/// to that rounding a sort interval later.
/// Returns both runs' contacts after the first of those steps.
fn check_twins(moved: &mut Simulation, plain: &mut Simulation) -> (Contacts, Contacts) {
    // One step: each contact is evaluated from the same inputs, so every spring, force and
    // geometry comes out bit for bit; positions moved with the forces of the step before.
    moved.step().unwrap();
    plain.step().unwrap();
    let (after_moved, after_plain) = (contacts(&mut moved.world), contacts(&mut plain.world));
    assert_eq!(
        after_moved.keys().collect::<Vec<_>>(),
        after_plain.keys().collect::<Vec<_>>(),
        "the same contacts after the step"
    );
    for (pair, (_, record)) in &after_plain {
        assert_eq!(
            &after_moved[pair].1, record,
            "contact {pair:?} after the step"
        );
    }
    assert_eq!(
        positions(&mut moved.world),
        positions(&mut plain.world),
        "positions after the step"
    );
    // Velocities took the step's forces, each grain's summed over its contacts in another
    // order: equal up to the rounding of those sums.
    let (v_moved, v_plain) = (velocities(&mut moved.world), velocities(&mut plain.world));
    let scale = v_plain.values().map(|v| v.length()).fold(0.0, f64::max);
    let worst = v_plain
        .iter()
        .map(|(e, v)| (v_moved[e] - *v).length())
        .fold(0.0, f64::max);
    eprintln!("largest velocity difference after the step: {worst:e} (largest speed {scale})");
    assert!(
        worst <= 1e-12 * scale,
        "velocities differ by {worst:e} (largest speed {scale})"
    );

    // A sort interval more (the narrow phase sorts both runs once more on the way):
    // contacts made and broken through the index, the same pairs in both runs, and their
    // springs equal up to the rounding the sums brought in.
    moved.run_steps(CONTACT_SORT_INTERVAL).unwrap();
    plain.run_steps(CONTACT_SORT_INTERVAL).unwrap();
    let (later_moved, later_plain) = (contacts(&mut moved.world), contacts(&mut plain.world));
    assert_eq!(
        later_moved.keys().collect::<Vec<_>>(),
        later_plain.keys().collect::<Vec<_>>(),
        "the same contacts an interval later"
    );
    let spring = |r: &Record| {
        glam::DVec3::from_array([r[SPRING], r[SPRING + 1], r[SPRING + 2]].map(f64::from_bits))
    };
    let largest = later_plain
        .values()
        .map(|(_, r)| spring(r).length())
        .fold(0.0, f64::max);
    for (pair, (_, record)) in &later_plain {
        let gap = (spring(&later_moved[pair].1) - spring(record)).length();
        assert!(
            gap <= 1e-9 * largest,
            "spring of {pair:?} differs by {gap:e} (largest spring {largest:e})"
        );
    }
    (after_moved, after_plain)
}
