//! Energy balance of pours: kinetic + elastic + dissipated − work by gravity and walls
//! stays constant. Each term is computed from its own formula (see
//! docs/physics/energy-accounting.md), so the balance measures the integration error.

mod common;

use std::path::Path;

use talus::cli::{Report, RunOptions, run_scene};

fn run(scene: &Path, name: &str) -> Report {
    let options = RunOptions {
        out: Some(common::temp_dir(name)),
        quiet: true,
        progress: false,
    };
    run_scene(scene, &talus::registry(), &options)
        .unwrap()
        .report
}

/// Largest |balance(t) − balance(0)| over the run, relative to the work of gravity.
fn worst_balance_error(report: &Report) -> f64 {
    let first = report.samples[0].energy_balance;
    let injected = report.samples.last().unwrap().gravity_work;
    assert!(injected > 0.0);
    report
        .samples
        .iter()
        .map(|s| (s.energy_balance - first).abs() / injected)
        .fold(0.0, f64::max)
}

fn small_pour(steps_per_collision: u32) -> String {
    format!(
        r#"Scene(
    name: "small-pour",
    gravity: (0.0, 0.0, -9.81),
    duration: 0.2,
    steps_per_collision: {steps_per_collision},
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 2000.0, restitution: 0.5, friction: 0.5))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.1), material: "glass")],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.005), max: (0.02, 0.02, 0.05)),
        count: 150, radius: Uniform(min: 0.0015, max: 0.0025), seed: 5)],
    output: (recording: false, report_interval: 0.002),
)"#
    )
}

/// The balance error is the integrator's: halving the time step must shrink it by at
/// least 3× (velocity Verlet is second order: 4×). A bookkeeping error would not shrink.
#[test]
fn pour_energy_balance_error_converges_at_second_order() {
    let dir = common::temp_dir("balance-scenes");
    let mut errors = Vec::new();
    for spc in [50u32, 100] {
        let path = dir.join(format!("pour{spc}.ron"));
        std::fs::write(&path, small_pour(spc)).unwrap();
        errors.push(worst_balance_error(&run(&path, &format!("balance-{spc}"))));
    }
    eprintln!("balance error at 50 and 100 steps per collision: {errors:?}");
    assert!(errors[0] < 2e-2, "{errors:?}");
    assert!(errors[0] / errors[1] > 3.0, "not second order: {errors:?}");
}

/// The issue's tolerance, 1e-6 of the gravity work, on the default pour scene. Out of
/// reach at the default time step (measured 1.1e-2 there): the residual is velocity
/// Verlet's energy error at contact onset and release, O((ω dt)²) per collision.
#[test]
#[ignore = "1e-6 is out of reach at the default step: measured 1.1e-2 (see docs/physics/energy-accounting.md)"]
fn pour_energy_balance_closes_to_1e_minus_6() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/pour.ron");
    let worst = worst_balance_error(&run(&scene, "pour-balance"));
    assert!(
        worst < 1e-6,
        "energy balance drifted by {worst:e} of the gravity work"
    );
}
