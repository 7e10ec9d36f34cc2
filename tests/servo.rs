//! A servo wall holds a pressure: a packing squeezed by a servo-controlled lid settles with
//! the lid's load equal to the target, and the sampled stress equal to the target pressure.

use crate::common;

use talus::cli::ReportSample;

const PRESSURE: f64 = 2.0e4;

/// 125 glass beads (R = 1 mm) on a simple cubic lattice in a 1 cm square column, no
/// gravity, sampled every 0.01 s, squeezed by `walls` for `duration` seconds.
fn squeezed_packing(name: &str, duration: f64, walls: &str) -> String {
    format!(
        r#"Scene(
    name: "{name}",
    gravity: (0.0, 0.0, 0.0),
    duration: {duration},
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.2, friction: 0.3))],
    walls: [
        {walls}
    ],
    grains: [Lattice(material: "glass", radius: 0.001, region: (min: (0.0, 0.0, 0.0), max: (0.01, 0.01, 0.01)),
        spacing: 0.002)],
    sampling: (interval: 0.01),
    output: (recording: false),
)"#
    )
}

#[test]
fn a_servo_lid_holds_the_target_pressure() {
    let text = squeezed_packing(
        "servo",
        0.15,
        &format!(
            r#"Box(min: (0.0, 0.0, 0.0), max: (0.01, 0.01, 0.1), material: "glass", omit: ["z_max"]),
        Plane(name: "lid", point: (0.0, 0.0, 0.0102), normal: (0.0, 0.0, -1.0), material: "glass",
            servo: (pressure: {PRESSURE:e}, area: 1e-4, gain: 0.05, max_speed: 0.05)),"#
        ),
    );
    let (mut sim, steps) = common::build(&text);
    assert!(
        sim.plan
            .stages
            .iter()
            .any(|(_, s)| s.iter().any(|n| n == "servo_walls"))
    );
    sim.run_steps(steps).unwrap();
    let sample = ReportSample::take(&sim.world);
    let mut q = sim
        .world
        .query::<(&talus::core::prelude::Wall, &talus::core::prelude::WallLoad)>();
    let (lid, load) = q.iter(&sim.world).find(|(w, _)| w.name == "lid").unwrap();
    let pushed = -load.0.dot(lid.normal);
    let target = PRESSURE * 1e-4;
    let stress = sample.stress.as_ref().expect("sampled");
    let domain = stress.regions.iter().find(|r| r.name == "domain").unwrap();
    let sigma_zz = domain.stress.0[2][2];
    eprintln!(
        "servo: lid load {pushed:.5} N (target {target} N), sampled σ_zz {sigma_zz:.2} Pa (target −{PRESSURE}), KE {:.2e} J",
        sample.kinetic()
    );
    assert!((pushed - target).abs() < 0.01 * target, "lid load {pushed}");
    assert!(
        (-sigma_zz - PRESSURE).abs() < 0.01 * PRESSURE,
        "σ_zz {sigma_zz}"
    );
}

/// A packing squeezed between a floor and a lid both driven at one strain rate: the gap
/// follows L₀ e^{−ε̇t} (the exact solution of L̇ = −ε̇L) to rounding, the mid-plane stays put, and while the packing is loaded
/// quasi-statically both walls carry the same load, equal to the sampled σ_zz × area.
#[test]
fn strain_rate_walls_follow_the_exponential_and_the_sampled_stress_matches_their_load() {
    const RATE: f64 = 0.4;
    const GAP: f64 = 0.0102;
    let text = squeezed_packing(
        "strain-rate",
        0.06,
        &format!(
            r#"Box(min: (0.0, 0.0, 0.0), max: (0.01, 0.01, 0.1), material: "glass", omit: ["z_min", "z_max"]),
        Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "glass",
            strain_rate: (rate: {RATE}, opposite: "lid")),
        Plane(name: "lid", point: (0.0, 0.0, {GAP}), normal: (0.0, 0.0, -1.0), material: "glass",
            strain_rate: (rate: {RATE}, opposite: "floor")),"#
        ),
    );
    let (mut sim, steps) = common::build(&text);
    assert!(
        sim.plan
            .stages
            .iter()
            .any(|(_, s)| s.iter().any(|n| n == "strain_rate_walls"))
    );
    let walls = |sim: &mut talus::core::schedule::Simulation| {
        let mut q = sim
            .world
            .query::<(&talus::core::prelude::Wall, &talus::core::prelude::WallLoad)>();
        let mut get = |name: &str| {
            q.iter(&sim.world)
                .find(|(w, _)| w.name == name)
                .map(|(w, l)| (w.point.z, -l.0.dot(w.normal)))
                .unwrap()
        };
        (get("floor"), get("lid"))
    };
    let chunks = 6;
    let mut worst_gap: f64 = 0.0;
    let mut worst_mid: f64 = 0.0;
    for chunk in 1..=chunks {
        sim.run_steps(steps / chunks).unwrap();
        let t = sim.world.resource::<talus::core::prelude::Clock>().time;
        let ((floor, floor_load), (lid, lid_load)) = walls(&mut sim);
        let gap_error = ((lid - floor) / (GAP * (-RATE * t).exp()) - 1.0).abs();
        worst_gap = worst_gap.max(gap_error);
        worst_mid = worst_mid.max((0.5 * (lid + floor) - 0.5 * GAP).abs() / GAP);
        if chunk == chunks {
            let sample = ReportSample::take(&sim.world);
            let stress = sample.stress.as_ref().expect("sampled");
            let domain = stress.regions.iter().find(|r| r.name == "domain").unwrap();
            let sigma_zz = -domain.stress.0[2][2];
            let area = 1e-4;
            eprintln!(
                "strain rate: t {t:.4} s, strain {:.4}, floor load {floor_load:.5} N, lid load {lid_load:.5} N, sampled −σ_zz·A {:.5} N",
                1.0 - (lid - floor) / GAP,
                sigma_zz * area
            );
            assert!(lid_load > 0.1, "the packing is loaded: {lid_load} N");
            assert!(
                (floor_load - lid_load).abs() < 0.01 * lid_load,
                "floor {floor_load} N against lid {lid_load} N"
            );
            assert!(
                (sigma_zz * area - lid_load).abs() < 0.01 * lid_load,
                "σ_zz·A {} N against lid {lid_load} N",
                sigma_zz * area
            );
        }
    }
    eprintln!("gap error {worst_gap:e}, mid-plane drift {worst_mid:e}");
    assert!(worst_gap < 1e-12, "gap off L₀e^(−ε̇t) by {worst_gap:e}");
    assert!(
        worst_mid < 1e-12,
        "mid-plane moved by {worst_mid:e} of the gap"
    );
}

/// One wall driven against a fixed one at a negative rate opens the gap as L₀ e^{|ε̇|t}.
#[test]
fn a_negative_strain_rate_opens_the_gap_exponentially() {
    const RATE: f64 = -5.0;
    let text = format!(
        r#"Scene(
    name: "extension",
    gravity: (0.0, 0.0, 0.0),
    steps: 20000,
    time_step: 1e-5,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.2))],
    walls: [
        Plane(name: "left", point: (0.0, 0.0, 0.0), normal: (1.0, 0.0, 0.0), material: "glass"),
        Plane(name: "right", point: (0.02, 0.0, 0.0), normal: (-1.0, 0.0, 0.0), material: "glass",
            strain_rate: (rate: {RATE}, opposite: "left")),
    ],
    grains: [List(material: "glass", grains: [(position: (0.01, 0.0, 0.0), radius: 0.001)])],
    output: (recording: false),
)"#
    );
    let (mut sim, steps) = common::build(&text);
    sim.run_steps(steps).unwrap();
    let t = sim.world.resource::<talus::core::prelude::Clock>().time;
    let mut q = sim.world.query::<&talus::core::prelude::Wall>();
    let mut x = |name: &str| q.iter(&sim.world).find(|w| w.name == name).unwrap().point.x;
    let (left, right) = (x("left"), x("right"));
    let expected = 0.02 * (-RATE * t).exp();
    let error = ((right - left) / expected - 1.0).abs();
    eprintln!(
        "extension: gap {:.6e} m against {expected:.6e} m",
        right - left
    );
    assert_eq!(left, 0.0, "the opposite wall is not driven");
    assert!(error < 1e-12, "{error:e}");
}
