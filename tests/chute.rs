//! LAMMPS's chute benchmark (`scenes/bench/chute.ron`, LAMMPS's own data file): the same
//! physics as LAMMPS gives the same kinetic energies. LAMMPS's output for this input:
//! Σ½mv² = 784139.13 and Σ½Iω² = 1601.1263 at step 0; 784292.08 and 1571.0968 at step 100.

use std::path::Path;

use talus::cli::ReportSample;

/// Builds the chute scene as shipped, or with its energy ledger on (`ledger`), and runs it
/// for its 100 steps; returns the samples at step 0 and step 100.
fn run_chute(ledger: bool) -> (ReportSample, ReportSample) {
    let (start, end, _) = run_chute_with(ledger, None);
    (start, end)
}

/// [`run_chute`], the grains re-sorted in memory every `sort_every` steps if given; also
/// returns the grains' entities in the snapshot's order at the end.
fn run_chute_with(
    ledger: bool,
    sort_every: Option<u64>,
) -> (ReportSample, ReportSample, Vec<bevy_ecs::entity::Entity>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench/chute.ron");
    let mut text = std::fs::read_to_string(&path).unwrap();
    if ledger {
        assert!(text.contains("energy_ledger: false"));
        text = text.replace("energy_ledger: false", "energy_ledger: true");
    }
    if let Some(every) = sort_every {
        assert!(text.contains("    steps: 100,"));
        text = text.replace(
            "    steps: 100,",
            &format!("    steps: 100,\n    sort_grains_every: {every},"),
        );
    }
    let scene = talus::scene::parse(&path, &text).unwrap_or_else(|e| panic!("{e}"));
    let built = scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(built.grain_count, 32_000);
    let steps = built.stop.steps;
    assert_eq!(steps, 100);
    let mut sim = built.builder.build();
    if !ledger {
        // The energies below then come through steps whose motion the snapshot holds.
        assert!(sim.may_hold_motion(), "the chute's plan reads no motion");
    }
    sim.prime().unwrap();
    let start = ReportSample::take(&sim.world);
    sim.run_steps(steps).unwrap();
    assert_lists_on_heap_are_the_long_ones(&sim.world);
    let order = sim
        .world
        .resource::<talus::core::snapshot::GrainSnapshot>()
        .entity
        .clone();
    (start, ReportSample::take(&sim.world), order)
}

/// After a step that sorted the contact tables (the 100th, `CONTACT_SORT_INTERVAL` = 20),
/// the only grains' contact lists on the heap are those longer than fits inline: the
/// lists that shrank back came inline again, so the heap's lists do not pile up over a
/// run (without that, the 512,000-grain chute had 36,000 lists on the heap after 100 steps
/// where 11,000 needed it).
fn assert_lists_on_heap_are_the_long_ones(world: &bevy_ecs::world::World) {
    let step = world.resource::<talus::core::resources::Clock>().step;
    assert!(step.is_multiple_of(talus::collision::narrow::CONTACT_SORT_INTERVAL));
    let (on_heap, longer) = world
        .resource::<talus::collision::ContactIndex>()
        .lists_on_heap();
    assert!(longer > 0, "no grain keys more contacts than fit inline");
    assert_eq!(
        on_heap, longer,
        "{on_heap} contact lists on the heap, of which {longer} need it"
    );
}

/// LAMMPS's change of the translational kinetic energy over the 100 steps within 2 %, and
/// its rotational kinetic energy at step 100 within 1e-3 relative.
fn assert_matches_lammps(start: &ReportSample, end: &ReportSample) {
    let gain = end.translational_kinetic - start.translational_kinetic;
    let lammps_gain = 784292.08 - 784139.13;
    assert!(
        (gain - lammps_gain).abs() < 0.02 * lammps_gain,
        "gain {gain}"
    );
    assert!(
        (end.rotational_kinetic - 1571.0968).abs() < 1e-3 * 1571.0968,
        "rotational {}",
        end.rotational_kinetic
    );
}

/// Re-sorting the grains in memory every 10 steps (`sort_grains_every`, LAMMPS's `atom_modify
/// sort`) changes their order and no physics: LAMMPS's energies still hold, and the run
/// agrees with the unsorted one to rounding (the sorts change only the order of the force
/// sums over the contacts the narrow phase makes after them).
#[test]
fn resorting_the_chute_grains_keeps_lammps_energies() {
    let (start, plain, plain_order) = run_chute_with(false, None);
    let (start_sorted, sorted, sorted_order) = run_chute_with(false, Some(10));
    assert_ne!(plain_order, sorted_order, "the sorts reordered the grains");
    assert_eq!(
        start.translational_kinetic.to_bits(),
        start_sorted.translational_kinetic.to_bits()
    );
    assert_matches_lammps(&start_sorted, &sorted);
    for (what, x, y) in [
        (
            "translational",
            plain.translational_kinetic,
            sorted.translational_kinetic,
        ),
        (
            "rotational",
            plain.rotational_kinetic,
            sorted.rotational_kinetic,
        ),
        ("gravity work", plain.gravity_work, sorted.gravity_work),
    ] {
        eprintln!("re-sorted chute: {what} {y} against {x} unsorted");
        assert!((x - y).abs() <= 1e-12 * x.abs(), "{what}: {x} against {y}");
    }
    assert_eq!(plain.contacts, sorted.contacts);
}

#[test]
fn chute_reproduces_lammps_kinetic_energies_over_100_steps() {
    // The scene as shipped: the contact energies are not booked (LAMMPS's run books none
    // either), which changes no force.
    let (start, end) = run_chute(false);
    assert!(end.elastic.is_nan() && end.bookkeeping_balance.is_nan());
    // Step 0 is the data file itself: both sums must match LAMMPS to its 8 printed digits.
    assert!(
        (start.translational_kinetic - 784139.13).abs() < 0.01,
        "{}",
        start.translational_kinetic
    );
    assert!(
        (start.rotational_kinetic - 1601.1263).abs() < 1e-4,
        "{}",
        start.rotational_kinetic
    );
    let gain = end.translational_kinetic - start.translational_kinetic;
    let lammps_gain = 784292.08 - 784139.13;
    eprintln!(
        "chute, 100 steps: translational gain {gain:.4} (LAMMPS {lammps_gain:.2}, {:+.3e} relative), rotational {:.6} (LAMMPS 1571.0968, {:+.3e} relative)",
        (gain - lammps_gain) / lammps_gain,
        end.rotational_kinetic,
        (end.rotational_kinetic - 1571.0968) / 1571.0968
    );
    assert_matches_lammps(&start, &end);
    // With the ledger on, the flow is the same bit for bit, and the ledger closes: no
    // contact among the frozen base (their reduced mass would be infinite), every term
    // finite, the bookkeeping balance constant to rounding against the work of gravity.
    let (start, booked) = run_chute(true);
    for (x, y) in [
        (end.translational_kinetic, booked.translational_kinetic),
        (end.rotational_kinetic, booked.rotational_kinetic),
        (end.gravity_work, booked.gravity_work),
        (end.max_overlap_ratio, booked.max_overlap_ratio),
    ] {
        assert_eq!(x.to_bits(), y.to_bits());
    }
    assert_eq!(end.contacts, booked.contacts);
    let end = booked;
    let bookkeeping = (end.bookkeeping_balance - start.bookkeeping_balance).abs();
    eprintln!(
        "chute, 100 steps: gravity work {:.4}, dissipated {:.4}, bookkeeping drift {:.3e} of the gravity work",
        end.gravity_work,
        end.dissipated_total,
        bookkeeping / end.gravity_work
    );
    assert!(end.energy_balance.is_finite() && end.dissipated_total > 0.0);
    assert!(bookkeeping < 1e-9 * end.gravity_work, "{bookkeeping:e}");
}

/// The 2×2 replica (128,000 grains) is the same flow tiled: it builds without an overlap
/// at the tile seams (the file's state is periodic), and its kinetic energy per grain at
/// step 0 is the original's.
#[test]
fn the_replicated_chute_tiles_the_same_state() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench");
    let text = std::fs::read_to_string(root.join("chute.ron"))
        .unwrap()
        .replace(
            "periodic: (x: (0.0, 40.0), y: (0.0, 20.0)),",
            "periodic: (x: (0.0, 80.0), y: (0.0, 40.0)),",
        )
        .replace(
            "grains: [LammpsData(file: \"data.chute\",",
            "grains: [LammpsData(file: \"data.chute\", replicate: (2, 2, 1),",
        )
        .replace("steps: 100,", "steps: 5,");
    let scene =
        talus::scene::parse(root.join("chute-2x2.ron"), &text).unwrap_or_else(|e| panic!("{e}"));
    let built = scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(built.grain_count, 128_000);
    let mut sim = built.builder.build();
    sim.prime().unwrap();
    let start = ReportSample::take(&sim.world);
    assert!((start.translational_kinetic / 4.0 - 784139.13).abs() < 0.01 * 4.0);
    sim.run_steps(5).unwrap();
}
