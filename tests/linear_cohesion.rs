//! The `linear_cohesion` law in scenes, against closed forms: the equilibrium overlap of
//! a grain stuck to a floor under gravity, the depth of the well that binds two grains
//! (they escape above it, stay below), energy conservation of an elastic cohesive
//! collision, capture of a slow damped approach, the bookkeeping balance of a cohesive
//! pour, and the demo scene `scenes/cohesive-pile.ron`.
//!
//! The pull is F_c = −(f_0 + k_c δ) for δ ≥ −f_0/k_c, so two grains of reduced mass m*
//! rest at δ_0 = f_0/(k_n − k_c), and the energy needed to pull them apart from there is
//! the pull's work across the gap, f_0²/(2k_c), plus its work inside the overlap less the
//! spring's, f_0 δ_0 + ½k_c δ_0² − ½k_n δ_0² = ½f_0 δ_0: W = f_0²/(2k_c) + f_0²/(2(k_n − k_c)).

use crate::common;

use talus::cli::ReportSample;

const STIFFNESS: f64 = 1e4;
const ADHESION_FORCE: f64 = 0.02;
const ADHESION_STIFFNESS: f64 = 2e3;
const RADIUS: f64 = 0.005;
const DENSITY: f64 = 2500.0;
const RANGE: f64 = ADHESION_FORCE / ADHESION_STIFFNESS;

/// Overlap at which a free pair rests: k_n δ = f_0 + k_c δ.
fn bound_overlap() -> f64 {
    ADHESION_FORCE / (STIFFNESS - ADHESION_STIFFNESS)
}

/// Energy that separates a pair resting at [`bound_overlap`], J.
fn well_depth() -> f64 {
    ADHESION_FORCE.powi(2) / (2.0 * ADHESION_STIFFNESS)
        + ADHESION_FORCE.powi(2) / (2.0 * (STIFFNESS - ADHESION_STIFFNESS))
}

fn grain_mass() -> f64 {
    4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3) * DENSITY
}

/// Two equal grains on the x axis, centres ±`half_distance`, moving apart at ±`speed`/2
/// (negative: approaching), no gravity, no friction.
fn pair_scene(half_distance: f64, speed: f64, restitution: f64, duration: f64) -> String {
    let v = 0.5 * speed;
    format!(
        r#"Scene(
    name: "cohesive-pair",
    duration: {duration},
    steps_per_collision: 1000,
    plugins: ["linear_cohesion"],
    materials: [(name: "sticky", density: {DENSITY},
        contact: (law: "linear_cohesion", stiffness: {STIFFNESS}, restitution: {restitution},
            adhesion_force: {ADHESION_FORCE}, adhesion_stiffness: {ADHESION_STIFFNESS}))],
    grains: [List(material: "sticky", grains: [
        (position: ({a}, 0.0, 0.0), radius: {RADIUS}, velocity: ({va}, 0.0, 0.0)),
        (position: ({half_distance}, 0.0, 0.0), radius: {RADIUS}, velocity: ({v}, 0.0, 0.0)),
    ])],
    output: (recording: false),
)"#,
        a = -half_distance,
        va = -v,
    )
}

/// Runs a pair scene; returns the largest centre distance reached, the final distance
/// and the final relative speed (positive separating).
fn run_pair(scene: &str) -> (f64, f64, f64) {
    let (mut sim, steps) = common::build(scene);
    let mut farthest = 0.0f64;
    for _ in 0..steps {
        sim.step().unwrap();
        let g = common::grains(&mut sim);
        farthest = farthest.max(g[1].position.x - g[0].position.x);
    }
    let g = common::grains(&mut sim);
    (
        farthest,
        g[1].position.x - g[0].position.x,
        g[1].velocity.x - g[0].velocity.x,
    )
}

#[test]
fn grain_on_a_floor_settles_at_the_cohesive_equilibrium_overlap() {
    let (mut sim, _) = common::build(&format!(
        r#"Scene(
    name: "cohesive-rest",
    gravity: (0.0, 0.0, -9.81),
    steps: 1,
    plugins: ["linear_cohesion"],
    materials: [(name: "sticky", density: {DENSITY},
        contact: (law: "linear_cohesion", stiffness: {STIFFNESS}, restitution: 0.1, friction: 0.5,
            adhesion_force: {ADHESION_FORCE}, adhesion_stiffness: {ADHESION_STIFFNESS}))],
    walls: [Plane(name: "floor", point: (0.0, 0.0, 0.0), normal: (0.0, 0.0, 1.0), material: "sticky")],
    grains: [List(material: "sticky", grains: [(position: (0.0, 0.0, {z}), radius: {RADIUS})])],
    output: (recording: false),
)"#,
        // Released within the range, short of touch: the pull draws it in.
        z = RADIUS + 0.5 * RANGE,
    ));
    sim.run_steps(20_000).unwrap();
    let g = common::grains(&mut sim)[0];
    // k_n δ = m g + f_0 + k_c δ.
    let expected = (g.mass * 9.81 + ADHESION_FORCE) / (STIFFNESS - ADHESION_STIFFNESS);
    let overlap = g.radius - g.position.z;
    let error = (overlap - expected).abs() / expected;
    println!(
        "floor: overlap {overlap:.9e} m, analytic {expected:.9e} m, relative error {error:.2e}"
    );
    assert!(error < 1e-6, "overlap {overlap} m vs analytic {expected} m");
    assert!(
        g.velocity.length() < 1e-9,
        "still moving at {} m/s",
        g.velocity.length()
    );
}

#[test]
fn bound_pair_escapes_only_with_more_than_the_analytic_well_depth() {
    let reduced_mass = 0.5 * grain_mass();
    let escape_speed = (2.0 * well_depth() / reduced_mass).sqrt();
    let resting = RADIUS - 0.5 * bound_overlap();
    let reach = 2.0 * RADIUS + RANGE;
    // Just below the well depth: the pair turns back inside the range, where the pull's
    // potential −(f_0 + k_c δ)²/(2k_c) has taken all but 0.02 W.
    let (farthest, last, _) = run_pair(&pair_scene(
        resting,
        0.98f64.sqrt() * escape_speed,
        1.0,
        0.05,
    ));
    assert!(
        farthest < reach,
        "escaped with 0.98 W: reached {farthest} m, range ends at {reach} m"
    );
    assert!(last < reach);
    let turning_gap = (ADHESION_FORCE - (2.0 * ADHESION_STIFFNESS * 0.02 * well_depth()).sqrt())
        / ADHESION_STIFFNESS;
    let gap = farthest - 2.0 * RADIUS;
    let error = (gap - turning_gap).abs() / turning_gap;
    println!(
        "0.98 W: farthest gap {gap:.9e} m, analytic {turning_gap:.9e} m, relative error {error:.2e}"
    );
    assert!(
        error < 1e-3,
        "turned at a gap of {gap} m, analytic {turning_gap} m"
    );
    // Just above: it leaves the range for good.
    let (_, last, speed) = run_pair(&pair_scene(
        resting,
        1.02f64.sqrt() * escape_speed,
        1.0,
        0.05,
    ));
    assert!(
        last > reach && speed > 0.0,
        "held with 1.02 W: distance {last} m, speed {speed} m/s"
    );
    // It keeps 0.02 W: v∞² = 0.02 × 2W/m*.
    let expected = 0.02 * escape_speed * escape_speed;
    let error = (speed * speed - expected).abs() / expected;
    println!(
        "1.02 W: v∞² = {:.6e} m²/s², analytic {expected:.6e}, relative error {error:.2e}",
        speed * speed
    );
    assert!(error < 1e-3, "v∞² {} vs analytic {expected}", speed * speed);
    // With twice the depth it leaves with ½m* v∞² = ½m* v² − W, i.e. v∞² = v²/2.
    let v = 2f64.sqrt() * escape_speed;
    let (_, last, speed) = run_pair(&pair_scene(resting, v, 1.0, 0.05));
    assert!(last > reach);
    let expected = v * v - 2.0 * well_depth() / reduced_mass;
    let error = (speed * speed - expected).abs() / expected;
    println!(
        "2 W: v∞² = {:.9e} m²/s², analytic {expected:.9e}, relative error {error:.2e}",
        speed * speed
    );
    assert!(error < 1e-3, "v∞² {} vs analytic {expected}", speed * speed);
}

#[test]
fn elastic_cohesive_collision_returns_the_approach_speed() {
    // Restitution 1: the spring and the pull are conservative, so a pair that comes in
    // from beyond the range leaves with the speed it came with, whatever the well depth.
    let escape_speed = (2.0 * well_depth() / (0.5 * grain_mass())).sqrt();
    let start = RADIUS + RANGE; // gap 2 × range
    for v_in in [0.3 * escape_speed, 3.0 * escape_speed, 0.05] {
        let (_, last, v_out) = run_pair(&pair_scene(start, -v_in, 1.0, 0.05));
        assert!(
            last > 2.0 * RADIUS + RANGE,
            "v_in = {v_in}: still bound at {last} m"
        );
        let error = (v_out * v_out - v_in * v_in).abs() / (v_in * v_in);
        println!(
            "elastic: v_in {v_in:.6e} m/s, v_out {v_out:.9e} m/s, |v_out² − v_in²|/v_in² = {error:.2e}"
        );
        assert!(error < 1e-3, "v_in {v_in} m/s, v_out {v_out} m/s");
    }
}

#[test]
fn slow_damped_approach_is_captured_and_rests_at_the_bound_overlap() {
    // Below the well depth and with a dashpot, the pair cannot climb back out: it stays
    // and comes to rest at k_n δ = f_0 + k_c δ.
    let escape_speed = (2.0 * well_depth() / (0.5 * grain_mass())).sqrt();
    let start = RADIUS + RANGE;
    let (farthest, last, speed) = run_pair(&pair_scene(start, -0.5 * escape_speed, 0.3, 0.1));
    assert!(farthest <= 2.0 * start + 1e-15, "moved apart: {farthest} m");
    let overlap = 2.0 * RADIUS - last;
    let error = (overlap - bound_overlap()).abs() / bound_overlap();
    println!(
        "captured: overlap {overlap:.9e} m, analytic {:.9e} m, relative error {error:.2e}",
        bound_overlap()
    );
    assert!(error < 1e-6, "overlap {overlap} m vs {}", bound_overlap());
    assert!(speed.abs() < 1e-9, "still moving at {speed} m/s");
}

#[test]
fn cohesive_pour_bookkeeping_balance_stays_constant() {
    let (mut sim, steps) = common::build(
        r#"Scene(
    name: "cohesive-pour",
    gravity: (0.0, 0.0, -9.81),
    duration: 0.2,
    plugins: ["linear_cohesion"],
    materials: [(name: "sticky", density: 2500.0,
        contact: (law: "linear_cohesion", stiffness: 2000.0, restitution: 0.5, friction: 0.5,
            adhesion_force: 0.002, adhesion_stiffness: 400.0))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.02, 0.02, 0.1), material: "sticky")],
    grains: [Random(material: "sticky", region: (min: (0.0, 0.0, 0.005), max: (0.02, 0.02, 0.05)),
        count: 150, radius: Uniform(min: 0.0015, max: 0.0025), seed: 5)],
    output: (recording: false),
)"#,
    );
    sim.prime().unwrap();
    let first = ReportSample::take(&sim.world);
    let mut samples = vec![first.clone()];
    let mut most_bound = 0.0f64;
    for step in 1..=steps {
        sim.step().unwrap();
        if step % 100 == 0 || step == steps {
            let s = ReportSample::take(&sim.world);
            most_bound = most_bound.min(s.elastic);
            samples.push(s);
        }
    }
    let injected = samples.last().unwrap().gravity_work;
    assert!(injected > 0.0);
    let drift = |f: fn(&ReportSample) -> f64| {
        samples
            .iter()
            .map(|s| (f(s) - f(&first)).abs() / injected)
            .fold(0.0, f64::max)
    };
    let bookkeeping = drift(|s| s.bookkeeping_balance);
    let physical = drift(|s| s.energy_balance);
    println!(
        "cohesive pour: {steps} steps, bookkeeping drift {bookkeeping:.2e}, physical drift {physical:.2e}, lowest elastic energy {most_bound:.3e} J, gravity work {injected:.3e} J"
    );
    // The pull held grains together at some point: its potential went negative.
    assert!(most_bound < 0.0, "no cohesive contact formed");
    assert!(
        bookkeeping < 1e-6,
        "bookkeeping balance drifted by {bookkeeping:e} of the gravity work"
    );
    assert!(
        physical < 1e-3,
        "energy balance drifted by {physical:e} of the gravity work"
    );
}

#[test]
fn cohesive_pile_scene_parses_and_builds() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cohesive-pile.ron");
    let scene = talus::scene::load(path).unwrap_or_else(|e| panic!("{e}"));
    let built = scene
        .build(&talus::registry())
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(built.stop.steps > 0);
}

#[test]
fn bad_cohesion_parameters_are_reported_with_their_field() {
    let scene = |params: &str| {
        format!(
            r#"Scene(
    name: "bad-cohesion",
    steps: 1,
    plugins: ["linear_cohesion"],
    materials: [(name: "sticky", density: 2500.0,
        contact: (law: "linear_cohesion", stiffness: 1000.0, restitution: 0.5, {params}))],
    grains: [List(material: "sticky", grains: [(position: (0.0, 0.0, 0.0), radius: 0.001)])],
    output: (recording: false),
)"#
        )
    };
    let cases = [
        ("adhesion_stiffness: 100.0", "adhesion_force"),
        ("adhesion_force: 0.01", "adhesion_stiffness"),
        (
            "adhesion_force: -0.01, adhesion_stiffness: 100.0",
            "adhesion_force",
        ),
        (
            "adhesion_force: 0.01, adhesion_stiffness: 0.0",
            "adhesion_stiffness",
        ),
        // k_c ≥ k_n: nothing would push the grains apart.
        (
            "adhesion_force: 0.01, adhesion_stiffness: 1000.0",
            "adhesion_stiffness",
        ),
    ];
    for (params, field) in cases {
        let text = scene(params);
        let scene =
            talus::scene::parse("bad-cohesion.ron", &text).unwrap_or_else(|e| panic!("{e}"));
        let err = match scene.build(&talus::registry()) {
            Ok(_) => panic!("`{params}` was accepted"),
            Err(e) => e,
        };
        assert!(
            err.field.ends_with(field),
            "`{params}`: error at `{}` ({}), expected at `{field}`",
            err.field,
            err.expected
        );
    }
}
