//! HDEM hysteresis rolling resistance (seed 001): a rolling part `rolling: "hdem"` whose
//! spring dissipates a rate-independent energy per cycle, beside the rolling parts of
//! `talus-rolling-resistance`.
//!
//! * [`hysteresis`]: the scalar hysteresis spring of eqs. (11)–(13), reversal points,
//!   elastic limit and slider, with its exact energy.
//! * [`rolling`]: [`HdemRolling`], the contact sub-model: hysteresis spring + dashpot +
//!   slider + no-tension joint in the rolling direction, for disks and spheres.
//!
//! Physics, the choice between eqs. (11) and (13), parameters and the free-rocking
//! experiment are in `docs/laws/hdem.md`.

#![warn(missing_docs)]

pub mod hysteresis;
pub mod rolling;

pub use hysteresis::{Branch, BranchShape, HysteresisLimits, HysteresisState, HysteresisStep};
pub use rolling::{
    ALUMINIUM_EXPONENT, HDEM, HdemHistory, HdemParams, HdemRolling, POLYURETHANE_EXPONENT,
};

use talus_contact::{ComposedLaw, LawRegistry, NoTwisting, SubModel};
use talus_rolling_resistance::SpringDashpotTwisting;

/// Registers, for the law `name` made of normal `N`, damping `D` and tangential `T`
/// parts, the variants with the HDEM rolling part: without twisting and with the
/// `spring_dashpot` twisting part, so that scenes select `rolling: "hdem"`.
pub fn register_variants<N: SubModel, D: SubModel, T: SubModel>(
    registry: &mut LawRegistry,
    name: &'static str,
    summary: &'static str,
) {
    registry.register(Box::new(
        ComposedLaw::<N, D, T, HdemRolling<N>, NoTwisting>::new(name, summary),
    ));
    registry.register(Box::new(ComposedLaw::<
        N,
        D,
        T,
        HdemRolling<N>,
        SpringDashpotTwisting<N>,
    >::new(name, summary)));
}
