//! Save, load, continue: a run resumed from a saved state is bit-identical to the run
//! that was never interrupted (every grain, wall and contact with its law's history, the
//! contact tables' vacant rows, the energy totals), through the library and through `talus run --resume`; a scene can
//! start from a saved packing with its contacts and their histories.

use crate::common;

use talus::cli::{RunOptions, run_scene};
use talus::core::schedule::Simulation;
use talus::scene::state::SavedState;

/// A frictional pour into a box whose lid moves down: tangential springs, wall
/// contacts, a moving wall's work, contacts made and broken all along.
fn pour(steps: u64) -> String {
    format!(
        r#"Scene(
    name: "resume-pour",
    gravity: (0.0, 0.0, -9.81),
    steps: {steps},
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 2000.0, restitution: 0.5, friction: 0.5))],
    walls: [
        Box(min: (0.0, 0.0, 0.0), max: (0.03, 0.03, 0.06), material: "glass", omit: ["z_max"]),
        Plane(name: "lid", point: (0.0, 0.0, 0.045), normal: (0.0, 0.0, -1.0), material: "glass",
            velocity: (0.0, 0.0, -0.5)),
    ],
    grains: [
        Lattice(material: "glass", radius: 0.0014, region: (min: (0.0, 0.0, 0.0), max: (0.03, 0.03, 0.015))),
        Random(material: "glass", region: (min: (0.0, 0.0, 0.016), max: (0.03, 0.03, 0.04)),
            count: 150, radius: Uniform(min: 0.001, max: 0.002), seed: 7, velocity_spread: 0.3),
    ],
    output: (recording: false, report_interval: 0.0005),
)"#
    )
}

/// Periodic in x and y over a floor, Hertz–Mindlin with constant-torque rolling
/// resistance (a second history per contact), integrated by Gear's predictor–corrector
/// (whose derivatives are part of the state).
fn periodic_rolling_gear(steps: u64) -> String {
    format!(
        r#"Scene(
    name: "resume-periodic",
    gravity: (0.0, 0.0, -9.81),
    steps: {steps},
    integrator: Gear,
    plugins: ["hertz_mindlin"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "hertz_mindlin", rolling: "constant_torque", youngs_modulus: 1e7,
            poisson_ratio: 0.3, restitution: 0.6, friction: 0.4, rolling_friction: 0.1))],
    periodic: (x: (0.0, 0.02), y: (0.0, 0.02)),
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "glass")],
    grains: [
        Lattice(material: "glass", radius: 0.0009, region: (min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.008))),
        Random(material: "glass", region: (min: (0.0, 0.0, 0.009), max: (0.02, 0.02, 0.02)),
            count: 100, radius: Uniform(min: 0.0008, max: 0.0015), seed: 3, velocity_spread: 0.5),
    ],
    output: (recording: false, report_interval: 0.0005),
)"#
    )
}

fn build(text: &str, resume: Option<&SavedState>) -> Simulation {
    common::build_or_resume(text, resume)
}

/// The whole state as text: equal texts mean equal bits (floats are written in their
/// shortest round-trip form), the same contacts in the same order, the same histories.
fn fingerprint(sim: &mut Simulation) -> String {
    let state = SavedState::capture(&mut sim.world, "x");
    ron::to_string(&state).unwrap()
}

/// Runs `total` steps in one go, and `split` steps then save, load, and the rest;
/// returns both fingerprints and the state saved at the split.
fn interrupted_and_not(
    scene: impl Fn(u64) -> String,
    split: u64,
    total: u64,
) -> (String, String, SavedState) {
    let dir = common::temp_dir(&format!("save-load-{split}"));
    let mut whole = build(&scene(total), None);
    whole.run_steps(total).unwrap();

    let mut first = build(&scene(total), None);
    first.run_steps(split).unwrap();
    let path = dir.join("state.ron");
    SavedState::capture(
        &mut first.world,
        &talus::scene::parse("s", &scene(total)).unwrap().file.name,
    )
    .write(&path)
    .unwrap();
    drop(first);
    let saved = SavedState::read(&path).unwrap();
    eprintln!("split at step {split}: {} contacts", saved.contacts.len());
    let mut second = build(&scene(total), Some(&saved));
    assert_eq!(second.step_count(), split);
    second.run_steps(total - split).unwrap();
    (fingerprint(&mut whole), fingerprint(&mut second), saved)
}

#[test]
fn a_resumed_frictional_pour_is_bit_identical_to_the_uninterrupted_run() {
    let (whole, resumed, saved) = interrupted_and_not(pour, 4321, 8000);
    assert!(
        saved.contacts.len() > 100,
        "the split must fall in a dense phase with many contacts, found {}",
        saved.contacts.len()
    );
    assert!(
        saved
            .contacts
            .iter()
            .any(|c| matches!(c.b, talus::scene::state::SavedBody::Wall(_))),
        "wall contacts are part of the state"
    );
    assert!(
        saved.contacts.iter().any(is_vacant_row),
        "vacant rows of the contact table are part of the state"
    );
    assert!(
        whole == resumed,
        "resumed run differs from the uninterrupted one"
    );
}

/// A saved vacant row of a contact table: grain `a` paired with itself.
fn is_vacant_row(c: &talus::scene::state::SavedContact) -> bool {
    c.b == talus::scene::state::SavedBody::Grain(c.a)
}

/// LAMMPS's chute, whose 32,000 grains make two regions of the contact tables' vacant rows
/// (`architecture.md` §6): resumed from a state saved between two sorts it is bit-identical
/// to the uninterrupted run; resumed without the state's vacant rows, its new contacts take
/// other rows until the next sort, and the run differs in the grains' motion (the order in
/// which each grain's contact forces are summed).
#[test]
fn a_resumed_chute_needs_its_vacant_rows() {
    let (split, total) = (33, 50);
    let text = crate::lane_forms::chute_text();
    let mut whole = build(&text, None);
    whole.prime().unwrap();
    whole.run_steps(total).unwrap();
    let mut first = build(&text, None);
    first.prime().unwrap();
    first.run_steps(split).unwrap();
    let saved = SavedState::capture(&mut first.world, "chute");
    let vacant = saved.contacts.iter().filter(|c| is_vacant_row(c)).count();
    assert!(vacant > 0, "the state holds vacant rows");
    let mut resumed = build(&text, Some(&saved));
    resumed.run_steps(total - split).unwrap();
    let mut without = saved.clone();
    without.contacts.retain(|c| !is_vacant_row(c));
    let mut resumed_without = build(&text, Some(&without));
    resumed_without.run_steps(total - split).unwrap();
    let grains = |sim: &mut Simulation| {
        let state = SavedState::capture(&mut sim.world, "chute");
        ron::to_string(&state.grains).unwrap()
    };
    assert!(
        fingerprint(&mut whole) == fingerprint(&mut resumed),
        "the resumed chute differs from the uninterrupted one"
    );
    assert!(
        grains(&mut whole) != grains(&mut resumed_without),
        "without its {vacant} vacant rows the resumed chute moves otherwise"
    );
}

#[test]
fn a_resumed_periodic_rolling_gear_run_is_bit_identical() {
    let (whole, resumed, saved) = interrupted_and_not(periodic_rolling_gear, 1501, 3000);
    assert!(saved.gear.is_some(), "Gear's derivatives are saved");
    assert!(
        saved.contacts.len() > 50,
        "{} contacts",
        saved.contacts.len()
    );
    assert!(
        whole == resumed,
        "resumed run differs from the uninterrupted one"
    );
}

/// A run that re-sorts its grains in memory every 500 steps (`sort_grains_every`) resumed
/// at a step where a sort is due: the resumed run sorts the restored grains as the
/// uninterrupted one sorted them (the order is a function of the positions and the order
/// before, both saved), and Gear's derivatives follow their grains through every sort.
#[test]
fn a_resumed_run_that_resorts_its_grains_is_bit_identical() {
    let scene = |steps: u64| {
        periodic_rolling_gear(steps).replace(
            "    integrator: Gear,",
            "    integrator: Gear,\n    sort_grains_every: 500,",
        )
    };
    assert!(scene(10).contains("sort_grains_every: 500"));
    let (whole, resumed, saved) = interrupted_and_not(scene, 1500, 3000);
    assert!(saved.gear.is_some(), "Gear's derivatives are saved");
    assert!(
        whole == resumed,
        "resumed run differs from the uninterrupted one"
    );
    // The sorts did reorder the grains: the run without them ends in another order.
    let mut unsorted = build(&periodic_rolling_gear(3000), None);
    unsorted.run_steps(3000).unwrap();
    assert_ne!(
        whole,
        fingerprint(&mut unsorted),
        "the sorts changed the grains' order"
    );
}

/// The comparison can fail: forgetting the contact histories (tangential springs) at the
/// split changes the continued run.
#[test]
fn resuming_without_the_contact_histories_would_differ() {
    let total = 2000;
    let mut whole = build(&pour(total), None);
    whole.run_steps(total).unwrap();
    let mut first = build(&pour(total), None);
    first.run_steps(1234).unwrap();
    let mut saved = SavedState::capture(&mut first.world, "resume-pour");
    assert!(
        saved
            .contacts
            .iter()
            .any(|c| c.history != "(s:(0.0,0.0,0.0))")
    );
    saved.contacts.clear();
    let mut second = build(&pour(total), Some(&saved));
    second.run_steps(total - 1234).unwrap();
    assert!(fingerprint(&mut whole) != fingerprint(&mut second));
}

/// Through the command line: `steps: 1500` with `--save-state`, then the same scene
/// with `steps: 3000` and `--resume`, against `steps: 3000` in one go: the final states
/// are identical, and so are the report samples the two runs share.
#[test]
fn talus_run_resume_continues_a_saved_run_exactly() {
    let dir = common::temp_dir("resume-cli");
    let short = dir.join("short.ron");
    let long = dir.join("long.ron");
    std::fs::write(&short, pour(1500)).unwrap();
    std::fs::write(&long, pour(3000)).unwrap();
    let run = |scene: &std::path::Path, out: &str, resume: Option<std::path::PathBuf>| {
        run_scene(
            scene,
            &talus::registry(),
            &RunOptions {
                out: Some(dir.join(out)),
                quiet: true,
                resume,
                save_state: true,
                ..Default::default()
            },
        )
        .unwrap_or_else(|e| panic!("{e}"))
    };
    let whole = run(&long, "whole", None);
    let first = run(&short, "first", None);
    let state = first.state.clone().expect("state written");
    let second = run(&long, "second", Some(state));
    let text =
        |p: &Option<std::path::PathBuf>| std::fs::read_to_string(p.as_ref().unwrap()).unwrap();
    assert!(
        text(&whole.state) == text(&second.state),
        "final states differ"
    );
    // The resumed report starts with the saved step's sample and goes on as the whole run.
    let bits = |s: &talus::cli::report::ReportSample| serde_json::to_string(s).unwrap();
    assert_eq!(second.report.samples[0].step, 1500);
    let after = |r: &talus::cli::Report| -> Vec<String> {
        r.samples
            .iter()
            .filter(|s| s.step > 1500)
            .map(bits)
            .collect()
    };
    assert!(after(&second.report).len() > 5);
    assert_eq!(after(&second.report), after(&whole.report));
}

/// A new scene starting from a saved packing gets its grains and contacts with their
/// histories: the forces it evaluates in its priming pass are those the saving run had.
#[test]
fn a_scene_can_start_from_a_saved_packing_with_its_contacts() {
    let dir = common::temp_dir("start-from");
    let mut first = build(&pour(4000), None);
    first.run_steps(4000).unwrap();
    let saved = SavedState::capture(&mut first.world, "resume-pour");
    saved.write(&dir.join("packing.ron")).unwrap();
    let scene = r#"Scene(
    name: "from-packing",
    gravity: (0.0, 0.0, -9.81),
    steps: 10,
    start_from: "packing.ron",
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 2000.0, restitution: 0.5, friction: 0.5))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.03, 0.03, 0.06), material: "glass", omit: ["z_max"])],
    output: (recording: false),
)"#;
    let path = dir.join("from.ron");
    std::fs::write(&path, scene).unwrap();
    let built = talus::scene::load(&path)
        .unwrap()
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(!built.resumed);
    assert_eq!(built.grain_count, saved.grains.len());
    let mut sim = built.builder.build();
    assert_eq!(sim.step_count(), 0, "a new run starts at step 0");
    let restored = SavedState::capture(&mut sim.world, "resume-pour");
    // Every grain–grain contact and every contact with the unchanged box faces comes
    // back (the lid is not in this scene).
    let kept = saved
        .contacts
        .iter()
        .filter(|c| !matches!(&c.b, talus::scene::state::SavedBody::Wall(w) if w == "lid"))
        .count();
    assert_eq!(restored.contacts.len(), kept);
    for (a, b) in saved
        .contacts
        .iter()
        .filter(|c| !matches!(&c.b, talus::scene::state::SavedBody::Wall(w) if w == "lid"))
        .zip(&restored.contacts)
    {
        assert_eq!(a.history, b.history, "history kept");
    }
    for (a, b) in saved.grains.iter().zip(&restored.grains) {
        assert_eq!(
            (
                a.position,
                a.velocity,
                a.angular_velocity,
                a.radius,
                a.mass,
                a.inertia
            ),
            (
                b.position,
                b.velocity,
                b.angular_velocity,
                b.radius,
                b.mass,
                b.inertia
            ),
            "grains come back exactly"
        );
    }
    assert_eq!(
        restored.ledger.gravity_work, 0.0,
        "a new run books from zero"
    );
}

/// A state file that is not one, or of another scene, is a clear error.
#[test]
fn bad_states_are_clear_errors() {
    let dir = common::temp_dir("bad-state");
    let path = dir.join("bad.ron");
    std::fs::write(&path, "(format: 1, grains: oops)").unwrap();
    let err = SavedState::read(&path).unwrap_err();
    assert!(err.contains("bad.ron:1:"), "{err}");
    let mut sim = build(&pour(10), None);
    sim.run_steps(5).unwrap();
    let mut state = SavedState::capture(&mut sim.world, "resume-pour");
    state.scene = "another".into();
    let scene = talus::scene::parse("x.ron", &pour(10)).unwrap();
    let err = scene
        .resume(&talus::registry(), &state)
        .err()
        .expect("another scene's state is refused");
    assert!(err.to_string().contains("another"), "{err}");
    let text = pour(10).replace("steps: 10,", "steps: 10,\n    start_from: \"missing.ron\",");
    let err = talus::scene::parse(dir.join("s.ron"), &text)
        .unwrap()
        .build(&talus::registry())
        .err()
        .expect("a missing state is refused");
    assert_eq!(err.field, "start_from", "{err}");
    assert!(err.line > 0, "{err}");
}
