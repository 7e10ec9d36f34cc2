//! Talus contacts: contact entities, contact kinematics, and the contact-law extension API.
//!
//! A contact lives while two bodies touch. Its entity is a handle for the current step:
//! the narrow phase periodically sorts each law's table into grain order by moving
//! contacts among the law's entities ([`order`]), and hands the entity of a contact that
//! ended to a new pair of its law ([`systems::LawSlot::recycle`]), so follow a contact over
//! time by its pair. It carries the pair ([`Contact`]),
//! the geometry and force of the last evaluation, and the law's own per-contact history
//! ([`LawState`]); the force loop sums the contacts' energies chunk by chunk
//! ([`ContactEnergyPartials`]). The core never names a law:
//! laws implement [`ContactLaw`] (the typed force routine) and [`LawDescriptor`]
//! (parameters, validation and installation), and a scene picks them by name. Laws are
//! usually assembled from sub-models by kind ([`compose`]): normal, damping, tangential,
//! rolling, twisting.

pub mod components;
pub mod compose;
pub mod kinematics;
pub mod law;
pub mod order;
pub mod params;
pub mod regions;
pub mod systems;

pub use components::*;
pub use compose::{
    Absent, Composed, ComposedHistory, ComposedLaw, ComposedParams, ContactState,
    ContactStateLanes, Needs, NoCohesion, NoDamping, NoRolling, NoTwisting, SubModel, SubModelKind,
    is_two_dimensional,
};
pub use kinematics::{ContactKinematics, ContactKinematicsLanes, SpinLanes};
pub use law::*;
pub use order::{ContactTableSort, ContactTableSorts};
pub use params::*;
pub use systems::{ContactPlugin, LaneForms, RegionStages, unbalanced_force_ratio};
