//! Generates the figures and the accuracy table of `docs/laws/jiang-liu.md` from engine
//! runs. Ignored by default (it writes into `docs/`); run once with
//! `cargo test --release -p talus-jiang-liu --test figures -- --ignored --nocapture`.

use std::path::PathBuf;
use std::time::Instant;

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus_contact::{LawRegistry, LawState};
use talus_core::prelude::*;
use talus_jiang_liu::JiangLiuState;
use talus_plot::{Axis, Chart, Series, write_svg};

const DENSITY: f64 = 2500.0;
const RADIUS: f64 = 0.005;

fn grain_mass() -> f64 {
    DENSITY * 4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3)
}

/// Hertz-like contact time 2.943 δ_max / v of f = k δ^{3/2}, reduced mass m/2.
fn contact_time(k: f64, v: f64) -> f64 {
    let m = 0.5 * grain_mass();
    2.943 * (5.0 * m * v * v / (4.0 * k)).powf(0.4) / v
}

fn figures_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/laws/figures")
}

fn registry() -> LawRegistry {
    let mut r = LawRegistry::new();
    talus_jiang_liu::register(&mut r);
    talus_hertz_mindlin::register(&mut r);
    r
}

fn head_on(v: f64, dt: f64, contact: &str) -> String {
    let x = RADIUS + v * dt;
    format!(
        r#"Scene(
    name: "jiang-liu-figure",
    steps: 100000000,
    time_step: {dt:e},
    plugins: ["jiang_liu", "hertz_mindlin"],
    materials: [(name: "glass", density: {DENSITY:e}, contact: ({contact}))],
    grains: [List(material: "glass", grains: [
        (position: ({nx:e}, 0.0, 0.0), radius: {RADIUS}, velocity: ({hv:e}, 0.0, 0.0)),
        (position: ({x:e}, 0.0, 0.0), radius: {RADIUS}, velocity: ({nhv:e}, 0.0, 0.0)),
    ])],
    output: (recording: false),
)"#,
        nx = -x,
        hv = 0.5 * v,
        nhv = -0.5 * v,
    )
}

/// One sample of the time course.
#[derive(Clone, Copy, Debug, Default)]
struct Sample {
    time: f64,
    distance: f64,
    force: f64,
    kinetic: f64,
    elastic: f64,
    relaxation: f64,
    heat: f64,
}

/// Runs a head-on collision to its end; returns e and the time course.
fn collide(text: &str, record: bool) -> (f64, Vec<Sample>) {
    let scene = talus_scene::parse("figure.ron", text).unwrap_or_else(|e| panic!("{e}"));
    let built = scene.build(&registry()).unwrap_or_else(|e| panic!("{e}"));
    let mut sim = built.builder.build();
    sim.prime().unwrap();
    let mut grains = sim
        .world
        .query_filtered::<(&Position, &Velocity, &Mass), With<Grain>>();
    let mut laws = sim.world.query::<&LawState<JiangLiuState>>();
    let read =
        |world: &World, grains: &mut QueryState<(&Position, &Velocity, &Mass), With<Grain>>| {
            let g: Vec<(DVec3, DVec3, f64)> = grains
                .iter(world)
                .map(|(p, v, m)| (p.0, v.0, m.0))
                .collect();
            g
        };
    let g0 = read(&sim.world, &mut grains);
    let v_in = (g0[0].1 - g0[1].1).x;
    let mut samples = Vec::new();
    let (mut touched, mut after) = (false, 0);
    let heat_channel = sim
        .world
        .resource::<DissipationChannels>()
        .names
        .iter()
        .position(|n| n == "heat");
    for _ in 0..100_000_000u64 {
        sim.step().unwrap();
        let g = read(&sim.world, &mut grains);
        let distance = (g[0].0 - g[1].0).length();
        let overlap = 2.0 * RADIUS - distance;
        touched |= overlap > 0.0;
        if record {
            let (mut force, mut elastic, mut relaxation) = (0.0, 0.0, 0.0);
            for s in laws.iter(&sim.world) {
                force += s.0.force.length();
                elastic += s.0.elastic_energy;
                relaxation += s.0.relaxation_energy;
            }
            let heat =
                heat_channel.map_or(0.0, |i| sim.world.resource::<EnergyLedger>().dissipated[i]);
            let kinetic: f64 = g.iter().map(|(_, v, m)| 0.5 * m * v.length_squared()).sum();
            samples.push(Sample {
                time: sim.world.resource::<Clock>().time,
                distance,
                force,
                kinetic,
                elastic,
                relaxation,
                heat,
            });
        }
        if touched && overlap <= 0.0 {
            after += 1;
            if after > 2 {
                break;
            }
        }
    }
    let g = read(&sim.world, &mut grains);
    (-(g[0].1 - g[1].1).x / v_in, samples)
}

#[test]
#[ignore]
fn generate_jiang_liu_figures() {
    let dir = figures_dir();
    std::fs::create_dir_all(&dir).unwrap();

    // e(v0): Jiang–Liu (glass-like k) beside Hertz–Mindlin with e = 0.9.
    let k = 2.0e9;
    let hertz =
        "law: \"hertz_mindlin\", youngs_modulus: 7.0e10, poisson_ratio: 0.25, restitution: 0.9";
    let (mut jl, mut hm) = (Vec::new(), Vec::new());
    for i in 0..=12 {
        let v = 1e-4 * 10f64.powf(0.5 * i as f64);
        let dt = contact_time(k, v) / 100.0;
        let (e, _) = collide(
            &head_on(v, dt, &format!("law: \"jiang_liu\", stiffness: {k:e}")),
            false,
        );
        let (e_h, _) = collide(&head_on(v, dt, hertz), false);
        println!("| {v:.3e} | {e:.6} | {e_h:.6} |");
        jl.push((v, e));
        hm.push((v, e_h));
    }
    let chart = Chart::new(
        "Head-on restitution e(v0): Jiang–Liu (37)–(41), k = 2e9, vs Hertz–Mindlin e = 0.9",
        Axis::log("impact speed v0 (m/s)"),
        Axis::linear("restitution e"),
    )
    .with(Series::line_and_points("Jiang–Liu", jl.clone()))
    .with(Series::line_and_points("Hertz–Mindlin", hm));
    write_svg(&chart, &dir.join("jiang-liu-restitution.svg")).unwrap();
    let chart = Chart::new(
        "Jiang–Liu: 1 − e against v0 (log–log)",
        Axis::log("impact speed v0 (m/s)"),
        Axis::log("1 − e"),
    )
    .with(Series::line_and_points(
        "Jiang–Liu",
        jl.iter().map(|&(v, e)| (v, 1.0 - e)).collect(),
    ));
    write_svg(&chart, &dir.join("jiang-liu-restitution-loss.svg")).unwrap();

    // Time course of one collision (the paper's Fig. 3): soft grains, k = 5e3, v0 = 1 m/s,
    // so that the dissipation is visible (e ≈ 0.98, overlap up to 0.37 R).
    let (k_soft, v0) = (5.0e3, 1.0);
    let tc = contact_time(k_soft, v0);
    let (e, samples) = collide(
        &head_on(
            v0,
            tc / 400.0,
            &format!("law: \"jiang_liu\", stiffness: {k_soft:e}"),
        ),
        true,
    );
    println!(
        "time course: k = {k_soft}, v0 = {v0}: e = {e:.5}, {} samples",
        samples.len()
    );
    let w0 = samples[0].kinetic;
    let d = 2.0 * RADIUS;
    let f0 = samples.iter().map(|s| s.force).fold(0.0, f64::max);
    let t = |s: &Sample| s.time / tc;
    let chart = Chart::new(
        "Head-on collision: (r − d)/d and |f|/max|f|",
        Axis::linear("t / t_c"),
        Axis::linear("dimensionless"),
    )
    .with(Series::line(
        "(r − d)/d × 10",
        samples
            .iter()
            .map(|s| (t(s), 10.0 * (s.distance - d) / d))
            .collect(),
    ))
    .with(Series::line(
        "|f| / max|f|",
        samples.iter().map(|s| (t(s), s.force / f0)).collect(),
    ));
    write_svg(&chart, &dir.join("jiang-liu-collision-motion.svg")).unwrap();
    let chart = Chart::new(
        "Head-on collision: energies over w0 = initial kinetic energy",
        Axis::linear("t / t_c"),
        Axis::linear("energy / w0"),
    )
    .with(Series::line(
        "kinetic",
        samples.iter().map(|s| (t(s), s.kinetic / w0)).collect(),
    ))
    .with(Series::line(
        "elastic w_e",
        samples.iter().map(|s| (t(s), s.elastic / w0)).collect(),
    ))
    .with(Series::line(
        "mechanical",
        samples
            .iter()
            .map(|s| (t(s), (s.kinetic + s.elastic) / w0))
            .collect(),
    ));
    write_svg(&chart, &dir.join("jiang-liu-collision-energy.svg")).unwrap();
    let chart = Chart::new(
        "Head-on collision: relaxation energy w_r and accumulated heat",
        Axis::linear("t / t_c"),
        Axis::linear("energy / w0"),
    )
    .with(Series::line(
        "relaxation w_r",
        samples.iter().map(|s| (t(s), s.relaxation / w0)).collect(),
    ))
    .with(Series::line(
        "heat",
        samples.iter().map(|s| (t(s), s.heat / w0)).collect(),
    ));
    write_svg(&chart, &dir.join("jiang-liu-collision-relaxation.svg")).unwrap();

    // What accuracy costs: the 1 m/s glass collision at steps per contact from 12.5 to
    // 3200, sharp and smoothed Θ; error in e against the finest run of the same variant.
    let variants = [
        ("sharp", String::new()),
        (
            "smoothed x1 = 1e-4, x0 = 3e-4",
            ", heaviside_width: 1.0e-4, heaviside_offset: 3.0e-4".to_string(),
        ),
    ];
    let steps = [12.5, 25.0, 50.0, 100.0, 200.0, 400.0, 800.0, 3200.0];
    let mut chart = Chart::new(
        "Cost of accuracy: |e − e_finest| against wall-clock time (1 m/s, k = 2e9)",
        Axis::log("wall-clock time per collision (s)"),
        Axis::log("|e − e_finest|"),
    );
    println!("| Θ | steps per contact | e | abs(e − e_finest) | wall-clock (ms) |");
    println!("|---|---:|---:|---:|---:|");
    for (name, extra) in &variants {
        let contact = format!("law: \"jiang_liu\", stiffness: {k:e}{extra}");
        let mut runs = Vec::new();
        for &n in &steps {
            let dt = contact_time(k, 1.0) / n;
            let text = head_on(1.0, dt, &contact);
            let start = Instant::now();
            let (e, _) = collide(&text, false);
            runs.push((n, e, start.elapsed().as_secs_f64()));
        }
        let finest = runs.last().unwrap().1;
        let mut points = Vec::new();
        for &(n, e, wall) in &runs {
            println!(
                "| {name} | {n} | {e:.9} | {:.2e} | {:.2} |",
                (e - finest).abs(),
                1e3 * wall
            );
            if n < 3200.0 {
                points.push((wall, (e - finest).abs().max(1e-16)));
            }
        }
        chart = chart.with(Series::line_and_points(*name, points));
    }
    write_svg(&chart, &dir.join("jiang-liu-accuracy.svg")).unwrap();
}
