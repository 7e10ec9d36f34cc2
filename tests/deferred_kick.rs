//! A step followed by another may leave its second velocity kick to the next step's first
//! kick (`DeferredKick`), and the grains' motion in the snapshot: free fall stays exact, the
//! state after any run is the one step-by-step integration gives to the bit, nothing
//! between two steps ever sees a half-kicked grain, no system that reads the grains'
//! motion ever finds it stale, and a non-finite velocity is still caught. The frozen grains'
//! force totals, left unsummed between unobserved steps, come back to the bit.

use crate::common;

use bevy_ecs::prelude::*;
use glam::DVec3;
use talus::core::prelude::*;
use talus::core::resources::{DeferredKick, FrozenTotals};
use talus::core::schedule::{Simulation, Stage};

/// One grain thrown up and sideways with a spin, no wall, no partner: nothing but gravity.
const FREE_FALL: &str = r#"Scene(
    name: "free-fall",
    gravity: (0.0, 0.0, -9.81),
    steps: 500,
    time_step: 1e-3,
    force_time_step: true,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e5, restitution: 0.5, friction: 0.5))],
    grains: [List(material: "glass", grains: [
        (position: (0.0, 0.0, 1.0), radius: 0.001, velocity: (0.3, -0.2, 2.5)),
    ])],
    output: (recording: false),
)"#;

/// Every grain's position, velocity and spin, as bits.
fn state_bits(sim: &mut Simulation) -> Vec<u64> {
    common::grains(sim)
        .iter()
        .flat_map(|g| [g.position, g.velocity, g.omega])
        .flat_map(|v| v.to_array().map(f64::to_bits))
        .collect()
}

/// Whether the coming steps sum the kinetic energies (only steps that do not may defer).
fn energies_due(sim: &mut Simulation, due: bool) {
    sim.world
        .resource_mut::<talus::core::resources::KineticEnergyDue>()
        .0 = due;
}

fn pending(sim: &Simulation) -> bool {
    let d = sim.world.resource::<DeferredKick>();
    d.translation.is_some() || d.rotation.is_some()
}

/// Velocity Verlet integrates a constant acceleration exactly: x = x0 + v0 t + g t²/2 and
/// v = v0 + g t after any number of steps, whether each step's second kick is applied at
/// its end or folded into the next step's first kick.
#[test]
fn free_fall_is_exact_through_deferred_kicks() {
    let (mut sim, steps) = common::build(FREE_FALL);
    sim.prime().unwrap();
    let start = common::grains(&mut sim)[0];
    // A step followed by another, whose kinetic energies are not asked for, leaves its kick
    // pending: the plan has nothing that reads the grains between steps.
    energies_due(&mut sim, false);
    sim.step_before_another().unwrap();
    assert!(pending(&sim), "the free fall's plan allows deferring");
    energies_due(&mut sim, true);
    sim.run_steps(steps - 1).unwrap();
    assert!(
        !pending(&sim),
        "run_steps ends with the last step's own kick"
    );
    let end = common::grains(&mut sim)[0];
    let g = DVec3::new(0.0, 0.0, -9.81);
    let t = steps as f64 * 1e-3;
    let x = start.position + start.velocity * t + 0.5 * g * t * t;
    let v = start.velocity + g * t;
    assert!(
        (end.position - x).length() < 1e-12 * x.length(),
        "{} against {x}",
        end.position
    );
    assert!(
        (end.velocity - v).length() < 1e-12 * v.length(),
        "{} against {v}",
        end.velocity
    );
}

/// Every grain's position, velocity and spin after a run of deferred steps, or after a
/// deferred step and `synchronize`, are those of the same steps taken one by one with
/// their own kicks, to the bit: frictional grains in a box, with walls, spins and
/// contacts made and ended.
#[test]
fn deferred_kicks_leave_the_step_by_step_state_to_the_bit() {
    let text = common::settling_box_scene("deferred", 15000);
    let (mut stepwise, steps) = common::build(&text);
    for _ in 0..steps {
        stepwise.step().unwrap();
    }
    let (mut batched, _) = common::build(&text);
    batched.run_steps(steps).unwrap();
    let (mut synchronized, _) = common::build(&text);
    for _ in 0..steps {
        synchronized.step_before_another().unwrap();
    }
    // The box's steps leave their kicks pending only when the kinetic energies are not
    // due (the default is due every step): this one ran every kick itself.
    assert!(!pending(&synchronized));
    let (mut deferred, _) = common::build(&text);
    energies_due(&mut deferred, false);
    assert!(deferred.may_hold_motion(), "the box's plan reads no motion");
    for _ in 0..steps {
        deferred.step_before_another().unwrap();
    }
    assert!(pending(&deferred));
    assert!(
        deferred
            .world
            .resource::<DeferredKick>()
            .snapshot_holds_motion,
        "the snapshot holds the motion between unobserved steps"
    );
    deferred.synchronize();
    assert!(!pending(&deferred));
    assert!(
        !deferred
            .world
            .resource::<DeferredKick>()
            .snapshot_holds_motion
    );

    let reference = state_bits(&mut stepwise);
    let contacts = stepwise.world.resource::<EnergySnapshot>().contacts;
    eprintln!("{contacts} contacts");
    assert!(contacts > 50, "the grains must touch: {contacts} contacts");
    assert!(
        common::grains(&mut stepwise)
            .iter()
            .any(|g| g.omega.length() > 1e-3),
        "the grains must spin"
    );
    assert_eq!(state_bits(&mut batched), reference, "run_steps");
    assert_eq!(
        state_bits(&mut synchronized),
        reference,
        "steps with kinetic energies due"
    );
    assert_eq!(
        state_bits(&mut deferred),
        reference,
        "deferred steps, then synchronize"
    );
}

/// A system that runs between two steps (here one in the sample stage that reads the
/// velocities, as a sampler or exporter does) keeps every step's second kick in its step:
/// it sees each step's end state, the same as with plain steps.
#[test]
fn a_plan_that_reads_between_steps_never_defers() {
    #[derive(Resource, Default)]
    struct Seen(Vec<u64>);
    let observer = |grains: Query<&Velocity, With<Grain>>, mut seen: ResMut<Seen>| {
        let total: DVec3 = grains.iter().map(|v| v.0).sum();
        seen.0.push(total.z.to_bits());
    };
    let build = || {
        let text = common::settling_box_scene("observed", 60);
        let scene = talus::scene::parse("observed.ron", &text).unwrap();
        let mut builder = scene.build(&talus::registry()).unwrap().builder;
        builder.world.insert_resource(Seen::default());
        builder.add_system(Stage::Sample, "observer", observer);
        builder.build()
    };
    let mut plain = build();
    let mut asked = build();
    energies_due(&mut asked, false);
    for _ in 0..60 {
        plain.step().unwrap();
        asked.step_before_another().unwrap();
        assert!(!pending(&asked));
    }
    assert_eq!(
        plain.world.resource::<Seen>().0,
        asked.world.resource::<Seen>().0
    );
}

/// A system in a stage inside the step that reads the grains' velocities (here a drag
/// force, F = −c v, in the body-force stage) finds them current: the plan never leaves the
/// motion in the snapshot, and the drag acts on the velocities of each step, so deferred
/// steps give the step-by-step state to the bit. A system that takes the whole world
/// without declaring itself motion-free also keeps the motion in the components.
#[test]
fn a_system_that_reads_the_motion_inside_the_step_always_finds_it_current() {
    let drag = |mut grains: Query<(&Velocity, &mut Force), With<Grain>>| {
        for (v, mut f) in &mut grains {
            f.0 -= 2e-4 * v.0;
        }
    };
    let build = |drag_on: bool, exclusive: bool| {
        let text = common::settling_box_scene("dragged", 3000);
        let scene = talus::scene::parse("dragged.ron", &text).unwrap();
        let mut builder = scene.build(&talus::registry()).unwrap().builder;
        if drag_on {
            builder.add_system(Stage::BodyForces, "drag", drag);
        }
        if exclusive {
            builder.add_system(Stage::NarrowPhase, "whole world", |_: &mut World| {});
        }
        builder.build()
    };
    assert!(build(false, false).may_hold_motion());
    assert!(
        !build(false, true).may_hold_motion(),
        "an undeclared exclusive system"
    );
    let mut stepwise = build(true, false);
    let mut deferred = build(true, false);
    assert!(!deferred.may_hold_motion(), "the drag reads the velocities");
    energies_due(&mut deferred, false);
    for _ in 0..3000 {
        stepwise.step().unwrap();
        deferred.step_before_another().unwrap();
        assert!(
            !deferred
                .world
                .resource::<DeferredKick>()
                .snapshot_holds_motion
        );
    }
    assert!(pending(&deferred), "the kick is still deferred");
    deferred.synchronize();
    // The drag matters: without it the grains end elsewhere.
    let mut undragged = build(false, false);
    undragged.run_steps(3000).unwrap();
    let reference = state_bits(&mut stepwise);
    assert_ne!(state_bits(&mut undragged), reference);
    assert_eq!(state_bits(&mut deferred), reference);
}

/// Every grain's force and torque totals, as bits: the frozen grains' or the others'.
fn totals_bits(sim: &mut Simulation, frozen: bool) -> Vec<u64> {
    let mut q = sim
        .world
        .query_filtered::<(&Force, &Torque, Has<Frozen>), With<Grain>>();
    q.iter(&sim.world)
        .filter(|&(.., f)| f == frozen)
        .flat_map(|(f, t, _)| [f.0, t.0])
        .flat_map(|v| v.to_array().map(f64::to_bits))
        .collect()
}

/// LAMMPS's chute benchmark as shipped (32,000 grains, 912 of them a frozen base).
fn build_chute() -> Simulation {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bench/chute.ron");
    let text = std::fs::read_to_string(&path).unwrap();
    let scene = talus::scene::parse(&path, &text).unwrap_or_else(|e| panic!("{e}"));
    scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"))
        .builder
        .build()
}

/// The frozen grains' force and torque totals, which nothing inside a step reads, are left
/// unsummed by the steps whose end nothing observes (`FrozenTotals`) and summed again by
/// `synchronize` or by the next observed step: after either, every grain's totals, frozen
/// or not, and every grain's motion are those of the same steps taken one by one, to the
/// bit. LAMMPS's chute, whose frozen base carries the flow; the reference on 1 thread,
/// the deferred runs on 2 (whose sums pick each thread's grains' sides).
#[test]
fn frozen_grains_totals_left_between_unobserved_steps_are_summed_to_the_bit() {
    const STEPS: usize = 20;
    let pool = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    };
    let (one, two) = (pool(1), pool(2));
    let mut stepwise = build_chute();
    one.install(|| {
        for _ in 0..STEPS {
            stepwise.step().unwrap();
        }
    });
    let frozen_reference = totals_bits(&mut stepwise, true);
    let moving_reference = totals_bits(&mut stepwise, false);
    assert_eq!(frozen_reference.len(), 912 * 6);
    // The base carries the flow: its totals are more than its weights.
    let mut q = stepwise
        .world
        .query_filtered::<(&Force, &Mass), (With<Grain>, With<Frozen>)>();
    let g = stepwise.config().gravity;
    let loaded = q
        .iter(&stepwise.world)
        .filter(|(f, m)| (f.0 - m.0 * g).length() > 1e-3 * m.0 * g.length())
        .count();
    assert!(loaded > 100, "only {loaded} frozen grains touch the flow");

    // Unobserved steps, then `synchronize`.
    let mut deferred = build_chute();
    assert!(
        deferred.world.resource::<FrozenTotals>().may_leave,
        "nothing in the chute's plan reads the totals"
    );
    energies_due(&mut deferred, false);
    two.install(|| {
        for _ in 0..STEPS {
            deferred.step_before_another().unwrap();
        }
    });
    assert!(deferred.world.resource::<FrozenTotals>().pending);
    assert_ne!(
        totals_bits(&mut deferred, true),
        frozen_reference,
        "left unsummed, the frozen totals are an earlier step's"
    );
    assert_eq!(totals_bits(&mut deferred, false), moving_reference);
    two.install(|| deferred.synchronize());
    assert!(!deferred.world.resource::<FrozenTotals>().pending);
    assert_eq!(totals_bits(&mut deferred, true), frozen_reference);
    assert_eq!(state_bits(&mut deferred), state_bits(&mut stepwise));

    // Unobserved steps ended by an observed one: no synchronize needed for the totals.
    let mut reported = build_chute();
    energies_due(&mut reported, false);
    two.install(|| {
        for _ in 0..STEPS - 1 {
            reported.step_before_another().unwrap();
        }
    });
    energies_due(&mut reported, true);
    two.install(|| reported.step_before_another().unwrap());
    assert!(!reported.world.resource::<FrozenTotals>().pending);
    assert_eq!(totals_bits(&mut reported, true), frozen_reference);
    assert_eq!(totals_bits(&mut reported, false), moving_reference);
}

/// A system of the plan that reads the grains' force totals, or takes the whole world
/// without declaring otherwise, keeps every step summing the frozen grains' totals.
#[test]
fn a_system_that_reads_the_totals_keeps_the_frozen_ones_summed() {
    let build = |reader: bool, exclusive: bool| {
        let text = common::settling_box_scene("totals", 10);
        let scene = talus::scene::parse("totals.ron", &text).unwrap();
        let mut builder = scene.build(&talus::registry()).unwrap().builder;
        if reader {
            builder.add_system(
                Stage::ContactForces,
                "force reader",
                |grains: Query<&Force, With<Grain>>| {
                    std::hint::black_box(grains.iter().count());
                },
            );
        }
        if exclusive {
            builder.add_system(Stage::NarrowPhase, "whole world", |_: &mut World| {});
        }
        builder.build()
    };
    let may_leave = |sim: Simulation| sim.world.resource::<FrozenTotals>().may_leave;
    assert!(may_leave(build(false, false)));
    assert!(!may_leave(build(true, false)), "a system that reads Force");
    assert!(
        !may_leave(build(false, true)),
        "an undeclared exclusive system"
    );
}

/// A velocity made non-finite while a kick is pending (here by a force set to NaN between
/// two steps) stops the next step with the health check's message, as it does without
/// deferring.
#[test]
fn a_non_finite_velocity_is_caught_through_a_pending_kick() {
    for defer in [false, true] {
        let (mut sim, _) = common::build(FREE_FALL);
        energies_due(&mut sim, !defer);
        sim.step_before_another().unwrap();
        sim.step_before_another().unwrap();
        assert_eq!(pending(&sim), defer);
        let mut forces = sim.world.query::<&mut Force>();
        for mut f in forces.iter_mut(&mut sim.world) {
            f.0.x = f64::NAN;
        }
        let blow_up = sim.step().expect_err("a NaN velocity must stop the run");
        assert_eq!(blow_up.step, 3, "deferring: {defer}");
        assert!(blow_up.reason.contains("NaN"), "{}", blow_up.reason);
        assert_eq!(blow_up.entities.len(), 1);
    }
}

/// The same when the next step also defers: its first kick works on the motion the
/// snapshot holds, and the health check finds the grain there.
#[test]
fn a_non_finite_velocity_is_caught_in_the_motion_the_snapshot_holds() {
    let (mut sim, _) = common::build(FREE_FALL);
    energies_due(&mut sim, false);
    sim.step_before_another().unwrap();
    sim.step_before_another().unwrap();
    assert!(sim.world.resource::<DeferredKick>().snapshot_holds_motion);
    let grain = sim
        .world
        .query_filtered::<Entity, With<Grain>>()
        .single(&sim.world)
        .unwrap();
    let mut forces = sim.world.query::<&mut Force>();
    for mut f in forces.iter_mut(&mut sim.world) {
        f.0.y = f64::INFINITY;
    }
    let blow_up = sim
        .step_before_another()
        .expect_err("an infinite velocity must stop the run");
    assert_eq!(blow_up.step, 3);
    assert!(
        blow_up.reason.contains("NaN or infinite"),
        "{}",
        blow_up.reason
    );
    assert_eq!(blow_up.entities, vec![grain]);
}
