//! The cohesion sub-model: a reversible linear adhesive force that acts from touch out to
//! a small gap, added to the normal force of whatever normal part it is composed with.
//!
//! Force along the normal, positive repulsive, at overlap δ (negative across a gap):
//!
//!   F_c(δ) = −(f_0 + k_c δ)   for δ ≥ −f_0/k_c,   0 beyond,
//!
//! so the pull is f_0 at touch, grows inside the overlap and falls linearly to zero at the
//! gap f_0/k_c, the part's interaction range. It is conservative, with the potential
//! U(δ) = −(f_0 + k_c δ)²/(2k_c) = −F_c²/(2k_c), zero at the range and negative while the
//! bodies are bound (MercuryDPM's `LinearReversibleAdhesiveInteraction` has the same gap
//! branch; inside the overlap it keeps the pull at f_0, this part lets it grow with k_c).

use glam::DVec3;
use talus_contact::*;
use talus_linear_spring::LinearSpringLaw;

/// Parameters of [`LinearCohesion`], as a scene writes them in a `contact: (...)`.
pub const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "adhesion_force",
        unit: "N",
        doc: "pull f_0 at touch; the pull falls linearly to zero at the gap f_0/k_c",
        range: ParamRange::NON_NEGATIVE,
        default: None,
        // Pull-off forces scale with the work of adhesion, whose value for unlike
        // surfaces is close to the geometric mean of the like ones; a material
        // that does not stick (f_0 = 0) then sticks to nothing.
        mix: MixRule::Geometric,
    },
    ParamSpec {
        name: "adhesion_stiffness",
        unit: "N/m",
        doc: "slope k_c of the pull with overlap; must be below the normal stiffness k_n",
        range: ParamRange::POSITIVE,
        default: None,
        // Like the normal stiffness: two equal adhesive layers in a row act as one.
        mix: MixRule::Harmonic,
    },
];

/// Reversible linear adhesion F_c = −(f_0 + k_c δ) for δ ≥ −f_0/k_c (the cohesion part
/// of the `linear_cohesion` law).
pub struct LinearCohesion;

/// Resolved parameters of [`LinearCohesion`] for one material pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CohesionParams {
    /// Pull at touch f_0, N.
    pub adhesion_force: f64,
    /// Slope of the pull with overlap k_c, N/m.
    pub adhesion_stiffness: f64,
}

impl CohesionParams {
    /// Gap at which the pull vanishes, f_0/k_c, m: the part's interaction range.
    pub fn range(&self) -> f64 {
        self.adhesion_force / self.adhesion_stiffness
    }

    /// Cohesive normal force at overlap `delta` (negative across a gap), N, positive
    /// repulsive: −(f_0 + k_c δ) within the range, 0 beyond.
    #[inline]
    pub fn force(&self, delta: f64) -> f64 {
        -(self.adhesion_force + self.adhesion_stiffness * delta).max(0.0)
    }

    /// Potential energy at overlap `delta`, J: −F_c²/(2k_c), zero at and beyond the
    /// range, −f_0²/(2k_c) at touch.
    #[inline]
    pub fn potential(&self, delta: f64) -> f64 {
        let force = self.force(delta);
        -0.5 * force * force / self.adhesion_stiffness
    }
}

/// History of [`LinearCohesion`]: its force at the previous evaluation, for the
/// trapezoidal work over the step and the potential it held.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CohesionHistory {
    /// Cohesive force on body `a` at the previous evaluation, N (zero for a new contact).
    pub force: DVec3,
}

/// The parameter `name`, or an error naming it when the scene left it out.
fn required(values: &ParamValues, name: &str) -> Result<f64, ParamError> {
    values.get(name).ok_or_else(|| ParamError {
        field: name.into(),
        expected: format!("`{name}`, required by the cohesion part"),
    })
}

impl SubModel for LinearCohesion {
    const KIND: SubModelKind = SubModelKind::Cohesion;
    const NAME: &'static str = "linear_cohesion";
    const PARAMS: &'static [ParamSpec] = PARAMS;
    // Reversible: the force depends on the overlap alone, so nothing is dissipated.
    const DISSIPATION: &'static [&'static str] = &[];
    type Params = CohesionParams;
    type History = CohesionHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        required(values, "adhesion_force")?;
        required(values, "adhesion_stiffness")?;
        Ok(())
    }

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<CohesionParams, ParamError> {
        let params = CohesionParams {
            adhesion_force: required(values, "adhesion_force")?,
            adhesion_stiffness: required(values, "adhesion_stiffness")?,
        };
        // Inside the overlap the net stiffness is k_n − k_c: with k_c ≥ k_n nothing
        // would push the bodies apart. The check applies when the pair's normal part is
        // the linear spring; another normal part reports its own parameters.
        if let Ok(linear) = LinearSpringLaw::resolve_params(values, pair.min_effective_mass)
            && params.adhesion_stiffness >= linear.normal_stiffness
        {
            return Err(ParamError {
                field: "adhesion_stiffness".into(),
                expected: format!(
                    "a value below the normal stiffness k_n = {:.6e} N/m, got {}",
                    linear.normal_stiffness, params.adhesion_stiffness
                ),
            });
        }
        Ok(params)
    }

    fn needs(values: &ParamValues) -> Needs {
        // Called on checked values; a missing or zero stiffness gives no range rather
        // than a division by zero (resolve reports it).
        let range = match (
            values.get("adhesion_force"),
            values.get("adhesion_stiffness"),
        ) {
            (Some(f0), Some(kc)) if kc > 0.0 => f0 / kc,
            _ => 0.0,
        };
        Needs {
            rotation: false,
            range,
        }
    }

    fn time_scale(params: &CohesionParams, pair: &PairAssignment) -> Option<TimeScale> {
        // The pull grows as the bodies close in, a spring of negative stiffness −k_c:
        // motion in the gap changes on the time scale √(m*/k_c), which the step must
        // resolve like a collision. Below k_n it never sets the step of the linear law;
        // it would with a softer normal part.
        let omega = (params.adhesion_stiffness / pair.min_effective_mass).sqrt();
        Some(TimeScale {
            contact_time: std::f64::consts::PI / omega,
            stability_limit: 2.0 / omega,
        })
    }

    #[inline]
    fn evaluate(
        p: &CohesionParams,
        kin: &ContactKinematics,
        h: &mut CohesionHistory,
        s: &mut ContactState,
        _dt: f64,
    ) {
        let cohesive_force = p.force(kin.overlap);
        let force = kin.normal * cohesive_force;
        s.normal_cohesion = cohesive_force;
        // Elastic energy: the potential now (negative while bound). Other parts add
        // theirs, so add rather than assign.
        let potential = -0.5 * cohesive_force * cohesive_force / p.adhesion_stiffness;
        s.elastic_energy += potential;
        // Integration error: the trapezoidal work of the force over the step (the rule
        // the integrator applies) plus the change of the potential. It vanishes while
        // the force is linear in the displacement; the steps that cross the range or
        // turn the normal leave O(dt²).
        let old_potential = -0.5 * h.force.length_squared() / p.adhesion_stiffness;
        s.integration_error +=
            0.5 * (h.force + force).dot(kin.displacement) + potential - old_potential;
        h.force = force;
    }
}
