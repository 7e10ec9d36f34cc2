//! The linear spring–dashpot contact law with a Coulomb-capped tangential spring.
//!
//! Normal: F_n = k_n δ − c_n v_n along the normal (v_n > 0 while separating). The
//! dashpot acts until the overlap closes, as in LAMMPS `gran/hooke`, so the measured
//! restitution equals the analytic exp(−ζπ/√(1 − ζ²)).
//! Tangential: a spring ξ (history) carried into the current tangent plane every step,
//! incremented by the step's tangential displacement, F_t = −k_t ξ − c_t v_t capped at
//! μ|F_n|; on slip the spring is reset to the capped force. Energy: ½k_n δ² + ½k_t|ξ|²
//! stored; dashpots and the slider dissipate, each reported on its own channel.
//! The first and last evaluations of a contact are made energy-consistent with the time
//! integration ([`onset_weight`], [`normal_spring_release`]), and the spring is rotated
//! about the mean normal of the step ([`advance_tangential_spring`]), so that the physical
//! energy balance of a run closes to third order in the step at contact events
//! (docs/physics/contact-onset.md).

mod lanes;
pub use lanes::rotate_into_plane as rotate_into_plane_lanes;
pub mod parts;

use std::any::Any;
use std::f64::consts::PI;

use glam::DVec3;
use talus_contact::*;
use talus_core::schedule::SimBuilder;

/// Name scenes use.
pub const NAME: &str = "linear_spring";

/// One line for `talus check` and the docs.
pub const SUMMARY: &str = "linear spring–dashpot normal force, Coulomb-capped tangential spring";

/// Normal damping of a pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NormalDamping {
    /// A fixed dashpot coefficient c_n, N s/m.
    Coefficient(f64),
    /// A damping ratio ζ: c_n = 2ζ√(m* k_n) for each contact's own reduced mass, so
    /// that every pair has the restitution the ratio was made from.
    Ratio(f64),
    /// A damping rate γ_n per unit reduced mass: c_n = m* γ_n (LAMMPS `gran/hooke`).
    Rate(f64),
}

impl NormalDamping {
    /// The dashpot coefficient c_n of a contact of stiffness `k` and reduced mass `m`.
    #[inline]
    pub fn coefficient(self, k: f64, m: f64) -> f64 {
        match self {
            Self::Coefficient(c) => c,
            Self::Ratio(zeta) => 2.0 * zeta * (m * k).sqrt(),
            Self::Rate(gamma) => gamma * m,
        }
    }
}

/// Resolved parameters of one material pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearParams {
    /// Normal stiffness k_n, N/m.
    pub normal_stiffness: f64,
    /// Normal damping.
    pub normal_damping: NormalDamping,
    /// Tangential stiffness k_t, N/m.
    pub tangential_stiffness: f64,
    /// Tangential damping c_t = ratio × c_n.
    pub tangential_damping_ratio: f64,
    /// Coulomb friction coefficient μ.
    pub friction: f64,
}

/// Per-contact history: the tangential spring, and the forces of the previous step (for
/// the trapezoidal work of the springs and dashpots, the rule velocity Verlet follows).
///
/// The normal forces of the previous evaluation lie along its normal, which the contact
/// keeps anyway ([`ContactKinematics::previous_normal`]): only their signed sizes are
/// stored, and `previous_normal × size` gives back the very vector, bit for bit (64 bytes
/// a contact instead of 96).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TangentialSpring {
    /// Tangential spring displacement ξ, m.
    pub spring: DVec3,
    /// Tangential dashpot force of the previous evaluation, N.
    pub tangential_dashpot: DVec3,
    /// Normal dashpot force of the previous evaluation along its normal, N.
    pub normal_dashpot: f64,
    /// Normal spring force of the previous evaluation along its normal (k_n δ, or the
    /// release pull), N.
    pub normal_spring: f64,
}

impl TangentialSpring {
    /// The normal dashpot force of the previous evaluation, N.
    #[inline]
    pub fn old_normal_dashpot(&self, kin: &ContactKinematics) -> DVec3 {
        kin.previous_normal * self.normal_dashpot
    }

    /// The normal spring force of the previous evaluation, N.
    #[inline]
    pub fn old_normal_spring(&self, kin: &ContactKinematics) -> DVec3 {
        kin.previous_normal * self.normal_spring
    }
}

/// The law's force routine.
pub struct LinearSpring;

/// Damping ratio that gives restitution `e` for a linear spring–dashpot:
/// ζ = −ln e / √(π² + ln² e).
pub fn damping_ratio_from_restitution(e: f64) -> f64 {
    let l = e.ln();
    -l / (PI * PI + l * l).sqrt()
}

/// Stiffness giving a collision time `tc` with restitution `e` for reduced mass `m`:
/// k = m (π² + ln² e) / tc².
pub fn stiffness_from_collision_time(tc: f64, e: f64, m: f64) -> f64 {
    let l = e.ln();
    m * (PI * PI + l * l) / (tc * tc)
}

/// Dashpot coefficient c = 2ζ√(m k) that gives restitution `e` to a pair of reduced mass
/// `m` and stiffness `k` (MercuryDPM's `setCollisionTimeAndRestitutionCoefficient` pairs
/// this with [`stiffness_from_collision_time`]).
pub fn damping_from_restitution(e: f64, k: f64, m: f64) -> f64 {
    2.0 * damping_ratio_from_restitution(e) * (m * k).sqrt()
}

/// Duration of a binary collision of reduced mass `m` with stiffness `k` and dashpot `c`,
/// the dashpot acting until the overlap closes: π / √(k/m − (c/2m)²); infinite when
/// overdamped.
pub fn collision_time(k: f64, c: f64, m: f64) -> f64 {
    let w2 = k / m - (c / (2.0 * m)).powi(2);
    if w2 > 0.0 {
        PI / w2.sqrt()
    } else {
        f64::INFINITY
    }
}

/// Restitution of that collision: exp(−ζπ/√(1 − ζ²)), ζ = c / (2√(m k)); 0 when
/// overdamped.
pub fn restitution(k: f64, c: f64, m: f64) -> f64 {
    let zeta = c / (2.0 * (m * k).sqrt());
    if zeta < 1.0 {
        (-zeta * PI / (1.0 - zeta * zeta).sqrt()).exp()
    } else {
        0.0
    }
}

/// The time step that resolves a collision of reduced mass `m`, stiffness `k` and dashpot
/// `c` with `steps` steps (what the automatic step does with `steps_per_collision`), kept
/// below 0.2 × the stability limit (2/ω₀)(√(1 + ζ²) − ζ) of the central-difference scheme.
pub fn time_step(k: f64, c: f64, m: f64, steps: f64) -> f64 {
    let omega0 = (k / m).sqrt();
    let zeta = c / (2.0 * (m * k).sqrt());
    let stability = 2.0 / omega0 * ((1.0 + zeta * zeta).sqrt() - zeta);
    (collision_time(k, c, m) / steps).min(0.2 * stability)
}

impl ContactLaw for LinearSpring {
    type Params = LinearParams;
    type History = TangentialSpring;
    fn dissipation() -> Vec<&'static str> {
        vec!["normal_damping", "tangential_damping", "friction_slip"]
    }

    const LANES: bool = true;

    #[inline(always)]
    fn evaluate_lanes(
        params: [&LinearParams; 4],
        kin: &ContactKinematicsLanes,
        history: [&mut TangentialSpring; 4],
        lanes: u32,
        dt: f64,
        book: bool,
    ) -> (u32, LaneResponse) {
        lanes::evaluate(params, kin, history, lanes, dt, book)
    }

    #[inline]
    fn evaluate(
        p: &LinearParams,
        kin: &ContactKinematics,
        spring: &mut TangentialSpring,
        dt: f64,
    ) -> ContactResponse {
        let mut out = ContactResponse::default();
        let delta = kin.overlap;
        // Relative displacement of the contact point over this step.
        let displacement = kin.displacement;
        let tangential_displacement = displacement - kin.normal * kin.normal.dot(displacement);
        if delta <= 0.0 {
            // The contact ended during this step (or, one evaluation later, the release
            // pull finishes its work). The dashpot forces of the last evaluation acted
            // over its first half; the slider, whose cap μ|F_n| is now zero, releases what
            // the tangential spring still held: the slip formula below with the spring
            // reset to zero, so that the step's tangential work is booked by the same
            // trapezoidal rule. The normal spring's release is in `normal_spring_release`.
            out.dissipated[0] += -0.5 * spring.old_normal_dashpot(kin).dot(displacement);
            out.dissipated[1] += -0.5 * spring.tangential_dashpot.dot(displacement);
            // Without friction the spring never held anything (and the composed law has
            // no stiffness to release it with).
            let kt = if p.friction > 0.0 {
                p.tangential_stiffness
            } else {
                0.0
            };
            let trial = advance_tangential_spring(spring.spring, kin);
            out.dissipated[2] += slip_work(kt, trial, DVec3::ZERO, tangential_displacement);
            let old_normal = spring.old_normal_spring(kin);
            let (pull, normal_error) = normal_spring_release(p.normal_stiffness, old_normal, kin);
            out.force = kin.normal * pull;
            let tangential_error = tangential_spring_error(kt, spring.spring, trial, displacement);
            out.integration_error = normal_error + tangential_error;
            *spring = TangentialSpring {
                normal_spring: pull,
                ..TangentialSpring::default()
            };
            return out;
        }
        let n = kin.normal;
        let k = p.normal_stiffness;
        let c = p.normal_damping.coefficient(k, kin.effective_mass);
        let vn = kin.normal_velocity;
        let spring_force = k * delta * onset_weight(kin, k, -c * vn, dt);
        let fn_mag = spring_force - c * vn;
        out.force = n * fn_mag;
        out.elastic_energy = 0.5 * k * delta * delta;
        // Integration error of the normal spring: its trapezoidal work over the step
        // plus the change of its potential ½k δ².
        let normal_spring = n * spring_force;
        let old_normal = spring.old_normal_spring(kin);
        out.integration_error = 0.5 * (old_normal + normal_spring).dot(displacement)
            + 0.5 * k * delta * delta
            - 0.5 * k * kin.previous_overlap.max(0.0).powi(2);
        spring.normal_spring = spring_force;
        // Work of the dashpot by the trapezoidal rule over the step's displacement.
        let normal_damping = -c * vn;
        let normal_dashpot = n * normal_damping;
        out.dissipated[0] +=
            -0.5 * (spring.old_normal_dashpot(kin) + normal_dashpot).dot(displacement);
        spring.normal_dashpot = normal_damping;

        let mut ft = DVec3::ZERO;
        if p.friction > 0.0 {
            let kt = p.tangential_stiffness;
            let ct = p.tangential_damping_ratio * c;
            let vt = kin.tangential_velocity;
            let trial = advance_tangential_spring(spring.spring, kin);
            let mut xi = trial;
            ft = -kt * xi - ct * vt;
            let cap = p.friction * fn_mag.abs();
            let ft_len = ft.length();
            if ft_len > cap {
                ft *= cap / ft_len;
                // Reset the spring so that it carries the capped force; the rest of
                // the step's tangential displacement slid.
                xi = -(ft + ct * vt) / kt;
                out.dissipated[2] += slip_work(kt, trial, xi, tangential_displacement);
            }
            let tangential_error = tangential_spring_error(kt, spring.spring, trial, displacement);
            out.integration_error += tangential_error;
            spring.spring = xi;
            out.elastic_energy += 0.5 * kt * xi.length_squared();
            let tangential_dashpot = -ct * vt;
            out.dissipated[1] +=
                -0.5 * (spring.tangential_dashpot + tangential_dashpot).dot(displacement);
            spring.tangential_dashpot = tangential_dashpot;
        }
        // Added even when zero: the composed form of this law does the same operations.
        out.force += ft;
        out
    }
}

/// The spring force of a linear contact at its first evaluation, as a fraction of k δ.
///
/// A contact whose bodies touched a time τ before the end of the step has its spring
/// force k δ₁ made to work, by the trapezoidal rule of the integrator, over the whole
/// step's approach A₁ (its first half-kick) and over the next step's approach A₂ (its
/// second), while the potential it builds is ½k δ₁². With the weight
/// w = (δ₁ + A₂)/(A₁ + A₂) these agree: −½w k δ₁ A₁ − ½(w − 1) k δ₁ A₂ = −½k δ₁² to leading
/// order, instead of missing ½k v² τ(dt − τ) on every impact (on average (ω dt)²/6 of
/// the impact energy, kept by every contact that persists). A₂ is predicted from the
/// pair's own spring and `damping_force` (N, positive repulsive) over the step
/// `dt`. The weight is 1 for a contact that already overlapped before this step.
/// See docs/physics/contact-onset.md.
#[inline]
pub fn onset_weight(kin: &ContactKinematics, k: f64, damping_force: f64, dt: f64) -> f64 {
    let delta = kin.overlap;
    let approach = -kin.normal.dot(kin.displacement);
    if kin.previous_overlap > 0.0 || approach <= delta {
        return 1.0;
    }
    // Fixed-point iteration on w (A₂ depends on w through the spring force): the
    // spring's share of A₂'s change is (ω dt)² τ/dt, so three passes converge to
    // rounding at any step the automatic time step allows.
    let mut weight = 0.5 * (1.0 + delta / approach);
    let slowing = dt * dt / kin.effective_mass;
    for _ in 0..3 {
        let next_approach = approach - slowing * (k * delta * weight + damping_force);
        if next_approach + approach > 0.0 {
            weight = ((delta + next_approach) / (approach + next_approach)).clamp(0.0, 1.0);
        }
    }
    weight
}

/// The normal spring of a linear contact (stiffness `k`, spring force of the previous
/// evaluation `old`) at an evaluation where the bodies no longer overlap: the force to
/// apply now along the normal (zero or negative: a pull), N, and the spring's integration
/// error over the step, J.
///
/// At the first evaluation after the bodies parted, the old force k δ_m worked over the
/// whole opening of the step while the potential ½k δ_m² was released over part of it.
/// A pull p along the normal, applied now, works over this step's opening and the next's
/// (the contact is kept one more evaluation while it carries the pull) and takes back the
/// excess: p = (F_old·Δ − k δ_m²)/(2 n·Δ), at most k δ_m. At the next evaluation the pull's
/// second half-step is booked and the force is zero. See docs/physics/contact-onset.md.
#[inline]
pub fn normal_spring_release(k: f64, old: DVec3, kin: &ContactKinematics) -> (f64, f64) {
    let displacement = kin.displacement;
    let old_potential = 0.5 * k * kin.previous_overlap.max(0.0).powi(2);
    let mut pull = 0.0;
    if kin.previous_overlap > 0.0 {
        let opening = kin.normal.dot(displacement);
        let excess = old.dot(displacement) - 2.0 * old_potential;
        if opening > 0.0 && excess > 0.0 {
            pull = -(excess / (2.0 * opening)).min(old.length());
        }
    }
    let error = 0.5 * (old + kin.normal * pull).dot(displacement) - old_potential;
    (pull, error)
}

/// Carries a tangential spring ξ through the step: rotated into the tangent plane of the
/// mean of the old and new normals, incremented there by the step's displacement, and
/// rotated on into the current tangent plane. Splitting the rotation at the mean normal
/// makes the spring's trapezoidal work match the change of ½k_t|ξ|² to third order per
/// step; rotating first and adding after (LAMMPS's order) leaves a second-order error per
/// step, first order over a contact.
// Always inlined into the force loop: the kinematics it reads then stay in registers,
// and the fields no law reads are never computed.
#[inline(always)]
pub fn advance_tangential_spring(spring: DVec3, kin: &ContactKinematics) -> DVec3 {
    let n = kin.normal;
    let previous = kin.previous_normal;
    if previous == n || previous == DVec3::ZERO {
        // No turn (a packing at rest keeps its normals to the bit), or a new contact
        // whose spring is zero: one projection, as before the turn was split.
        return rotate_into_plane(spring, n) + (kin.displacement - n * n.dot(kin.displacement));
    }
    let mid = (previous + n).normalize_or(n);
    let step = kin.displacement - mid * mid.dot(kin.displacement);
    rotate_into_plane(rotate_into_plane(spring, mid) + step, n)
}

/// Energy the time integration created in a tangential spring of stiffness `kt` over a
/// step: the trapezoidal work of its force on the bodies, −½k_t(ξ_old + ξ_trial)·Δ, plus
/// the change of its potential ½k_t(|ξ_trial|² − |ξ_old|²). Written with the trial spring
/// (before the Coulomb cap), since [`slip_work`] books the slider's share.
#[inline]
pub fn tangential_spring_error(kt: f64, old: DVec3, trial: DVec3, displacement: DVec3) -> f64 {
    0.5 * kt * (trial.length_squared() - old.length_squared() - (old + trial).dot(displacement))
}

/// Work of the Coulomb slider (in series with the spring, so carrying the spring force)
/// over the step in which the spring went from its trial `trial` to `capped`: the slip
/// ξ_trial − ξ_capped times the mean of the force before (ξ_trial less the step's
/// tangential displacement: the old spring in the new plane) and after, by the
/// trapezoidal rule.
#[inline]
pub fn slip_work(kt: f64, trial: DVec3, capped: DVec3, tangential_displacement: DVec3) -> f64 {
    0.5 * kt * (trial - tangential_displacement + capped).dot(trial - capped)
}

/// Rotates a tangential spring into the tangent plane of normal `n`, keeping its length.
#[inline]
pub fn rotate_into_plane(spring: DVec3, n: DVec3) -> DVec3 {
    let projected = spring - n * n.dot(spring);
    let len2 = projected.length_squared();
    if len2 > 0.0 {
        projected * (spring.length_squared() / len2).sqrt()
    } else {
        projected
    }
}

/// Declared parameters, in the order the parts of [`parts`] slice them: normal
/// (stiffness, collision_time), damping (damping, restitution, damping_rate), tangential
/// (the rest).
pub(crate) const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "stiffness",
        unit: "N/m",
        doc: "normal stiffness k_n; give this or `collision_time`",
        range: ParamRange::POSITIVE,
        default: None,
        mix: MixRule::Harmonic,
    },
    ParamSpec {
        name: "collision_time",
        unit: "s",
        doc: "duration of a binary collision of the lightest pair; sets k_n (with `restitution`)",
        range: ParamRange::POSITIVE,
        default: None,
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "damping",
        unit: "N s/m",
        doc: "normal dashpot coefficient c_n; give this or `restitution`",
        range: ParamRange::NON_NEGATIVE,
        default: None,
        mix: MixRule::Harmonic,
    },
    ParamSpec {
        name: "restitution",
        unit: "1",
        doc: "normal coefficient of restitution e; sets the damping ratio for every pair",
        range: ParamRange::UNIT_OPEN_CLOSED,
        default: None,
        mix: MixRule::Geometric,
    },
    ParamSpec {
        name: "damping_rate",
        unit: "1/s",
        doc: "normal damping per unit reduced mass γ_n: c_n = m* γ_n for each contact (LAMMPS gran/hooke)",
        range: ParamRange::NON_NEGATIVE,
        default: None,
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "friction",
        unit: "1",
        doc: "Coulomb friction coefficient μ (0: no tangential force, no torque)",
        range: ParamRange::NON_NEGATIVE,
        default: Some(0.0),
        mix: MixRule::Geometric,
    },
    ParamSpec {
        name: "tangential_stiffness_ratio",
        unit: "1",
        doc: "k_t / k_n (2/7 makes tangential and normal periods equal for spheres)",
        range: ParamRange::POSITIVE,
        default: Some(2.0 / 7.0),
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "tangential_damping_ratio",
        unit: "1",
        doc: "c_t / c_n",
        range: ParamRange::NON_NEGATIVE,
        default: Some(0.0),
        mix: MixRule::Arithmetic,
    },
];

/// Registers `linear_spring` (written whole). Its `rolling:`/`twisting:` variants are
/// assembled from [`parts`] by the rolling-resistance plugin.
pub fn register(registry: &mut LawRegistry) {
    registry.register(Box::new(LinearSpringLaw));
}

/// What scenes see of the linear law.
pub struct LinearSpringLaw;

impl LinearSpringLaw {
    /// Resolves typed parameters for a pair whose lightest reduced mass is `min_mass`.
    pub fn resolve_params(values: &ParamValues, min_mass: f64) -> Result<LinearParams, ParamError> {
        let err = |field: &str, expected: &str| ParamError {
            field: field.into(),
            expected: expected.into(),
        };
        let restitution = values.get("restitution");
        let k = match (values.get("stiffness"), values.get("collision_time")) {
            (Some(k), None) => k,
            (None, Some(tc)) => {
                let e = restitution.ok_or_else(|| {
                    err(
                        "restitution",
                        "a restitution coefficient, required with `collision_time`",
                    )
                })?;
                stiffness_from_collision_time(tc, e, min_mass)
            }
            (Some(_), Some(_)) => {
                return Err(err(
                    "collision_time",
                    "either `stiffness` or `collision_time`, not both",
                ));
            }
            (None, None) => return Err(err("stiffness", "`stiffness` or `collision_time`")),
        };
        let damping = match (
            values.get("damping"),
            restitution,
            values.get("damping_rate"),
        ) {
            (Some(c), None, None) => NormalDamping::Coefficient(c),
            (None, Some(e), None) => NormalDamping::Ratio(damping_ratio_from_restitution(e)),
            (None, None, Some(gamma)) => NormalDamping::Rate(gamma),
            (None, None, None) => {
                return Err(err(
                    "restitution",
                    "`restitution`, `damping` or `damping_rate`",
                ));
            }
            (_, _, Some(_)) => {
                return Err(err(
                    "damping_rate",
                    "one of `damping`, `restitution` and `damping_rate`, not several",
                ));
            }
            (Some(_), Some(_), None) => {
                return Err(err(
                    "damping",
                    "either `damping` or `restitution`, not both",
                ));
            }
        };
        Ok(LinearParams {
            normal_stiffness: k,
            normal_damping: damping,
            tangential_stiffness: k * values
                .get("tangential_stiffness_ratio")
                .unwrap_or(2.0 / 7.0),
            tangential_damping_ratio: values.get("tangential_damping_ratio").unwrap_or(0.0),
            friction: values.get("friction").unwrap_or(0.0),
        })
    }

    /// Contact time and stability limit of a pair of reduced mass `m`.
    pub fn time_scale(p: &LinearParams, m: f64) -> TimeScale {
        let k = p.normal_stiffness;
        let omega0 = (k / m).sqrt();
        let zeta = match p.normal_damping {
            NormalDamping::Coefficient(c) => c / (2.0 * (k * m).sqrt()),
            NormalDamping::Ratio(z) => z,
            NormalDamping::Rate(gamma) => gamma * m / (2.0 * (k * m).sqrt()),
        };
        let contact_time = if zeta < 1.0 {
            PI / (omega0 * (1.0 - zeta * zeta).sqrt())
        } else {
            f64::INFINITY
        };
        // Tangential spring with rolling spheres: effective mass 2/7 m*, so ω_t² = 3.5 k_t / m*.
        let omega_t = if p.friction > 0.0 {
            (3.5 * p.tangential_stiffness / m).sqrt()
        } else {
            0.0
        };
        let omega = omega0.max(omega_t);
        // Stability of the explicit central-difference scheme for a damped oscillator.
        let stability_limit = 2.0 / omega * ((1.0 + zeta * zeta).sqrt() - zeta);
        TimeScale {
            contact_time: contact_time.min(PI / omega),
            stability_limit,
        }
    }
}

impl LawDescriptor for LinearSpringLaw {
    fn name(&self) -> &'static str {
        NAME
    }

    fn summary(&self) -> &'static str {
        SUMMARY
    }

    fn params(&self) -> &[ParamSpec] {
        PARAMS
    }

    fn validate(&self, values: &ParamValues) -> Result<(), ParamError> {
        // Resolve with a unit mass: catches missing or conflicting fields.
        Self::resolve_params(values, 1.0).map(|_| ())
    }

    fn produces_torque(&self, values: &ParamValues) -> bool {
        values.get("friction").unwrap_or(0.0) > 0.0
    }

    fn resolve(
        &self,
        pair: &PairAssignment,
    ) -> Result<(Box<dyn Any + Send + Sync>, TimeScale), ParamError> {
        let p = Self::resolve_params(&pair.values, pair.min_effective_mass)?;
        Ok((Box::new(p), Self::time_scale(&p, pair.min_effective_mass)))
    }

    fn install(
        &self,
        sim: &mut SimBuilder,
        pairs: &[(PairAssignment, Box<dyn Any + Send + Sync>)],
    ) {
        install_law::<LinearSpring>(sim, NAME, pairs);
    }
}

#[cfg(test)]
mod helper_tests {
    use super::*;

    /// The helpers invert each other: a stiffness and a dashpot made from (t_c, e) give
    /// back that collision time and restitution.
    #[test]
    fn parameter_helpers_are_consistent() {
        let m = 2.5e-3;
        for (tc, e) in [(1e-4, 0.3), (5e-3, 0.9), (1e-2, 1.0)] {
            let k = stiffness_from_collision_time(tc, e, m);
            let c = damping_from_restitution(e, k, m);
            assert!((collision_time(k, c, m) - tc).abs() < 1e-12 * tc);
            assert!((restitution(k, c, m) - e).abs() < 1e-12);
            assert!((time_step(k, c, m, 50.0) - tc / 50.0).abs() < 1e-12 * tc);
        }
        assert_eq!(restitution(1.0, 10.0, 1.0), 0.0);
        assert!(collision_time(1.0, 10.0, 1.0).is_infinite());
    }
}
