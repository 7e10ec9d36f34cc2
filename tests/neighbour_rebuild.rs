//! The neighbour list is only a superset of the touching pairs: rebuilding it every step
//! instead of when a grain has moved half the skin changes nothing, bit for bit, and every
//! persistent contact keeps its tangential spring across rebuilds.

mod common;

use talus::collision::NeighbourList;
use talus::contact::{Contact, LawState};
use talus_linear_spring::TangentialSpring;

/// Final grain states and the tangential springs of all contacts, keyed by grain pair.
fn run(rebuild_every_step: bool) -> (Vec<[u64; 9]>, Vec<((u64, u64), [u64; 3])>, u64) {
    let (mut sim, steps) = common::build(&common::settling_box_scene("rebuild", 3000));
    for _ in 0..steps {
        if rebuild_every_step {
            sim.world.resource_mut::<NeighbourList>().invalidate();
        }
        sim.step().unwrap();
    }
    let grains = common::grains(&mut sim)
        .iter()
        .map(|g| {
            let mut out = [0u64; 9];
            for (k, x) in g
                .position
                .to_array()
                .iter()
                .chain(g.velocity.to_array().iter())
                .chain(g.omega.to_array().iter())
                .enumerate()
            {
                out[k] = x.to_bits();
            }
            out
        })
        .collect();
    let mut q = sim.world.query::<(&Contact, &LawState<TangentialSpring>)>();
    let mut springs: Vec<((u64, u64), [u64; 3])> = q
        .iter(&sim.world)
        .map(|(c, h)| {
            (
                (c.a.to_bits(), c.b.to_bits()),
                h.0.spring.to_array().map(f64::to_bits),
            )
        })
        .collect();
    springs.sort();
    let builds = sim.world.resource::<NeighbourList>().builds;
    (grains, springs, builds)
}

#[test]
fn rebuilding_the_neighbour_list_every_step_changes_nothing() {
    let (grains_lazy, springs_lazy, builds_lazy) = run(false);
    let (grains_eager, springs_eager, builds_eager) = run(true);
    eprintln!("neighbour list builds: {builds_lazy} (as needed), {builds_eager} (every step)");
    assert!(builds_lazy < builds_eager / 4, "the skin saves most builds");
    assert!(
        springs_lazy.iter().any(|(_, s)| *s != [0; 3]),
        "some contact holds a spring"
    );
    assert_eq!(grains_lazy, grains_eager, "grain states differ");
    assert_eq!(springs_lazy, springs_eager, "tangential springs differ");
}
