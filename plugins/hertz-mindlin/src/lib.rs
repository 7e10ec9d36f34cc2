//! The Hertz–Mindlin contact law for elastic spheres, assembled from sub-models.
//!
//! Normal: Hertz, F_n = (4/3) E* √R* δ^{3/2} ([`HertzNormal`]), with a dashpot
//! c ∝ δ^{1/4} calibrated so that the restitution is the prescribed one at every impact
//! speed, and that never pulls ([`HertzDamping`]). Tangential: Mindlin's stiffness
//! k_t = 8 G* √(R* δ) applied incrementally to a force rotated into the tangent plane,
//! capped by Coulomb friction ([`MindlinTangential`]). E* and G* come from both
//! materials' E and ν exactly. 3-D scenes only. The physics, the damping calibration and
//! the energy definitions are in `docs/physics/hertz-mindlin.md`; [`analytic`] holds the
//! closed-form results.

pub mod analytic;
pub mod damping;
pub mod normal;
pub mod params;
pub mod tangential;

use talus_contact::{Composed, ComposedLaw, LawRegistry};

pub use damping::{HertzDamping, HertzDampingHistory, HertzDampingParams};
pub use normal::{HertzNormal, HertzNormalHistory, HertzNormalParams};
pub use params::HertzModuli;
pub use tangential::{MindlinHistory, MindlinParams, MindlinTangential};

/// Name scenes use.
pub const NAME: &str = "hertz_mindlin";

/// One line for `talus check` and the docs.
pub const SUMMARY: &str = "Hertz normal force with a restitution-calibrated δ^1/4 dashpot, \
     Mindlin tangential spring capped by Coulomb friction (3-D)";

/// The force routine of the law: Hertz normal, calibrated dashpot, Mindlin tangential.
pub type HertzMindlin = Composed<HertzNormal, HertzDamping, MindlinTangential>;

/// The descriptor of `hertz_mindlin`, without rolling or twisting part.
pub fn descriptor() -> ComposedLaw<HertzNormal, HertzDamping, MindlinTangential> {
    ComposedLaw::new(NAME, SUMMARY)
}

/// Registers `hertz_mindlin`. Rolling and twisting variants are registered on top of the
/// same parts with [`NAME`] and [`SUMMARY`].
pub fn register(registry: &mut LawRegistry) {
    registry.register(Box::new(descriptor()));
}
