//! Rolling-resistance parts: constant torque (Ai et al. 2011 model A), viscous torque
//! (model-B-like, capped), and the elastic–plastic spring–dashpot–slider (model C, the
//! Iwashita–Oda "conventional" model of seed 001).
//!
//! The rolling velocity of a contact is the part of the relative spin perpendicular to
//! the normal, ω_r = ω_rel − (ω_rel·n) n with ω_rel = ω_a − ω_b; in 2-D it is the z
//! component of ω_rel. Each part's torque M acts on `a`, −M on `b`, and its limit is
//! μ_r F_n R* with F_n the total normal force (no tension: F_n < 0 counts as 0) and R*
//! the reduced radius (the grain's radius against a wall).

use std::marker::PhantomData;

use glam::DVec3;
use talus_contact::compose::is_two_dimensional;
use talus_contact::*;
use talus_core::lanes::{F4, M4, V4};
use talus_linear_spring::rotate_into_plane;

use crate::element::{
    TorqueSpringHistory, TorqueSpringLaw, centre_inertia_factor, contact_inertia_factor,
    contact_spin_inertia, min_spin_inertia, normal_frequency, oscillator_limit, rolling_part,
    torque_limit,
};

/// Scene name of [`ConstantTorque`].
pub const CONSTANT_TORQUE: &str = "constant_torque";
/// Scene name of [`ViscousRolling`].
pub const VISCOUS: &str = "viscous";
/// Scene name of [`ElasticPlasticRolling`].
pub const ELASTIC_PLASTIC: &str = "elastic_plastic";

/// Default rolling damping ratio η_r of the elastic–plastic part (Ai et al. use 0.3 in
/// their sandpile simulations).
pub const DEFAULT_ROLLING_DAMPING_RATIO: f64 = 0.3;

/// Factor of Ai et al.'s rolling stiffness k_r = 2.25 μ_r² R*² k_n.
pub const AI_ROLLING_STIFFNESS_FACTOR: f64 = 2.25;

const ROLLING_FRICTION_REQUIRED: ParamSpec = ParamSpec {
    name: "rolling_friction",
    unit: "1",
    doc: "rolling friction coefficient μ_r: the torque limit is μ_r F_n R* (required)",
    range: ParamRange::NON_NEGATIVE,
    default: None,
    mix: MixRule::Geometric,
};

const ROLLING_FRICTION_CAP: ParamSpec = ParamSpec {
    name: "rolling_friction",
    unit: "1",
    doc: "rolling friction coefficient μ_r: caps the viscous torque at μ_r F_n R* (absent: no cap)",
    range: ParamRange::NON_NEGATIVE,
    default: None,
    mix: MixRule::Geometric,
};

const ROLLING_DAMPING: ParamSpec = ParamSpec {
    name: "rolling_damping",
    unit: "N m s",
    doc: "rolling dashpot coefficient c_r: M = −c_r ω_r (required)",
    range: ParamRange::NON_NEGATIVE,
    default: None,
    mix: MixRule::Harmonic,
};

const ROLLING_STIFFNESS: ParamSpec = ParamSpec {
    name: "rolling_stiffness",
    unit: "N m/rad",
    doc: "rolling spring stiffness k_r, the same for every contact; give this or `rolling_stiffness_ratio`, or neither",
    range: ParamRange::POSITIVE,
    default: None,
    mix: MixRule::Harmonic,
};

const ROLLING_STIFFNESS_RATIO: ParamSpec = ParamSpec {
    name: "rolling_stiffness_ratio",
    unit: "1",
    doc: "k_r / (k_n R*²) with k_n the current normal stiffness; absent: 2.25 μ_r² (Ai et al. 2011)",
    range: ParamRange::POSITIVE,
    default: None,
    mix: MixRule::Arithmetic,
};

const ROLLING_DAMPING_RATIO: ParamSpec = ParamSpec {
    name: "rolling_damping_ratio",
    unit: "1",
    doc: "η_r: the rolling dashpot is c_r = η_r 2√(I_r k_r), active while the spring holds",
    range: ParamRange::NON_NEGATIVE,
    default: Some(DEFAULT_ROLLING_DAMPING_RATIO),
    mix: MixRule::Arithmetic,
};

/// The error a part reports for a required parameter the scene left out.
fn required(field: &str, what: &str, part: &str) -> ParamError {
    ParamError {
        field: field.into(),
        expected: format!("{what}, required by the rolling part `{part}`"),
    }
}

/// Per-contact history of a part whose torque has no spring: the torque of the last
/// evaluation, for the trapezoidal work of the step.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TorqueHistory {
    /// Torque on `a` of the last evaluation, N m.
    pub torque: DVec3,
}

/// Constant directional torque (Ai et al. 2011 model A): M = −μ_r F_n R* ω_r/|ω_r|,
/// zero when ω_r = 0. It has no state, so at rest it flips sign every step
/// (chatter) instead of holding the grain: that is the model, not a defect of the code.
pub struct ConstantTorque;

/// Resolved parameters of [`ConstantTorque`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantTorqueParams {
    /// Rolling friction coefficient μ_r.
    pub friction: f64,
    /// Disks in the xy-plane: only the z component of rotation exists.
    pub planar: bool,
}

impl SubModel for ConstantTorque {
    const KIND: SubModelKind = SubModelKind::Rolling;
    const NAME: &'static str = CONSTANT_TORQUE;
    const PARAMS: &'static [ParamSpec] = &[ROLLING_FRICTION_REQUIRED];
    const DISSIPATION: &'static [&'static str] = &["rolling_slip"];
    type Params = ConstantTorqueParams;
    type History = TorqueHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        values.get("rolling_friction").map(|_| ()).ok_or_else(|| {
            required(
                "rolling_friction",
                "a rolling friction coefficient μ_r",
                Self::NAME,
            )
        })
    }

    fn resolve(
        values: &ParamValues,
        pair: &PairAssignment,
    ) -> Result<ConstantTorqueParams, ParamError> {
        Self::validate(values)?;
        Ok(ConstantTorqueParams {
            friction: values.get("rolling_friction").unwrap_or(0.0),
            planar: is_two_dimensional(pair),
        })
    }

    fn needs(_values: &ParamValues) -> Needs {
        Needs::ROTATION
    }

    #[inline]
    fn evaluate(
        p: &ConstantTorqueParams,
        kin: &ContactKinematics,
        h: &mut TorqueHistory,
        s: &mut ContactState,
        dt: f64,
    ) {
        let full_increment = kin.relative_omega * dt;
        if kin.overlap <= 0.0 {
            // Ended: the last torque worked over the first half of the step.
            s.dissipate(0, -0.5 * h.torque.dot(full_increment));
            *h = TorqueHistory::default();
            return;
        }
        let rate = rolling_part(kin.relative_omega, kin.normal, p.planar);
        let speed = rate.length();
        let limit = torque_limit(p.friction, s, kin.effective_radius);
        // `speed > 0` is also false for NaN: no direction, no torque.
        let torque = if speed > 0.0 {
            rate * (-limit / speed)
        } else {
            DVec3::ZERO
        };
        s.dissipate(0, -0.5 * (h.torque + torque).dot(full_increment));
        h.torque = torque;
        s.torque_a += torque;
        s.torque_b -= torque;
    }

    const LANES: bool = true;

    #[inline(always)]
    fn evaluate_lanes(
        p: [&ConstantTorqueParams; 4],
        kin: &ContactKinematicsLanes,
        h: [&mut TorqueHistory; 4],
        s: &mut ContactStateLanes,
        dt: f64,
        book: bool,
    ) {
        let zero = F4::zero();
        let released = kin.overlap.le(zero);
        let omega = kin.relative_omega;
        let n = kin.normal;
        // Disks keep only the z component of rotation (`rolling_part`).
        let planar = M4::from_bits((0..4).map(|l| u32::from(p[l].planar) << l).sum());
        let spatial = omega - n * n.dot(omega);
        let rate = V4 {
            x: planar.select(zero, spatial.x),
            y: planar.select(zero, spatial.y),
            z: planar.select(omega.z, spatial.z),
        };
        let speed = rate.length();
        let friction = F4::from_fn(|l| p[l].friction);
        // `torque_limit`: μ F_n⁺ R*.
        let limit = friction * s.normal_force().max(zero) * kin.effective_radius;
        // `speed > 0` is also false for NaN: no direction, no torque.
        let torque = speed.gt(zero).select3(rate * (-limit / speed), V4::zero());
        let torque = released.select3(V4::zero(), torque);
        if book {
            let full_increment = omega * F4::splat(dt);
            let old = V4::from_fn(|l| h[l].torque);
            let minus_half = F4::splat(-0.5);
            let work = released.select(
                minus_half * old.dot(full_increment),
                minus_half * (old + torque).dot(full_increment),
            );
            s.dissipate(0, work);
        }
        let contact = !released;
        s.torque_a = contact.select3(s.torque_a + torque, s.torque_a);
        s.torque_b = contact.select3(s.torque_b - torque, s.torque_b);
        let torque = torque.to_array();
        for (l, h) in h.into_iter().enumerate() {
            h.torque = torque[l];
        }
    }
}

/// Viscous rolling resistance: M = −c_r ω_r, capped at μ_r F_n R* when `rolling_friction`
/// is given. A torque proportional to the rolling velocity, like Ai et al.'s model B,
/// but with a constant coefficient c_r; it vanishes at rest, so it cannot hold a grain
/// on a slope.
pub struct ViscousRolling;

/// Resolved parameters of [`ViscousRolling`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViscousParams {
    /// Dashpot coefficient c_r, N m s.
    pub damping: f64,
    /// Rolling friction coefficient μ_r of the cap, if any.
    pub friction: Option<f64>,
    /// Disks in the xy-plane.
    pub planar: bool,
}

impl SubModel for ViscousRolling {
    const KIND: SubModelKind = SubModelKind::Rolling;
    const NAME: &'static str = VISCOUS;
    const PARAMS: &'static [ParamSpec] = &[ROLLING_DAMPING, ROLLING_FRICTION_CAP];
    const DISSIPATION: &'static [&'static str] = &["rolling_damping"];
    type Params = ViscousParams;
    type History = TorqueHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        values.get("rolling_damping").map(|_| ()).ok_or_else(|| {
            required(
                "rolling_damping",
                "a rolling dashpot coefficient c_r in N m s",
                Self::NAME,
            )
        })
    }

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<ViscousParams, ParamError> {
        Self::validate(values)?;
        Ok(ViscousParams {
            damping: values.get("rolling_damping").unwrap_or(0.0),
            friction: values.get("rolling_friction"),
            planar: is_two_dimensional(pair),
        })
    }

    fn needs(_values: &ParamValues) -> Needs {
        Needs::ROTATION
    }

    /// The explicit dashpot on a spin is stable for dt < 2 I / c_r; I is bounded below by
    /// the spin inertia of the lightest, smallest contact, κ m*_min R*_min² (κ = 2/5 for
    /// spheres, 1/2 for disks; exact against a wall, conservative between grains).
    fn time_scale(p: &ViscousParams, pair: &PairAssignment) -> Option<TimeScale> {
        let inertia = min_spin_inertia(pair, is_two_dimensional(pair));
        let limit = 2.0 * inertia / p.damping;
        (limit.is_finite() && limit > 0.0).then_some(TimeScale {
            contact_time: f64::INFINITY,
            stability_limit: limit,
        })
    }

    #[inline]
    fn evaluate(
        p: &ViscousParams,
        kin: &ContactKinematics,
        h: &mut TorqueHistory,
        s: &mut ContactState,
        dt: f64,
    ) {
        let full_increment = kin.relative_omega * dt;
        if kin.overlap <= 0.0 {
            s.dissipate(0, -0.5 * h.torque.dot(full_increment));
            *h = TorqueHistory::default();
            return;
        }
        let rate = rolling_part(kin.relative_omega, kin.normal, p.planar);
        let mut torque = rate * -p.damping;
        if let Some(friction) = p.friction {
            let limit = torque_limit(friction, s, kin.effective_radius);
            let magnitude = torque.length();
            if magnitude > limit {
                torque *= limit / magnitude;
            }
        }
        s.dissipate(0, -0.5 * (h.torque + torque).dot(full_increment));
        h.torque = torque;
        s.torque_a += torque;
        s.torque_b -= torque;
    }
}

/// How the rolling spring stiffness of a pair is set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RollingStiffness {
    /// k_r = β k_n R*², with k_n the normal part's current stiffness (Ai et al.:
    /// β = 2.25 μ_r²).
    Ratio(f64),
    /// A fixed k_r, N m/rad.
    Absolute(f64),
}

/// Elastic–plastic spring–dashpot rolling resistance (Ai et al. 2011 model C; the
/// Iwashita–Oda spring, dashpot and slider). Incremental spring M_k ← M_k − k_r Δθ_r,
/// carried with the rolling plane as the normal turns; slider |M_k| ≤ μ_r F_n R*;
/// dashpot M_d = −c_r ω_r with c_r = η_r 2√(I_r k_r) while the spring holds, none while
/// it slides. `N` is the law's normal part: k_r follows its stiffness, and the
/// stability estimate its time scale.
pub struct ElasticPlasticRolling<N>(PhantomData<fn() -> N>);

/// Resolved parameters of [`ElasticPlasticRolling`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ElasticPlasticParams {
    /// Rolling friction coefficient μ_r.
    pub friction: f64,
    /// Spring stiffness rule.
    pub stiffness: RollingStiffness,
    /// Damping ratio η_r.
    pub damping_ratio: f64,
    /// Disks in the xy-plane.
    pub planar: bool,
}

impl<N: SubModel> SubModel for ElasticPlasticRolling<N> {
    const KIND: SubModelKind = SubModelKind::Rolling;
    const NAME: &'static str = ELASTIC_PLASTIC;
    const PARAMS: &'static [ParamSpec] = &[
        ROLLING_FRICTION_REQUIRED,
        ROLLING_STIFFNESS,
        ROLLING_STIFFNESS_RATIO,
        ROLLING_DAMPING_RATIO,
    ];
    const DISSIPATION: &'static [&'static str] = &["rolling_damping", "rolling_slip"];
    type Params = ElasticPlasticParams;
    type History = TorqueSpringHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        if values.get("rolling_friction").is_none() {
            return Err(required(
                "rolling_friction",
                "a rolling friction coefficient μ_r",
                Self::NAME,
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

    fn resolve(
        values: &ParamValues,
        pair: &PairAssignment,
    ) -> Result<ElasticPlasticParams, ParamError> {
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
        Ok(ElasticPlasticParams {
            friction,
            stiffness,
            damping_ratio: values
                .get("rolling_damping_ratio")
                .unwrap_or(DEFAULT_ROLLING_DAMPING_RATIO),
            planar: is_two_dimensional(pair),
        })
    }

    fn needs(_values: &ParamValues) -> Needs {
        Needs::ROTATION
    }

    /// The rolling spring against the spin inertia of the lightest contact (rotation about
    /// the grain's centre, I = κ m*_min R*_min², the smallest inertia the spring can meet;
    /// κ = 2/5 for spheres, 1/2 for disks). With the ratio form, ω_r² = β k_n R*²/I =
    /// (β/κ) ω_n², ω_n estimated from the normal part's stability limit. The dashpot's
    /// ratio against that inertia is η_r √(κ_contact/κ).
    fn time_scale(p: &ElasticPlasticParams, pair: &PairAssignment) -> Option<TimeScale> {
        let planar = is_two_dimensional(pair);
        let kappa = centre_inertia_factor(planar);
        let omega = match p.stiffness {
            RollingStiffness::Absolute(k) => (k / min_spin_inertia(pair, planar)).sqrt(),
            RollingStiffness::Ratio(beta) => normal_frequency::<N>(pair)? * (beta / kappa).sqrt(),
        };
        let zeta = p.damping_ratio * (contact_inertia_factor(planar) / kappa).sqrt();
        oscillator_limit(omega, zeta)
    }

    #[inline]
    fn evaluate(
        p: &ElasticPlasticParams,
        kin: &ContactKinematics,
        h: &mut TorqueSpringHistory,
        s: &mut ContactState,
        dt: f64,
    ) {
        let n = kin.normal;
        let full_increment = kin.relative_omega * dt;
        let increment = rolling_part(full_increment, n, p.planar);
        let rotated = if p.planar {
            DVec3::new(0.0, 0.0, h.spring.z)
        } else {
            rotate_into_plane(h.spring, n)
        };
        let radius = kin.effective_radius;
        let stiffness = match p.stiffness {
            RollingStiffness::Ratio(beta) => beta * s.normal_stiffness * radius * radius,
            RollingStiffness::Absolute(k) => k,
        };
        if kin.overlap <= 0.0 || !(stiffness > 0.0 && stiffness.is_finite()) {
            // Ended (or no spring this step): the slider lets go of the spring and the
            // last torques are booked over the first half of the step.
            TorqueSpringLaw::release(h).advance(
                h,
                rotated,
                increment,
                full_increment,
                DVec3::ZERO,
                s,
            );
            *h = TorqueSpringHistory::default();
            return;
        }
        let rate = rolling_part(kin.relative_omega, n, p.planar);
        // Ai et al.'s I_r = [1/(I_a + m_a R_a²) + 1/(I_b + m_b R_b²)]⁻¹ about the contact
        // point, taken as κ_contact m* R_min²: exact for equal grains and against a wall.
        let inertia = contact_spin_inertia(p.planar, kin);
        let element = TorqueSpringLaw {
            stiffness,
            damping: p.damping_ratio * 2.0 * (inertia * stiffness).sqrt(),
            cap: torque_limit(p.friction, s, radius),
        };
        let torque = element.advance(h, rotated, increment, full_increment, rate, s);
        s.torque_a += torque;
        s.torque_b -= torque;
    }
}
