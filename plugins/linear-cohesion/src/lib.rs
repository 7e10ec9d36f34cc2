//! The `linear_cohesion` contact law: the linear spring–dashpot law with a reversible
//! linear adhesion that holds grains together from touch out to a small gap. It is the
//! law built step by step in `docs/writing-a-contact-law.md`; the tutorial's code is this
//! crate's code.
//!
//! Normal force, positive repulsive, at overlap δ (negative across a gap):
//! k_n δ − c_n v_n while the bodies overlap, plus −(f_0 + k_c δ) for δ ≥ −f_0/k_c.
//! Tangential: the Coulomb-capped spring of `linear_spring`, capped at μ times the total
//! normal force. Energy: ½k_n δ² + ½k_t|ξ|² − (f_0 + k_c δ)²/(2k_c) stored (the last
//! term negative while bound); the dashpots and the slider dissipate, each on its own
//! channel; the cohesion is conservative.

pub mod cohesion;

#[cfg(test)]
mod tests;

pub use cohesion::{CohesionHistory, CohesionParams, LinearCohesion};

use talus_contact::*;
use talus_linear_spring::parts::{CoulombSpring, LinearDashpot, LinearNormal};

/// Name scenes use.
pub const NAME: &str = "linear_cohesion";

/// One line for `talus check` and the docs.
pub const SUMMARY: &str = "linear spring–dashpot with reversible linear adhesion up to the gap f_0/k_c, Coulomb-capped tangential spring";

/// The law's force routine: the three parts of `linear_spring` and [`LinearCohesion`].
pub type LinearCohesionContact =
    Composed<LinearNormal, LinearDashpot, CoulombSpring, NoRolling, NoTwisting, LinearCohesion>;

/// What scenes see of the law: its name, parameters and parts.
pub type LinearCohesionLaw =
    ComposedLaw<LinearNormal, LinearDashpot, CoulombSpring, NoRolling, NoTwisting, LinearCohesion>;

/// The descriptor of `linear_cohesion`.
pub fn descriptor() -> LinearCohesionLaw {
    ComposedLaw::new(NAME, SUMMARY)
}

/// Registers `linear_cohesion`.
pub fn register(registry: &mut LawRegistry) {
    registry.register(Box::new(descriptor()));
}
