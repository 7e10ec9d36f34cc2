//! The rerun recording of a run holds every grain and one force-chain strip per active
//! contact at each recorded step (read back from the .rrd file).

mod common;

use talus::cli::{RunOptions, run_scene};

#[test]
fn recording_holds_all_grains_and_one_strip_per_contact() {
    let dir = common::temp_dir("recording");
    let scene = dir.join("rec.ron");
    std::fs::write(
        &scene,
        r#"Scene(
    name: "rec",
    gravity: (0.0, 0.0, -9.81),
    duration: 0.02,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 2000.0, restitution: 0.5, friction: 0.5))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.02), material: "glass")],
    grains: [Lattice(material: "glass", radius: 0.001, region: (min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.01)),
        spacing: 0.002)],
    output: (recording_interval: 0.002, report_interval: 0.002),
)"#,
    )
    .unwrap();
    let options = RunOptions {
        out: Some(dir.join("out")),
        quiet: true,
        progress: false,
        ..Default::default()
    };
    let summary = run_scene(&scene, &talus::registry(), &options).unwrap();
    let n = summary.report.grain_count;
    let frames = talus::rerun_export::read_counts(summary.recording.as_ref().unwrap()).unwrap();
    assert!(frames.len() >= 5, "{} frames", frames.len());
    let mut compared = 0;
    for sample in &summary.report.samples {
        if let Some(frame) = frames.iter().find(|f| f.step == sample.step) {
            assert_eq!(frame.grains, n, "step {}", sample.step);
            assert_eq!(frame.force_chains, sample.contacts, "step {}", sample.step);
            compared += 1;
        }
    }
    assert!(compared >= 5, "compared {compared} steps");
    assert!(summary.report.samples.last().unwrap().contacts > 0);
}
