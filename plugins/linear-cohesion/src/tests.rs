//! Unit tests of the cohesion part and the composed law against the closed forms:
//! the force–overlap curve, the range, the stored energy as the integral of the force,
//! the energy bookkeeping over a path, and the parameter checks.

use glam::DVec3;
use talus_contact::*;

use crate::{CohesionParams, LinearCohesion, LinearCohesionContact, descriptor};

const NORMAL_STIFFNESS: f64 = 1e4;
const ADHESION_FORCE: f64 = 0.02;
const ADHESION_STIFFNESS: f64 = 2e3;
const RANGE: f64 = ADHESION_FORCE / ADHESION_STIFFNESS;
const REDUCED_MASS: f64 = 1e-3;

fn pair(values: &[(&str, f64)]) -> PairAssignment {
    PairAssignment {
        materials: (0, 0),
        names: ("sticky".into(), "sticky".into()),
        values: ParamValues(values.iter().map(|(k, v)| (k.to_string(), *v)).collect()),
        min_effective_mass: REDUCED_MASS,
        min_effective_radius: 1e-3,
        dimension: talus_core::resources::Dimension::Three,
        material_values: None,
    }
}

fn sticky(restitution: f64, friction: f64) -> PairAssignment {
    pair(&[
        ("stiffness", NORMAL_STIFFNESS),
        ("restitution", restitution),
        ("friction", friction),
        ("adhesion_force", ADHESION_FORCE),
        ("adhesion_stiffness", ADHESION_STIFFNESS),
    ])
}

fn resolved(pair: &PairAssignment) -> <LinearCohesionContact as ContactLaw>::Params {
    let (params, _) = descriptor().resolve(pair).expect("valid parameters");
    params
        .downcast::<<LinearCohesionContact as ContactLaw>::Params>()
        .map(|b| *b)
        .unwrap_or_else(|_| panic!("the law's parameter type"))
}

/// Two bodies along a fixed normal +z at overlap `delta`, with normal velocity `vn`
/// (positive separating) and the displacement of a step from `previous_delta`.
fn kinematics(delta: f64, previous_delta: f64, vn: f64) -> ContactKinematics {
    let normal = DVec3::Z;
    let relative_velocity = normal * vn;
    ContactKinematics {
        normal,
        overlap: delta,
        point: DVec3::ZERO,
        branch_a: -normal * (1e-3 - 0.5 * delta),
        branch_b: normal * (1e-3 - 0.5 * delta),
        relative_velocity,
        normal_velocity: vn,
        tangential_velocity: DVec3::ZERO,
        // a approaches b (displacement against the normal) when the overlap grows.
        displacement: -normal * (delta - previous_delta),
        previous_overlap: previous_delta,
        previous_normal: normal,
        relative_omega: DVec3::ZERO,
        effective_mass: REDUCED_MASS,
        effective_radius: 5e-4,
        min_radius: 1e-3,
    }
}

/// The closed forms the law must follow.
fn analytic_force(delta: f64) -> f64 {
    let spring = NORMAL_STIFFNESS * delta.max(0.0);
    let cohesion = if delta >= -RANGE {
        -(ADHESION_FORCE + ADHESION_STIFFNESS * delta)
    } else {
        0.0
    };
    spring + cohesion
}

fn analytic_energy(delta: f64) -> f64 {
    let spring = 0.5 * NORMAL_STIFFNESS * delta.max(0.0).powi(2);
    let cohesion = if delta >= -RANGE {
        -(ADHESION_FORCE + ADHESION_STIFFNESS * delta).powi(2) / (2.0 * ADHESION_STIFFNESS)
    } else {
        0.0
    };
    spring + cohesion
}

/// Overlaps from twice the range across the gap to 3 times the range into the overlap.
fn overlaps() -> impl Iterator<Item = f64> {
    (0..=500).map(|k| RANGE * (-2.0 + 5.0 * k as f64 / 500.0))
}

#[test]
fn force_follows_the_linear_adhesion_formula_across_gap_and_overlap() {
    let p = resolved(&sticky(1.0, 0.0));
    for delta in overlaps() {
        // A fresh contact at rest at this overlap: no dashpot, no history.
        let mut h = Default::default();
        let r = LinearCohesionContact::evaluate(&p, &kinematics(delta, delta, 0.0), &mut h, 0.0);
        let expected = analytic_force(delta);
        assert!(
            (r.force.z - expected).abs() <= 1e-12 * ADHESION_FORCE.max(expected.abs()),
            "δ = {delta:e}: force {} N, formula {expected} N",
            r.force.z
        );
        assert_eq!(r.force.x, 0.0);
        assert_eq!(r.force.y, 0.0);
    }
    // The sub-model alone: −f_0 at touch, zero at the range and beyond.
    let c = CohesionParams {
        adhesion_force: ADHESION_FORCE,
        adhesion_stiffness: ADHESION_STIFFNESS,
    };
    assert_eq!(c.force(0.0), -ADHESION_FORCE);
    assert_eq!(c.force(-RANGE), 0.0);
    assert_eq!(c.force(-2.0 * RANGE), 0.0);
    assert!(c.force(-0.999 * RANGE) < 0.0);
}

#[test]
fn range_is_adhesion_force_over_adhesion_stiffness() {
    let law = descriptor();
    let values = sticky(0.5, 0.3).values;
    assert_eq!(
        law.interaction_range(&values),
        ADHESION_FORCE / ADHESION_STIFFNESS
    );
    let c = CohesionParams {
        adhesion_force: ADHESION_FORCE,
        adhesion_stiffness: ADHESION_STIFFNESS,
    };
    assert_eq!(c.range(), RANGE);
    // No adhesion force: a pull only inside the overlap, no range.
    let mut no_pull = values.clone();
    no_pull.set("adhesion_force", 0.0);
    assert_eq!(law.interaction_range(&no_pull), 0.0);
    // Incomplete values give no range instead of a division by zero.
    assert_eq!(law.interaction_range(&ParamValues::default()), 0.0);
    // Friction needs rotation; cohesion alone does not.
    assert!(law.produces_torque(&values));
    assert!(!law.produces_torque(&sticky(0.5, 0.0).values));
}

#[test]
fn stored_energy_is_the_integral_of_the_force_from_the_range() {
    let p = resolved(&sticky(1.0, 0.0));
    // U(δ) = ∫_{−r}^{δ} F(x) dx, F positive repulsive. Simpson's rule on a grid whose
    // nodes include −r and 0 (the kinks) is exact for the piecewise quadratic U.
    let integral = |delta: f64| {
        if delta <= -RANGE {
            return 0.0;
        }
        let simpson = |a: f64, b: f64| {
            let n = 64;
            let h = (b - a) / n as f64;
            let mut sum = analytic_force(a) + analytic_force(b);
            for k in 1..n {
                let w = if k % 2 == 1 { 4.0 } else { 2.0 };
                sum += w * analytic_force(a + k as f64 * h);
            }
            sum * h / 3.0
        };
        if delta <= 0.0 {
            simpson(-RANGE, delta)
        } else {
            simpson(-RANGE, 0.0) + simpson(0.0, delta)
        }
    };
    // Well depth at touch: f_0²/(2k_c).
    assert!((integral(0.0) + ADHESION_FORCE.powi(2) / (2.0 * ADHESION_STIFFNESS)).abs() < 1e-18);
    let c = CohesionParams {
        adhesion_force: ADHESION_FORCE,
        adhesion_stiffness: ADHESION_STIFFNESS,
    };
    for delta in overlaps() {
        let mut h = Default::default();
        let r = LinearCohesionContact::evaluate(&p, &kinematics(delta, delta, 0.0), &mut h, 0.0);
        let scale = ADHESION_FORCE * RANGE;
        let spring = 0.5 * NORMAL_STIFFNESS * delta.max(0.0).powi(2);
        assert!((c.potential(delta) + spring - analytic_energy(delta)).abs() < 1e-12 * scale);
        assert!(
            (r.elastic_energy - analytic_energy(delta)).abs() < 1e-12 * scale,
            "δ = {delta:e}: stored {} J, closed form {} J",
            r.elastic_energy,
            analytic_energy(delta)
        );
        assert!(
            (r.elastic_energy - integral(delta)).abs() < 1e-12 * scale,
            "δ = {delta:e}: stored {} J, ∫F dδ = {} J",
            r.elastic_energy,
            integral(delta)
        );
    }
}

#[test]
fn integration_error_vanishes_where_the_force_is_linear_and_the_path_closes() {
    // A contact entering the range, pressed to 2r, and pulled out again, with no
    // damping: every step where the force is linear over the step books no integration
    // error; the steps over a kink (the range, touch) book O(k Δδ²), and so does the step
    // after touch or separation, where the linear spring's first force and its release
    // pull finish their trapezoidal work (linear_spring's `onset_weight`).
    let p = resolved(&sticky(1.0, 0.0));
    let steps = 2000;
    let path = |k: usize| {
        let t = k as f64 / steps as f64;
        -1.5 * RANGE + 3.5 * RANGE * (std::f64::consts::PI * t).sin()
    };
    let mut h = Default::default();
    let mut previous = path(0);
    let mut total_error = 0.0;
    let mut kink_bound = 0.0;
    let mut touch_crossed = false;
    for k in 1..=steps {
        let delta = path(k);
        let r =
            LinearCohesionContact::evaluate(&p, &kinematics(delta, previous, 0.0), &mut h, 1e-5);
        let (lo, hi) = (previous.min(delta), previous.max(delta));
        let crosses_touch = lo < 0.0 && hi > 0.0;
        let crosses_kink = (lo < -RANGE && hi > -RANGE) || crosses_touch || touch_crossed;
        touch_crossed = crosses_touch;
        let step = hi - lo;
        if crosses_kink {
            kink_bound += (NORMAL_STIFFNESS + ADHESION_STIFFNESS) * step * step;
        } else {
            assert!(
                r.integration_error.abs() < 1e-12 * ADHESION_FORCE * RANGE,
                "step {k} (δ = {delta:e}): integration error {}",
                r.integration_error
            );
        }
        assert!(
            r.dissipated.iter().all(|&d| d == 0.0),
            "restitution 1 dissipates nothing"
        );
        total_error += r.integration_error;
        previous = delta;
    }
    assert!(kink_bound > 0.0, "the path crosses the kinks");
    assert!(
        total_error.abs() <= kink_bound,
        "integration error {total_error} J above the kink bound {kink_bound} J"
    );
}

#[test]
fn dashpot_and_friction_act_only_while_the_bodies_overlap() {
    let p = resolved(&sticky(0.3, 0.5));
    // In the gap, approaching fast with a tangential slip: only the pull acts.
    let delta = -0.5 * RANGE;
    let mut kin = kinematics(delta, delta - 1e-7, -0.1);
    kin.tangential_velocity = DVec3::X * 0.05;
    kin.relative_velocity += kin.tangential_velocity;
    let mut h = Default::default();
    let r = LinearCohesionContact::evaluate(&p, &kin, &mut h, 1e-5);
    assert_eq!(r.force, DVec3::Z * analytic_force(delta));
    assert!(r.dissipated.iter().all(|&d| d == 0.0));
    // Inside the overlap the dashpot adds −c_n v_n with c_n = 2ζ√(m* k_n).
    let delta = 0.5 * RANGE;
    let mut h = Default::default();
    let r = LinearCohesionContact::evaluate(&p, &kinematics(delta, delta, -0.1), &mut h, 0.0);
    let ln = 0.3f64.ln();
    let zeta = -ln / (std::f64::consts::PI.powi(2) + ln * ln).sqrt();
    let c = 2.0 * zeta * (REDUCED_MASS * NORMAL_STIFFNESS).sqrt();
    let expected = analytic_force(delta) + c * 0.1;
    assert!(
        (r.force.z - expected).abs() < 1e-12 * expected.abs(),
        "{} vs {expected}",
        r.force.z
    );
}

#[test]
fn parameters_are_declared_checked_and_mixed() {
    let law = descriptor();
    let names: Vec<&str> = law.params().iter().map(|s| s.name).collect();
    for name in [
        "stiffness",
        "restitution",
        "friction",
        "adhesion_force",
        "adhesion_stiffness",
    ] {
        assert!(names.contains(&name), "{name} declared");
    }
    assert_eq!(
        LinearCohesionContact::dissipation(),
        ["normal_damping", "tangential_damping", "friction_slip"]
    );
    assert!(
        law.parts()
            .contains(&(SubModelKind::Cohesion, "linear_cohesion"))
    );

    // Missing parameters are named.
    let mut missing = sticky(0.5, 0.0).values;
    missing.0.retain(|(n, _)| n != "adhesion_stiffness");
    let err = law.validate(&missing).unwrap_err();
    assert_eq!(err.field, "adhesion_stiffness");
    let err = law.resolve(&pair(&[
        ("stiffness", 1e4),
        ("restitution", 0.5),
        ("adhesion_stiffness", 10.0),
    ]));
    assert_eq!(
        err.err().map(|e| e.field),
        Some("adhesion_force".to_string())
    );
    // Ranges are the declared ones: f_0 ≥ 0, k_c > 0.
    let specs = law.params();
    let negative = ParamValues(vec![("adhesion_force".into(), -1.0)]);
    assert_eq!(
        check_params(specs, &negative).unwrap_err().field,
        "adhesion_force"
    );
    let zero = ParamValues(vec![("adhesion_stiffness".into(), 0.0)]);
    assert_eq!(
        check_params(specs, &zero).unwrap_err().field,
        "adhesion_stiffness"
    );
    // k_c ≥ k_n would leave nothing to push the bodies apart.
    let mut too_stiff = sticky(0.5, 0.0);
    too_stiff.values.set("adhesion_stiffness", NORMAL_STIFFNESS);
    let err = law.resolve(&too_stiff).expect_err("k_c = k_n is refused");
    assert_eq!(err.field, "adhesion_stiffness");
    // The same with k_n from a collision time: k_n = m* (π² + ln²e)/t_c².
    let from_time = pair(&[
        ("collision_time", 1e-3),
        ("restitution", 1.0),
        ("adhesion_force", 0.01),
        ("adhesion_stiffness", 1e3),
    ]);
    let kn = REDUCED_MASS * std::f64::consts::PI.powi(2) / 1e-6;
    assert!(kn > 1e3, "k_n = {kn} N/m lies above k_c");
    assert!(law.resolve(&from_time).is_ok());

    // Mixing: geometric f_0 (a non-sticky material sticks to nothing), harmonic k_c.
    let specs = crate::cohesion::PARAMS;
    let a = ParamValues(vec![
        ("adhesion_force".into(), 0.04),
        ("adhesion_stiffness".into(), 1000.0),
    ]);
    let b = ParamValues(vec![
        ("adhesion_force".into(), 0.01),
        ("adhesion_stiffness".into(), 3000.0),
    ]);
    let mixed = ParamValues::mix(specs, &a, &b);
    assert!((mixed.get("adhesion_force").unwrap() - 0.02).abs() < 1e-15);
    assert!((mixed.get("adhesion_stiffness").unwrap() - 1500.0).abs() < 1e-12);
    let none = ParamValues(vec![
        ("adhesion_force".into(), 0.0),
        ("adhesion_stiffness".into(), 3000.0),
    ]);
    assert_eq!(
        ParamValues::mix(specs, &a, &none).get("adhesion_force"),
        Some(0.0)
    );
}

#[test]
fn time_step_comes_from_the_normal_spring_below_the_adhesion_stiffness() {
    let law = descriptor();
    let (_, ts) = law.resolve(&sticky(1.0, 0.0)).unwrap();
    // The normal part's contact time π√(m*/k_n) is shorter than the pull's π√(m*/k_c).
    let normal = std::f64::consts::PI * (REDUCED_MASS / NORMAL_STIFFNESS).sqrt();
    assert!((ts.contact_time - normal).abs() < 1e-12 * normal);
    let c = CohesionParams {
        adhesion_force: ADHESION_FORCE,
        adhesion_stiffness: ADHESION_STIFFNESS,
    };
    let own = <LinearCohesion as SubModel>::time_scale(&c, &sticky(1.0, 0.0)).unwrap();
    assert!(own.contact_time > ts.contact_time);
}
