//! Two-grain head-on collisions with the linear spring–dashpot law against the
//! analytic damped oscillator: restitution e and contact time π / √(k/m* − (c/2m*)²).

use crate::common;

use std::f64::consts::PI;

fn scene(e: f64) -> String {
    format!(
        r#"Scene(
    name: "binary",
    duration: 0.008,
    steps_per_collision: 2000,
    plugins: ["linear_spring"],
    materials: [(name: "glass", density: 2500.0,
        contact: (law: "linear_spring", stiffness: 1e4, restitution: {e}))],
    grains: [List(material: "glass", grains: [
        (position: (-0.0105, 0.0, 0.0), radius: 0.01, velocity: (0.5, 0.0, 0.0)),
        (position: (0.0105, 0.0, 0.0), radius: 0.01, velocity: (-0.5, 0.0, 0.0)),
    ])],
    output: (recording: false),
)"#
    )
}

#[test]
fn restitution_and_contact_time_match_the_damped_oscillator() {
    for e in [0.3, 0.7, 1.0] {
        let (mut sim, steps) = common::build(&scene(e));
        let dt = sim.config().dt;
        let g0 = common::grains(&mut sim);
        let m_eff = g0[0].mass * g0[1].mass / (g0[0].mass + g0[1].mass);
        let v_in = (g0[0].velocity - g0[1].velocity).x;
        let mut contact_steps = 0u64;
        for _ in 0..steps {
            sim.step().unwrap();
            if common::energies(&sim).0.contacts > 0 {
                contact_steps += 1;
            }
        }
        let g = common::grains(&mut sim);
        let v_out = (g[0].velocity - g[1].velocity).x;
        let measured_e = -v_out / v_in;
        assert!(
            (measured_e - e).abs() / e < 0.005,
            "e = {e}: measured restitution {measured_e}"
        );

        let k = 1e4;
        let ln = e.ln();
        let zeta = -ln / (PI * PI + ln * ln).sqrt();
        let c = 2.0 * zeta * (m_eff * k).sqrt();
        let analytic = PI / (k / m_eff - (c / (2.0 * m_eff)).powi(2)).sqrt();
        let measured = contact_steps as f64 * dt;
        assert!(
            (measured - analytic).abs() / analytic < 0.01,
            "e = {e}: contact time {measured} s, analytic {analytic} s"
        );
    }
}
