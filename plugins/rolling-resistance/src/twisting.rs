//! Twisting (torsional) resistance: a spring–dashpot–slider about the contact normal.
//!
//! The twisting velocity is the normal part of the relative spin, (ω_rel·n) n. The
//! spring M_k ← M_k − k_tw Δθ_tw is kept along the current normal; the slider caps it at
//! μ_tw F_n a with a = √(R* δ) the contact radius (the Hertz contact radius, also used
//! for the linear law, as LAMMPS' granular twisting models do); the dashpot
//! c_tw = η_tw 2√(I_tw k_tw) acts while the spring holds. In 2-D the normal lies in the
//! xy-plane and spins are along z, so there is no twisting and the part does nothing.

use std::marker::PhantomData;

use glam::DVec3;
use talus_contact::compose::is_two_dimensional;
use talus_contact::*;

use crate::element::{TorqueSpringHistory, TorqueSpringLaw, centre_inertia_factor};
use crate::element::{normal_frequency, oscillator_limit, torque_limit};

/// Scene name of [`SpringDashpotTwisting`].
pub const SPRING_DASHPOT: &str = "spring_dashpot";

/// Default k_tw / (k_n a²): Marshall's (2009) k_tw = ½ k_t a² with the linear law's
/// default k_t = 2/7 k_n.
pub const DEFAULT_TWISTING_STIFFNESS_RATIO: f64 = 1.0 / 7.0;

/// Default twisting damping ratio η_tw.
pub const DEFAULT_TWISTING_DAMPING_RATIO: f64 = 0.3;

/// Largest overlap over reduced radius assumed by the stability estimate: the engine
/// stops a run (blow-up) once an overlap exceeds half the smaller radius.
const LARGEST_OVERLAP_RATIO: f64 = 0.5;

/// Twisting spring–dashpot–slider about the contact normal. `N` is the law's normal part:
/// k_tw = χ k_n a² follows its stiffness, and the stability estimate its time scale.
pub struct SpringDashpotTwisting<N>(PhantomData<fn() -> N>);

/// Resolved parameters of [`SpringDashpotTwisting`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwistingParams {
    /// Twisting friction coefficient μ_tw: the limit is μ_tw F_n a.
    pub friction: f64,
    /// χ = k_tw / (k_n a²).
    pub stiffness_ratio: f64,
    /// η_tw: c_tw = η_tw 2√(I_tw k_tw).
    pub damping_ratio: f64,
    /// Disks in the xy-plane: no twisting exists.
    pub planar: bool,
}

impl<N: SubModel> SubModel for SpringDashpotTwisting<N> {
    const KIND: SubModelKind = SubModelKind::Twisting;
    const NAME: &'static str = SPRING_DASHPOT;
    const PARAMS: &'static [ParamSpec] = &[
        ParamSpec {
            name: "twisting_friction",
            unit: "1",
            doc: "twisting friction coefficient μ_tw: the torque limit is μ_tw F_n a, a = √(R* δ) (required)",
            range: ParamRange::NON_NEGATIVE,
            default: None,
            mix: MixRule::Geometric,
        },
        ParamSpec {
            name: "twisting_stiffness_ratio",
            unit: "1",
            doc: "χ = k_tw / (k_n a²), a = √(R* δ) the contact radius",
            range: ParamRange::POSITIVE,
            default: Some(DEFAULT_TWISTING_STIFFNESS_RATIO),
            mix: MixRule::Arithmetic,
        },
        ParamSpec {
            name: "twisting_damping_ratio",
            unit: "1",
            doc: "η_tw: the twisting dashpot is c_tw = η_tw 2√(I_tw k_tw), active while the spring holds",
            range: ParamRange::NON_NEGATIVE,
            default: Some(DEFAULT_TWISTING_DAMPING_RATIO),
            mix: MixRule::Arithmetic,
        },
    ];
    const DISSIPATION: &'static [&'static str] = &["twisting_damping", "twisting_slip"];
    type Params = TwistingParams;
    type History = TorqueSpringHistory;

    fn validate(values: &ParamValues) -> Result<(), ParamError> {
        values
            .get("twisting_friction")
            .map(|_| ())
            .ok_or_else(|| ParamError {
                field: "twisting_friction".into(),
                expected: format!(
                    "a twisting friction coefficient μ_tw, required by the twisting part `{}`",
                    Self::NAME
                ),
            })
    }

    fn resolve(values: &ParamValues, pair: &PairAssignment) -> Result<TwistingParams, ParamError> {
        Self::validate(values)?;
        Ok(TwistingParams {
            friction: values.get("twisting_friction").unwrap_or(0.0),
            stiffness_ratio: values
                .get("twisting_stiffness_ratio")
                .unwrap_or(DEFAULT_TWISTING_STIFFNESS_RATIO),
            damping_ratio: values
                .get("twisting_damping_ratio")
                .unwrap_or(DEFAULT_TWISTING_DAMPING_RATIO),
            planar: is_two_dimensional(pair),
        })
    }

    fn needs(_values: &ParamValues) -> Needs {
        Needs::ROTATION
    }

    /// ω_tw² = χ k_n R* δ / I_tw with I_tw ≥ (2/5) m* R*² (rotation about the normal of
    /// a grain against a wall; between grains at least 4 times more relative to m* R*²,
    /// which covers their overlap ratio δ/R* being up to twice the wall's), bounded with
    /// δ/R* ≤ ½: ω_tw² ≤ 1.25 χ ω_n². The dashpot ratio against that inertia is η_tw.
    fn time_scale(p: &TwistingParams, pair: &PairAssignment) -> Option<TimeScale> {
        if is_two_dimensional(pair) {
            return None;
        }
        let ratio = p.stiffness_ratio * LARGEST_OVERLAP_RATIO / centre_inertia_factor(false);
        oscillator_limit(normal_frequency::<N>(pair)? * ratio.sqrt(), p.damping_ratio)
    }

    #[inline]
    fn evaluate(
        p: &TwistingParams,
        kin: &ContactKinematics,
        h: &mut TorqueSpringHistory,
        s: &mut ContactState,
        dt: f64,
    ) {
        if p.planar {
            // Spins are along z and normals in the xy-plane: nothing twists.
            return;
        }
        let n = kin.normal;
        let full_increment = kin.relative_omega * dt;
        let increment = n * n.dot(full_increment);
        // The spring stays along the normal as it turns; it keeps its magnitude and its
        // sense relative to the normal.
        let rotated = n * h.spring.length().copysign(h.spring.dot(n));
        let radius = kin.effective_radius;
        let contact_radius_squared = radius * kin.overlap;
        let stiffness = p.stiffness_ratio * s.normal_stiffness * contact_radius_squared;
        if kin.overlap <= 0.0 || !(stiffness > 0.0 && stiffness.is_finite()) {
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
        let rate = n * n.dot(kin.relative_omega);
        // Relative inertia about the normal, [1/I_a + 1/I_b]⁻¹, taken as (2/5) m* R_min²:
        // exact for equal grains and against a wall.
        let inertia =
            centre_inertia_factor(false) * kin.effective_mass * kin.min_radius * kin.min_radius;
        let element = TorqueSpringLaw {
            stiffness,
            damping: p.damping_ratio * 2.0 * (inertia * stiffness).sqrt(),
            cap: torque_limit(p.friction, s, contact_radius_squared.sqrt()),
        };
        let torque = element.advance(h, rotated, increment, full_increment, rate, s);
        s.torque_a += torque;
        s.torque_b -= torque;
    }
}
