//! The leapfrogs' first pass copies the grains into the step's snapshot while it kicks,
//! drifts and wraps them (`talus::core::integrate::kick_drift_snapshot`), instead of the
//! broad phase copying them in a pass of its own. Same scenes with the copy in the first
//! pass and in the broad phase (`SnapshotInFirstPass`): the same grains, contacts,
//! energies and snapshot to the bit, on the LAMMPS chute (periodic, with a frozen base
//! and rotation, on one and two threads), on a pile settling in a walled box, and with
//! symplectic Euler.

mod common;

use std::path::Path;

use talus::core::integrate::SnapshotInFirstPass;
use talus::core::prelude::*;

/// The snapshot's grain arrays and move bounds, as bits.
fn snapshot_bits(s: &GrainSnapshot) -> Vec<u64> {
    let records = s.records.iter().flat_map(|g| {
        let [x, y, z] = g.position.to_array();
        let [u, v, w] = g.velocity.to_array();
        [x, y, z, g.radius, u, v, w, g.inverse_mass]
    });
    let blocks = s
        .block_moves()
        .unwrap_or(&[])
        .iter()
        .flat_map(|b| [b.centre.x, b.centre.y, b.centre.z, b.spread, b.largest]);
    records
        .chain(s.omega.iter().flat_map(|w| w.to_array()))
        .chain(blocks)
        .chain([s.max_radius, s.move_bound_sq()])
        .map(f64::to_bits)
        .chain(s.material.iter().map(|&m| u64::from(m)))
        .collect()
}

/// Runs a scene for `steps` steps on `threads` threads with the copy in the first pass
/// or not; returns the state and snapshot at the end and the number of active contacts.
fn run(
    text: &str,
    steps: u64,
    threads: usize,
    in_first_pass: bool,
) -> (impl PartialEq + std::fmt::Debug, usize) {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let (mut sim, _) = common::build(text);
        sim.world
            .insert_resource(SnapshotInFirstPass(in_first_pass));
        sim.prime().unwrap();
        sim.run_steps(steps).unwrap();
        let contacts = sim.world.resource::<EnergySnapshot>().contacts;
        let snapshot = snapshot_bits(sim.world.resource::<GrainSnapshot>());
        ((common::state_bits(&mut sim.world), snapshot), contacts)
    })
}

/// Asserts that a scene ends the same with the copy in the first pass and in the broad
/// phase.
fn same_either_way(what: &str, text: &str, steps: u64, threads: usize) {
    let (first_pass, contacts) = run(text, steps, threads, true);
    let (broad_phase, _) = run(text, steps, threads, false);
    assert!(contacts > 0, "{what}: the grains must touch");
    assert!(
        first_pass == broad_phase,
        "{what}: copying the grains in the first pass changed the results"
    );
}

fn chute_text() -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    std::fs::read_to_string(root.join("chute.ron"))
        .unwrap()
        .replace("\"data.chute\"", &format!("{:?}", root.join("data.chute")))
        .replace("energy_ledger: false", "energy_ledger: true")
}

#[test]
fn the_chute_is_the_same_with_the_copy_in_the_first_pass() {
    let text = chute_text();
    assert!(text.contains("energy_ledger: true"));
    // 70 steps: past the neighbour list's second build, so that the moves since a
    // reference are measured (and compared) too.
    same_either_way("chute, 1 thread", &text, 70, 1);
    same_either_way("chute, 2 threads", &text, 70, 2);
}

#[test]
fn a_settling_pile_in_a_box_is_the_same_with_the_copy_in_the_first_pass() {
    same_either_way(
        "settling box",
        &common::settling_box_scene("first-pass-box", 3000),
        3000,
        2,
    );
}

#[test]
fn symplectic_euler_is_the_same_with_the_copy_in_the_first_pass() {
    let text = common::settling_box_scene("first-pass-euler", 3000);
    let text = text.replacen("Scene(", "Scene(\n    integrator: SymplecticEuler,", 1);
    assert!(text.contains("SymplecticEuler"));
    same_either_way("settling box, symplectic Euler", &text, 3000, 1);
}
