//! A long run keeps no bookkeeping that grows with the number of steps: what a run holds
//! between steps is bounded by its grains and live contacts, not by its history.

use crate::common;

use std::collections::HashSet;

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus::contact::Contact;
use talus::core::components::{Position, Velocity};
use talus::core::schedule::Simulation;

/// Every contact that ends leaves a removal message per component in the world (and
/// every `resource_scope` one per resource it takes out); a run that never clears them
/// holds them all (a leak of 10 MB per 100 steps at 128,000 flowing grains). After a
/// settling pile has ended far more contacts than it holds at once, the world holds only
/// the messages of the last two steps: one `Contact` removal per contact ended there,
/// and a fixed number of others.
#[test]
fn ended_contacts_leave_no_growing_removal_messages() {
    let (mut sim, _) = common::build(&common::settling_box_scene("long", 4000));
    // Ended contacts are despawned, not kept as vacant rows for new ones, so that the pile
    // ends many and a leak of their removal messages would show.
    sim.world
        .resource_mut::<talus::collision::narrow::ContactIndex>()
        .despawn_unused = true;
    sim.prime().unwrap();
    let live = |sim: &mut Simulation| -> HashSet<Entity> {
        sim.world
            .query_filtered::<Entity, With<Contact>>()
            .iter(&sim.world)
            .collect()
    };
    let contact_id = sim.world.register_component::<Contact>();
    let mut previous = live(&mut sim);
    let mut ended = 0;
    let mut ended_last_two = [0usize; 2];
    let mut others_at_start = None;
    for _ in 0..4000 {
        sim.step().unwrap();
        let now = live(&mut sim);
        let gone = previous.difference(&now).count();
        ended += gone;
        ended_last_two = [ended_last_two[1], gone];
        previous = now;
        let removed = sim.world.removed_components();
        let contacts_held = removed.get(contact_id).map_or(0, |m| m.len());
        let held: usize = removed.iter().map(|(_, m)| m.len()).sum();
        let recent = ended_last_two[0] + ended_last_two[1];
        assert!(
            contacts_held <= recent,
            "{contacts_held} contact removals held after {} steps; {recent} contacts ended in the last two",
            sim.step_count()
        );
        // Components of a contact entity: the pair, geometry, force, body indices and
        // the law's history; the rest come from the steps themselves, as many each step.
        let others = held - 5 * contacts_held.min(recent);
        let start = *others_at_start.get_or_insert(others);
        assert!(
            others <= start.max(1) * 2,
            "{others} other removal messages held after {} steps ({start} after the first)",
            sim.step_count()
        );
    }
    assert!(
        ended > 200,
        "the pile ended too few contacts ({ended}) for the test to tell a leak"
    );
}

/// The rows of ended contacts kept vacant for new ones (`docs/architecture.md` §6) do not
/// outlive the contacts they served: a settled pile blown apart ends most of its contacts at
/// once, and the sorts that follow keep at most twice a region's share of vacant rows (eight
/// times one per 128 contacts, at least 8), so the contact table comes back near its live
/// contacts.
#[test]
fn vacant_contact_rows_of_a_pile_blown_apart_are_let_go() {
    let (mut sim, _) = common::build(&common::settling_box_scene("blown", 30_000));
    sim.prime().unwrap();
    sim.run_steps(20_000).unwrap();
    let count = |sim: &mut Simulation| {
        let mut q = sim.world.query::<&Contact>();
        let vacant = q.iter(&sim.world).filter(|c| c.is_vacant()).count();
        (q.iter(&sim.world).count() - vacant, vacant)
    };
    let (settled, _) = count(&mut sim);
    // Every grain flung away from the pile's centre.
    let mut grains = sim
        .world
        .query_filtered::<(&Position, &mut Velocity), With<talus::core::components::Grain>>();
    let centre = DVec3::new(0.01, 0.01, 0.005);
    for (p, mut v) in grains.iter_mut(&mut sim.world) {
        v.0 = (p.0 - centre).normalize_or_zero() * 2.0;
    }
    let mut most_vacant = 0;
    let mut after_sort = 0;
    for _ in 0..200 {
        sim.step().unwrap();
        let (live, vacant) = count(&mut sim);
        most_vacant = most_vacant.max(vacant);
        if sim
            .step_count()
            .is_multiple_of(talus::collision::narrow::CONTACT_SORT_INTERVAL)
        {
            // The pile's grains are one region of the tables.
            let bound = 2 * 8 * (live / 128).max(8);
            assert!(
                vacant <= bound,
                "{vacant} vacant rows after the sort at step {} for {live} contacts (bound {bound})",
                sim.step_count()
            );
            after_sort = vacant;
        }
    }
    eprintln!(
        "{settled} contacts settled; at most {most_vacant} vacant rows, {after_sort} after the last sort"
    );
    assert!(
        most_vacant > 2 * 8 * 8,
        "the pile ended too few contacts at once ({most_vacant} vacant rows) for the test to tell"
    );
}
