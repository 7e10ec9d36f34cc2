//! The neighbour list is only a superset of the touching pairs: rebuilding it every step
//! instead of when a grain has moved half the skin changes nothing, bit for bit, and every
//! persistent contact keeps its tangential spring across rebuilds. Between rebuilds the
//! narrow phase skips the candidates whose gap at the build exceeds twice the largest move
//! since; right after a rebuild it skips none of those within reach, so the same
//! comparison checks that the skip is exact, in a walled box and in a periodic one. So it
//! does for the narrow phase's live bits (a candidate pair with a contact is not tested):
//! derived afresh at every build in the eager run, set and cleared contact by contact
//! between builds in the lazy one.

use crate::common;

use talus::collision::NeighbourList;
use talus::contact::{Contact, LawState};
use talus_linear_spring::TangentialSpring;

/// Final grain states and the tangential springs of all contacts, keyed by grain pair.
type Outcome = (Vec<[u64; 9]>, Vec<((u64, u64), [u64; 3])>, u64);

/// The settling box, run with the list rebuilt when needed or at every step.
fn run(rebuild_every_step: bool) -> Outcome {
    let (sim, steps) = common::build(&common::settling_box_scene("rebuild", 3000));
    run_sim(sim, steps, rebuild_every_step)
}

/// Runs `steps` steps, rebuilding the neighbour list when needed or at every step.
fn run_sim(
    mut sim: talus::core::schedule::Simulation,
    steps: u64,
    rebuild_every_step: bool,
) -> Outcome {
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

/// The two runs agree bit for bit, and the lazy one did save builds and held springs.
fn assert_same(scene: &str, lazy: Outcome, eager: Outcome) {
    let (grains_lazy, springs_lazy, builds_lazy) = lazy;
    let (grains_eager, springs_eager, builds_eager) = eager;
    eprintln!(
        "{scene}: neighbour list builds: {builds_lazy} (as needed), {builds_eager} (every step)"
    );
    assert!(builds_lazy < builds_eager / 4, "the skin saves most builds");
    assert!(
        springs_lazy.iter().any(|(_, s)| *s != [0; 3]),
        "some contact holds a spring"
    );
    assert_eq!(grains_lazy, grains_eager, "grain states differ");
    assert_eq!(springs_lazy, springs_eager, "tangential springs differ");
}

#[test]
fn rebuilding_the_neighbour_list_every_step_changes_nothing() {
    assert_same("settling box", run(false), run(true));
}

/// The LAMMPS chute (periodic in x and y, a flowing layer on a frozen base), 60 steps:
/// candidate pairs cross the periodic seams and the flow moves grains far enough between
/// rebuilds for the gap skip to matter.
#[test]
fn rebuilding_the_neighbour_list_every_step_changes_nothing_in_a_periodic_flow() {
    let chute = |rebuild_every_step: bool| {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench/chute.ron");
        let scene = talus::scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let built = scene
            .build(&talus::registry())
            .unwrap_or_else(|e| panic!("{e}"));
        let mut sim = built.builder.build();
        sim.prime().unwrap();
        run_sim(sim, 60, rebuild_every_step)
    };
    assert_same("chute", chute(false), chute(true));
}

/// A gas sheared by Lees–Edwards boundaries (flow x, gradient z, the images across the z
/// seam sliding at 1 m/s): the moving image offset counts against the skin, and the gap
/// skip must allow for it.
#[test]
fn rebuilding_the_neighbour_list_every_step_changes_nothing_in_a_sheared_gas() {
    let shear = ",\n        shear: (rate: 5e1, flow: \"x\", gradient: \"z\")";
    let scene = common::glass_gas("sheared-rebuild", 1500, 0.02, shear, "");
    let gas = |rebuild_every_step: bool| {
        let (sim, steps) = common::build(&scene);
        run_sim(sim, steps, rebuild_every_step)
    };
    assert_same("sheared gas", gas(false), gas(true));
}
