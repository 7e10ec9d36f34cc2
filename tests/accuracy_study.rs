//! `talus accuracy`: the study of an elastic Hertz collision's duration against the analytic
//! t_c = 2.9433 δ_max/v converges at second order as the step shrinks, and the tool writes
//! its table, CSV and plot.

mod common;

use std::path::Path;

use talus::cli::accuracy::{load_study, run_study};

#[test]
fn hertz_contact_time_study_converges_at_second_order() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let study = root.join("scenes/studies/hertz-contact-time.study.ron");
    let out = common::temp_dir("accuracy");
    let result = run_study(&study, &talus::registry(), &out).unwrap_or_else(|e| panic!("{e}"));
    // Settings 20, 40, 80, 160, 320 steps per collision each halve the step.
    let refined: Vec<f64> = result
        .rows
        .iter()
        .filter(|r| r.setting.steps_per_collision.is_some_and(|n| n >= 20.0))
        .map(|r| r.error)
        .collect();
    eprintln!("contact-time errors: {refined:?}");
    assert_eq!(refined.len(), 5);
    for pair in refined.windows(2) {
        let order = (pair[0] / pair[1]).log2();
        assert!(order > 1.7, "order {order:.2} from errors {refined:?}");
    }
    assert!(refined[4] < 1e-5, "{refined:?}");
    let fastest = result.fastest_within_tolerance.expect("a setting within 1e-2");
    assert!(result.rows[fastest].error <= 1e-2);
    for f in &result.files {
        assert!(std::fs::metadata(f).unwrap().len() > 100, "{}", f.display());
    }
    assert_eq!(result.files.len(), 3, "table, CSV and plot");
}

#[test]
fn a_bad_study_file_names_its_line() {
    let dir = common::temp_dir("accuracy-bad");
    let path = dir.join("bad.study.ron");
    std::fs::write(&path, "Study(\n    scene: \"x.ron\",\n    quantity: Restitution(grain: (0, 1)),\n    settings: [()],\n)").unwrap();
    let e = load_study(&path).unwrap_err().to_string();
    assert!(e.contains("bad.study.ron:3:"), "{e}");
}
