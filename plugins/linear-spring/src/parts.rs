//! The linear law as sub-models: a linear normal spring, a linear normal dashpot and a
//! Coulomb-capped tangential spring. Composed, they give forces bit-identical to
//! [`crate::LinearSpring`] written whole; other laws reuse them (a Hertz normal part
//! with this tangential spring, rolling resistance on top of the linear law).

use glam::DVec3;
use talus_contact::*;

use crate::{
    LinearSpringLaw, NormalDamping, PARAMS, advance_tangential_spring, normal_spring_release,
    onset_weight, slip_work, tangential_spring_error,
};

/// Linear normal spring F = k_n δ. Parameters `stiffness` or `collision_time` (with
/// `restitution`, which sets the stiffness that gives that time with that damping).
pub struct LinearNormal;

/// History of [`LinearNormal`]: the spring force of the previous evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NormalSpringHistory {
    /// k_n δ n of the previous evaluation, N.
    pub spring: DVec3,
}

impl SubModel for LinearNormal {
    const KIND: SubModelKind = SubModelKind::Normal;
    const NAME: &'static str = "linear";
    const PARAMS: &'static [ParamSpec] = PARAMS.split_at(2).0;
    const DISSIPATION: &'static [&'static str] = &[];
    type Params = f64;
    type History = NormalSpringHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        LinearSpringLaw::resolve_params(values, 1.0).map(|_| ())
    }

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<f64, ParamError> {
        LinearSpringLaw::resolve_params(values, pair.min_effective_mass).map(|p| p.normal_stiffness)
    }

    fn time_scale(k: &f64, pair: &PairAssignment) -> Option<TimeScale> {
        let p = LinearSpringLaw::resolve_params(&pair.values, pair.min_effective_mass).ok()?;
        debug_assert_eq!(p.normal_stiffness, *k);
        Some(LinearSpringLaw::time_scale(&p, pair.min_effective_mass))
    }

    #[inline]
    fn evaluate(
        &k: &f64,
        kin: &ContactKinematics,
        h: &mut NormalSpringHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let delta = kin.overlap;
        if delta <= 0.0 {
            // Ended, or the release pull's second half-step: see `normal_spring_release`.
            let (pull, error) = normal_spring_release(k, h.spring, kin);
            s.normal_elastic = pull;
            s.integration_error = error;
            h.spring = kin.normal * pull;
            return;
        }
        // k δ, which the damping part reads; the spring is finished in `after_damping`.
        s.normal_elastic = k * delta;
        s.normal_stiffness = k;
        s.elastic_energy = 0.5 * k * delta * delta;
    }

    /// Finishes the spring once the damping force is known: at a contact's first
    /// evaluation its force is weighted by [`onset_weight`]; the force is stored and its
    /// integration error booked (trapezoidal work over the step plus the change of ½k δ²).
    #[inline]
    fn after_damping(
        &k: &f64,
        kin: &ContactKinematics,
        h: &mut NormalSpringHistory,
        s: &mut ContactState,
        dt: f64,
    ) {
        let delta = kin.overlap;
        if delta <= 0.0 {
            return;
        }
        s.normal_elastic = k * delta * onset_weight(kin, k, s.normal_damping, dt);
        let spring = kin.normal * s.normal_elastic;
        s.integration_error = 0.5 * (h.spring + spring).dot(kin.displacement)
            + 0.5 * k * delta * delta
            - 0.5 * k * kin.previous_overlap.max(0.0).powi(2);
        h.spring = spring;
    }
}

/// Linear normal dashpot F = −c_n v_n, acting while the bodies overlap. Parameters
/// `damping` (c_n) or `restitution` (a damping ratio, c_n = 2ζ√(m* k_n) per contact).
pub struct LinearDashpot;

/// History of a dashpot: its force at the previous evaluation (trapezoidal work).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DashpotHistory {
    /// Dashpot force of the previous evaluation, N.
    pub force: DVec3,
}

impl SubModel for LinearDashpot {
    const KIND: SubModelKind = SubModelKind::Damping;
    const NAME: &'static str = "linear_dashpot";
    const PARAMS: &'static [ParamSpec] = PARAMS.split_at(5).0.split_at(2).1;
    const DISSIPATION: &'static [&'static str] = &["normal_damping"];
    type Params = NormalDamping;
    type History = DashpotHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        LinearSpringLaw::resolve_params(values, 1.0).map(|_| ())
    }

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<NormalDamping, ParamError> {
        LinearSpringLaw::resolve_params(values, pair.min_effective_mass).map(|p| p.normal_damping)
    }

    #[inline]
    fn evaluate(
        p: &NormalDamping,
        kin: &ContactKinematics,
        h: &mut DashpotHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let displacement = kin.displacement;
        if kin.overlap <= 0.0 {
            s.dissipate(0, -0.5 * h.force.dot(displacement));
            *h = DashpotHistory::default();
            return;
        }
        let k = s.normal_stiffness;
        let c = p.coefficient(k, kin.effective_mass);
        let vn = kin.normal_velocity;
        s.normal_damping = -c * vn;
        s.damping_coefficient = c;
        let force = -c * vn * kin.normal;
        s.dissipate(0, -0.5 * (h.force + force).dot(displacement));
        h.force = force;
    }
}

/// Tangential spring ξ rotated into the tangent plane every step, incremented by the
/// tangential displacement, with an optional dashpot; the force is capped at μ|F_n|
/// (Coulomb) and the spring reset to carry the capped force. Parameters `friction`,
/// `tangential_stiffness_ratio` (k_t / k_n), `tangential_damping_ratio` (c_t / c_n).
pub struct CoulombSpring;

/// Resolved parameters of [`CoulombSpring`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoulombParams {
    /// Coulomb friction coefficient μ.
    pub friction: f64,
    /// k_t / k_n.
    pub stiffness_ratio: f64,
    /// c_t / c_n.
    pub damping_ratio: f64,
}

/// History of [`CoulombSpring`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CoulombHistory {
    /// Tangential spring displacement ξ, m.
    pub spring: DVec3,
    /// Tangential dashpot force of the previous evaluation, N.
    pub dashpot: DVec3,
    /// Tangential stiffness k_t of the previous evaluation, N/m: the normal part reports
    /// no stiffness once the bodies separate, and the spring is released with this one.
    pub stiffness: f64,
}

impl SubModel for CoulombSpring {
    const KIND: SubModelKind = SubModelKind::Tangential;
    const NAME: &'static str = "coulomb_spring";
    const PARAMS: &'static [ParamSpec] = PARAMS.split_at(5).1;
    const DISSIPATION: &'static [&'static str] = &["tangential_damping", "friction_slip"];
    type Params = CoulombParams;
    type History = CoulombHistory;

    fn resolve(values: &ParamValues, _pair: &PairAssignment) -> Result<CoulombParams, ParamError> {
        Ok(CoulombParams {
            friction: values.get("friction").unwrap_or(0.0),
            stiffness_ratio: values
                .get("tangential_stiffness_ratio")
                .unwrap_or(2.0 / 7.0),
            damping_ratio: values.get("tangential_damping_ratio").unwrap_or(0.0),
        })
    }

    fn needs(values: &ParamValues) -> Needs {
        Needs {
            rotation: values.get("friction").unwrap_or(0.0) > 0.0,
            range: 0.0,
        }
    }

    #[inline]
    fn evaluate(
        p: &CoulombParams,
        kin: &ContactKinematics,
        h: &mut CoulombHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let displacement = kin.displacement;
        let n = kin.normal;
        let tangential_displacement = displacement - n * n.dot(displacement);
        if kin.overlap <= 0.0 {
            // Ended: the slider's cap is zero, so it releases the spring (the slip
            // formula below with ξ = 0); the dashpot's last force worked half a step.
            let kt = h.stiffness;
            s.dissipate(0, -0.5 * h.dashpot.dot(displacement));
            let trial = advance_tangential_spring(h.spring, kin);
            s.dissipate(
                1,
                slip_work(kt, trial, DVec3::ZERO, tangential_displacement),
            );
            s.integration_error += tangential_spring_error(kt, h.spring, trial, displacement);
            *h = CoulombHistory::default();
            return;
        }
        if p.friction <= 0.0 {
            return;
        }
        let kt = s.normal_stiffness * p.stiffness_ratio;
        let ct = p.damping_ratio * s.damping_coefficient;
        let vt = kin.tangential_velocity;
        let trial = advance_tangential_spring(h.spring, kin);
        let mut xi = trial;
        let mut ft = -kt * xi - ct * vt;
        let cap = p.friction * s.normal_force().abs();
        let ft_len = ft.length();
        if ft_len > cap {
            ft *= cap / ft_len;
            xi = -(ft + ct * vt) / kt;
            s.dissipate(1, slip_work(kt, trial, xi, tangential_displacement));
        }
        s.integration_error += tangential_spring_error(kt, h.spring, trial, displacement);
        h.spring = xi;
        h.stiffness = kt;
        s.tangential_force = ft;
        s.elastic_energy += 0.5 * kt * xi.length_squared();
        let dashpot = -ct * vt;
        s.dissipate(0, -0.5 * (h.dashpot + dashpot).dot(displacement));
        h.dashpot = dashpot;
    }
}

/// The linear law assembled from its parts.
pub type ComposedLinearSpring = Composed<LinearNormal, LinearDashpot, CoulombSpring>;

/// Descriptor of the composed linear law, named `linear_spring_parts`: what the
/// composition test compares with the whole law. Scenes reach these parts through the
/// `rolling:`/`twisting:` variants of `linear_spring`.
pub fn composed_descriptor() -> ComposedLaw<LinearNormal, LinearDashpot, CoulombSpring> {
    ComposedLaw::new(
        "linear_spring_parts",
        "linear_spring assembled from sub-models: linear normal, linear dashpot, Coulomb spring",
    )
}
