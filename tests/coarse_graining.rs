//! Coarse-grained fields (`sampling.fields`) and stress regions at periodic seams, against
//! independent references: the total mass and momentum of the grains, the Love–Weber sum
//! Σ f ⊗ l computed here from the contacts, the sampled Gaussian of a lone grain, and the
//! additivity of regions that tile a periodic box (with contacts through its seams);
//! and the plumbing: the system only when asked for, located errors, `fields.json`, the
//! point clouds in the recording.

use crate::common;

use common::sampling::{field, region, regions};
use glam::DVec3;
use talus::contact::{Contact, ContactForce, ContactGeometry, ContactKind};
use talus::core::prelude::*;
use talus::core::schedule::Simulation;
use talus_stress::{FieldRecord, FieldSample, StressRecord, Tensor};

/// Edge of the periodic cube of the dense gas, m.
const CUBE: f64 = 0.02;

/// The shared glass gas (`common::glass_gas`) in a periodic cube, one step: about a
/// hundred contacts open at any time, some through the seams.
fn periodic_gas(sampling: &str) -> String {
    common::glass_gas("periodic-gas", 1, CUBE, "", sampling)
}

/// A gas between a floor and a lid (z) in a box periodic along x and y, under gravity:
/// grains rest on the floor, touch the lid, and cross the seams.
fn walled_gas(sampling: &str) -> String {
    format!(
        r#"Scene(
    name: "walled-gas",
    steps: 1,
    periodic: (x: (0.0, {CUBE}), y: (0.0, {CUBE})),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 500.0, restitution: 0.5, friction: 0.3))],
    walls: [
        Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "glass"),
        Plane(name: "lid", point: (0.0, 0.0, 0.012), normal: (0.0, 0.0, -1.0), material: "glass"),
    ],
    grains: [
        Random(material: "glass", region: (min: (0.001, 0.001, 0.0), max: (0.019, 0.019, 0.012)),
            count: 300, radius: Uniform(min: 0.0007, max: 0.0009), seed: 9, velocity_spread: 0.5),
        List(material: "glass", grains: [
            (position: (0.0001, 0.0199, 0.0008), radius: 0.0008, velocity: (-0.3, 0.2, 0.0)),
        ]),
    ],
    {sampling}
    output: (recording: false),
)"#
    )
}

/// The same in 2-D: disks periodic along x between a floor and a lid along y.
fn walled_disks(sampling: &str) -> String {
    format!(
        r#"Scene(
    name: "walled-disks",
    dimension: 2,
    steps: 1,
    periodic: (x: (0.0, {CUBE})),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e5, restitution: 0.5, friction: 0.3))],
    walls: [
        Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 1.0, 0.0), material: "glass"),
        Plane(name: "lid", point: (0.0, 0.012, 0.0), normal: (0.0, -1.0, 0.0), material: "glass"),
    ],
    grains: [Random(material: "glass", region: (min: (0.001, 0.0, 0.0), max: (0.019, 0.012, 0.0)),
        count: 60, radius: Uniform(min: 0.0007, max: 0.0009), seed: 4, velocity_spread: 0.2)],
    {sampling}
    output: (recording: false),
)"#
    )
}

/// Σ over the nodes of `value` × cell volume.
fn integral(f: &FieldSample, value: impl Fn(usize) -> f64) -> f64 {
    (0..f.node_count()).map(value).sum::<f64>() * f.cell_volume
}

/// (total mass, total momentum, Σ m |v|) of the grains.
fn totals(sim: &mut Simulation) -> (f64, DVec3, f64) {
    common::grains(sim)
        .iter()
        .fold((0.0, DVec3::ZERO, 0.0), |(m, p, s), g| {
            (
                m + g.mass,
                p + g.mass * g.velocity,
                s + g.mass * g.velocity.length(),
            )
        })
}

/// Checks that the density integrates to the mass and the momentum density to the
/// momentum of the grains; returns the largest relative errors (mass, momentum).
fn check_conservation(sim: &mut Simulation) -> (f64, f64) {
    let f = field(sim);
    let (mass, momentum, scale) = totals(sim);
    let mass_error = (integral(&f, |n| f.density[n]) / mass - 1.0).abs();
    let momentum_error = (0..3)
        .map(|d| (integral(&f, |n| f.momentum[n][d]) - momentum[d]).abs() / scale)
        .fold(0.0, f64::max);
    assert!(mass_error < 1e-6, "density integral off by {mass_error:e}");
    assert!(
        momentum_error < 1e-6,
        "momentum integral off by {momentum_error:e} of Σ m|v|"
    );
    (mass_error, momentum_error)
}

/// Grains within `reach` of a periodic face along `axis` (0 … L).
fn grains_near(sim: &mut Simulation, axis: usize, lo: f64, hi: f64, reach: f64) -> usize {
    common::grains(sim)
        .iter()
        .filter(|g| g.position[axis] - lo < reach || hi - g.position[axis] < reach)
        .count()
}

#[test]
fn density_and_momentum_integrate_to_the_totals_at_seams_and_walls() {
    // 3-D, periodic along x and y, floor and lid along z; 4 × 4 × 3 cells (5 mm × 5 mm
    // × 4 mm) and a width of 1.5 mm, so that the kernel of a grain near a seam or a wall
    // reaches past it.
    let sampling =
        "sampling: (interval: 2e-4, domain: false, fields: (cells: (4, 4, 3), width: 0.0015)),";
    let (mut sim, _) = common::build(&walled_gas(sampling));
    sim.prime().unwrap();
    let mut worst = (0.0f64, 0.0f64);
    let mut near_seams = 0;
    let mut near_walls = 0;
    for _ in 0..10 {
        let (m, p) = check_conservation(&mut sim);
        worst = (worst.0.max(m), worst.1.max(p));
        near_seams += grains_near(&mut sim, 0, 0.0, CUBE, 0.0045);
        near_walls += grains_near(&mut sim, 2, 0.0, 0.012, 0.0045);
        let every = sim
            .world
            .resource::<talus_stress::FieldSettings>()
            .spec
            .every;
        sim.run_steps(every).unwrap();
    }
    assert!(
        near_seams > 100 && near_walls > 100,
        "{near_seams}, {near_walls}"
    );
    println!("3-D: mass {:e}, momentum {:e}", worst.0, worst.1);

    // 2-D: disks periodic along x, walls along y; 5 × 3 × 1 cells.
    let sampling =
        "sampling: (interval: 2e-4, domain: false, fields: (cells: (5, 3, 1), width: 0.0015)),";
    let (mut sim, _) = common::build(&walled_disks(sampling));
    sim.prime().unwrap();
    for _ in 0..10 {
        let (m, p) = check_conservation(&mut sim);
        worst = (worst.0.max(m), worst.1.max(p));
        let every = sim
            .world
            .resource::<talus_stress::FieldSettings>()
            .spec
            .every;
        sim.run_steps(every).unwrap();
    }
    let f = field(&sim);
    assert_eq!(f.cells, [5, 3, 1]);
    assert_eq!(f.min[2], -0.5);
    println!("with 2-D: mass {:e}, momentum {:e}", worst.0, worst.1);
}

#[test]
fn the_density_of_a_lone_grain_is_the_sampled_gaussian() {
    // One grain in a wall-less periodic box, 0.9 mm below the z seam, a grid of 40³ nodes
    // (h = 0.5 mm) and a width w = 1 mm. Reference: the continuous Gaussian
    // φ(d) = exp(−d²/2w²) / ((2π)^{3/2} w³) cut at 3 w along each axis, divided by its
    // mass erf(3/√2)³. The kernel is normalised over the nodes instead, a sum that differs
    // from the integral by at most about g(3w) h per axis (the nodes next to the cut;
    // sampling errors of a Gaussian at h = w/2 are below e^{−2π²·4}):
    // 3 × e^{−9/2} × h / (√(2π) w erf(3/√2)) = 6.7e-3 in all.
    let scene = r#"Scene(
    name: "lone",
    gravity: (0.0, 0.0, 0.0),
    steps: 1,
    periodic: (x: (0.0, 0.02), y: (0.0, 0.02), z: (0.0, 0.02)),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 200.0, restitution: 0.8))],
    grains: [List(material: "glass", grains: [
        (position: (0.0103, 0.0097, 0.0191), radius: 0.001, velocity: (0.1, -0.2, 0.3))])],
    sampling: (domain: false, fields: (cells: (40, 40, 40), width: 0.001)),
    output: (recording: false),
)"#;
    let (mut sim, _) = common::build(scene);
    sim.prime().unwrap();
    let f = field(&sim);
    let g = common::grains(&mut sim)[0];
    let w = 0.001;
    const ERF_3_OVER_SQRT2: f64 = 0.997_300_203_936_739_8;
    let truncated = ERF_3_OVER_SQRT2.powi(3);
    let mut checked = 0;
    let mut worst = 0.0f64;
    for n in 0..f.node_count() {
        // Nearest image: the grain sits 0.9 mm below the z seam.
        let mut d = f.node_position(n) - g.position;
        for a in 0..3 {
            d[a] -= 0.02 * (d[a] / 0.02).round();
        }
        let inside = d.abs().max_element() <= 3.0 * w;
        if !inside {
            assert_eq!(f.density[n], 0.0);
            continue;
        }
        let gauss = (-0.5 * d.length_squared() / (w * w)).exp()
            / ((2.0 * std::f64::consts::PI).powf(1.5) * w.powi(3));
        let expected = g.mass * gauss / truncated;
        worst = worst.max((f.density[n] / expected - 1.0).abs());
        // The velocity field is the grain's velocity wherever it has mass.
        assert!((DVec3::from(f.velocity[n]) - g.velocity).length() < 1e-12);
        // A lone grain has no velocity fluctuation about the field.
        assert!(f.kinetic_stress[n].norm() <= 1e-20 * f.density[n]);
        checked += 1;
    }
    println!("lone grain: {checked} nodes, largest relative difference {worst:e}");
    assert!(checked > 1000);
    let bound =
        3.0 * (-4.5f64).exp() * 0.5 / ((2.0 * std::f64::consts::PI).sqrt() * ERF_3_OVER_SQRT2);
    assert!(worst < bound, "{worst:e} above {bound:e}");
}

/// Σ f ⊗ l over the contacts, computed here: l from the centre of `a` to the nearest
/// image of `b` (to the contact point for a wall); and the number of grain–grain contacts
/// whose centres lie on opposite sides of a seam along x.
fn love_weber_sum(sim: &mut Simulation) -> (Tensor, usize) {
    let mut q = sim
        .world
        .query::<(&Contact, &ContactGeometry, &ContactForce)>();
    let contacts: Vec<(Contact, ContactGeometry, ContactForce)> =
        q.iter(&sim.world).map(|(c, g, f)| (*c, *g, *f)).collect();
    let mut sum = Tensor::ZERO;
    let mut across = 0;
    for (c, g, f) in contacts {
        let xa = sim.world.get::<Position>(c.a).unwrap().0;
        let branch = match c.kind {
            ContactKind::GrainGrain => {
                let xb = sim.world.get::<Position>(c.b).unwrap().0;
                let mut l = xb - xa;
                for a in 0..3 {
                    l[a] -= CUBE * (l[a] / CUBE).round();
                }
                if (xb.x - xa.x).abs() > 0.5 * CUBE && f.force != DVec3::ZERO {
                    across += 1;
                }
                l
            }
            // From the centre to the middle of the overlap.
            ContactKind::GrainWall => {
                let ra = sim.world.get::<Radius>(c.a).unwrap().0;
                -g.normal * (ra - 0.5 * g.overlap)
            }
        };
        sum.add_outer(f.force, branch, 1.0);
    }
    (sum, across)
}

#[test]
fn slabs_tiling_a_periodic_box_add_up_to_the_domain_stress() {
    // Four slabs tiling the box along x, and a slab across the seam [−L/8, L/8) with the
    // two slabs it is made of, [0, L/8) and [7L/8, L): with the contacts through the
    // seam, each region must see the part of their branch inside it or inside its images.
    let q = CUBE / 8.0;
    let slabs = [
        ("s0", 0.0, 2.0 * q),
        ("s1", 2.0 * q, 4.0 * q),
        ("s2", 4.0 * q, 6.0 * q),
        ("s3", 6.0 * q, 8.0 * q),
        ("seam", -q, q),
        ("seam_low", 7.0 * q, 8.0 * q),
        ("seam_high", 0.0, q),
        // The seam slab given one period up: the same region.
        ("seam_shifted", CUBE - q, CUBE + q),
    ];
    let list: String = slabs
        .iter()
        .map(|(name, lo, hi)| {
            format!("Slab(name: \"{name}\", axis: \"x\", min: {lo:e}, max: {hi:e}),")
        })
        .collect();
    let sampling = format!("sampling: (interval: 2e-4, regions: [{list}]),");
    let (mut sim, _) = common::build(&periodic_gas(&sampling));
    sim.prime().unwrap();
    let every = sim.world.resource::<talus_stress::StressSettings>().every;
    // Let the gas spread through the seams (it was placed a radius away from them).
    sim.run_steps(10 * every).unwrap();
    let mut across_total = 0;
    let mut worst_tiling = 0.0f64;
    let mut worst_seam = 0.0f64;
    let mut worst_reference = 0.0f64;
    for _ in 0..8 {
        sim.run_steps(every).unwrap();
        let (reference, across) = love_weber_sum(&mut sim);
        across_total += across;
        println!(
            "step {} (dt {:e}): {} contacts, {across} through the x seam",
            sim.step_count(),
            sim.config().dt,
            common::energies(&sim).0.contacts
        );
        let all = regions(&sim);
        assert_eq!(
            sim.world
                .resource::<StressRecord>()
                .latest
                .as_ref()
                .unwrap()
                .step,
            sim.step_count()
        );
        let moment = |name: &str| {
            let r = region(&all, name);
            r.contact_stress.scaled(r.volume)
        };
        let domain = moment("domain");
        let scale = reference.norm();
        worst_reference = worst_reference.max(domain.minus(reference).norm() / scale);
        let tiled = ["s0", "s1", "s2", "s3"]
            .iter()
            .fold(Tensor::ZERO, |t, n| t.plus(moment(n)));
        worst_tiling = worst_tiling.max(tiled.minus(domain).norm() / scale);
        let parts = moment("seam_low").plus(moment("seam_high"));
        worst_seam = worst_seam
            .max(moment("seam").minus(parts).norm() / scale)
            .max(moment("seam_shifted").minus(parts).norm() / scale);
        // Volumes: a slab across the seam is a quarter of the box wherever it is given.
        for name in ["seam", "seam_shifted", "s0"] {
            let v = region(&all, name).volume;
            assert!(
                (v / (0.25 * CUBE.powi(3)) - 1.0).abs() < 1e-12,
                "{name}: {v}"
            );
        }
        // Each grain counts once in the tiling, and the seam slab holds its two parts'.
        let grains = |n: &str| region(&all, n).grains;
        assert_eq!(
            grains("s0") + grains("s1") + grains("s2") + grains("s3"),
            800
        );
        assert_eq!(grains("seam"), grains("seam_low") + grains("seam_high"));
        assert_eq!(grains("seam"), grains("seam_shifted"));
    }
    println!(
        "contacts through the x seam over the samples: {across_total}; domain vs Σ f⊗l {worst_reference:e}; tiling {worst_tiling:e}; seam slab {worst_seam:e}"
    );
    assert!(across_total >= 3, "too few contacts through the seam");
    assert!(worst_reference < 1e-12);
    assert!(worst_tiling < 1e-10);
    assert!(worst_seam < 1e-10);
}

#[test]
fn coarse_grained_stress_averages_to_the_love_weber_stress() {
    // The dense periodic gas on a 10³ grid (2 mm cells), width 1 mm: the mean over the
    // nodes of the contact-stress field is (1/V) Σ f ⊗ l (computed here from the
    // contacts), since each quadrature point of each branch puts a kernel of unit
    // integral on the grid. Its kinetic field, averaged, is the domain's kinetic stress
    // less the part of the fluctuations that the local mean velocity absorbs: checked
    // only to lie between 0 and it (in trace).
    let sampling = "sampling: (interval: 1e-4, fields: (cells: (10, 10, 10), width: 0.001)),";
    let (mut sim, _) = common::build(&periodic_gas(sampling));
    sim.prime().unwrap();
    let every = sim
        .world
        .resource::<talus_stress::FieldSettings>()
        .spec
        .every;
    // Let the gas spread through the seams (it was placed a radius away from them).
    sim.run_steps(24 * every).unwrap();
    let volume = CUBE.powi(3);
    let mut worst = 0.0f64;
    let mut worst_domain = 0.0f64;
    let mut across_total = 0;
    for _ in 0..6 {
        sim.run_steps(every).unwrap();
        let (reference, across) = love_weber_sum(&mut sim);
        across_total += across;
        let f = field(&sim);
        assert_eq!(f.step, sim.step_count());
        let mean = (0..f.node_count())
            .fold(Tensor::ZERO, |t, n| t.plus(f.contact_stress[n]))
            .scaled(f.cell_volume / volume);
        let expected = reference.scaled(1.0 / volume);
        worst = worst.max(mean.minus(expected).norm() / expected.norm());
        let all = regions(&sim);
        let domain = region(&all, "domain");
        worst_domain = worst_domain.max(mean.minus(domain.contact_stress).norm() / expected.norm());
        let kinetic_mean = (0..f.node_count())
            .map(|n| f.kinetic_stress[n].trace(3))
            .sum::<f64>()
            * f.cell_volume
            / volume;
        let kinetic_domain = domain.kinetic_stress.trace(3);
        assert!(kinetic_mean <= 0.0 && kinetic_mean >= kinetic_domain);
        println!(
            "step {}: {across} contacts through the x seam, p_contact = {:.4e} Pa",
            sim.step_count(),
            -expected.trace(3) / 3.0
        );
        assert!(expected.norm() > 0.0);
    }
    println!("mean field vs Σ f⊗l / V: {worst:e}; vs the domain sample: {worst_domain:e}");
    assert!(across_total > 0, "no contact through the seam");
    assert!(worst < 1e-12);
    assert!(worst_domain < 1e-12);
}

#[test]
fn fields_are_computed_only_when_the_scene_asks() {
    let plan_of = |text: &str| {
        let scene = talus::scene::parse("plan.ron", text).unwrap();
        let built = scene.build(&talus::registry()).unwrap();
        built.builder.plan().clone()
    };
    let sample_stage = |plan: &talus::core::schedule::Plan| {
        plan.stages
            .iter()
            .find(|(s, _)| *s == Stage::Sample)
            .unwrap()
            .1
            .clone()
    };
    let without = plan_of(&periodic_gas("sampling: (),"));
    assert!(
        !sample_stage(&without)
            .iter()
            .any(|s| s == talus_stress::FIELD_SYSTEM_NAME)
    );
    let (sim, _) = common::build(&periodic_gas("sampling: (),"));
    assert!(sim.world.get_resource::<FieldRecord>().is_none());

    let only = plan_of(&periodic_gas(
        "sampling: (domain: false, fields: (cells: (2, 2, 2), width: 0.002)),",
    ));
    assert_eq!(
        sample_stage(&only),
        ["health_check", talus_stress::FIELD_SYSTEM_NAME]
    );
    assert!(
        only.notes
            .iter()
            .any(|n| n.starts_with("coarse-grained fields every"))
    );
    let both = plan_of(&periodic_gas(
        "sampling: (fields: (cells: (2, 2, 2), width: 0.002)),",
    ));
    assert_eq!(
        sample_stage(&both),
        [
            "health_check",
            talus_stress::SYSTEM_NAME,
            talus_stress::FIELD_SYSTEM_NAME
        ]
    );
}

#[test]
fn bad_field_input_is_a_located_scene_error() {
    // (scene, field in the error, text at the error position, expected words)
    let cases = [
        (
            periodic_gas("sampling: (fields: (cells: (4, 0, 4), width: 0.001)),"),
            "sampling.fields.cells",
            "(4, 0, 4)",
            "at least one cell",
        ),
        (
            walled_disks("sampling: (fields: (cells: (4, 4, 4), width: 0.001)),"),
            "sampling.fields.cells",
            "(4, 4, 4)",
            "one cell along z in a 2-D scene",
        ),
        (
            periodic_gas("sampling: (fields: (cells: (200, 200, 200), width: 0.001)),"),
            "sampling.fields.cells",
            "(200, 200, 200)",
            "at most 2000000 cells",
        ),
        (
            periodic_gas("sampling: (fields: (cells: (4, 4, 4), width: -0.001)),"),
            "sampling.fields.width",
            "-0.001",
            "a positive kernel width",
        ),
        (
            periodic_gas("sampling: (fields: (cells: (4, 4, 4), width: 0.004)),"),
            "sampling.fields.width",
            "0.004",
            "at most half the periodic length along x",
        ),
        (
            periodic_gas("sampling: (fields: (cells: (4, 4, 4), width: 0.001, interval: 0.0)),"),
            "sampling.fields.interval",
            "0.0",
            "a positive interval",
        ),
        (
            periodic_gas("sampling: (fields: (widht: 0.001, cells: (4, 4, 4))),"),
            "sampling.fields.widht",
            "widht",
            "one of the fields",
        ),
    ];
    for (text, field, at, words) in cases {
        let result = talus::scene::parse("bad.ron", &text)
            .and_then(|s| s.build(&talus::registry()).map(|_| ()));
        let e = result.expect_err(field);
        println!("{e}");
        assert_eq!(e.field, field, "{at}");
        assert!(e.expected.contains(words), "{at}: {}", e.expected);
        let line = text.lines().nth(e.line - 1).expect("line in the text");
        let rest: String = line.chars().skip(e.column - 1).collect();
        assert!(
            rest.starts_with(at),
            "{field}: {}:{} is at `{rest}`",
            e.line,
            e.column
        );
    }
}

#[test]
fn report_and_recording_carry_the_fields() {
    let dir = common::temp_dir("fields-report");
    let text = walled_gas(
        "sampling: (interval: 2e-4, fields: (cells: (4, 4, 3), width: 0.0015, interval: 4e-4)),",
    )
    .replace("steps: 1,", "steps: 60,")
    .replace(
        "output: (recording: false),",
        "output: (report_interval: 2e-4, recording_interval: 1e-3),",
    )
    .replace(
        "    name: \"walled-gas\",",
        "    name: \"walled-gas\",\n    time_step: 2e-5,",
    );
    let path = dir.join("fields.ron");
    std::fs::write(&path, &text).unwrap();
    let options = talus::cli::RunOptions {
        out: Some(dir.join("out")),
        quiet: true,
        progress: false,
        ..Default::default()
    };
    let summary = talus::cli::run_scene(&path, &talus::registry(), &options).unwrap();
    let written: FieldSample =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/fields.json")).unwrap())
            .unwrap();
    // The last field sample: steps 0, 20, 40, 60.
    assert_eq!(written.step, 60);
    assert_eq!(written.density.len(), 48);
    assert_eq!(written.contact_stress.len(), 48);
    let mass: f64 = {
        let scene = talus::scene::parse("fields.ron", &text).unwrap();
        let built = scene.build(&talus::registry()).unwrap();
        let mut sim = built.builder.build();
        common::grains(&mut sim).iter().map(|g| g.mass).sum()
    };
    let integral = written.density.iter().sum::<f64>() * written.cell_volume;
    assert!((integral / mass - 1.0).abs() < 1e-6);

    let entities =
        talus::rerun_export::read_entities(summary.recording.expect("recording")).unwrap();
    for path in ["/fields/density", "/fields/pressure"] {
        let e = entities
            .iter()
            .find(|e| e.path == path)
            .unwrap_or_else(|| panic!("{path}"));
        assert_eq!(e.temporal_rows, 4, "{path}");
    }
    // A scene without fields writes no fields.json.
    let plain = text.replace(
        ", fields: (cells: (4, 4, 3), width: 0.0015, interval: 4e-4)",
        "",
    );
    std::fs::write(&path, &plain).unwrap();
    let options = talus::cli::RunOptions {
        out: Some(dir.join("plain")),
        quiet: true,
        progress: false,
        ..Default::default()
    };
    talus::cli::run_scene(&path, &talus::registry(), &options).unwrap();
    assert!(!dir.join("plain/fields.json").exists());
    assert!(dir.join("plain/report.json").exists());
}
