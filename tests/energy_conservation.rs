//! Conservation: elastic (e = 1), frictionless grains in a closed box without gravity
//! keep their total energy (kinetic + elastic) over 100,000 steps at the default step.

use crate::common;

#[test]
fn total_energy_drift_is_below_1e_minus_4() {
    let (mut sim, steps) = common::build(
        r#"Scene(
    name: "gas",
    steps: 100000,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: 1.0))],
    walls: [Box(min: (0.0, 0.0, 0.0), max: (0.1, 0.1, 0.1), material: "glass")],
    grains: [Random(material: "glass", region: (min: (0.0, 0.0, 0.0), max: (0.1, 0.1, 0.1)),
        count: 1000, radius: Uniform(min: 0.0015, max: 0.0025), seed: 3, velocity_spread: 0.5)],
    output: (recording: false),
)"#,
    );
    assert!(
        !sim.config().rotation,
        "no friction: rotation must not be integrated"
    );
    sim.prime().unwrap();
    let total = |sim: &talus::core::schedule::Simulation| {
        let (e, _) = common::energies(sim);
        e.translational_kinetic + e.rotational_kinetic + e.elastic
    };
    let e0 = total(&sim);
    let mut worst = 0.0f64;
    let mut collisions_seen = 0usize;
    for step in 1..=steps {
        sim.step().unwrap();
        if step % 1000 == 0 {
            worst = worst.max((total(&sim) - e0).abs() / e0);
            collisions_seen += common::energies(&sim).0.contacts;
        }
    }
    assert!(collisions_seen > 0, "the gas must collide");
    assert!(worst < 1e-4, "relative energy drift {worst:e}");
}
