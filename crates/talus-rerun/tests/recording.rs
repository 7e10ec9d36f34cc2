//! End-to-end tests of the rerun exporter: run small simulations, close the recording,
//! read it back, and compare it with the simulation's own counts.

use std::path::PathBuf;

use bevy_ecs::prelude::*;
use talus_contact::{Contact, LawDescriptor, PairAssignment, ParamValues};
use talus_core::components::*;
use talus_core::prelude::*;
use talus_rerun::{RerunExportError, RerunExportPlugin, RerunRecorder, read_counts, read_entities};

const RADIUS: f64 = 0.005;
const DENSITY: f64 = 2500.0;

/// A fresh output path for one test.
fn output(name: &str) -> PathBuf {
    let path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("talus-rerun-{name}.rrd"));
    let _ = std::fs::remove_file(&path);
    path
}

/// A builder with contacts, the linear spring law for material 0 and collision detection.
fn builder(dimension: Dimension, gravity: DVec3) -> SimBuilder {
    let mut b = SimBuilder::new(SimConfig {
        dimension,
        dt: 1e-5,
        gravity,
        integrator: Integrator::VelocityVerlet,
        rotation: true,
    });
    b.world.insert_resource(Materials(vec![Material {
        name: "glass".into(),
        density: DENSITY,
    }]));
    b.add_plugin(&talus_contact::ContactPlugin);
    let law = talus_linear_spring::LinearSpringLaw;
    let pair = PairAssignment {
        materials: (0, 0),
        names: ("glass".into(), "glass".into()),
        values: ParamValues(vec![
            ("stiffness".into(), 1e4),
            ("restitution".into(), 0.5),
            ("friction".into(), 0.3),
        ]),
        min_effective_mass: 1e-3,
        min_effective_radius: 1e-3,
        dimension,
        material_values: None,
    };
    let (typed, _time_scale) = law.resolve(&pair).expect("valid parameters");
    law.install(&mut b, &[(pair, typed)]);
    b.add_plugin(&talus_collision::CollisionPlugin::default());
    b
}

/// One grain half a metre up (along y in 2-D, z in 3-D).
fn lone_grain(dimension: Dimension) -> GrainBundle {
    let up = match dimension {
        Dimension::Two => DVec3::Y,
        Dimension::Three => DVec3::Z,
    };
    GrainBundle::new(dimension, 0.5 * up, RADIUS, DENSITY, MaterialId(0))
}

/// Contacts in the world, the vacant rows of its contact tables left out.
fn contact_count(world: &mut World) -> usize {
    world
        .query::<&Contact>()
        .iter(world)
        .filter(|c| !c.is_vacant())
        .count()
}

/// 4 × 4 × 3 grains on a slightly compressed lattice in a box whose lid moves down:
/// contacts exist at step 0 and break as the packing springs apart.
#[test]
fn recording_holds_every_grain_and_one_strip_per_contact() {
    let path = output("box");
    let mut b = builder(Dimension::Three, DVec3::new(0.0, 0.0, -9.81));
    let every = 10;
    RerunExportPlugin::new(&path, every)
        .with_recording_name("box test")
        .install(&mut b)
        .expect("recording created");
    assert!(b.plan().plugins.iter().any(|p| p == "rerun_export"));

    let spacing = 2.0 * RADIUS * 0.98;
    let first = RADIUS * 0.99;
    let (nx, ny, nz) = (4, 4, 3);
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let p = DVec3::new(
                    first + i as f64 * spacing,
                    first + j as f64 * spacing,
                    first + k as f64 * spacing,
                );
                b.world.spawn(GrainBundle::new(
                    Dimension::Three,
                    p,
                    RADIUS,
                    DENSITY,
                    MaterialId(0),
                ));
            }
        }
    }
    let n_grains = nx * ny * nz;
    let far = |n: usize| first + (n - 1) as f64 * spacing + first;
    let m = MaterialId(0);
    b.world
        .spawn(WallBundle::new("floor", DVec3::ZERO, DVec3::Z, m));
    b.world
        .spawn(WallBundle::new("x min", DVec3::ZERO, DVec3::X, m));
    b.world
        .spawn(WallBundle::new("y min", DVec3::ZERO, DVec3::Y, m));
    b.world
        .spawn(WallBundle::new("x max", DVec3::X * far(nx), -DVec3::X, m));
    b.world
        .spawn(WallBundle::new("y max", DVec3::Y * far(ny), -DVec3::Y, m));
    b.world.spawn(
        WallBundle::new("lid", DVec3::Z * (far(nz) + 0.002), -DVec3::Z, m)
            .with_velocity(DVec3::new(0.0, 0.0, -1.0)),
    );

    let mut sim = b.build();
    sim.prime().expect("no blow-up");
    let mut expected = vec![(0u64, contact_count(&mut sim.world))];
    for _ in 0..200 {
        sim.step().expect("no blow-up");
        let step = sim.step_count();
        if step.is_multiple_of(every) {
            let n = contact_count(&mut sim.world);
            assert_eq!(n, sim.world.resource::<EnergySnapshot>().contacts);
            expected.push((step, n));
        }
    }
    let frames = talus_rerun::finish(&mut sim.world).expect("recording closed");
    assert_eq!(frames, expected.len() as u64);
    assert!(!sim.world.contains_resource::<RerunRecorder>());

    let counts = read_counts(&path).expect("recording readable");
    assert_eq!(counts.len(), expected.len(), "one frame per exported step");
    for (frame, &(step, contacts)) in counts.iter().zip(&expected) {
        assert_eq!(frame.step, step);
        assert!(
            (frame.sim_time - step as f64 * 1e-5).abs() < 1e-9,
            "{frame:?}"
        );
        assert_eq!(frame.grains, n_grains, "grains at step {step}");
        assert_eq!(frame.force_chains, contacts, "strips at step {step}");
    }
    assert!(expected[0].1 > 0, "the initial packing has contacts");
    let (lo, hi) = expected
        .iter()
        .fold((usize::MAX, 0), |(lo, hi), &(_, n)| (lo.min(n), hi.max(n)));
    assert!(
        lo < hi,
        "the contact count changes during the run: {expected:?}"
    );

    let entities = read_entities(&path).expect("recording readable");
    let rows = |name: &str| {
        let e = entities.iter().find(|e| e.path == name);
        e.map(|e| (e.static_rows, e.temporal_rows))
            .unwrap_or_else(|| panic!("{name} missing from {entities:#?}"))
    };
    let n = expected.len();
    assert_eq!(rows("/"), (1, 0), "view coordinates, static");
    assert_eq!(rows("/grains"), (0, n));
    assert_eq!(rows("/contacts/force_chains"), (0, n));
    assert_eq!(rows("/walls/floor"), (1, 0), "a wall at rest is static");
    assert_eq!(
        rows("/walls/x\\ min"),
        (1, 0),
        "names are escaped, not split"
    );
    assert_eq!(
        rows("/walls/lid"),
        (0, n),
        "a moving wall is logged every frame"
    );
    for stat in [
        "translational_kinetic",
        "rotational_kinetic",
        "elastic",
        "gravity_work",
        "wall_work",
        "contacts",
        "max_overlap_ratio",
        "dissipated/normal_damping",
        "dissipated/tangential_damping",
        "dissipated/friction_slip",
    ] {
        assert_eq!(rows(&format!("/stats/{stat}")), (0, n), "{stat}");
    }
}

/// A grain falling freely: no contact, so every frame holds an empty strip batch; in
/// 2-D, to exercise the planar wall outline.
#[test]
fn frames_without_contacts_hold_no_strips() {
    let path = output("free-fall");
    let mut b = builder(Dimension::Two, DVec3::new(0.0, -9.81, 0.0));
    b.add_plugin(&RerunExportPlugin::new(&path, 25));
    b.world.spawn(lone_grain(Dimension::Two));
    b.world.spawn(WallBundle::new(
        "floor",
        DVec3::ZERO,
        DVec3::Y,
        MaterialId(0),
    ));
    let mut sim = b.build();
    sim.run_steps(100).expect("no blow-up");
    assert_eq!(contact_count(&mut sim.world), 0);
    assert_eq!(talus_rerun::finish(&mut sim.world), Ok(5));

    let counts = read_counts(&path).expect("recording readable");
    let steps: Vec<u64> = counts.iter().map(|f| f.step).collect();
    assert_eq!(steps, [0, 25, 50, 75, 100]);
    for frame in &counts {
        assert_eq!(frame.grains, 1);
        assert_eq!(frame.force_chains, 0);
    }
}

/// A file that cannot be created is an error, never a panic, whichever way the plugin
/// is added.
#[test]
fn unwritable_path_is_an_error() {
    let path = output("missing-dir").join("sub").join("run.rrd");
    let plugin = RerunExportPlugin::new(&path, 1);

    let mut b = builder(Dimension::Three, DVec3::ZERO);
    assert!(plugin.install(&mut b).is_err());
    assert!(!b.world.contains_resource::<RerunRecorder>());

    let mut b = builder(Dimension::Three, DVec3::ZERO);
    b.world.spawn(lone_grain(Dimension::Three));
    b.add_plugin(&plugin);
    assert!(b.world.contains_resource::<RerunExportError>());
    assert!(
        b.plan()
            .stages
            .iter()
            .all(|(_, systems)| !systems.iter().any(|s| s == talus_rerun::SYSTEM_NAME))
    );
    let mut sim = b.build();
    sim.run_steps(3).expect("no blow-up");
    let err = talus_rerun::finish(&mut sim.world).expect_err("the error is reported");
    assert!(err.contains("run.rrd"), "{err}");

    assert!(read_counts(&path).is_err());
}

/// Finishing a simulation without an exporter does nothing.
#[test]
fn finish_without_exporter_is_a_no_op() {
    let mut b = builder(Dimension::Three, DVec3::ZERO);
    b.world.spawn(lone_grain(Dimension::Three));
    let mut sim = b.build();
    sim.run_steps(1).expect("no blow-up");
    assert_eq!(talus_rerun::finish(&mut sim.world), Ok(0));
}
