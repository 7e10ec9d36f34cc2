//! Declared parameters of the Hertz–Mindlin parts and the elastic constants of a pair:
//! E* and G* computed exactly from both materials, not mixed field by field.

use talus_contact::compose::is_two_dimensional;
use talus_contact::{MixRule, PairAssignment, ParamError, ParamRange, ParamSpec, ParamValues};

use crate::analytic::{effective_modulus, effective_shear_modulus};

/// Poisson's ratio of an isotropic, thermodynamically stable material in compression:
/// [0, 0.5). At 0.5 the material is incompressible and the Mindlin shear terms degenerate.
pub const POISSON_RANGE: ParamRange = ParamRange {
    min: 0.0,
    min_inclusive: true,
    max: 0.5,
    max_inclusive: false,
};

/// Default characteristic impact speed for the time scale, m/s.
pub const DEFAULT_CHARACTERISTIC_VELOCITY: f64 = 1.0;

/// Parameters of [`crate::HertzNormal`].
pub const NORMAL_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "youngs_modulus",
        unit: "Pa",
        doc: "Young's modulus E of the material (pairs: E* from both materials exactly)",
        range: ParamRange::POSITIVE,
        default: None,
        // Only used by `pairs` entries made of mixed values, which never happens: a pair
        // of materials gets E* = 1/((1 − ν_a²)/E_a + (1 − ν_b²)/E_b) from both sides.
        mix: MixRule::Harmonic,
    },
    ParamSpec {
        name: "poisson_ratio",
        unit: "1",
        doc: "Poisson's ratio ν of the material, in [0, 0.5)",
        range: POISSON_RANGE,
        default: None,
        mix: MixRule::Arithmetic,
    },
    ParamSpec {
        name: "characteristic_velocity",
        unit: "m/s",
        doc: "normal impact speed the automatic time step is made for (Hertz contact time at this speed)",
        range: ParamRange::POSITIVE,
        default: Some(DEFAULT_CHARACTERISTIC_VELOCITY),
        // The faster impact has the shorter contact: the safer choice.
        mix: MixRule::Max,
    },
];

/// Parameters of [`crate::HertzDamping`].
pub const DAMPING_PARAMS: &[ParamSpec] = &[ParamSpec {
    name: "restitution",
    unit: "1",
    doc: "normal coefficient of restitution e, the same at every impact speed",
    range: ParamRange::UNIT_OPEN_CLOSED,
    default: None,
    mix: MixRule::Geometric,
}];

/// Parameters of [`crate::MindlinTangential`].
pub const TANGENTIAL_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "friction",
        unit: "1",
        doc: "Coulomb friction coefficient μ (0: no tangential force, no torque)",
        range: ParamRange::NON_NEGATIVE,
        default: Some(0.0),
        mix: MixRule::Geometric,
    },
    ParamSpec {
        name: "tangential_damping_ratio",
        unit: "1",
        doc: "c_t / c_n, the tangential dashpot as a fraction of the normal one",
        range: ParamRange::NON_NEGATIVE,
        default: Some(0.0),
        mix: MixRule::Arithmetic,
    },
];

/// Elastic constants of a material pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HertzModuli {
    /// E*, Pa.
    pub effective_modulus: f64,
    /// G*, Pa.
    pub effective_shear_modulus: f64,
}

/// A value a part needs, with a message naming it when it is absent.
pub(crate) fn required(values: &ParamValues, name: &str, what: &str) -> Result<f64, ParamError> {
    values.get(name).ok_or_else(|| ParamError {
        field: name.into(),
        expected: format!("{what} (required by `{}`)", crate::NAME),
    })
}

/// Young's modulus and Poisson's ratio of one material's values.
fn elastic_constants(values: &ParamValues) -> Result<(f64, f64), ParamError> {
    Ok((
        required(values, "youngs_modulus", "a Young's modulus in Pa")?,
        required(values, "poisson_ratio", "a Poisson's ratio in [0, 0.5)")?,
    ))
}

/// Checks that a set of values names both elastic constants.
pub(crate) fn validate_elastic(values: &ParamValues) -> Result<(), ParamError> {
    elastic_constants(values).map(|_| ())
}

impl HertzModuli {
    /// E* and G* of a pair: exactly from each material's own E and ν when the pair's law
    /// comes from its materials (a grain–wall pair: the wall's material is the other
    /// side), else from the pair's values as if both bodies were of that material
    /// (E* = E/(2(1 − ν²)), G* = G/(2(2 − ν))). Hertz contact is between spheres:
    /// a 2-D scene (disks) is refused.
    pub fn of_pair(pair: &PairAssignment) -> Result<Self, ParamError> {
        if is_two_dimensional(pair) {
            return Err(ParamError {
                field: "law".into(),
                expected: format!(
                    "a 3-D scene: `{}` is the contact law of elastic spheres (Hertz–Mindlin theory); \
                     a 2-D scene of disks needs a law for disks, such as `linear_spring`",
                    crate::NAME
                ),
            });
        }
        let (a, b) = match &pair.material_values {
            Some((a, b)) => (a, b),
            None => (&pair.values, &pair.values),
        };
        let (e_a, nu_a) = elastic_constants(a)?;
        let (e_b, nu_b) = elastic_constants(b)?;
        Ok(Self {
            effective_modulus: effective_modulus(e_a, nu_a, e_b, nu_b),
            effective_shear_modulus: effective_shear_modulus(e_a, nu_a, e_b, nu_b),
        })
    }
}

/// Characteristic impact speed of a pair's values, m/s.
pub(crate) fn characteristic_velocity(values: &ParamValues) -> f64 {
    values
        .get("characteristic_velocity")
        .unwrap_or(DEFAULT_CHARACTERISTIC_VELOCITY)
}
