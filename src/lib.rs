//! Talus: discrete-element simulation of granular matter on an entity-component system.
//!
//! This facade re-exports the crates of the workspace and assembles the registry of
//! contact laws the `talus` binary offers.

pub use talus_cli as cli;
pub use talus_collision as collision;
pub use talus_contact as contact;
pub use talus_core as core;
pub use talus_rerun as rerun_export;
pub use talus_scene as scene;

/// Every contact law shipped with Talus, by name.
pub fn registry() -> talus_contact::LawRegistry {
    let mut r = talus_contact::LawRegistry::new();
    talus_linear_spring::register(&mut r);
    talus_hertz_mindlin::register(&mut r);
    talus_linear_cohesion::register(&mut r);
    talus_jiang_liu::register(&mut r);
    // Rolling and twisting parts on top of each law assembled from sub-models.
    {
        use talus_hertz_mindlin::{HertzDamping, HertzNormal, MindlinTangential};
        use talus_linear_spring::parts::{CoulombSpring, LinearDashpot, LinearNormal};
        talus_rolling_resistance::register_variants::<LinearNormal, LinearDashpot, CoulombSpring>(
            &mut r,
            talus_linear_spring::NAME,
            talus_linear_spring::SUMMARY,
        );
        talus_rolling_resistance::register_variants::<HertzNormal, HertzDamping, MindlinTangential>(
            &mut r,
            talus_hertz_mindlin::NAME,
            talus_hertz_mindlin::SUMMARY,
        );
        talus_hdem::register_variants::<LinearNormal, LinearDashpot, CoulombSpring>(
            &mut r,
            talus_linear_spring::NAME,
            talus_linear_spring::SUMMARY,
        );
        talus_hdem::register_variants::<HertzNormal, HertzDamping, MindlinTangential>(
            &mut r,
            talus_hertz_mindlin::NAME,
            talus_hertz_mindlin::SUMMARY,
        );
    }
    r
}
