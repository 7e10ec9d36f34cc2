//! The HDEM rolling part driven directly through prescribed rotations: the branches of
//! eqs. (12)–(13), the loop loss against its analytic area at two loading rates a
//! decade apart, the linear limit β = 1, and bad input.

use glam::DVec3;
use talus_contact::{ContactKinematics, ContactState, SubModel};
use talus_hdem::hysteresis::loop_loss;
use talus_hdem::rolling::{DAMPING_CHANNEL, HYSTERESIS_CHANNEL, SLIP_CHANNEL};
use talus_hdem::{HdemHistory, HdemParams, HdemRolling, HysteresisLimits, HysteresisState};
use talus_linear_spring::parts::LinearNormal;
use talus_rolling_resistance::RollingStiffness;

type Part = HdemRolling<LinearNormal>;

const NORMAL_FORCE: f64 = 1.0; // N
const RADIUS: f64 = 1.0; // m (lever R*)
const FRICTION: f64 = 0.01; // μ_r: M_e = 0.01 N m
const STIFFNESS: f64 = 1.0; // K_r, N m/rad: Δ_e = 0.01 rad

fn params(exponent: f64) -> HdemParams {
    HdemParams {
        friction: FRICTION,
        stiffness: RollingStiffness::Absolute(STIFFNESS),
        damping_ratio: 0.0,
        exponent,
        stiffness_ceiling: 10.0,
        planar: true,
    }
}

fn limits(exponent: f64) -> HysteresisLimits {
    HysteresisLimits {
        stiffness: STIFFNESS,
        limit_moment: FRICTION * NORMAL_FORCE * RADIUS,
        exponent,
        stiffness_ceiling: 10.0 * STIFFNESS,
    }
}

/// Totals of a prescribed rotation run.
#[derive(Default, Debug)]
struct Totals {
    hysteresis: f64,
    damping: f64,
    slip: f64,
    integration_error: f64,
    /// Trapezoidal ∮ −T·dθ of the torques (the work done on the spring).
    work_on_spring: f64,
}

/// Drives a 2-D contact (normal +y, F_n = 1 N) through θ(t) for the steps in `range`,
/// each step with ω = (θ(t+dt) − θ(t))/dt, so the spring follows θ exactly. Returns the
/// totals booked during the steps `measure` (a sub-range).
fn drive(
    p: &HdemParams,
    theta: impl Fn(f64) -> f64,
    dt: f64,
    steps: usize,
    measure: std::ops::Range<usize>,
    history: &mut HdemHistory,
) -> Totals {
    let mut totals = Totals::default();
    let mut previous_torque = 0.0;
    for k in 0..steps {
        let omega = (theta((k + 1) as f64 * dt) - theta(k as f64 * dt)) / dt;
        let kin = ContactKinematics {
            normal: DVec3::Y,
            overlap: 1e-6,
            relative_omega: DVec3::new(0.0, 0.0, omega),
            effective_mass: 1.0,
            effective_radius: RADIUS,
            min_radius: RADIUS,
            ..Default::default()
        };
        let mut state = ContactState {
            normal_elastic: NORMAL_FORCE,
            normal_stiffness: 1e6,
            ..Default::default()
        };
        Part::evaluate(p, &kin, history, &mut state, dt);
        if measure.contains(&k) {
            totals.hysteresis += state.dissipated[HYSTERESIS_CHANNEL];
            totals.damping += state.dissipated[DAMPING_CHANNEL];
            totals.slip += state.dissipated[SLIP_CHANNEL];
            totals.integration_error += state.integration_error;
            totals.work_on_spring -= 0.5 * (previous_torque + state.torque_a.z) * omega * dt;
        }
        previous_torque = state.torque_a.z;
    }
    totals
}

/// The energy lost in one closed loop θ: A → −A → A (after the first loading from rest),
/// at periods 0.1 s and 1 s with the same step, against 2 (1 − β)/(1 + β) M_A A.
#[test]
fn loop_loss_is_rate_independent_and_equals_the_analytic_area() {
    let beta = 0.844;
    let p = params(beta);
    let amplitude = 0.5 * limits(beta).limit_deformation();
    let analytic = loop_loss(&limits(beta), amplitude);
    let dt: f64 = 1e-4;
    let mut losses = Vec::new();
    for period in [0.1f64, 1.0] {
        let per = (period / dt).round() as usize;
        let quarter = per / 4;
        let theta = |t: f64| amplitude * (2.0 * std::f64::consts::PI * t / period).sin();
        let mut history = HdemHistory::default();
        let totals = drive(
            &p,
            theta,
            dt,
            per + quarter,
            quarter..per + quarter,
            &mut history,
        );
        let error = (totals.hysteresis - analytic).abs() / analytic;
        let trapezoid = (totals.work_on_spring - analytic).abs() / analytic;
        eprintln!(
            "period {period} s: loop loss {:.6e} J, analytic {analytic:.6e} J, relative error {error:.2e}; \
             trapezoidal ∮M dθ {:.6e} J (error {trapezoid:.2e}); dashpot {:.1e}, slip {:.1e}, integration error {:.2e} J",
            totals.hysteresis,
            totals.work_on_spring,
            totals.damping,
            totals.slip,
            totals.integration_error
        );
        assert!(
            error < 1e-3,
            "loop loss {} against {analytic}",
            totals.hysteresis
        );
        assert!(
            trapezoid < 1e-2,
            "trapezoidal loop work {}",
            totals.work_on_spring
        );
        assert_eq!(totals.slip, 0.0);
        losses.push(totals.hysteresis);
    }
    let spread = (losses[0] - losses[1]).abs() / losses[1];
    eprintln!("rate dependence over a decade: {spread:.2e}");
    assert!(spread < 0.01, "losses {losses:?}");
}

/// First loading from the origin is eq. (13), M = M_e (Δ/Δ_e)^β; unloading from
/// (Δ_rev, M_rev) is eq. (12), M = M_rev [1 − (1 − Δ/Δ_rev)^β]; past Δ_e the slider
/// holds M_e and books M_e times the slipped rotation.
#[test]
fn branches_follow_equations_12_and_13() {
    let beta = 0.874;
    let l = limits(beta);
    let de = l.limit_deformation();
    let me = l.limit_moment;
    let mut spring = HysteresisState::default();
    spring.advance(0.25 * de, &l);
    let loading = spring.moment(&l);
    let expected = me * 0.25f64.powf(beta);
    assert!(
        (loading - expected).abs() < 1e-12 * me,
        "{loading} vs {expected}"
    );
    // Unload half way back.
    let (rev_d, rev_m) = (spring.deformation, loading);
    spring.advance(-0.125 * de, &l);
    let unloading = spring.moment(&l);
    let expected = rev_m * (1.0 - (1.0 - 0.125 * de / rev_d).powf(beta));
    assert!(
        (unloading - expected).abs() < 1e-12 * me,
        "{unloading} vs {expected}"
    );
    // Load far past the limit: slides at M_e.
    let mut spring = HysteresisState::default();
    let step = spring.advance(3.0 * de, &l);
    assert!(step.sliding);
    assert!((spring.moment(&l) - me).abs() < 1e-15);
    assert!((step.slip - me * 2.0 * de).abs() < 1e-12 * me * de);
    assert!((spring.deformation - de).abs() < 1e-15);
}

/// β = 1: the spring is linear (K_r), its loops lose nothing.
#[test]
fn exponent_one_is_a_linear_spring_without_loss() {
    let p = params(1.0);
    let amplitude = 0.5 * limits(1.0).limit_deformation();
    let dt: f64 = 1e-4;
    let theta = |t: f64| amplitude * (2.0 * std::f64::consts::PI * t / 0.1).sin();
    let mut history = HdemHistory::default();
    let totals = drive(&p, theta, dt, 1250, 250..1250, &mut history);
    eprintln!("β = 1: loop loss {:.3e} J", totals.hysteresis);
    assert!(totals.hysteresis.abs() < 1e-15);
    let l = limits(1.0);
    let mut spring = HysteresisState::default();
    spring.advance(0.3 * l.limit_deformation(), &l);
    spring.advance(-0.1 * l.limit_deformation(), &l);
    let expected = STIFFNESS * 0.2 * l.limit_deformation();
    assert!((spring.moment(&l) - expected).abs() < 1e-15);
}

/// NaN and infinite rotations, zero or NaN normal forces, and a contact that ends give
/// finite torques and energies, and no panic.
#[test]
fn bad_input_gives_finite_results() {
    let p = params(0.844);
    let mut history = HdemHistory::default();
    for (omega, force, overlap) in [
        (1.0, 1.0, 1e-6),
        (f64::NAN, 1.0, 1e-6),
        (f64::INFINITY, 1.0, 1e-6),
        (1.0, f64::NAN, 1e-6),
        (-1.0, -5.0, 1e-6),
        (1.0, 0.0, 1e-6),
        (1.0, 1.0, -1e-6),
    ] {
        let kin = ContactKinematics {
            normal: DVec3::Y,
            overlap,
            relative_omega: DVec3::new(0.0, 0.0, omega),
            effective_mass: 1.0,
            effective_radius: RADIUS,
            min_radius: RADIUS,
            ..Default::default()
        };
        let mut state = ContactState {
            normal_elastic: force,
            normal_stiffness: 1e6,
            ..Default::default()
        };
        Part::evaluate(&p, &kin, &mut history, &mut state, 1e-4);
        assert!(
            history.spring_torque.is_finite() && history.stored.is_finite(),
            "{history:?} after ω = {omega}, F_n = {force}"
        );
    }
}
