//! The Hertz–Mindlin law against analytic references: the elastic Hertz impact (contact
//! time 2.868 (m*²/(R* E*² v))^{1/5}, largest overlap (15 m* v²/(16 E* √R*))^{2/5}),
//! the prescribed restitution at impact speeds over two decades, the rigid-body Coulomb
//! impulse of an oblique sliding impact, scene errors, and the energy bookkeeping.
//! Every reference is computed here from its formula, not from the law's own code.

use crate::common;

use talus::scene::{SceneError, parse};

/// Steel: Young's modulus, Poisson's ratio, density.
const STEEL: (f64, f64, f64) = (2e11, 0.3, 7800.0);
/// Radius of the test spheres, m.
const RADIUS: f64 = 0.01;

/// E* of two like materials, 1/E* = 2(1 − ν²)/E.
fn like_modulus(e: f64, nu: f64) -> f64 {
    e / (2.0 * (1.0 - nu * nu))
}

fn sphere_mass(density: f64, radius: f64) -> f64 {
    density * 4.0 / 3.0 * std::f64::consts::PI * radius.powi(3)
}

/// Hertz contact time at normal speed v.
fn contact_time(m: f64, r: f64, e_star: f64, v: f64) -> f64 {
    2.868 * (m * m / (r * e_star * e_star * v)).powf(0.2)
}

/// Largest overlap of an elastic Hertz impact at normal speed v.
fn max_overlap(m: f64, r: f64, e_star: f64, v: f64) -> f64 {
    (15.0 * m * v * v / (16.0 * e_star * r.sqrt())).powf(0.4)
}

/// Step that resolves the elastic head-on impact of two steel spheres at relative speed
/// `v` with `steps` steps.
fn steel_step(v: f64, steps: f64) -> f64 {
    let (e, nu, rho) = STEEL;
    contact_time(
        0.5 * sphere_mass(rho, RADIUS),
        0.5 * RADIUS,
        like_modulus(e, nu),
        v,
    ) / steps
}

/// Two steel spheres approaching head-on along x at relative speed `v`, two steps
/// apart, with a step `dt`.
fn head_on(v: f64, restitution: f64, dt: f64) -> String {
    let (e, nu, rho) = STEEL;
    let x = RADIUS + v * dt;
    format!(
        r#"Scene(
    name: "hertz-head-on",
    steps: 1000000,
    time_step: {dt:e},
    plugins: ["hertz_mindlin"],
    materials: [(name: "steel", density: {rho:e},
        contact: (law: "hertz_mindlin", youngs_modulus: {e:e}, poisson_ratio: {nu}, restitution: {restitution}))],
    grains: [List(material: "steel", grains: [
        (position: ({neg_x:e}, 0.0, 0.0), radius: {RADIUS}, velocity: ({half_v:e}, 0.0, 0.0)),
        (position: ({x:e}, 0.0, 0.0), radius: {RADIUS}, velocity: ({neg_half_v:e}, 0.0, 0.0)),
    ])],
    output: (recording: false),
)"#,
        neg_x = -x,
        half_v = 0.5 * v,
        neg_half_v = -0.5 * v,
    )
}

/// What a head-on collision measured: restitution, contact time (from the first to the
/// last instant of overlap, each found by linear interpolation between steps), largest
/// overlap.
struct Collision {
    restitution: f64,
    contact_time: f64,
    max_overlap: f64,
}

/// Runs a two-grain scene until the grains have touched and parted; measures along x.
fn collide(text: &str, dt: f64) -> Collision {
    let (mut sim, _) = common::build(text);
    let g0 = common::grains(&mut sim);
    let v_in = (g0[0].velocity - g0[1].velocity).x;
    let overlap_of = |g: &[common::GrainState]| {
        g[0].radius + g[1].radius - (g[1].position - g[0].position).length()
    };
    let mut previous = overlap_of(&g0);
    let (mut max_overlap, mut start, mut end) = (0.0f64, None, None);
    for step in 1..1_000_000u64 {
        sim.step().unwrap();
        let g = common::grains(&mut sim);
        let overlap = overlap_of(&g);
        max_overlap = max_overlap.max(overlap);
        // Instant within the step at which the overlap crossed zero.
        let crossing = (step - 1) as f64 * dt + dt * previous / (previous - overlap);
        if start.is_none() && overlap > 0.0 {
            start = Some(crossing);
        } else if start.is_some() && overlap <= 0.0 {
            end = Some(crossing);
            break;
        }
        previous = overlap;
    }
    let (Some(start), Some(end)) = (start, end) else {
        panic!("the grains did not touch and part");
    };
    let g = common::grains(&mut sim);
    Collision {
        restitution: -(g[0].velocity - g[1].velocity).x / v_in,
        contact_time: end - start,
        max_overlap,
    }
}

#[test]
fn elastic_impact_matches_hertz_contact_time_and_overlap() {
    let (e, nu, rho) = STEEL;
    let m_eff = 0.5 * sphere_mass(rho, RADIUS);
    for v in [0.1, 1.0] {
        let dt = steel_step(v, 2000.0);
        let c = collide(&head_on(v, 1.0, dt), dt);
        let t_c = contact_time(m_eff, 0.5 * RADIUS, like_modulus(e, nu), v);
        let delta = max_overlap(m_eff, 0.5 * RADIUS, like_modulus(e, nu), v);
        let time_error = (c.contact_time - t_c) / t_c;
        let overlap_error = (c.max_overlap - delta) / delta;
        println!(
            "v = {v} m/s: contact time {:.6e} s (analytic {t_c:.6e}, error {time_error:+.2e}), \
             max overlap {:.6e} m (analytic {delta:.6e}, error {overlap_error:+.2e}), e = {:.8}",
            c.contact_time, c.max_overlap, c.restitution
        );
        assert!(
            time_error.abs() < 0.01,
            "v = {v}: contact time error {time_error}"
        );
        assert!(
            overlap_error.abs() < 0.01,
            "v = {v}: overlap error {overlap_error}"
        );
        assert!(
            (c.restitution - 1.0).abs() < 1e-3,
            "v = {v}: e = {}",
            c.restitution
        );
    }
}

/// The automatic step: the elastic Hertz contact time of the lightest pair at the
/// characteristic speed (default 1 m/s), over `steps_per_collision`.
#[test]
fn automatic_time_step_is_the_hertz_contact_time_over_steps_per_collision() {
    let (e, nu, rho) = STEEL;
    for (speed, field) in [(1.0, ""), (0.2, ", characteristic_velocity: 0.2")] {
        let text = head_on(0.1, 0.9, 1e-6)
            .replace("time_step: 1e-6,", "steps_per_collision: 40.0,")
            .replace("restitution: 0.9", &format!("restitution: 0.9{field}"));
        let (sim, _) = common::build(&text);
        let expected = contact_time(
            0.5 * sphere_mass(rho, RADIUS),
            0.5 * RADIUS,
            like_modulus(e, nu),
            speed,
        ) / 40.0;
        let dt = sim.config().dt;
        assert!(
            (dt - expected).abs() / expected < 1e-3,
            "v = {speed}: dt {dt}, expected {expected}"
        );
    }
}

/// One time step for all speeds (1000 steps per contact at 1 m/s, 2500 at 0.01 m/s): the
/// restitution must not depend on the impact speed.
#[test]
fn restitution_is_the_prescribed_one_at_every_speed() {
    let dt = steel_step(1.0, 1000.0);
    for e in [0.5, 0.8] {
        for v in [0.01, 0.1, 1.0] {
            let measured = collide(&head_on(v, e, dt), dt).restitution;
            let error = (measured - e) / e;
            println!("e = {e}, v = {v} m/s: measured {measured:.6} (error {error:+.2e})");
            assert!(error.abs() < 0.01, "e = {e}, v = {v}: measured {measured}");
        }
    }
}

#[test]
fn unlike_materials_use_the_exact_effective_modulus() {
    // Steel against a soft polymer: 1/E* = (1 − ν_a²)/E_a + (1 − ν_b²)/E_b. Mixing E and ν
    // field by field (harmonic E, arithmetic ν) would give an E* 7 % lower and a contact
    // time 3 % longer.
    let (e_a, nu_a, rho_a) = STEEL;
    let (e_b, nu_b, rho_b) = (1e7, 0.45, 1200.0);
    let v = 0.5;
    let (m_a, m_b) = (sphere_mass(rho_a, RADIUS), sphere_mass(rho_b, RADIUS));
    let m_eff = m_a * m_b / (m_a + m_b);
    let e_star = 1.0 / ((1.0 - nu_a * nu_a) / e_a + (1.0 - nu_b * nu_b) / e_b);
    let t_c = contact_time(m_eff, 0.5 * RADIUS, e_star, v);
    let dt = t_c / 2000.0;
    // Centre of mass at rest: each grain moves at v m_other/(m_a + m_b).
    let (v_a, v_b) = (v * m_b / (m_a + m_b), -v * m_a / (m_a + m_b));
    let x = RADIUS + v * dt;
    let text = format!(
        r#"Scene(
    name: "hertz-unlike",
    steps: 1000000,
    time_step: {dt:e},
    plugins: ["hertz_mindlin"],
    materials: [
        (name: "steel", density: {rho_a:e},
            contact: (law: "hertz_mindlin", youngs_modulus: {e_a:e}, poisson_ratio: {nu_a}, restitution: 1.0)),
        (name: "polymer", density: {rho_b:e},
            contact: (law: "hertz_mindlin", youngs_modulus: {e_b:e}, poisson_ratio: {nu_b}, restitution: 1.0)),
    ],
    grains: [
        List(material: "steel", grains: [(position: ({neg_x:e}, 0.0, 0.0), radius: {RADIUS}, velocity: ({v_a:e}, 0.0, 0.0))]),
        List(material: "polymer", grains: [(position: ({x:e}, 0.0, 0.0), radius: {RADIUS}, velocity: ({v_b:e}, 0.0, 0.0))]),
    ],
    output: (recording: false),
)"#,
        neg_x = -x,
    );
    let c = collide(&text, dt);
    let error = (c.contact_time - t_c) / t_c;
    println!(
        "steel–polymer: contact time {:.6e} s, analytic {t_c:.6e} s, error {error:+.2e}",
        c.contact_time
    );
    assert!(error.abs() < 0.01, "contact time error {error}");
}

#[test]
fn oblique_sliding_impact_gives_the_rigid_body_coulomb_impulse() {
    let (e, nu, rho) = STEEL;
    let (friction, restitution) = (0.1, 0.8);
    // Incidence v_t / v_n = 5, well above the sliding bound (7/2) μ (1 + e) = 0.63.
    let (v_n, v_t) = (1.0, 5.0);
    let m = sphere_mass(rho, RADIUS);
    let dt = contact_time(m, RADIUS, like_modulus(e, nu), v_n) / 2000.0;
    let z = RADIUS + v_n * dt;
    let text = format!(
        r#"Scene(
    name: "hertz-oblique",
    steps: 1000000,
    time_step: {dt:e},
    plugins: ["hertz_mindlin"],
    materials: [(name: "steel", density: {rho:e},
        contact: (law: "hertz_mindlin", youngs_modulus: {e:e}, poisson_ratio: {nu},
                  restitution: {restitution}, friction: {friction}))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "steel")],
    grains: [List(material: "steel", grains: [
        (position: (0.0, 0.0, {z:e}), radius: {RADIUS}, velocity: ({v_t}, 0.0, {neg_v_n})),
    ])],
    output: (recording: false),
)"#,
        neg_v_n = -v_n,
    );
    let (mut sim, _) = common::build(&text);
    assert!(
        sim.config().rotation,
        "friction torques the grain: rotation is on"
    );
    let mut touched = false;
    for _ in 0..1_000_000 {
        sim.step().unwrap();
        let g = common::grains(&mut sim)[0];
        if g.position.z < g.radius {
            touched = true;
        } else if touched {
            break;
        }
    }
    assert!(touched, "the grain never touched the floor");
    let g = common::grains(&mut sim)[0];
    let e_measured = g.velocity.z / v_n;
    let impulse = friction * (1.0 + e_measured) * v_n;
    let expected_vt = v_t - impulse;
    let expected_omega = 2.5 / RADIUS * impulse;
    let vt_error = (g.velocity.x - expected_vt) / (v_t - expected_vt);
    let omega_error = (g.omega.y - expected_omega) / expected_omega;
    let slip = g.velocity.x - g.omega.y * RADIUS;
    println!(
        "oblique: e = {e_measured:.6}, Δv_t = {:.6e} (rigid body {:.6e}, error {vt_error:+.2e}), \
         ω = {:.6e} rad/s (rigid body {expected_omega:.6e}, error {omega_error:+.2e}), slip {slip:.4} m/s",
        g.velocity.x - v_t,
        -impulse,
        g.omega.y
    );
    assert!(
        (e_measured - restitution).abs() / restitution < 0.01,
        "e = {e_measured}"
    );
    assert!(slip > 0.0, "the grain stopped sliding: slip {slip}");
    // Δv_t is compared relative to itself (−μ(1 + e) v_n), not to v_t, which would hide it.
    assert!(vt_error.abs() < 0.01, "Δv_t error {vt_error}");
    assert!(omega_error.abs() < 0.01, "ω error {omega_error}");
    assert!(g.omega.x.abs() < 1e-9 * g.omega.y.abs() && g.omega.z.abs() < 1e-9 * g.omega.y.abs());
}

fn error_of(text: &str) -> SceneError {
    let outcome = std::panic::catch_unwind(|| {
        parse("bad.ron", text).and_then(|s| s.build(&talus::registry()).map(|_| ()))
    });
    match outcome {
        Ok(Err(e)) => e,
        Ok(Ok(())) => panic!("scene was accepted:\n{text}"),
        Err(_) => panic!("scene handling panicked:\n{text}"),
    }
}

const GOOD: &str = r#"Scene(
    name: "ok",
    steps: 10,
    plugins: ["hertz_mindlin"],
    materials: [(name: "steel", density: 7800.0,
        contact: (law: "hertz_mindlin", youngs_modulus: 2e11, poisson_ratio: 0.3, restitution: 0.9, friction: 0.3))],
    grains: [List(material: "steel", grains: [(position: (0.0, 0.0, 0.0), radius: 0.01)])],
)"#;

#[test]
fn the_good_scene_is_accepted() {
    let built = parse("good.ron", GOOD)
        .unwrap()
        .build(&talus::registry())
        .unwrap();
    assert!(built.builder.build().config().rotation);
}

#[test]
fn poisson_ratio_of_one_half_is_a_scene_error() {
    let e = error_of(&GOOD.replace("poisson_ratio: 0.3", "poisson_ratio: 0.5"));
    assert_eq!(e.field, "materials[0].contact.poisson_ratio", "{e}");
    assert!(e.expected.contains("[0, 0.5)"), "{e}");
    assert!(e.line > 0, "{e}");
}

#[test]
fn a_two_dimensional_scene_is_a_scene_error() {
    let e = error_of(&GOOD.replace("steps: 10,", "steps: 10,\n    dimension: 2,"));
    assert_eq!(e.field, "materials[0].contact.law", "{e}");
    assert!(e.expected.contains("3-D"), "{e}");
    assert!(e.line > 0, "{e}");
}

#[test]
fn missing_elastic_constants_and_restitution_are_scene_errors() {
    for (field, value) in [
        ("youngs_modulus", "youngs_modulus: 2e11, "),
        ("poisson_ratio", "poisson_ratio: 0.3, "),
        ("restitution", "restitution: 0.9, "),
    ] {
        let e = error_of(&GOOD.replace(value, ""));
        assert_eq!(e.field, format!("materials[0].contact.{field}"), "{e}");
    }
    let e = error_of(&GOOD.replace("restitution: 0.9", "restitution: 0.0"));
    assert_eq!(e.field, "materials[0].contact.restitution", "{e}");
}

/// A small pour of soft spheres under gravity, with random initial velocities.
fn small_pour(friction: f64, steps_per_collision: f64) -> String {
    format!(
        r#"Scene(
    name: "hertz-small-pour",
    gravity: (0.0, 0.0, -9.81),
    duration: 0.15,
    steps_per_collision: {steps_per_collision},
    plugins: ["hertz_mindlin"],
    materials: [(name: "soft-glass", density: 2500.0,
        contact: (law: "hertz_mindlin", youngs_modulus: 1e7, poisson_ratio: 0.25,
                  restitution: 0.5, friction: {friction}, tangential_damping_ratio: 0.3))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.1), material: "soft-glass")],
    grains: [Random(material: "soft-glass", region: (min: (0.0, 0.0, 0.005), max: (0.02, 0.02, 0.05)),
        count: 120, radius: Uniform(min: 0.0015, max: 0.0025), seed: 5, velocity_spread: 0.3)],
    output: (recording: false),
)"#
    )
}

/// What a pour run measured, relative to the energy put in (gravity work plus the
/// initial kinetic energy): the largest drifts of the bookkeeping and physical balances,
/// and the final integration error; with the most contacts at once and the final sample.
struct PourDrift {
    bookkeeping: f64,
    physical: f64,
    integration_error: f64,
    most_contacts: usize,
    last: talus::cli::ReportSample,
}

fn pour_drift(text: &str) -> PourDrift {
    let (mut sim, steps) = common::build(text);
    sim.prime().unwrap();
    let first = talus::cli::ReportSample::take(&sim.world);
    let (mut book, mut physical, mut most_contacts) = (0.0f64, 0.0f64, 0usize);
    for _ in 0..steps {
        sim.step().unwrap();
        let s = talus::cli::ReportSample::take(&sim.world);
        book = book.max((s.bookkeeping_balance - first.bookkeeping_balance).abs());
        physical = physical.max((s.energy_balance - first.energy_balance).abs());
        most_contacts = most_contacts.max(s.contacts);
    }
    let last = talus::cli::ReportSample::take(&sim.world);
    let injected = last.gravity_work + first.translational_kinetic + first.rotational_kinetic;
    assert!(injected > 0.0);
    PourDrift {
        bookkeeping: book / injected,
        physical: physical / injected,
        integration_error: (last.integration_error - first.integration_error) / injected,
        most_contacts,
        last,
    }
}

/// With friction and both dashpots, the bookkeeping balance (kinetic + elastic +
/// dissipated − work − integration error) stays constant.
#[test]
fn bookkeeping_balance_closes_in_a_pour() {
    let d = pour_drift(&small_pour(0.5, 50.0));
    let slip = d
        .last
        .dissipated
        .get("friction_slip")
        .copied()
        .unwrap_or(0.0);
    let tangential = d
        .last
        .dissipated
        .get("tangential_damping")
        .copied()
        .unwrap_or(0.0);
    println!(
        "pour μ = 0.5: up to {} contacts; E_book drift {:.2e}, E_bal drift {:.2e}, \
         integration error {:.3e} (relative to the energy put in); slip {slip:.4e} J, \
         tangential damping {tangential:.4e} J, normal damping {:.4e} J",
        d.most_contacts,
        d.bookkeeping,
        d.physical,
        d.integration_error,
        d.last
            .dissipated
            .get("normal_damping")
            .copied()
            .unwrap_or(0.0),
    );
    assert!(
        d.most_contacts > 100,
        "the grains hardly touched: {} contacts",
        d.most_contacts
    );
    assert!(
        slip > 0.0 && tangential > 0.0,
        "slip {slip}, tangential damping {tangential}"
    );
    assert!(d.bookkeeping < 1e-6, "bookkeeping drift {}", d.bookkeeping);
    // The Mindlin spring's stiffness-change energy has its own channel, so the physical
    // balance moves only by the integrator's error.
    assert!(d.physical < 1e-3, "physical drift {}", d.physical);
}

/// Without friction the only integration error is the time integration's: the physical
/// balance shrinks by about 4 when the step is halved (velocity Verlet, second order).
#[test]
fn physical_balance_is_second_order_without_friction() {
    let coarse = pour_drift(&small_pour(0.0, 50.0));
    let fine = pour_drift(&small_pour(0.0, 100.0));
    println!(
        "pour μ = 0: E_bal drift {:.2e} (50 steps per collision), {:.2e} (100); E_book {:.2e}, {:.2e}",
        coarse.physical, fine.physical, coarse.bookkeeping, fine.bookkeeping
    );
    assert!(coarse.bookkeeping < 1e-6 && fine.bookkeeping < 1e-6);
    assert!(coarse.physical < 1e-3, "physical drift {}", coarse.physical);
    assert!(
        coarse.physical > 3.0 * fine.physical,
        "{} → {}",
        coarse.physical,
        fine.physical
    );
}
