//! The HDEM rolling part (`rolling: "hdem"`): hysteresis spring, dashpot, slider and
//! no-tension joint in the rolling direction (seed 001, Fig. 4).
//!
//! Kinematics, stiffness rule, dashpot and time scale follow
//! [`talus_rolling_resistance::ElasticPlasticRolling`] (the "conventional" model of the
//! paper), so that with β = 1 the two parts coincide in 2-D. The spring is the scalar
//! [`HysteresisState`] acting along a rolling axis: in 2-D the z axis; in 3-D the axis
//! of the first rolling rotation of the contact, carried with the rolling plane as the
//! normal turns, and re-aligned with the rolling direction while the slider slides.

use std::marker::PhantomData;

use glam::DVec3;
use talus_contact::compose::is_two_dimensional;
use talus_contact::*;
use talus_linear_spring::rotate_into_plane;
use talus_rolling_resistance::RollingStiffness;
use talus_rolling_resistance::element::{
    centre_inertia_factor, contact_inertia_factor, contact_spin_inertia, min_spin_inertia,
    normal_frequency, oscillator_limit, rolling_part, torque_limit,
};

use crate::hysteresis::{HysteresisLimits, HysteresisState};

/// Scene name of [`HdemRolling`].
pub const HDEM: &str = "hdem";

/// β fitted to polyurethane cylinders in seed 001 (mean of its Fig. 11).
pub const POLYURETHANE_EXPONENT: f64 = 0.844;
/// β fitted to aluminium cylinders in seed 001 (mean of its Fig. 11).
pub const ALUMINIUM_EXPONENT: f64 = 0.874;
/// Default hysteresis exponent: the polyurethane value.
pub const DEFAULT_HYSTERESIS_EXPONENT: f64 = POLYURETHANE_EXPONENT;
/// Default ceiling of the tangent stiffness, in units of K_r.
pub const DEFAULT_STIFFNESS_CEILING: f64 = 10.0;
/// Default rolling damping ratio η_r (the elastic–plastic part's default).
pub const DEFAULT_ROLLING_DAMPING_RATIO: f64 = 0.3;
/// Ai et al.'s rolling stiffness factor, k_r = 2.25 μ_r² R*² k_n (the default rule).
pub const AI_ROLLING_STIFFNESS_FACTOR: f64 = 2.25;

/// Index of the hysteresis channel in [`HdemRolling`]'s `DISSIPATION`.
pub const HYSTERESIS_CHANNEL: usize = 0;
/// Index of the dashpot channel.
pub const DAMPING_CHANNEL: usize = 1;
/// Index of the slider channel.
pub const SLIP_CHANNEL: usize = 2;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "rolling_friction",
        unit: "1",
        doc: "rolling friction coefficient μ_r: elastic limit and slider at μ_r F_n R* (required)",
        range: ParamRange::NON_NEGATIVE,
        default: None,
        mix: MixRule::Geometric,
    },
    ParamSpec {
        name: "rolling_stiffness",
        unit: "N m/rad",
        doc: "reference rolling stiffness K_r (secant of the first loading branch), the same for every contact; give this or `rolling_stiffness_ratio`, or neither",
        range: ParamRange::POSITIVE,
        default: None,
        mix: MixRule::Harmonic,
    },
    ParamSpec {
        name: "rolling_stiffness_ratio",
        unit: "1",
        doc: "K_r / (k_n R*²) with k_n the current normal stiffness; absent: 2.25 μ_r² (Ai et al. 2011)",
        range: ParamRange::POSITIVE,
        default: None,
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "rolling_damping_ratio",
        unit: "1",
        doc: "ζ: the rolling dashpot is c_r = 2 ζ √(J_z K_r) (seed 001 eq. (22)), active while the slider holds",
        range: ParamRange::NON_NEGATIVE,
        default: Some(DEFAULT_ROLLING_DAMPING_RATIO),
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "hysteresis_exponent",
        unit: "1",
        doc: "β of the hysteresis spring, in (0, 1]: 0.844 polyurethane, 0.874 aluminium (seed 001); 1 is the linear spring",
        range: ParamRange::UNIT_OPEN_CLOSED,
        default: Some(DEFAULT_HYSTERESIS_EXPONENT),
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "hysteresis_stiffness_ceiling",
        unit: "1",
        doc: "largest tangent stiffness of a branch, in units of K_r (the power law's slope is infinite where a branch starts)",
        range: ParamRange {
            min: 1.0,
            min_inclusive: true,
            max: f64::INFINITY,
            max_inclusive: false,
        },
        default: Some(DEFAULT_STIFFNESS_CEILING),
        mix: MixRule::Arithmetic,
    },
];

/// HDEM rolling resistance: hysteresis spring (eqs. (11)–(13) of seed 001, power-law
/// loading from every reversal point), dashpot c_r = 2ζ√(J_z K_r) while the spring
/// holds, slider at μ_r F_n R*, no tension (F_n < 0 counts as 0). `N` is the law's
/// normal part: K_r may follow its stiffness, and the stability estimate its time scale.
pub struct HdemRolling<N>(PhantomData<fn() -> N>);

/// Resolved parameters of [`HdemRolling`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HdemParams {
    /// Rolling friction coefficient μ_r.
    pub friction: f64,
    /// Reference stiffness rule K_r.
    pub stiffness: RollingStiffness,
    /// Damping ratio ζ of the dashpot.
    pub damping_ratio: f64,
    /// Exponent β.
    pub exponent: f64,
    /// Ceiling of the tangent stiffness, in units of K_r.
    pub stiffness_ceiling: f64,
    /// Disks in the xy-plane.
    pub planar: bool,
}

/// Per-contact history of [`HdemRolling`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HdemHistory {
    /// The hysteresis spring.
    pub spring: HysteresisState,
    /// Unit rolling axis of the spring (zero until the contact first rolls; z in 2-D).
    pub axis: DVec3,
    /// Spring torque on `a` of the last evaluation, N m.
    pub spring_torque: DVec3,
    /// Dashpot torque on `a` of the last evaluation, N m.
    pub dashpot_torque: DVec3,
    /// Recoverable energy of the spring after the last evaluation, J.
    pub stored: f64,
}

fn required(field: &str, what: &str) -> ParamError {
    ParamError {
        field: field.into(),
        expected: format!("{what}, required by the rolling part `{HDEM}`"),
    }
}

impl<N: SubModel> SubModel for HdemRolling<N> {
    const KIND: SubModelKind = SubModelKind::Rolling;
    const NAME: &'static str = HDEM;
    const PARAMS: &'static [ParamSpec] = PARAMS;
    const DISSIPATION: &'static [&'static str] =
        &["rolling_hysteresis", "rolling_damping", "rolling_slip"];
    type Params = HdemParams;
    type History = HdemHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        if values.get("rolling_friction").is_none() {
            return Err(required(
                "rolling_friction",
                "a rolling friction coefficient μ_r",
            ));
        }
        if values.get("rolling_stiffness").is_some()
            && values.get("rolling_stiffness_ratio").is_some()
        {
            return Err(ParamError {
                field: "rolling_stiffness_ratio".into(),
                expected: "either `rolling_stiffness` or `rolling_stiffness_ratio`, not both"
                    .into(),
            });
        }
        Ok(())
    }

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<HdemParams, ParamError> {
        Self::validate(values)?;
        let friction = values.get("rolling_friction").unwrap_or(0.0);
        let stiffness = match (
            values.get("rolling_stiffness"),
            values.get("rolling_stiffness_ratio"),
        ) {
            (Some(k), _) => RollingStiffness::Absolute(k),
            (None, Some(ratio)) => RollingStiffness::Ratio(ratio),
            (None, None) => {
                RollingStiffness::Ratio(AI_ROLLING_STIFFNESS_FACTOR * friction * friction)
            }
        };
        Ok(HdemParams {
            friction,
            stiffness,
            damping_ratio: values
                .get("rolling_damping_ratio")
                .unwrap_or(DEFAULT_ROLLING_DAMPING_RATIO),
            exponent: values
                .get("hysteresis_exponent")
                .unwrap_or(DEFAULT_HYSTERESIS_EXPONENT),
            stiffness_ceiling: values
                .get("hysteresis_stiffness_ceiling")
                .unwrap_or(DEFAULT_STIFFNESS_CEILING),
            planar: is_two_dimensional(pair),
        })
    }

    fn needs(_values: &ParamValues) -> Needs {
        Needs::ROTATION
    }

    /// As the elastic–plastic part, with the spring at its stiffest, the ceiling times
    /// K_r: the oscillator of that stiffness against the smallest spin inertia
    /// κ m*_min R*_min² is stable for dt < 2/ω (√(1 + ζ²) − ζ).
    fn time_scale(p: &HdemParams, pair: &PairAssignment) -> Option<TimeScale> {
        let planar = is_two_dimensional(pair);
        let kappa = centre_inertia_factor(planar);
        let omega = match p.stiffness {
            RollingStiffness::Absolute(k) => {
                (p.stiffness_ceiling * k / min_spin_inertia(pair, planar)).sqrt()
            }
            RollingStiffness::Ratio(ratio) => {
                normal_frequency::<N>(pair)? * (p.stiffness_ceiling * ratio / kappa).sqrt()
            }
        };
        let zeta = p.damping_ratio * (contact_inertia_factor(planar) / kappa).sqrt();
        oscillator_limit(omega, zeta)
    }

    #[inline]
    fn evaluate(
        p: &HdemParams,
        kin: &ContactKinematics,
        h: &mut HdemHistory,
        s: &mut ContactState,
        dt: f64,
    ) {
        let n = kin.normal;
        let full_increment = kin.relative_omega * dt;
        let radius = kin.effective_radius;
        let stiffness = match p.stiffness {
            RollingStiffness::Ratio(ratio) => ratio * s.normal_stiffness * radius * radius,
            RollingStiffness::Absolute(k) => k,
        };
        if kin.overlap <= 0.0 || !(stiffness > 0.0 && stiffness.is_finite()) {
            // Ended (or no spring this step): the last torques worked over the first half
            // of the step; what the spring still held is released through the slider.
            let spring_work = 0.5 * h.spring_torque.dot(full_increment);
            s.dissipate(SLIP_CHANNEL, h.stored - spring_work);
            s.dissipate(DAMPING_CHANNEL, -0.5 * h.dashpot_torque.dot(full_increment));
            *h = HdemHistory::default();
            return;
        }
        let increment = rolling_part(full_increment, n, p.planar);
        let rate = rolling_part(kin.relative_omega, n, p.planar);
        let limits = HysteresisLimits {
            stiffness,
            limit_moment: torque_limit(p.friction, s, radius),
            exponent: p.exponent,
            stiffness_ceiling: p.stiffness_ceiling * stiffness,
        };
        // The spring's axis: fixed in 2-D; in 3-D carried into the new rolling plane, or
        // taken from the first rolling rotation of the contact.
        let mut axis = if p.planar {
            DVec3::Z
        } else {
            rotate_into_plane(h.axis, n).normalize_or_zero()
        };
        if axis == DVec3::ZERO {
            axis = increment.normalize_or_zero();
        }
        let along = increment.dot(axis);
        let sliding_before = h.spring.branch == crate::hysteresis::Branch::Loading
            && h.spring.moment(&limits).abs() >= limits.limit_moment;
        if !p.planar && sliding_before && along > 0.0 {
            // While the slider slides it resists the rolling direction, whatever it is:
            // re-align the spring's axis with the rotation (the held moment is M_e either
            // way), so that a sphere rolling along a curve meets the limit torque.
            axis = increment.normalize_or_zero();
        }
        let along = if axis == DVec3::ZERO {
            0.0
        } else {
            increment.dot(axis)
        };
        let stored_before = h.spring.recoverable_energy(&limits);
        let step = h.spring.advance(along, &limits);
        let stored = h.spring.recoverable_energy(&limits);
        let moment = h.spring.moment(&limits);
        let spring_torque = axis * -moment;
        // Exact work into the spring = Δ(recoverable) + hysteresis loss + slip; the
        // change of the limit with F_n between steps shows up in the stored energy
        // (stored_before is taken with this step's limits) and is booked with the loss.
        let hysteresis = step.branch_work - (stored - stored_before);
        let released = stored_before - h.stored;
        s.dissipate(HYSTERESIS_CHANNEL, hysteresis - released);
        s.dissipate(SLIP_CHANNEL, step.slip);
        s.elastic_energy += stored;
        // Trapezoidal work of the spring torques on the bodies + Δstored + dissipation:
        // the energy the explicit integration created (zero up to O(dt²) per step).
        let spring_work = 0.5 * (h.spring_torque + spring_torque).dot(full_increment);
        s.integration_error += spring_work + step.branch_work + step.slip;
        // The dashpot acts while the spring holds (as in the elastic–plastic part).
        let dashpot = if step.sliding {
            DVec3::ZERO
        } else {
            rate * -(p.damping_ratio
                * 2.0
                * (contact_spin_inertia(p.planar, kin) * stiffness).sqrt())
        };
        s.dissipate(
            DAMPING_CHANNEL,
            -0.5 * (h.dashpot_torque + dashpot).dot(full_increment),
        );
        h.axis = axis;
        h.spring_torque = spring_torque;
        h.dashpot_torque = dashpot;
        h.stored = stored;
        s.torque_a += spring_torque + dashpot;
        s.torque_b -= spring_torque + dashpot;
    }
}
