//! The rerun recording of a run holds every grain and one force-chain strip per active
//! contact at each recorded step (read back from the .rrd file).

use crate::common;

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
    output: (recording_interval: 0.005, report_interval: 0.005),
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

/// Runs `scene` (RON text) with the recording on; returns the report and the recording.
fn run_recorded(name: &str, scene: &str) -> (talus::cli::Report, std::path::PathBuf) {
    let dir = common::temp_dir(name);
    let path = dir.join("scene.ron");
    std::fs::write(&path, scene).unwrap();
    let options = RunOptions {
        out: Some(dir.join("out")),
        quiet: true,
        progress: false,
        ..Default::default()
    };
    let summary = run_scene(&path, &talus::registry(), &options).unwrap();
    (summary.report, summary.recording.unwrap())
}

/// Reads one `jiang_liu` contact quantity back, by step.
fn quantity(recording: &std::path::Path, name: &str) -> std::collections::BTreeMap<u64, Vec<f64>> {
    talus::rerun_export::read_contact_quantity(recording, "jiang_liu", name)
        .unwrap()
        .into_iter()
        .collect()
}

/// The per-contact quantities a law exposes are in the recording, one value per active
/// contact of the law and frame, and agree with independent references: each contact's
/// w_e with the potential (19) k √(−u_n) ((2/5) u_n² + |u_t|²/ξ) evaluated here from its
/// recorded u_n and |u_t|; their sums over the contacts with the report's totals, which
/// the energy ledger accumulates step by step (w_e with `elastic`, w_r with the running
/// sum of the `relaxation_storage` channel). A many-grain pour under gravity.
#[test]
fn recording_holds_jiang_liu_contact_quantities_matching_the_report() {
    let stiffness = 2.0e7;
    let (report, recording) = run_recorded(
        "recording-jl-pour",
        &format!(
            r#"Scene(
    name: "jl-pour",
    gravity: (0.0, 0.0, -9.81),
    duration: 0.15,
    plugins: ["jiang_liu"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "jiang_liu", stiffness: {stiffness:e}, eta_relax_n: 10.0, eta_relax_t: 10.0))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.1), material: "glass")],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.03)),
        count: 30, radius: Uniform(min: 0.0015, max: 0.0025), seed: 5, velocity_spread: 0.3)],
    output: (recording_interval: 0.005, report_interval: 0.005),
)"#
        ),
    );
    let frames = talus::rerun_export::read_counts(&recording).unwrap();
    let elastic = quantity(&recording, "elastic_energy");
    let relaxation = quantity(&recording, "relaxation_energy");
    let normal = quantity(&recording, "normal_displacement");
    let tangential = quantity(&recording, "tangential_displacement");
    let (heat, rate) = (
        quantity(&recording, "heat"),
        quantity(&recording, "heat_rate"),
    );
    // The running sum of `relaxation_storage` returns to 0 only to rounding once the
    // contacts holding w_r have ended: compare at the scale of its largest value.
    let stored_scale = report
        .samples
        .iter()
        .map(|s| s.dissipated["relaxation_storage"].abs())
        .fold(0.0, f64::max);
    assert!(stored_scale > 0.0);
    let mut compared = 0;
    let mut most = 0;
    for sample in &report.samples {
        let Some(w_e) = elastic.get(&sample.step) else {
            continue;
        };
        let frame = frames.iter().find(|f| f.step == sample.step).unwrap();
        // Every contact is a jiang_liu contact: one value per force-chain strip.
        assert_eq!(w_e.len(), frame.force_chains, "step {}", sample.step);
        assert_eq!(w_e.len(), sample.contacts, "step {}", sample.step);
        let (u_n, u_t) = (&normal[&sample.step], &tangential[&sample.step]);
        for (k, &w) in w_e.iter().enumerate() {
            // ξ = 1, c = 0.
            let expected = if u_n[k] < 0.0 {
                stiffness * (-u_n[k]).sqrt() * (0.4 * u_n[k] * u_n[k] + u_t[k] * u_t[k])
            } else {
                0.0
            };
            assert!(
                (w - expected).abs() <= 1e-12 * expected.abs().max(1e-30),
                "step {} contact {k}: w_e {w:e}, from u {expected:e}",
                sample.step
            );
            assert!(heat[&sample.step][k] >= 0.0 && rate[&sample.step][k] >= 0.0);
        }
        let sum_elastic: f64 = w_e.iter().sum();
        assert!(
            (sum_elastic - sample.elastic).abs() <= 1e-9 * sample.elastic.abs().max(1e-30),
            "step {}: Σ w_e {sum_elastic:e}, report {:e}",
            sample.step,
            sample.elastic
        );
        let sum_relaxation: f64 = relaxation[&sample.step].iter().sum();
        let stored = sample.dissipated["relaxation_storage"];
        assert!(
            (sum_relaxation - stored).abs() <= 1e-9 * stored_scale,
            "step {}: Σ w_r {sum_relaxation:e}, report {stored:e}",
            sample.step
        );
        most = most.max(w_e.len());
        compared += 1;
    }
    assert!(compared >= 15, "compared {compared} frames");
    assert!(most >= 10, "at most {most} contacts at once");
}

/// In a single collision the contact's accumulated heat is the scene's heat and its heat
/// rate R the scene's (the report's `dissipation_power` of channel `heat`) at every frame
/// while the grains touch; a law without contact quantities records none.
#[test]
fn recording_of_one_collision_holds_its_heat_and_heat_rate() {
    let scene =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/jiang-liu-oblique.ron");
    let text = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("recording_interval: 2.0e-6", "recording_interval: 1.0e-9")
        .replace("report_interval: 2.0e-6", "report_interval: 1.0e-9");
    let (report, recording) = run_recorded("recording-jl-oblique", &text);
    let heat = quantity(&recording, "heat");
    let rate = quantity(&recording, "heat_rate");
    let mut touching = 0;
    for sample in &report.samples {
        let Some(h) = heat.get(&sample.step) else {
            continue;
        };
        assert!(h.len() <= 1, "one pair, {} contacts", h.len());
        if let [h] = h[..] {
            let total = sample.dissipated["heat"];
            assert!(
                (h - total).abs() <= 1e-12 * total,
                "step {}: {h:e} vs {total:e}",
                sample.step
            );
            let r = rate[&sample.step][0];
            let power = sample.dissipation_power["heat"];
            assert!((r - power).abs() <= 1e-12 * power.abs().max(1e-30));
            touching += 1;
        }
    }
    assert!(touching > 20, "{touching} frames in contact");
    // The linear spring exposes no contact quantity: nothing is recorded under contacts/
    // besides the force chains.
    let (_, plain) = run_recorded(
        "recording-plain",
        &text.replace(
            "contact: (law: \"jiang_liu\", stiffness: 2.0e9, xi: 1.0, characteristic_velocity: 1.0)",
            "contact: (law: \"linear_spring\", stiffness: 2000.0, restitution: 0.5, friction: 0.5)",
        )
        .replace("plugins: [\"jiang_liu\"]", "plugins: [\"linear_spring\"]"),
    );
    let entities = talus::rerun_export::read_entities(&plain).unwrap();
    assert!(
        entities
            .iter()
            .all(|e| !e.path.starts_with("/contacts/") || e.path == "/contacts/force_chains"),
        "{entities:?}"
    );
}
