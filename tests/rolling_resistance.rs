//! Rolling and twisting resistance against analytic references: a sphere (or disk)
//! rolling without slip on a floor stops after the distance its constant resisting
//! torque allows; a viscous torque decays its spin exponentially; a twisting cap slows a
//! spin about the normal linearly; the elastic–plastic spring brings a grain to rest
//! where the constant torque chatters; scene errors; and the energy bookkeeping.

use crate::common;

use talus::cli::ReportSample;

const GRAVITY: f64 = 9.81;
const RADIUS: f64 = 0.01;
const DENSITY: f64 = 7800.0;

/// Mass of the test grain: a steel sphere of radius 1 cm, or a disk of 1 m thickness.
fn mass(dimension: u8) -> f64 {
    if dimension == 3 {
        4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3) * DENSITY
    } else {
        std::f64::consts::PI * RADIUS * RADIUS * DENSITY
    }
}

/// One grain on a floor (z = 0 in 3-D, y = 0 in 2-D), resting at its equilibrium
/// overlap δ = m g / k_n so that F_n = m g from the first step, moving along +x with
/// speed `speed` and spin `spin` (about the axis that rolls it along +x when
/// `spin = speed / R`), plus an extra spin about the floor normal `twist`.
fn scene(
    dimension: u8,
    stiffness: f64,
    contact: &str,
    speed: f64,
    spin: f64,
    twist: f64,
    duration: f64,
) -> String {
    let overlap = mass(dimension) * GRAVITY / stiffness;
    let height = RADIUS - overlap;
    // Rolling along +x: ω = +y in 3-D (v = ω × (R n) with n = +z), −z in 2-D (n = +y).
    let (gravity, normal, position, omega) = if dimension == 3 {
        (
            "(0.0, 0.0, -9.81)",
            "(0.0, 0.0, 1.0)",
            format!("(0.0, 0.0, {height:e})"),
            format!("(0.0, {spin:e}, {twist:e})"),
        )
    } else {
        (
            "(0.0, -9.81, 0.0)",
            "(0.0, 1.0, 0.0)",
            format!("(0.0, {height:e}, 0.0)"),
            format!("(0.0, 0.0, {:e})", -spin),
        )
    };
    format!(
        r#"Scene(
    name: "rolling-resistance",
    dimension: {dimension},
    gravity: {gravity},
    duration: {duration},
    plugins: ["linear_spring"],
    materials: [(name: "steel", density: {DENSITY:e},
        contact: (law: "linear_spring", stiffness: {stiffness:e}, restitution: 0.5, friction: 0.5, {contact}))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: {normal}, material: "steel")],
    grains: [List(material: "steel", grains: [
        (position: {position}, radius: {RADIUS:e}, velocity: ({speed:e}, 0.0, 0.0), angular_velocity: {omega}),
    ])],
    output: (recording: false),
)"#
    )
}

/// Rolling spin of the grain about the axis that rolls it along +x.
fn rolling_spin(dimension: u8, omega: glam::DVec3) -> f64 {
    if dimension == 3 { omega.y } else { -omega.z }
}

/// Rolls a grain started rolling without slip at `speed` under a constant rolling
/// torque; returns (distance travelled when it first stops, analytic distance).
///
/// Rolling without slip on a plane with a resisting torque M = μ_r F_n R* = μ_r m g R
/// (R* = R against a wall): the kinetic energy ½ (m + I/R²) v² falls at the rate
/// M ω = μ_r m g v, so the deceleration is a = μ_r g / (1 + I/(m R²)), that is
/// (5/7) μ_r g for a sphere (I = 2/5 m R²) and (2/3) μ_r g for a disk (I = 1/2 m R²),
/// and the grain stops after d = v₀² / (2a).
fn constant_torque_stop(dimension: u8, stiffness: f64) -> (f64, f64) {
    let (speed, rolling_friction) = (0.1, 0.05);
    let lever = RADIUS - 0.5 * mass(dimension) * GRAVITY / stiffness;
    let text = scene(
        dimension,
        stiffness,
        &format!(r#"rolling: "constant_torque", rolling_friction: {rolling_friction}"#),
        speed,
        speed / lever,
        0.0,
        0.5,
    );
    let (mut sim, steps) = common::build(&text);
    let x0 = common::grains(&mut sim)[0].position.x;
    let mut stopped_at = None;
    for _ in 0..steps {
        sim.step().unwrap();
        let g = common::grains(&mut sim)[0];
        if rolling_spin(dimension, g.omega) <= 0.0 {
            stopped_at = Some(g.position.x - x0);
            break;
        }
    }
    let inertia_ratio = if dimension == 3 { 0.4 } else { 0.5 };
    let deceleration = rolling_friction * GRAVITY / (1.0 + inertia_ratio);
    let analytic = speed * speed / (2.0 * deceleration);
    (
        stopped_at.expect("the grain stops within the run"),
        analytic,
    )
}

#[test]
fn constant_torque_sphere_stops_after_analytic_distance() {
    let (d, analytic) = constant_torque_stop(3, 1e6);
    let error = (d - analytic).abs() / analytic;
    eprintln!(
        "sphere: stopped after {d:.6e} m, analytic {analytic:.6e} m, relative error {error:.2e}"
    );
    assert!(error < 0.01, "stopped after {d} m, analytic {analytic} m");
}

#[test]
fn constant_torque_disk_stops_after_analytic_distance() {
    let (d, analytic) = constant_torque_stop(2, 1e8);
    let error = (d - analytic).abs() / analytic;
    eprintln!(
        "disk: stopped after {d:.6e} m, analytic {analytic:.6e} m, relative error {error:.2e}"
    );
    assert!(error < 0.01, "stopped after {d} m, analytic {analytic} m");
}

/// Rolling spin over the last `window` seconds of a 0.5 s run of a sphere started
/// rolling at 5 cm/s (with μ_r = 0.05 it stops after 0.05/((5/7) μ_r g) = 0.143 s), cut
/// into `parts` equal sub-windows: the largest |ω| and the number of sign changes of each.
fn rest_behaviour(contact: &str, window: f64, parts: usize) -> Vec<(f64, usize)> {
    let speed = 0.05;
    let text = scene(3, 1e6, contact, speed, speed / RADIUS, 0.0, 0.5);
    let (mut sim, steps) = common::build(&text);
    let dt = sim.config().dt;
    let part_steps = (window / dt) as u64 / parts as u64;
    let first = steps - part_steps * parts as u64;
    let mut out = vec![(0.0f64, 0usize); parts];
    let mut previous = 0.0f64;
    for step in 1..=steps {
        sim.step().unwrap();
        if step > first {
            let part = &mut out[((step - first - 1) / part_steps) as usize];
            let w = rolling_spin(3, common::grains(&mut sim)[0].omega);
            part.0 = part.0.max(w.abs());
            if w * previous < 0.0 {
                part.1 += 1;
            }
            previous = w;
        }
    }
    out
}

/// At rest the constant torque has no state: it flips sign with the spin and, with the
/// tangential spring, rocks the sphere for ever (a limit cycle at the tangential
/// spring's period, about 1.1 ms here). The elastic–plastic spring holds the sphere and
/// its dashpot (η_r = 0.3 of the critical damping of the rocking about the contact
/// point, ω = √(k_r / (7/5 m R²)) = 351 rad/s) damps the rocking at the rate
/// η_r ω = 105 /s: below the threshold within about 0.1 s of stopping, and for good.
#[test]
fn elastic_plastic_comes_to_rest_while_constant_torque_chatters() {
    const THRESHOLD: f64 = 1e-6; // rad/s
    const WINDOW: f64 = 0.3; // s, from 0.2 s to the end of the 0.5 s run
    const PARTS: usize = 15;
    let constant = rest_behaviour(
        r#"rolling: "constant_torque", rolling_friction: 0.05"#,
        WINDOW,
        PARTS,
    );
    let elastic = rest_behaviour(
        r#"rolling: "elastic_plastic", rolling_friction: 0.05"#,
        WINDOW,
        PARTS,
    );
    let show = |parts: &[(f64, usize)]| {
        parts
            .iter()
            .map(|(w, n)| format!("({w:.2e}, {n})"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    eprintln!("last {WINDOW} s in {PARTS} parts, (max |ω| rad/s, sign changes):");
    eprintln!("  constant torque: {}", show(&constant));
    eprintln!("  elastic-plastic: {}", show(&elastic));
    for (k, (largest, flips)) in constant.iter().enumerate() {
        assert!(
            *largest > 100.0 * THRESHOLD && *flips >= 10,
            "constant torque came to rest in part {k}: {largest:e} rad/s, {flips} sign changes"
        );
    }
    let settled = elastic
        .iter()
        .position(|(largest, _)| *largest < THRESHOLD)
        .expect("the elastic-plastic sphere comes to rest");
    assert!(
        settled <= PARTS - 5,
        "elastic-plastic at rest only from part {settled}"
    );
    for (k, (largest, _)) in elastic.iter().enumerate().skip(settled) {
        assert!(
            *largest < THRESHOLD,
            "elastic-plastic moving again in part {k}: {largest:e} rad/s"
        );
    }
}

/// Rolling without slip with a viscous torque M = −c_r ω: about the contact point,
/// (I + m R²) ω̇ = −c_r ω (friction and weight act through it), so
/// ω(t) = ω₀ exp(−c_r t / (I + m R²)), I + m R² = 7/5 m R² for a sphere. The cap
/// μ_r m g R is never reached (c_r ω₀ is 60 % of it).
#[test]
fn viscous_rolling_decays_exponentially_at_analytic_rate() {
    let (speed, damping, rolling_friction) = (0.1, 2e-5, 0.1);
    let m = mass(3);
    let cap = rolling_friction * m * GRAVITY * RADIUS;
    assert!(damping * speed / RADIUS < 0.7 * cap);
    let text = scene(
        3,
        1e6,
        &format!(
            r#"rolling: "viscous", rolling_damping: {damping:e}, rolling_friction: {rolling_friction}"#
        ),
        speed,
        speed / RADIUS,
        0.0,
        0.3,
    );
    let (mut sim, steps) = common::build(&text);
    let dt = sim.config().dt;
    // Skip the first 20 ms, in which the tangential spring settles to carry the friction
    // force the torque calls for, then fit ln ω = a − λ t by least squares: the fit
    // averages out the ringing of the (undamped) tangential spring.
    let start = 0.02;
    let (mut n, mut st, mut sy, mut stt, mut sty) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for step in 1..=steps {
        sim.step().unwrap();
        let t = step as f64 * dt;
        if t >= start {
            let y = rolling_spin(3, common::grains(&mut sim)[0].omega).ln();
            n += 1.0;
            st += t;
            sy += y;
            stt += t * t;
            sty += t * y;
        }
    }
    let measured = -(n * sty - st * sy) / (n * stt - st * st);
    let analytic = damping / (1.4 * m * RADIUS * RADIUS);
    let error = (measured - analytic).abs() / analytic;
    eprintln!(
        "viscous: decay rate {measured:.6e} 1/s, analytic {analytic:.6e} 1/s, relative error {error:.2e}"
    );
    assert!(error < 0.01, "decay rate {measured}, analytic {analytic}");
}

/// A sphere resting on the floor spins about the normal. Once the twisting spring
/// slides, the torque is the cap μ_tw F_n a with F_n = m g and a = √(R δ), δ = m g / k_n,
/// so ω falls linearly at the rate μ_tw m g a / I, I = 2/5 m R².
#[test]
fn twisting_spin_decreases_linearly_at_analytic_rate() {
    let (twist, twisting_friction, stiffness) = (3.0, 0.5, 1e6);
    let text = scene(
        3,
        stiffness,
        &format!(r#"twisting: "spring_dashpot", twisting_friction: {twisting_friction}"#),
        0.0,
        0.0,
        twist,
        0.6,
    );
    let (mut sim, steps) = common::build(&text);
    let dt = sim.config().dt;
    // Times at which the spin falls through 90 % and 10 % of its initial value: the
    // spring has long reached the cap by then (after about 7 ms).
    let (mut t_high, mut t_low) = (None, None);
    let mut stopped = false;
    for step in 1..=steps {
        sim.step().unwrap();
        let w = common::grains(&mut sim)[0].omega.z;
        let t = step as f64 * dt;
        if t_high.is_none() && w <= 0.9 * twist {
            t_high = Some(t);
        }
        if t_low.is_none() && w <= 0.1 * twist {
            t_low = Some(t);
        }
        if w.abs() < 0.01 * twist && t_low.is_some() {
            stopped = true;
        }
    }
    let (t_high, t_low) = (t_high.unwrap(), t_low.unwrap());
    let measured = 0.8 * twist / (t_low - t_high);
    let m = mass(3);
    let overlap = m * GRAVITY / stiffness;
    let contact_radius = (RADIUS * overlap).sqrt();
    let analytic = twisting_friction * m * GRAVITY * contact_radius / (0.4 * m * RADIUS * RADIUS);
    let error = (measured - analytic).abs() / analytic;
    eprintln!(
        "twisting: spin falls at {measured:.6e} rad/s², analytic {analytic:.6e} rad/s², relative error {error:.2e}"
    );
    assert!(error < 0.01, "rate {measured}, analytic {analytic}");
    assert!(stopped, "the spin stops");
}

fn build_error(text: &str) -> talus::scene::SceneError {
    let outcome = std::panic::catch_unwind(|| {
        talus::scene::parse("bad.ron", text).and_then(|s| s.build(&talus::registry()).map(|_| ()))
    });
    match outcome {
        Ok(Err(e)) => e,
        Ok(Ok(())) => panic!("scene was accepted:\n{text}"),
        Err(_) => panic!("scene handling panicked:\n{text}"),
    }
}

#[test]
fn unknown_rolling_part_is_a_scene_error_naming_rolling() {
    let text = scene(
        3,
        1e6,
        r#"rolling: "no_such_model", rolling_friction: 0.05"#,
        0.0,
        0.0,
        0.0,
        0.01,
    );
    let e = build_error(&text);
    eprintln!("{e}");
    assert!(e.field.ends_with("contact.rolling"), "{e}");
    assert!(e.expected.contains("no_such_model"), "{e}");
    assert!(e.expected.contains("constant_torque"), "{e}");
}

#[test]
fn rolling_part_with_rotation_off_is_a_scene_error_naming_the_law() {
    let text = scene(
        3,
        1e6,
        r#"rolling: "elastic_plastic", rolling_friction: 0.05"#,
        0.0,
        0.0,
        0.0,
        0.01,
    )
    .replace("duration:", "rotation: false,\n    duration:");
    let e = build_error(&text);
    eprintln!("{e}");
    assert!(e.field.ends_with("contact.law"), "{e}");
    assert!(e.expected.contains("rotation: false"), "{e}");
    assert!(e.expected.contains("rolling `elastic_plastic`"), "{e}");
}

#[test]
fn rolling_part_without_its_coefficient_is_a_scene_error() {
    let text = scene(3, 1e6, r#"rolling: "constant_torque""#, 0.0, 0.0, 0.0, 0.01);
    let e = build_error(&text);
    eprintln!("{e}");
    assert!(e.field.ends_with("contact.rolling_friction"), "{e}");
}

/// A sphere dropped from 1 mm with speed, rolling spin and a spin about the vertical
/// bounces (its contact starts and ends several times), then rolls and twists to rest
/// with the elastic–plastic rolling part and the twisting part: every element loads,
/// slides, unloads and is released. kinetic + elastic + dissipated − work of gravity,
/// less the integration error the laws measure, stays constant to rounding; the
/// physical balance moves by the integrator's truncation error.
///
/// The reference is the sample after the first step, not the one after `prime()`: the
/// priming pass runs with a step of 0, so its sample has no kinetic staggering term
/// (−⅛ dt² (|F|²/m + |T|²/I) under velocity Verlet) and every balance jumps by that
/// much at the first step (1.4e-7 of the initial kinetic energy here, from gravity alone
/// while the sphere falls; 2.5e-6 for a sphere started on the floor, where the rolling
/// dashpot's first torque is large). The jump is the core's sampling, not a law's.
/// Largest drifts of the bookkeeping and of the physical balance over a run, relative
/// to the initial kinetic energy, with `steps_per_collision` steps per contact time.
struct Drift {
    bookkeeping: f64,
    physical: f64,
    last: ReportSample,
    initial_kinetic: f64,
}

fn drop_and_roll(steps_per_collision: u32) -> Drift {
    let text = scene(
        3,
        1e6,
        r#"rolling: "elastic_plastic", rolling_friction: 0.05, twisting: "spring_dashpot", twisting_friction: 0.5"#,
        0.1,
        5.0,
        3.0,
        0.3,
    )
    .replace(&format!("{:e}), radius", RADIUS - mass(3) * GRAVITY / 1e6), "1.1e-2), radius")
    .replace("duration:", &format!("steps_per_collision: {steps_per_collision},\n    duration:"));
    let (mut sim, steps) = common::build(&text);
    sim.prime().unwrap();
    let initial_kinetic = ReportSample::take(&sim.world).kinetic();
    assert!(initial_kinetic > 0.0);
    sim.step().unwrap();
    let first = ReportSample::take(&sim.world);
    let (mut bookkeeping, mut physical) = (0.0f64, 0.0f64);
    for _ in 1..steps {
        sim.step().unwrap();
        let s = ReportSample::take(&sim.world);
        bookkeeping = bookkeeping.max((s.bookkeeping_balance - first.bookkeeping_balance).abs());
        physical = physical.max((s.energy_balance - first.energy_balance).abs());
    }
    Drift {
        bookkeeping: bookkeeping / initial_kinetic,
        physical: physical / initial_kinetic,
        last: ReportSample::take(&sim.world),
        initial_kinetic,
    }
}

#[test]
fn rolling_and_twisting_energy_bookkeeping_closes() {
    let coarse = drop_and_roll(50);
    let fine = drop_and_roll(100);
    let last = &coarse.last;
    let channel = |name: &str| last.dissipated.get(name).copied().unwrap_or(0.0);
    eprintln!(
        "energy, 50 steps per collision: bookkeeping drift {:.2e}, physical drift {:.2e} of the initial kinetic energy {:.4e} J; \
         gravity work {:.4e} J; dissipated: rolling_damping {:.3e}, rolling_slip {:.3e}, twisting_damping {:.3e}, twisting_slip {:.3e}, total {:.4e} J",
        coarse.bookkeeping,
        coarse.physical,
        coarse.initial_kinetic,
        last.gravity_work,
        channel("rolling_damping"),
        channel("rolling_slip"),
        channel("twisting_damping"),
        channel("twisting_slip"),
        last.dissipated_total,
    );
    eprintln!(
        "energy, 100 steps per collision: bookkeeping drift {:.2e}, physical drift {:.2e}",
        fine.bookkeeping, fine.physical
    );
    for name in [
        "rolling_damping",
        "rolling_slip",
        "twisting_damping",
        "twisting_slip",
    ] {
        assert!(channel(name) > 0.0, "{name} dissipated nothing");
    }
    for drift in [&coarse, &fine] {
        assert!(
            drift.bookkeeping < 1e-6,
            "bookkeeping drift {:e}",
            drift.bookkeeping
        );
    }
    // The physical balance moves by the integrator's truncation error, which here comes
    // from the bounces (a contact's spring works over the whole step it starts in and
    // half of the one it ends in): the base law alone, with no rolling or twisting part,
    // drifts by as much in this run (1.05e-4 and 7.3e-5 at 50 and 100 steps per
    // collision). Its convergence is irregular with so few contact events, so only an
    // upper bound is asserted.
    for drift in [&coarse, &fine] {
        assert!(drift.physical < 1e-3, "physical drift {:e}", drift.physical);
    }
}

/// The demo scene runs and shows what its comments promise (v₀ = 0.2 m/s, ω₀ = 20
/// rad/s, μ_r = 0.05, k_n = 1e5 N/m):
/// * constant torque: stops after d = v₀² / (2 (5/7) μ_r g);
/// * elastic–plastic: the same, less the spin its uncapped dashpot takes while the new
///   contact's spring loads to the limit M = μ_r m g R: the angular impulse c_r θ_load,
///   θ_load = M / k_r, that is Δω = c_r M / (k_r I_r) = 2 η_r M / √(I_r k_r) with
///   I_r = 7/5 m R² and k_r = 2.25 μ_r² R² k_n; then at rest;
/// * viscous: capped while c_r ω > M (decelerating at α = (5/7) μ_r g / R), then
///   ω = (M / c_r) exp(−(t − t₁)/τ), τ = I_r / c_r;
/// * spinner: stopped.
#[test]
fn demo_scene_shows_each_model() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/rolling-resistance.ron");
    let text = std::fs::read_to_string(&path).unwrap();
    let (mut sim, steps) = common::build(&text);
    for _ in 0..steps {
        sim.step().unwrap();
    }
    let duration = steps as f64 * sim.config().dt;
    let grains = common::grains(&mut sim);
    let lane = |y: f64| {
        *grains
            .iter()
            .find(|g| (g.position.y - y).abs() < 1e-3)
            .expect("a grain in each lane")
    };
    let (constant, viscous, elastic, spinner) = (lane(0.0), lane(0.03), lane(0.06), lane(0.09));
    let (speed, spin, rolling_friction, damping, stiffness) = (0.2, 20.0, 0.05, 2e-5, 1e5);
    let m = mass(3);
    let limit = rolling_friction * m * GRAVITY * RADIUS;
    let inertia = 1.4 * m * RADIUS * RADIUS;
    let deceleration = 5.0 / 7.0 * rolling_friction * GRAVITY;
    let distance = speed * speed / (2.0 * deceleration);
    let rolling_stiffness =
        2.25 * rolling_friction * rolling_friction * RADIUS * RADIUS * stiffness;
    let lost_spin = 2.0 * 0.3 * limit / (inertia * rolling_stiffness).sqrt();
    let elastic_distance = (speed - RADIUS * lost_spin).powi(2) / (2.0 * deceleration);
    let capped_until = (spin - limit / damping) / (deceleration / RADIUS);
    let viscous_spin = limit / damping * (-(duration - capped_until) * damping / inertia).exp();
    eprintln!(
        "demo after {duration:.3} s: constant torque at x = {:.5} m (analytic {distance:.5} m, still rocking, ω_y {:.2e} rad/s); \
         elastic-plastic at x = {:.5} m (analytic {elastic_distance:.5} m, ω_y {:.2e} rad/s); \
         viscous ω_y = {:.4} rad/s (analytic {viscous_spin:.4}); spinner ω_z = {:.2e} rad/s",
        constant.position.x,
        constant.omega.y,
        elastic.position.x,
        elastic.omega.y,
        viscous.omega.y,
        spinner.omega.z
    );
    assert!(
        (constant.position.x - distance).abs() < 0.01 * distance,
        "{constant:?}"
    );
    assert!(
        (elastic.position.x - elastic_distance).abs() < 0.01 * elastic_distance,
        "{elastic:?}"
    );
    assert!(elastic.omega.length() < 1e-6, "{elastic:?}");
    assert!(
        (viscous.omega.y - viscous_spin).abs() < 0.01 * viscous_spin,
        "{viscous:?}"
    );
    assert!(spinner.omega.z.abs() < 0.01 * 5.0, "{spinner:?}");
}
