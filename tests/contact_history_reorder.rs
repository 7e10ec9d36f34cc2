//! Contact history survives a reordering of the grains: when the grains' order in memory
//! changes (by moving half of them through another table and back, which is what any
//! change of a grain's component set does, or by the re-sort in rows of cells a scene may
//! ask for, `Simulation::sort_grains`), the narrow phase re-keys its contact
//! index by entity, every persistent contact keeps its entity and its tangential spring,
//! and the step that follows is the same, bit for bit, as without the reordering. (The step
//! taken is not one at which the narrow phase sorts the contact tables, which moves
//! contacts among entities; `tests/contact_table_sort.rs` tests that.)

use crate::common;

use std::collections::BTreeMap;

use bevy_ecs::prelude::*;
use talus::contact::{Contact, LawState};
use talus::core::components::{AngularVelocity, Grain, Position, Velocity};
use talus::core::snapshot::GrainSnapshot;
use talus_linear_spring::TangentialSpring;

/// A marker that moves a grain to another table and back.
#[derive(Component)]
struct Moved;

/// Each contact by its pair: its entity and its tangential spring, bit for bit.
type Springs = BTreeMap<(u64, u64), (u64, [u64; 3])>;

/// What [`run`] returns: the contacts before and after the last step, the grain states
/// after it (bits, by id), and the snapshot's grain order before and after it.
type RunResult = (
    Springs,
    Springs,
    BTreeMap<u64, [u64; 9]>,
    Vec<Entity>,
    Vec<Entity>,
);

fn springs(world: &mut World) -> Springs {
    let mut q = world.query::<(Entity, &Contact, &LawState<TangentialSpring>)>();
    q.iter(world)
        .map(|(e, c, h)| {
            (
                (c.a.to_bits(), c.b.to_bits()),
                (e.to_bits(), h.0.spring.to_array().map(f64::to_bits)),
            )
        })
        .collect()
}

/// Grain positions, velocities and spins by entity, bit for bit.
fn grain_bits(world: &mut World) -> BTreeMap<u64, [u64; 9]> {
    let mut q =
        world.query_filtered::<(Entity, &Position, &Velocity, &AngularVelocity), With<Grain>>();
    q.iter(world)
        .map(|(e, p, v, w)| {
            let mut bits = [0u64; 9];
            for (k, x) in
                p.0.to_array()
                    .into_iter()
                    .chain(v.0.to_array())
                    .chain(w.0.to_array())
                    .enumerate()
            {
                bits[k] = x.to_bits();
            }
            (e.to_bits(), bits)
        })
        .collect()
}

/// How the grains are reordered before the last step.
#[derive(Clone, Copy, PartialEq)]
enum Reorder {
    /// Not at all.
    No,
    /// Every second grain through another table and back (to the table's end).
    HalfMoved,
    /// By `Simulation::sort_grains` (the scene's grains are in the order drawn).
    Sorted,
}

/// Runs the scene's steps (with the Gear integrator if `gear`), reorders the grains as
/// asked, then takes one more step. Returns the contacts before and after that step, the
/// grain states after it, and the snapshot's grain order before and after it.
fn run(reorder: Reorder, gear: bool) -> RunResult {
    let mut scene = common::settling_box_scene("reorder", 30000);
    if gear {
        scene = scene.replace("    steps:", "    integrator: Gear,\n    steps:");
    }
    let (mut sim, steps) = common::build(&scene);
    assert_ne!(
        (steps + 1) % talus::collision::narrow::CONTACT_SORT_INTERVAL,
        0,
        "the step taken must not sort the contact tables"
    );
    for _ in 0..steps {
        sim.step().unwrap();
    }
    let before = springs(&mut sim.world);
    let order_before = sim.world.resource::<GrainSnapshot>().entity.clone();
    if reorder == Reorder::HalfMoved {
        let mut q = sim.world.query_filtered::<Entity, With<Grain>>();
        let grains: Vec<Entity> = q.iter(&sim.world).collect();
        for &e in grains.iter().step_by(2) {
            sim.world.entity_mut(e).insert(Moved);
        }
        for &e in grains.iter().step_by(2) {
            sim.world.entity_mut(e).remove::<Moved>();
        }
    }
    if reorder == Reorder::Sorted {
        let moved = sim.sort_grains();
        assert!(moved > 0, "the sort moved grains");
        // The definition of the order: keys of rows of cells one largest diameter wide
        // (x fastest, then y, then z) over all grains, non-decreasing in the table.
        let mut q = sim
            .world
            .query_filtered::<(&Position, &talus::core::components::Radius), With<Grain>>();
        let grains: Vec<(glam::DVec3, f64)> = q.iter(&sim.world).map(|(p, r)| (p.0, r.0)).collect();
        let cell = grains.iter().map(|g| 2.0 * g.1).fold(0.0, f64::max);
        let low = grains
            .iter()
            .fold(glam::DVec3::INFINITY, |low, g| low.min(g.0));
        let high = grains
            .iter()
            .fold(glam::DVec3::NEG_INFINITY, |high, g| high.max(g.0));
        let cells = ((high - low) / cell).floor() + 1.0;
        let keys: Vec<f64> = grains
            .iter()
            .map(|(p, _)| {
                let c = ((*p - low) / cell).floor();
                (c.z * cells.y + c.y) * cells.x + c.x
            })
            .collect();
        assert!(
            keys.windows(2).all(|k| k[0] <= k[1]),
            "the grains are in rows of cells: {keys:?}"
        );
        assert_eq!(sim.sort_grains(), 0, "a sorted packing is left as it is");
    }
    sim.step().unwrap();
    let after = springs(&mut sim.world);
    let order_after = sim.world.resource::<GrainSnapshot>().entity.clone();
    let grains = grain_bits(&mut sim.world);
    (before, after, grains, order_before, order_after)
}

#[test]
fn reordering_the_grains_keeps_every_contact_and_its_spring() {
    check_reordering(Reorder::HalfMoved, false);
}

#[test]
fn sorting_the_grains_keeps_every_contact_and_its_spring() {
    check_reordering(Reorder::Sorted, false);
}

/// The Gear integrator keeps derivatives per grain in grain order: the sort carries them
/// with their grains, so the step after it is the same, bit for bit.
#[test]
fn sorting_the_grains_keeps_the_gear_integrators_derivatives() {
    check_reordering(Reorder::Sorted, true);
}

fn check_reordering(reorder: Reorder, gear: bool) {
    let (before, after_plain, grains_plain, order, order_plain) = run(Reorder::No, gear);
    let (before_again, after_reordered, grains_reordered, _, order_reordered) = run(reorder, gear);
    assert_eq!(before, before_again, "the runs agree up to the reordering");
    assert_eq!(
        order, order_plain,
        "without reordering the grain order stays"
    );
    assert_ne!(
        order, order_reordered,
        "the reordering changed the grains' order in the snapshot"
    );
    let loaded = before.values().filter(|(_, s)| *s != [0; 3]).count();
    eprintln!("{} contacts, {loaded} holding a spring", before.len());
    assert!(loaded > 20, "enough contacts hold a spring ({loaded})");
    // Every contact that was there before the step and is still there after it is the
    // same entity with the same spring, reordered or not.
    let mut persistent = 0;
    for (pair, (entity, _)) in &before {
        if let Some(plain) = after_plain.get(pair) {
            persistent += 1;
            assert_eq!(plain.0, *entity, "the contact {pair:?} persisted");
            assert_eq!(
                after_reordered.get(pair),
                Some(plain),
                "the contact {pair:?} keeps its entity and spring through the reordering"
            );
        }
    }
    assert!(persistent > 20, "enough persistent contacts ({persistent})");
    assert_eq!(
        after_plain.len(),
        after_reordered.len(),
        "the same contacts after the step"
    );
    assert_eq!(
        grains_plain, grains_reordered,
        "grain states after the step"
    );
}
