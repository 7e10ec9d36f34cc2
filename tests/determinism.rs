//! Determinism: the same scene run twice, or on another number of threads, gives
//! bit-identical reports (timings excluded).

use crate::common;

use talus::cli::{RunOptions, run_scene};

const SCENE: &str = r#"Scene(
    name: "det",
    gravity: (0.0, 0.0, -9.81),
    steps: 3000,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 2000.0, restitution: 0.5, friction: 0.5))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.03, 0.03, 0.05), material: "glass")],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: (0.03, 0.03, 0.05)),
        count: 400, radius: Uniform(min: 0.001, max: 0.002), seed: 11, velocity_spread: 0.3)],
    output: (recording: false, report_interval: 0.0005),
)"#;

#[test]
fn same_scene_twice_gives_bit_identical_reports() {
    let dir = common::temp_dir("determinism");
    let scene = dir.join("det.ron");
    std::fs::write(&scene, SCENE).unwrap();
    let run = |name: &str| {
        let options = RunOptions {
            out: Some(dir.join(name)),
            quiet: true,
            progress: false,
            ..Default::default()
        };
        let mut report = run_scene(&scene, &talus::registry(), &options)
            .unwrap()
            .report;
        report.wall_clock = Default::default();
        report
    };
    let a = run("a");
    let b = run("b");
    assert!(a.samples.len() > 10);
    assert!(
        a.samples.last().unwrap().contacts > 0,
        "the grains must touch"
    );
    // Compare bit patterns, not approximate values.
    let bits = |r: &talus::cli::Report| serde_json::to_string(r).unwrap();
    assert_eq!(bits(&a), bits(&b));
}

/// Runs `scene` on `threads` threads with its output in `out`; returns its report.
fn report_on(scene: &std::path::Path, out: &std::path::Path, threads: usize) -> talus::cli::Report {
    let options = RunOptions {
        out: Some(out.to_path_buf()),
        quiet: true,
        progress: false,
        ..Default::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| run_scene(scene, &talus::registry(), &options))
        .unwrap()
        .report
}

/// The same scene on 1, 2 and 3 threads gives bit-identical reports: every parallel loop
/// splits its work into chunks fixed by the state (grains, contacts) or sums each grain's
/// contacts in a fixed order whichever thread does it, never by the number of threads.
#[test]
fn the_thread_count_does_not_change_the_results() {
    let dir = common::temp_dir("determinism-threads");
    let scene = dir.join("det.ron");
    std::fs::write(&scene, SCENE).unwrap();
    let run = |threads: usize| {
        let mut report = report_on(&scene, &dir.join(format!("threads-{threads}")), threads);
        report.wall_clock = Default::default();
        serde_json::to_string(&report).unwrap()
    };
    let one = run(1);
    assert!(one.contains("\"contacts\""));
    assert_eq!(one, run(2), "1 and 2 threads");
    assert_eq!(one, run(3), "1 and 3 threads");
}

/// With the grains re-sorted in memory every 700 steps (`sort_grains_every`), a run is
/// still bit-identical twice over and on 1 and 2 threads (the order is a function of the
/// positions and the order before), and its report counts the four re-sorts of its 3,000
/// steps (before steps 701, 1401, 2101 and 2801; the one before step 1 is the priming's).
#[test]
fn runs_that_resort_their_grains_stay_deterministic() {
    let dir = common::temp_dir("determinism-sorted");
    let scene = dir.join("det-sorted.ron");
    let text = SCENE.replace(
        "    steps: 3000,",
        "    steps: 3000,\n    sort_grains_every: 700,",
    );
    assert!(text.contains("sort_grains_every: 700"));
    std::fs::write(&scene, text).unwrap();
    let run = |threads: usize, name: &str| {
        let mut report = report_on(&scene, &dir.join(name), threads);
        assert_eq!(report.wall_clock.grain_sorts, 4);
        assert!(report.wall_clock.grain_sorting > 0.0);
        report.wall_clock = Default::default();
        serde_json::to_string(&report).unwrap()
    };
    let once = run(1, "a");
    assert_eq!(once, run(1, "b"), "twice on 1 thread");
    assert_eq!(once, run(2, "c"), "1 and 2 threads");
}
