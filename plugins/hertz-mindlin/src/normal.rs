//! The Hertz normal part: the elastic force between two spheres,
//! F_n = (4/3) E* √R* δ^{3/2}, with its potential (8/15) E* √R* δ^{5/2}.

use glam::DVec3;
use talus_contact::*;
use talus_core::lanes::{F4, V4};

use crate::analytic::{hertz_contact_time, hertz_max_overlap, hertz_stiffness};
use crate::params::{HertzModuli, NORMAL_PARAMS, characteristic_velocity, validate_elastic};

/// Hertz normal spring between two elastic spheres (or a sphere and a half-space).
/// Parameters `youngs_modulus`, `poisson_ratio` (E* from both materials exactly) and
/// `characteristic_velocity` (the impact speed the time step is made for).
pub struct HertzNormal;

/// Resolved parameters of [`HertzNormal`] for one material pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HertzNormalParams {
    /// Effective modulus E*, Pa.
    pub effective_modulus: f64,
    /// Impact speed the time scale is computed for, m/s.
    pub characteristic_velocity: f64,
}

/// History of [`HertzNormal`]: what the previous evaluation stored, for the trapezoidal
/// work of the spring and the change of its potential.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HertzNormalHistory {
    /// Elastic force F_n n of the previous evaluation, N.
    pub force: DVec3,
    /// Elastic energy of the previous evaluation, J.
    pub energy: f64,
}

impl SubModel for HertzNormal {
    const KIND: SubModelKind = SubModelKind::Normal;
    const NAME: &'static str = "hertz";
    const PARAMS: &'static [ParamSpec] = NORMAL_PARAMS;
    const DISSIPATION: &'static [&'static str] = &[];
    type Params = HertzNormalParams;
    type History = HertzNormalHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        validate_elastic(values)
    }

    fn resolve(
        values: &ParamValues,
        pair: &PairAssignment,
    ) -> Result<HertzNormalParams, ParamError> {
        let moduli = HertzModuli::of_pair(pair)?;
        Ok(HertzNormalParams {
            effective_modulus: moduli.effective_modulus,
            characteristic_velocity: characteristic_velocity(values),
        })
    }

    /// The elastic Hertz contact time of the pair's lightest contact (m*_min, R*_min) at
    /// the characteristic speed; the stability limit 2/ω of the stiffness at that
    /// impact's largest overlap, ω = √(k_n(δ_max)/m*), the stiffest the contact gets.
    fn time_scale(p: &HertzNormalParams, pair: &PairAssignment) -> Option<TimeScale> {
        let (m, r, v) = (
            pair.min_effective_mass,
            pair.min_effective_radius,
            p.characteristic_velocity,
        );
        let e_star = p.effective_modulus;
        let contact_time = hertz_contact_time(m, r, e_star, v);
        let stiffness = hertz_stiffness(e_star, r, hertz_max_overlap(m, r, e_star, v));
        let stability_limit = 2.0 / (stiffness / m).sqrt();
        (contact_time.is_finite() && contact_time > 0.0 && stability_limit > 0.0).then_some(
            TimeScale {
                contact_time,
                stability_limit,
            },
        )
    }

    #[inline]
    fn evaluate(
        p: &HertzNormalParams,
        kin: &ContactKinematics,
        h: &mut HertzNormalHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let delta = kin.overlap;
        let displacement = kin.displacement;
        if delta <= 0.0 {
            // Ended: the old force worked over half of the step while the potential fell
            // to zero.
            s.integration_error += 0.5 * h.force.dot(displacement) - h.energy;
            *h = HertzNormalHistory::default();
            return;
        }
        // k_n = 2E*√(R*δ), F_n = (2/3) k_n δ, U = (2/5) F_n δ: one square root for all.
        let stiffness = 2.0 * p.effective_modulus * (kin.effective_radius * delta).sqrt();
        let magnitude = 2.0 / 3.0 * stiffness * delta;
        let energy = 0.4 * magnitude * delta;
        s.normal_elastic = magnitude;
        s.normal_stiffness = stiffness;
        s.elastic_energy += energy;
        let force = kin.normal * magnitude;
        // Trapezoidal work of the spring force on the bodies plus the change of its
        // potential: the energy the time integration created at this contact.
        s.integration_error += 0.5 * (h.force + force).dot(displacement) + energy - h.energy;
        h.force = force;
        h.energy = energy;
    }

    const LANES: bool = true;

    #[inline(always)]
    fn evaluate_lanes(
        p: [&HertzNormalParams; 4],
        kin: &ContactKinematicsLanes,
        h: [&mut HertzNormalHistory; 4],
        s: &mut ContactStateLanes,
        _dt: f64,
        book: bool,
    ) {
        let zero = F4::zero();
        let delta = kin.overlap;
        let released = delta.le(zero);
        let modulus = F4::from_fn(|l| p[l].effective_modulus);
        let stiffness = F4::splat(2.0) * modulus * (kin.effective_radius * delta).sqrt();
        let magnitude = F4::splat(2.0 / 3.0) * stiffness * delta;
        let energy = F4::splat(0.4) * magnitude * delta;
        let force = kin.normal * magnitude;
        // Lanes that released keep the zero elastic force and stiffness of the state.
        s.normal_elastic = released.select(zero, magnitude);
        s.normal_stiffness = released.select(zero, stiffness);
        if book {
            let displacement = kin.displacement;
            let old_force = V4::from_fn(|l| h[l].force);
            let old_energy = F4::from_fn(|l| h[l].energy);
            let half = F4::splat(0.5);
            let error = released.select(
                half * old_force.dot(displacement) - old_energy,
                half * (old_force + force).dot(displacement) + energy - old_energy,
            );
            s.elastic_energy = released.select(s.elastic_energy, s.elastic_energy + energy);
            s.integration_error = s.integration_error + error;
        }
        let (force, energy, released) = (force.to_array(), energy.to_array(), released.bits());
        for (l, h) in h.into_iter().enumerate() {
            *h = if released >> l & 1 == 1 {
                HertzNormalHistory::default()
            } else {
                HertzNormalHistory {
                    force: force[l],
                    energy: energy[l],
                }
            };
        }
    }
}
