//! The viscoelastic normal dashpot of the Hertz contact (Tsuji et al. 1992 form,
//! c ∝ δ^{1/4}), calibrated so that every impact speed rebounds with the prescribed
//! restitution, and never pulling the bodies together.

use glam::DVec3;
use talus_contact::*;
use talus_core::lanes::{F4, V4};

use crate::analytic::{damping_from_restitution, hertz_max_overlap, hertz_stiffness};
use crate::params::{DAMPING_PARAMS, HertzModuli, characteristic_velocity, required};

/// Normal dashpot F_d = −c(δ) v_n with c(δ) = γ̂ √((2/3) m* k_n(δ)) = γ̂ √(m* K) δ^{1/4}
/// (K = (4/3)E*√R*). With the Hertz spring this makes the restitution a function of γ̂
/// alone, for every impact speed ([`crate::analytic::restitution_from_damping`]); γ̂ is
/// found from `restitution` by [`damping_from_restitution`]. The total normal force is
/// never attractive: the dashpot is clipped at −F_elastic, so it acts until the normal
/// force reaches zero, after which the bodies separate freely. Compose it with
/// [`crate::HertzNormal`], whose stiffness it reads.
pub struct HertzDamping;

/// Resolved parameters of [`HertzDamping`] for one material pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HertzDampingParams {
    /// Prescribed restitution e.
    pub restitution: f64,
    /// Dimensionless damping γ̂ that gives it.
    pub gamma: f64,
    /// γ̂ √(2/3), so that c = this × √(m* k_n) per contact.
    pub coefficient_factor: f64,
}

/// History of [`HertzDamping`]: its force at the previous evaluation (trapezoidal work).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HertzDampingHistory {
    /// Dashpot force of the previous evaluation, N.
    pub force: DVec3,
}

impl SubModel for HertzDamping {
    const KIND: SubModelKind = SubModelKind::Damping;
    const NAME: &'static str = "hertz_dashpot";
    const PARAMS: &'static [ParamSpec] = DAMPING_PARAMS;
    const DISSIPATION: &'static [&'static str] = &["normal_damping"];
    type Params = HertzDampingParams;
    type History = HertzDampingHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        required(values, "restitution", "a restitution coefficient in (0, 1]").map(|_| ())
    }

    fn resolve(
        values: &ParamValues,
        _pair: &PairAssignment,
    ) -> Result<HertzDampingParams, ParamError> {
        let restitution = required(values, "restitution", "a restitution coefficient in (0, 1]")?;
        let gamma = damping_from_restitution(restitution).ok_or_else(|| ParamError {
            field: "restitution".into(),
            expected: format!("a restitution coefficient in (0, 1], got {restitution}"),
        })?;
        Ok(HertzDampingParams {
            restitution,
            gamma,
            coefficient_factor: gamma * (2.0f64 / 3.0).sqrt(),
        })
    }

    /// No contact time of its own (the damped force pulse is shorter than the elastic one,
    /// but the time step is made from the elastic contact time, see the docs); the
    /// stability limit of the damped oscillator at the characteristic impact's largest
    /// overlap, (2/ω)(√(1 + ζ²) − ζ), where the damping ratio c/(2√(m* k_n)) is γ̂/√6 at
    /// every overlap.
    fn time_scale(p: &HertzDampingParams, pair: &PairAssignment) -> Option<TimeScale> {
        let moduli = HertzModuli::of_pair(pair).ok()?;
        let (m, r) = (pair.min_effective_mass, pair.min_effective_radius);
        let v = characteristic_velocity(&pair.values);
        let e_star = moduli.effective_modulus;
        let stiffness = hertz_stiffness(e_star, r, hertz_max_overlap(m, r, e_star, v));
        let omega = (stiffness / m).sqrt();
        let zeta = p.gamma / 6.0f64.sqrt();
        let stability_limit = 2.0 / omega * ((1.0 + zeta * zeta).sqrt() - zeta);
        (stability_limit > 0.0).then_some(TimeScale {
            contact_time: f64::INFINITY,
            stability_limit,
        })
    }

    #[inline]
    fn evaluate(
        p: &HertzDampingParams,
        kin: &ContactKinematics,
        h: &mut HertzDampingHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let displacement = kin.displacement;
        if kin.overlap <= 0.0 {
            // Ended: the old dashpot force worked over the first half of the step.
            s.dissipate(0, -0.5 * h.force.dot(displacement));
            *h = HertzDampingHistory::default();
            return;
        }
        let c = p.coefficient_factor * (kin.effective_mass * s.normal_stiffness).sqrt();
        // No tension: the dashpot may cancel the elastic force, never exceed it.
        let magnitude = (-c * kin.normal_velocity).max(-s.normal_elastic);
        s.normal_damping = magnitude;
        s.damping_coefficient = c;
        let force = kin.normal * magnitude;
        s.dissipate(0, -0.5 * (h.force + force).dot(displacement));
        h.force = force;
    }

    const LANES: bool = true;

    #[inline(always)]
    fn evaluate_lanes(
        p: [&HertzDampingParams; 4],
        kin: &ContactKinematicsLanes,
        h: [&mut HertzDampingHistory; 4],
        s: &mut ContactStateLanes,
        _dt: f64,
        book: bool,
    ) {
        let released = kin.overlap.le(F4::zero());
        let factor = F4::from_fn(|l| p[l].coefficient_factor);
        let c = factor * (kin.effective_mass * s.normal_stiffness).sqrt();
        let magnitude = (-c * kin.normal_velocity).max(-s.normal_elastic);
        s.normal_damping = released.select(s.normal_damping, magnitude);
        s.damping_coefficient = released.select(s.damping_coefficient, c);
        let force = kin.normal * magnitude;
        if book {
            let displacement = kin.displacement;
            let old = V4::from_fn(|l| h[l].force);
            let minus_half = F4::splat(-0.5);
            let work = released.select(
                minus_half * old.dot(displacement),
                minus_half * (old + force).dot(displacement),
            );
            s.dissipate(0, work);
        }
        let (force, released) = (force.to_array(), released.bits());
        for (l, h) in h.into_iter().enumerate() {
            *h = if released >> l & 1 == 1 {
                HertzDampingHistory::default()
            } else {
                HertzDampingHistory { force: force[l] }
            };
        }
    }
}
