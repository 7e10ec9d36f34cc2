//! The rolling and twisting parts on their own: registration, parameter checks, time
//! scales, 2-D torques along z, no panic on bad input, and, along a synthetic contact
//! path (turning normal, varying overlap and stiffness, loading, sliding, reversing,
//! separating), the energy identity of every step: work of the part's torques on the
//! bodies + change of its stored energy + what it dissipated = the integration error it
//! reports.

use glam::DVec3;
use talus_contact::*;
use talus_core::resources::Dimension;
use talus_linear_spring::parts::{CoulombSpring, LinearDashpot, LinearNormal};
use talus_rolling_resistance::*;

type Rolling = ElasticPlasticRolling<LinearNormal>;
type Twisting = SpringDashpotTwisting<LinearNormal>;

fn values(entries: &[(&str, f64)]) -> ParamValues {
    ParamValues(entries.iter().map(|(k, v)| (k.to_string(), *v)).collect())
}

fn pair(entries: &[(&str, f64)], dimension: Dimension) -> PairAssignment {
    PairAssignment {
        materials: (0, 0),
        names: ("a".into(), "a".into()),
        values: values(entries),
        min_effective_mass: 1e-3,
        min_effective_radius: 5e-4,
        dimension,
        material_values: None,
    }
}

fn registry() -> LawRegistry {
    let mut r = LawRegistry::new();
    talus_linear_spring::register(&mut r);
    register_variants::<LinearNormal, LinearDashpot, CoulombSpring>(
        &mut r,
        "linear_spring",
        "test",
    );
    r
}

#[test]
fn every_rolling_and_twisting_combination_is_registered() {
    let r = registry();
    let mut count = 0;
    for rolling in [
        None,
        Some("constant_torque"),
        Some("viscous"),
        Some("elastic_plastic"),
    ] {
        for twisting in [None, Some("spring_dashpot")] {
            let law = r
                .get_with("linear_spring", rolling, twisting)
                .expect("registered");
            assert_eq!((law.rolling(), law.twisting()), (rolling, twisting));
            count += 1;
        }
    }
    assert_eq!(count, 8);
    assert_eq!(
        r.part_choices("linear_spring", false),
        ROLLING_PARTS.to_vec()
    );
    assert_eq!(
        r.part_choices("linear_spring", true),
        TWISTING_PARTS.to_vec()
    );
    // The base law is still the whole one (it declares no parts).
    assert!(r.get("linear_spring").unwrap().parts().is_empty());
    let law = r
        .get_with(
            "linear_spring",
            Some("elastic_plastic"),
            Some("spring_dashpot"),
        )
        .unwrap();
    let names: Vec<&str> = law.params().iter().map(|p| p.name).collect();
    for name in [
        "stiffness",
        "friction",
        "rolling_friction",
        "rolling_stiffness",
        "rolling_stiffness_ratio",
        "rolling_damping_ratio",
        "twisting_friction",
        "twisting_stiffness_ratio",
        "twisting_damping_ratio",
    ] {
        assert!(names.contains(&name), "{name} not declared: {names:?}");
    }
    for spec in law.params() {
        assert!(!spec.unit.is_empty() && !spec.doc.is_empty(), "{spec:?}");
    }
    assert!(law.produces_torque(&values(&[("stiffness", 1e4), ("restitution", 0.5)])));
}

#[test]
fn missing_and_conflicting_parameters_name_the_field() {
    let base = [("stiffness", 1e4), ("restitution", 0.5)];
    let r = registry();
    let check = |rolling: Option<&str>, twisting: Option<&str>, extra: &[(&str, f64)]| {
        let law = r.get_with("linear_spring", rolling, twisting).unwrap();
        let mut v = values(&base);
        for (k, x) in extra {
            v.set(k, *x);
        }
        let v = check_params(law.params(), &v).unwrap();
        law.validate(&v).map_err(|e| e.field)
    };
    assert_eq!(
        check(Some("constant_torque"), None, &[]),
        Err("rolling_friction".into())
    );
    assert_eq!(
        check(Some("elastic_plastic"), None, &[]),
        Err("rolling_friction".into())
    );
    assert_eq!(
        check(Some("viscous"), None, &[]),
        Err("rolling_damping".into())
    );
    assert_eq!(
        check(None, Some("spring_dashpot"), &[]),
        Err("twisting_friction".into())
    );
    assert_eq!(
        check(
            Some("elastic_plastic"),
            None,
            &[
                ("rolling_friction", 0.1),
                ("rolling_stiffness", 1.0),
                ("rolling_stiffness_ratio", 0.1)
            ]
        ),
        Err("rolling_stiffness_ratio".into())
    );
    assert_eq!(
        check(Some("viscous"), None, &[("rolling_damping", 1e-5)]),
        Ok(())
    );
    assert_eq!(
        check(
            Some("elastic_plastic"),
            Some("spring_dashpot"),
            &[("rolling_friction", 0.1), ("twisting_friction", 0.3)]
        ),
        Ok(())
    );
    // Out of range values are refused by the declared ranges.
    let law = r
        .get_with("linear_spring", Some("constant_torque"), None)
        .unwrap();
    let mut v = values(&base);
    v.set("rolling_friction", -0.1);
    assert_eq!(
        check_params(law.params(), &v).unwrap_err().field,
        "rolling_friction"
    );
    // Resolving without the coefficient is an error too, not a panic.
    assert!(law.resolve(&pair(&base, Dimension::Three)).is_err());
}

#[test]
fn elastic_plastic_defaults_follow_ai() {
    let p = Rolling::resolve(
        &values(&[("rolling_friction", 0.1)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    assert_eq!(p.stiffness, RollingStiffness::Ratio(2.25 * 0.1 * 0.1));
    assert_eq!(p.damping_ratio, 0.3);
    let p = Rolling::resolve(
        &values(&[("rolling_friction", 0.1), ("rolling_stiffness", 2.0)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    assert_eq!(p.stiffness, RollingStiffness::Absolute(2.0));
}

#[test]
fn time_scales_bound_the_stiff_and_viscous_parts() {
    let base = [
        ("stiffness", 1e4),
        ("restitution", 0.5),
        ("rolling_friction", 0.05),
    ];
    let law = |rolling: &str| {
        ComposedLaw::<LinearNormal, LinearDashpot, CoulombSpring, Rolling, Twisting>::new("t", "t")
            .resolve(&pair(
                &[
                    &base[..],
                    &[("twisting_friction", 0.3), ("rolling_damping", 1.0)],
                ]
                .concat(),
                Dimension::Three,
            ))
            .map(|(_, ts)| ts)
            .map_err(|e| format!("{rolling}: {e}"))
    };
    let normal = LinearNormal::time_scale(
        &LinearNormal::resolve(&values(&base), &pair(&base, Dimension::Three)).unwrap(),
        &pair(&base, Dimension::Three),
    )
    .unwrap();
    // Default stiffness, small μ_r and χ: neither spring is stiffer than the normal one.
    let composed = law("elastic_plastic").unwrap();
    assert_eq!(composed.stability_limit, normal.stability_limit);
    assert_eq!(composed.contact_time, normal.contact_time);
    // A rolling spring given directly, stiff against the smallest spin inertia
    // (2/5 m* R*² = 1e-10 kg m²): ω = √(k / I) = 1e6 rad/s, undamped-ish bound 2/ω reduced
    // by the damping ratio η √(7/2).
    let stiff = pair(
        &[
            &base[..],
            &[("rolling_stiffness", 100.0), ("rolling_damping_ratio", 0.0)],
        ]
        .concat(),
        Dimension::Three,
    );
    let p = Rolling::resolve(&stiff.values, &stiff).unwrap();
    let ts = Rolling::time_scale(&p, &stiff).unwrap();
    assert!((ts.stability_limit - 2e-6).abs() < 1e-12, "{ts:?}");
    assert!(ts.contact_time.is_infinite());
    // The viscous part: dt < 2 I / c_r.
    let viscous = pair(&[("rolling_damping", 1e-6)], Dimension::Three);
    let p = ViscousRolling::resolve(&viscous.values, &viscous).unwrap();
    let ts = ViscousRolling::time_scale(&p, &viscous).unwrap();
    assert!(
        (ts.stability_limit - 2.0 * 0.4 * 1e-3 * 25e-8 / 1e-6).abs() < 1e-15,
        "{ts:?}"
    );
    // No twisting in 2-D, so no bound from it.
    let flat = pair(
        &[&base[..], &[("twisting_friction", 0.3)]].concat(),
        Dimension::Two,
    );
    let p = Twisting::resolve(&flat.values, &flat).unwrap();
    assert!(Twisting::time_scale(&p, &flat).is_none());
}

/// A deterministic contact path over `steps` steps: the normal turns, the overlap rises
/// and falls through zero at the end, the relative spin changes sign several times and
/// has rolling and twisting parts.
fn kinematics(step: usize, steps: usize, dt: f64, planar: bool) -> ContactKinematics {
    let t = step as f64 * dt;
    let phase = step as f64 / steps as f64;
    let angle = 0.4 * (t * 30.0).sin();
    let normal = if planar {
        DVec3::new(angle.sin(), angle.cos(), 0.0)
    } else {
        DVec3::new(angle.sin(), 0.3 * angle, angle.cos()).normalize()
    };
    // Positive until the last 2 % of the path.
    let overlap = 2e-6 * ((std::f64::consts::PI * phase / 0.98).sin() + 0.05 * (t * 700.0).sin());
    let omega = if planar {
        DVec3::new(0.0, 0.0, 3.0 * (t * 50.0).cos() + 0.5)
    } else {
        DVec3::new(
            3.0 * (t * 50.0).cos(),
            -2.0 * (t * 23.0).sin() + 0.4,
            5.0 * (t * 17.0).cos(),
        )
    };
    ContactKinematics {
        normal,
        overlap,
        point: DVec3::ZERO,
        branch_a: -normal * 1e-3,
        branch_b: normal * 1e-3,
        relative_velocity: DVec3::ZERO,
        normal_velocity: 0.0,
        tangential_velocity: DVec3::ZERO,
        displacement: DVec3::ZERO,
        // The rolling and twisting parts read neither.
        previous_overlap: 0.0,
        previous_normal: DVec3::ZERO,
        relative_omega: omega,
        effective_mass: 1e-3,
        effective_radius: 5e-4,
        min_radius: 1e-3,
    }
}

/// The state the normal part would leave: a stiffness that varies (as Hertz's does) and
/// the force k_n δ.
fn normal_state(kin: &ContactKinematics, step: usize) -> ContactState {
    let mut s = ContactState::default();
    if kin.overlap > 0.0 {
        s.normal_stiffness = 1e4 * (1.0 + 0.3 * (step as f64 * 0.01).sin());
        s.normal_elastic = s.normal_stiffness * kin.overlap;
    }
    s
}

/// Runs part `P` along the path; returns the largest per-step residual of the energy
/// identity relative to the largest energy flow, the total dissipated, the largest
/// torque component off z (2-D) and the net integration error.
fn energy_identity<P: SubModel>(entries: &[(&str, f64)], planar: bool) -> (f64, f64, f64, f64) {
    let dimension = if planar {
        Dimension::Two
    } else {
        Dimension::Three
    };
    let pair = pair(entries, dimension);
    let params = P::resolve(&pair.values, &pair).unwrap();
    let mut history = P::History::default();
    let (steps, dt) = (4000, 1e-5);
    let (mut old_torque, mut old_energy) = (DVec3::ZERO, 0.0);
    let (mut worst, mut scale, mut dissipated, mut off_plane) = (0.0f64, 0.0f64, 0.0, 0.0f64);
    let mut created = 0.0;
    for step in 0..=steps {
        let kin = kinematics(step, steps, if step == 0 { 0.0 } else { dt }, planar);
        let mut s = normal_state(&kin, step);
        // Step 0 is the priming pass (dt = 0).
        let step_dt = if step == 0 { 0.0 } else { dt };
        P::evaluate(&params, &kin, &mut history, &mut s, step_dt);
        let work = 0.5 * (old_torque + s.torque_a).dot(kin.relative_omega * step_dt);
        let lost: f64 = s.dissipated.iter().sum();
        let residual = work + (s.elastic_energy - old_energy) + lost - s.integration_error;
        worst = worst.max(residual.abs());
        scale = scale.max(work.abs()).max(lost.abs()).max(s.elastic_energy);
        dissipated += lost;
        created += s.integration_error;
        off_plane = off_plane.max(s.torque_a.x.abs()).max(s.torque_a.y.abs());
        assert_eq!(s.torque_b, -s.torque_a, "b gets the opposite torque");
        old_torque = s.torque_a;
        old_energy = s.elastic_energy;
    }
    assert!(scale > 0.0, "the part did something");
    (worst / scale, dissipated, off_plane, created)
}

#[test]
fn every_part_closes_its_energy_step_by_step() {
    let rolling = [("rolling_friction", 0.05)];
    for (name, (residual, dissipated, _, created)) in [
        (
            "constant_torque",
            energy_identity::<ConstantTorque>(&rolling, false),
        ),
        (
            "viscous",
            energy_identity::<ViscousRolling>(
                &[("rolling_damping", 1e-7), ("rolling_friction", 0.05)],
                false,
            ),
        ),
        (
            "elastic_plastic",
            energy_identity::<Rolling>(&rolling, false),
        ),
        (
            "elastic_plastic, stiffness given",
            energy_identity::<Rolling>(
                &[("rolling_friction", 0.05), ("rolling_stiffness", 1e-4)],
                false,
            ),
        ),
        (
            "spring_dashpot",
            energy_identity::<Twisting>(&[("twisting_friction", 0.5)], false),
        ),
    ] {
        eprintln!(
            "{name}: residual {residual:.2e}, dissipated {dissipated:.3e} J, integration error {created:.3e} J"
        );
        assert!(residual < 1e-12, "{name}: residual {residual:e}");
        assert!(dissipated > 0.0, "{name}: dissipated {dissipated:e}");
        // What the time integration creates is only the turning of the contact frame and
        // the change of stiffness within each step: small against the work the part does.
        assert!(
            created.abs() < 1e-3 * dissipated,
            "{name}: integration error {created:e} J"
        );
    }
}

#[test]
fn two_dimensional_torques_are_along_z() {
    let rolling = [("rolling_friction", 0.05)];
    for (name, (residual, _, off_plane, _)) in [
        (
            "constant_torque",
            energy_identity::<ConstantTorque>(&rolling, true),
        ),
        (
            "viscous",
            energy_identity::<ViscousRolling>(&[("rolling_damping", 1e-7)], true),
        ),
        (
            "elastic_plastic",
            energy_identity::<Rolling>(&rolling, true),
        ),
    ] {
        assert_eq!(off_plane, 0.0, "{name}");
        assert!(residual < 1e-12, "{name}: residual {residual:e}");
    }
    // No twisting exists in 2-D: the part does nothing.
    let flat = pair(&[("twisting_friction", 0.5)], Dimension::Two);
    let p = Twisting::resolve(&flat.values, &flat).unwrap();
    let mut h = TorqueSpringHistory::default();
    let kin = kinematics(10, 100, 1e-5, true);
    let mut s = normal_state(&kin, 10);
    Twisting::evaluate(&p, &kin, &mut h, &mut s, 1e-5);
    assert_eq!((s.torque_a, s.elastic_energy), (DVec3::ZERO, 0.0));
}

#[test]
fn the_spring_holds_below_its_cap_and_slides_at_it() {
    let p = Rolling::resolve(
        &values(&[("rolling_friction", 0.1)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    let mut kin = kinematics(1, 100, 1e-5, false);
    kin.normal = DVec3::Z;
    kin.relative_omega = DVec3::new(0.0, 1.0, 0.0);
    let mut h = TorqueSpringHistory::default();
    let mut s = ContactState {
        normal_stiffness: 1e4,
        normal_elastic: 1e4 * kin.overlap,
        ..Default::default()
    };
    let cap = 0.1 * s.normal_elastic * kin.effective_radius;
    let k = 2.25 * 0.01 * 1e4 * kin.effective_radius * kin.effective_radius;
    // One small step: elastic, M_k = −k Δθ, plus the dashpot.
    Rolling::evaluate(&p, &kin, &mut h, &mut s, 1e-6);
    assert!((h.spring.y + k * 1e-6).abs() < 1e-12 * k, "{:?}", h.spring);
    assert!(h.dashpot.y < 0.0);
    // Keep rolling: the spring reaches the cap, the dashpot switches off.
    for _ in 0..100 {
        s.torque_a = DVec3::ZERO;
        Rolling::evaluate(&p, &kin, &mut h, &mut s, 1e-3);
    }
    assert!((h.spring.length() - cap).abs() < 1e-12 * cap);
    assert_eq!(h.dashpot, DVec3::ZERO);
    // Separation releases it.
    kin.overlap = -1e-9;
    let mut s = ContactState::default();
    Rolling::evaluate(&p, &kin, &mut h, &mut s, 1e-5);
    assert_eq!(h, TorqueSpringHistory::default());
    assert!(s.dissipated[1] > 0.0);
}

#[test]
fn bad_kinematics_give_no_panic() {
    let bad = [f64::NAN, f64::INFINITY, -f64::INFINITY, 0.0, -1.0];
    let rolling = Rolling::resolve(
        &values(&[("rolling_friction", 0.1)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    let constant = ConstantTorque::resolve(
        &values(&[("rolling_friction", 0.1)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    let viscous = ViscousRolling::resolve(
        &values(&[("rolling_damping", 1e-6), ("rolling_friction", 0.1)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    let twisting = Twisting::resolve(
        &values(&[("twisting_friction", 0.1)]),
        &pair(&[], Dimension::Three),
    )
    .unwrap();
    for &x in &bad {
        let mut kin = kinematics(5, 100, 1e-5, false);
        kin.overlap = if x.is_nan() { x } else { kin.overlap };
        kin.relative_omega = DVec3::splat(x);
        kin.effective_mass = x;
        kin.effective_radius = x;
        kin.min_radius = x;
        for dt in [1e-5, x] {
            let mut s = normal_state(&kin, 5);
            s.normal_stiffness = x;
            let mut h = TorqueSpringHistory::default();
            Rolling::evaluate(&rolling, &kin, &mut h, &mut s, dt);
            Twisting::evaluate(&twisting, &kin, &mut h, &mut s, dt);
            let mut h = TorqueHistory::default();
            ConstantTorque::evaluate(&constant, &kin, &mut h, &mut s, dt);
            ViscousRolling::evaluate(&viscous, &kin, &mut h, &mut s, dt);
        }
    }
    // Pairs with degenerate masses give no bound rather than a panic.
    let mut degenerate = pair(&[("rolling_damping", 1e-6)], Dimension::Three);
    degenerate.min_effective_mass = 0.0;
    let p = ViscousRolling::resolve(&degenerate.values, &degenerate).unwrap();
    assert!(ViscousRolling::time_scale(&p, &degenerate).is_none());
}
