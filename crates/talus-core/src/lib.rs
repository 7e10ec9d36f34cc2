//! Talus core: the grain, wall and contact-independent components, the resources a
//! step reads, the staged step schedule, the plugin builder, and the integrators.
//!
//! Everything physical is an ECS entity; hot loops read a dense [`GrainSnapshot`]
//! rebuilt from the entities every step, so the entities stay the source of truth.

pub mod components;
pub mod counting;
pub mod energy;
pub mod gear;
pub mod grain_order;
pub mod integrate;
pub mod lanes;
pub mod periodic;
pub mod regions;
pub mod resources;
pub mod schedule;
pub mod snapshot;
pub mod workers;

pub use glam::DVec3;

/// Everything a plugin or a scene builder usually needs.
pub mod prelude {
    pub use crate::components::*;
    pub use crate::energy::*;
    pub use crate::periodic::{LeesEdwards, PeriodicBox};
    pub use crate::resources::*;
    pub use crate::schedule::*;
    pub use crate::snapshot::*;
    pub use glam::DVec3;
}
