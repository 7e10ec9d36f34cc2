//! Lees–Edwards (sheared periodic) boundaries: a collision through the sheared seam is
//! the collision of the same pair in the middle of a plain periodic box with the image
//! velocity added; a grain crossing the seam keeps its peculiar velocity and follows the
//! sliding-brick geometry; the peculiar momentum of a sheared gas follows its exact law;
//! a frictional packing sheared from rest develops the linear mean velocity profile; and
//! the stress ratio μ = τ/p of dense simple shear rises with the inertial number I.

mod common;

use glam::DVec3;

/// Two glass spheres of radius 1 cm in a box periodic in x and z over [0, 0.2), with the
/// given centres and velocities, and `shear` inserted into the `periodic` field.
fn pair_scene(a: DVec3, va: DVec3, b: DVec3, vb: DVec3, shear: &str) -> String {
    format!(
        r#"Scene(
    name: "le-pair",
    duration: 0.006,
    steps_per_collision: 2000,
    periodic: (x: (0.0, 0.2), z: (0.0, 0.2){shear}),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.7, friction: 0.3))],
    grains: [List(material: "glass", grains: [
        (position: ({:e}, {:e}, {:e}), radius: 0.01, velocity: ({:e}, {:e}, {:e})),
        (position: ({:e}, {:e}, {:e}), radius: 0.01, velocity: ({:e}, {:e}, {:e})),
    ])],
    output: (recording: false),
)"#,
        a.x, a.y, a.z, va.x, va.y, va.z, b.x, b.y, b.z, vb.x, vb.y, vb.z
    )
}

/// Runs a scene to its end; returns the final grains and the number of steps with a contact.
fn run_counting_contacts(text: &str) -> (Vec<common::GrainState>, usize) {
    let (mut sim, steps) = common::build(text);
    let mut contact_steps = 0;
    for _ in 0..steps {
        sim.step().unwrap();
        contact_steps += common::energies(&sim).0.contacts;
    }
    (common::grains(&mut sim), contact_steps)
}

#[test]
fn a_collision_through_the_sheared_seam_is_the_collision_with_the_image_velocity() {
    // γ̇ = 10 /s over L_z = 0.2 m: the image one box up slides along x at 2 m/s, twice
    // the approach speed, so the collision is strongly oblique and friction acts.
    let rate = 10.0;
    let image_speed = rate * 0.2;
    let shear = format!(
        ", shear: (rate: {rate:e}, flow: \"x\", gradient: \"z\", start_on_profile: false)"
    );
    let va = DVec3::new(0.0, 0.0, 0.5);
    let vb = DVec3::new(0.0, 0.0, -0.5);
    // Through the seam: a near the top face moving up meets b near the bottom face (its
    // image at z = 0.2105, x shifted by Δ(0) = 0) moving down.
    let seam = pair_scene(
        DVec3::new(0.1, 0.0, 0.1895),
        va,
        DVec3::new(0.09, 0.0, 0.0105),
        vb,
        &shear,
    );
    // The reference: the same pair in the middle of a plain periodic box, b carrying its
    // image's velocity.
    let middle = pair_scene(
        DVec3::new(0.1, 0.0, 0.0895),
        va,
        DVec3::new(0.09, 0.0, 0.1105),
        vb + DVec3::new(image_speed, 0.0, 0.0),
        "",
    );
    let (seam_grains, seam_steps) = run_counting_contacts(&seam);
    let (middle_grains, middle_steps) = run_counting_contacts(&middle);
    assert!(middle_steps > 100, "the grains collided in the middle");
    assert_eq!(seam_steps, middle_steps, "same contact duration");
    let (sa, sb) = (&seam_grains[0], &seam_grains[1]);
    let (ma, mb) = (&middle_grains[0], &middle_grains[1]);
    let tolerance = 1e-9;
    assert!(
        (sa.velocity - ma.velocity).length() < tolerance,
        "{:?} vs {:?}",
        sa.velocity,
        ma.velocity
    );
    let sb_image = sb.velocity + DVec3::new(image_speed, 0.0, 0.0);
    assert!(
        (sb_image - mb.velocity).length() < tolerance,
        "{sb_image:?} vs {:?}",
        mb.velocity
    );
    assert!((sa.omega - ma.omega).length() < 1e-7 && (sb.omega - mb.omega).length() < 1e-7);
    // Friction acted: the tangential impulse turned the grains.
    assert!(ma.omega.length() > 1.0, "spin {:?}", ma.omega);
    // a is still above mid-box in both runs, 0.1 m apart along z, and level along x.
    assert!((sa.position.z - ma.position.z - 0.1).abs() < 1e-12);
    assert!((sa.position.x - ma.position.x).abs() < 1e-12);
    // Momentum of the pair, b counted at its image's velocity, is that of the middle run.
    let p_seam = sa.mass * sa.velocity + sb.mass * sb_image;
    let p_middle = ma.mass * ma.velocity + mb.mass * mb.velocity;
    assert!((p_seam - p_middle).length() < 1e-12);
    // The collision was a real one: the normal impulse reversed the approach.
    assert!(ma.velocity.z < 0.0 && mb.velocity.z > 0.0);
}

/// One grain alone in a sheared box, crossing the top face of the gradient axis.
#[test]
fn a_grain_crossing_the_seam_keeps_its_peculiar_velocity_and_slides_with_the_images() {
    let rate = 25.0;
    let (lx, ly) = (0.1, 0.08);
    let scene = format!(
        r#"Scene(
    name: "le-crossing",
    dimension: 2,
    steps: 3000,
    time_step: 1e-4,
    periodic: (x: (0.0, {lx:e}), y: (0.0, {ly:e}),
        shear: (rate: {rate:e}, flow: "x", gradient: "y")),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 0.7, friction: 0.3))],
    grains: [List(material: "glass", grains: [
        (position: (0.02, 0.07, 0.0), radius: 0.005, velocity: (0.03, 0.6, 0.0)),
    ])],
    output: (recording: false),
)"#
    );
    let (mut sim, steps) = common::build(&scene);
    let start = common::grains(&mut sim)[0];
    // Started on the profile: u = γ̇ (y − L_y/2) = 25 × 0.03 = 0.75 m/s added along x.
    let u0 = rate * (start.position.y - 0.5 * ly);
    assert!((start.velocity.x - (0.03 + u0)).abs() < 1e-12);
    let peculiar = DVec3::new(0.03, 0.6, 0.0);
    let mut crossings = 0;
    let mut previous_y = start.position.y;
    for step in 1..=steps {
        sim.step().unwrap();
        let g = common::grains(&mut sim)[0];
        if g.position.y < previous_y {
            crossings += 1;
        }
        let t = step as f64 * 1e-4;
        previous_y = g.position.y;
        // No force acts: the velocity is constant but for the jump −γ̇ L_y at each
        // crossing, which keeps the peculiar velocity v − γ̇ (y − L_y/2) e_x continuous:
        // it changes only as the grain moves up the profile, v′_x = v′_x0 − γ̇ v_y t.
        let jump = DVec3::new(crossings as f64 * rate * ly, 0.0, 0.0);
        assert!(
            (g.velocity - (start.velocity - jump)).length() < 1e-12,
            "step {step}: velocity {:?}",
            g.velocity
        );
        let u = rate * (g.position.y - 0.5 * ly);
        let expected = peculiar - DVec3::new(rate * peculiar.y * t, 0.0, 0.0);
        assert!(
            (g.velocity - DVec3::new(u, 0.0, 0.0) - expected).length() < 1e-12,
            "step {step}: peculiar velocity {:?}",
            g.velocity - DVec3::new(u, 0.0, 0.0)
        );
        // Unwrapped: y = y0 + v_y t, and x = x0 + v_x0 t − (crossings) Δ(t): each
        // crossing of the top face puts the grain on the image one box down, which is
        // shifted back by Δ and slides at −γ̇ L_y.
        let y = start.position.y + 0.6 * t - crossings as f64 * ly;
        let x = start.position.x + start.velocity.x * t - crossings as f64 * rate * ly * t;
        let wrap = |d: f64, l: f64| d - l * (d / l).round();
        assert!(wrap(g.position.x - x, lx).abs() < 1e-12, "step {step}: x");
        assert!((g.position.y - y).abs() < 1e-12, "step {step}: y");
    }
    assert_eq!(crossings, 3, "0.3 s at 0.6 m/s from y = 0.07 crosses the face at unwrapped y = 0.08, 0.16, 0.24");
}

/// A frictional gas sheared between images: Σ m v_g is conserved, and the flow component
/// of the peculiar momentum Σ m (v − γ̇ (x_g − c_g) e_f) changes exactly as −γ̇ P_g t.
#[test]
fn the_peculiar_momentum_of_a_sheared_gas_follows_its_exact_law() {
    let rate = 20.0;
    let scene = format!(
        r#"Scene(
    name: "le-gas",
    steps: 6000,
    periodic: (x: (0.0, 0.02), y: (0.0, 0.02), z: (0.0, 0.02),
        shear: (rate: {rate:e}, flow: "x", gradient: "z")),
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e3, restitution: 0.6, friction: 0.4))],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.02)),
        count: 200, radius: Uniform(min: 0.0008, max: 0.001), seed: 5, velocity_spread: 0.5)],
    output: (recording: false),
)"#
    );
    let (mut sim, steps) = common::build(&scene);
    let dt = sim.config().dt;
    let peculiar_momentum = |sim: &mut talus::core::schedule::Simulation| {
        common::grains(sim).iter().fold(DVec3::ZERO, |acc, g| {
            acc + g.mass * (g.velocity - DVec3::new(rate * (g.position.z - 0.01), 0.0, 0.0))
        })
    };
    let scale: f64 = common::grains(&mut sim)
        .iter()
        .map(|g| g.mass * g.velocity.length())
        .sum();
    let p0 = peculiar_momentum(&mut sim);
    let mut crossings = 0;
    let mut previous: Vec<f64> = common::grains(&mut sim)
        .iter()
        .map(|g| g.position.z)
        .collect();
    for _ in 0..steps {
        sim.step().unwrap();
        let now: Vec<f64> = common::grains(&mut sim)
            .iter()
            .map(|g| g.position.z)
            .collect();
        crossings += now
            .iter()
            .zip(&previous)
            .filter(|(a, b)| (**a - **b).abs() > 0.01)
            .count();
        previous = now;
    }
    let p1 = peculiar_momentum(&mut sim);
    let t = steps as f64 * dt;
    let expected = p0 - DVec3::new(rate * p0.z * t, 0.0, 0.0);
    let error = (p1 - expected).length() / scale;
    eprintln!(
        "sheared gas: {crossings} seam crossings, P'(0) = {p0:?}, P'(t) = {p1:?}, error {error:.2e}"
    );
    assert!(crossings > 10, "grains crossed the gradient seam");
    assert!(error < 1e-11, "peculiar momentum error {error:e}");
}
