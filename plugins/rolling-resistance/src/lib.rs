//! Rolling and twisting resistance sub-models, added to a contact law assembled from
//! parts with `rolling: "..."` and `twisting: "..."` in a scene's contact spec.
//!
//! Rolling parts ([`rolling`]), after the classification of Ai, Chen, Rotter & Ooi,
//! Powder Technology 206 (2011) 269–282:
//! * `constant_torque` ([`ConstantTorque`], their model A): |M| = μ_r F_n R*, opposing
//!   the relative rolling angular velocity. It chatters at rest, by construction.
//! * `viscous` ([`ViscousRolling`], a model-B-like torque): M = −c_r ω_r, optionally
//!   capped at μ_r F_n R*.
//! * `elastic_plastic` ([`ElasticPlasticRolling`], their model C, the "conventional"
//!   Iwashita–Oda spring–dashpot–slider of seed 001): an incremental rotational spring
//!   capped at μ_r F_n R*, with a dashpot active while the spring holds.
//!
//! Twisting part ([`twisting`]): `spring_dashpot` ([`SpringDashpotTwisting`]), the same
//! spring–dashpot–slider about the contact normal, capped at μ_tw F_n a with a = √(R* δ).
//!
//! Conventions: ω_rel = ω_a − ω_b (ω_a against a wall), n from b to a; the rolling
//! velocity is ω_r = ω_rel − (ω_rel·n) n, the twisting velocity (ω_rel·n) n. A part's
//! torque M acts on a and −M on b. In 2-D (disks in the xy-plane) only rotation about z
//! exists: rolling torques are along z, and there is no twisting. The physics, energy
//! definitions and parameter tables are in `docs/physics/rolling-resistance.md`.

pub mod element;
pub mod rolling;
pub mod twisting;

pub use element::{TorqueSpringHistory, TorqueSpringLaw};
pub use rolling::{
    ConstantTorque, ConstantTorqueParams, ElasticPlasticParams, ElasticPlasticRolling,
    RollingStiffness, TorqueHistory, ViscousParams, ViscousRolling,
};
pub use twisting::{SpringDashpotTwisting, TwistingParams};

use talus_contact::{ComposedLaw, LawRegistry, NoRolling, NoTwisting, SubModel};

/// Scene names of the rolling parts, in registration order.
pub const ROLLING_PARTS: [&str; 3] = [
    rolling::CONSTANT_TORQUE,
    rolling::VISCOUS,
    rolling::ELASTIC_PLASTIC,
];

/// Scene names of the twisting parts.
pub const TWISTING_PARTS: [&str; 1] = [twisting::SPRING_DASHPOT];

/// Registers, for the law `name` made of normal `N`, damping `D` and tangential `T`
/// parts, one variant per rolling and twisting part a scene may add: every rolling part
/// (none, `constant_torque`, `viscous`, `elastic_plastic`) with every twisting part
/// (none, `spring_dashpot`), except the law without either, which the base law
/// registers itself. The spring parts derive their stiffness from `N`'s, so they also
/// take their stability estimate from `N`'s time scale.
pub fn register_variants<N: SubModel, D: SubModel, T: SubModel>(
    registry: &mut LawRegistry,
    name: &'static str,
    summary: &'static str,
) {
    register_twisting_choices::<N, D, T, ConstantTorque>(registry, name, summary);
    register_twisting_choices::<N, D, T, ViscousRolling>(registry, name, summary);
    register_twisting_choices::<N, D, T, ElasticPlasticRolling<N>>(registry, name, summary);
    registry.register(Box::new(ComposedLaw::<
        N,
        D,
        T,
        NoRolling,
        SpringDashpotTwisting<N>,
    >::new(name, summary)));
}

/// Registers rolling part `R` without twisting and with each twisting part.
fn register_twisting_choices<N: SubModel, D: SubModel, T: SubModel, R: SubModel>(
    registry: &mut LawRegistry,
    name: &'static str,
    summary: &'static str,
) {
    registry.register(Box::new(ComposedLaw::<N, D, T, R, NoTwisting>::new(
        name, summary,
    )));
    registry.register(Box::new(
        ComposedLaw::<N, D, T, R, SpringDashpotTwisting<N>>::new(name, summary),
    ));
}
