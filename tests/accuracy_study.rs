//! `talus accuracy`: the study of an elastic Hertz collision's duration against the analytic
//! t_c = 2.9433 δ_max/v converges at second order as the step shrinks, and the tool writes
//! its table, CSV and plot.

use crate::common;

use std::path::Path;

use talus::cli::accuracy::{load_study, run_study};
use talus::scene::schema::IntegratorName;

#[test]
fn hertz_contact_time_study_converges_at_second_order() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let study = root.join("scenes/studies/hertz-contact-time.study.ron");
    let out = common::temp_dir("accuracy");
    let result = run_study(&study, &talus::registry(), &out).unwrap_or_else(|e| panic!("{e}"));
    // Settings 20, 40, 80, 160, 320 steps per collision each halve the step.
    let errors = |gear: bool| -> Vec<f64> {
        result
            .rows
            .iter()
            .filter(|r| r.setting.steps_per_collision.is_some_and(|n| n >= 20.0))
            .filter(|r| (r.setting.integrator == Some(IntegratorName::Gear)) == gear)
            .map(|r| r.error)
            .collect()
    };
    let refined = errors(false);
    let gear = errors(true);
    eprintln!("Gear contact-time errors: {gear:?}");
    // The higher-order scheme is more accurate at every step of the sweep.
    assert_eq!(gear.len(), refined.len());
    for (g, v) in gear.iter().zip(&refined) {
        assert!(g < v, "Gear {gear:?} vs velocity Verlet {refined:?}");
    }
    eprintln!("contact-time errors: {refined:?}");
    assert_eq!(refined.len(), 5);
    for pair in refined.windows(2) {
        let order = (pair[0] / pair[1]).log2();
        assert!(order > 1.7, "order {order:.2} from errors {refined:?}");
    }
    assert!(refined[4] < 1e-5, "{refined:?}");
    let fastest = result
        .fastest_within_tolerance
        .expect("a setting within 1e-2");
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

/// Free fall: velocity Verlet and Gear integrate a constant force exactly (they are exact
/// for quadratic trajectories); symplectic Euler, which kicks a whole step before the
/// first drift, lands ½ g dt t off: x_N = x₀ + v₀t + ½gt² + ½g dt t.
#[test]
fn every_integrator_integrates_free_fall_exactly() {
    for integrator in ["VelocityVerlet", "SymplecticEuler", "Gear"] {
        let text = format!(
            r#"Scene(
    name: "fall",
    gravity: (0.0, 0.0, -9.81),
    steps: 1000,
    time_step: 1e-4,
    integrator: {integrator},
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0, contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.5))],
    grains: [List(material: "glass", grains: [(position: (0.0, 0.0, 1.0), radius: 0.01, velocity: (0.3, 0.0, 2.0))])],
    output: (recording: false),
)"#
        );
        let (mut sim, steps) = common::build(&text);
        sim.run_steps(steps).unwrap();
        let g = common::grains(&mut sim)[0];
        let t = 0.1;
        let euler_offset = if integrator == "SymplecticEuler" {
            -0.5 * 9.81 * 1e-4 * t
        } else {
            0.0
        };
        let z = 1.0 + 2.0 * t - 0.5 * 9.81 * t * t + euler_offset;
        assert!(
            (g.position.z - z).abs() < 1e-12,
            "{integrator}: z {} vs {z}",
            g.position.z
        );
        assert!(
            (g.position.x - 0.03).abs() < 1e-12,
            "{integrator}: x {}",
            g.position.x
        );
        let vz = 2.0 - 9.81 * t;
        assert!(
            (g.velocity.z - vz).abs() < 1e-11,
            "{integrator}: vz {} vs {vz}",
            g.velocity.z
        );
    }
}

/// The step as a fraction of the critical step: the contact-time error of the elastic Hertz
/// collision falls at second order as the fraction halves.
#[test]
fn critical_step_fractions_converge_too() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = root.join("scenes/studies/hertz-elastic.ron");
    let dir = common::temp_dir("accuracy-critical");
    let study = dir.join("critical.study.ron");
    std::fs::write(
        &study,
        format!(
            "Study(scene: {:?}, quantity: ContactTime(grains: (0, 1)), reference: Analytic(3.2495773750e-05),\n settings: [(critical_step_fraction: 0.02), (critical_step_fraction: 0.01), (critical_step_fraction: 0.005)])",
            scene.display().to_string()
        ),
    )
    .unwrap();
    let result =
        run_study(&study, &talus::registry(), &dir.join("out")).unwrap_or_else(|e| panic!("{e}"));
    let errors: Vec<f64> = result.rows.iter().map(|r| r.error).collect();
    let steps: Vec<f64> = result.rows.iter().map(|r| r.dt).collect();
    eprintln!("critical fractions: dt {steps:?}, errors {errors:?}");
    assert!((steps[0] / steps[1] - 2.0).abs() < 1e-12 && (steps[1] / steps[2] - 2.0).abs() < 1e-12);
    for pair in errors.windows(2) {
        assert!(pair[0] / pair[1] > 3.0, "{errors:?}");
    }
}
