//! Talus collision detection: a uniform cell grid (broad phase) and exact
//! sphere–sphere and sphere–plane tests (narrow phase) that create and remove
//! contact entities.
//!
//! Contract: the broad phase may propose pairs that do not touch, never miss one that
//! does. Cost is O(N): Verlet neighbour lists with a skin, built (when a grain has moved
//! half the skin) by a counting sort into cells of edge ≥ 2 R_max + r_c + skin and a
//! 27-cell stencil per grain. No hashing anywhere.

pub mod grid;
pub mod narrow;
pub mod neighbours;

use talus_core::schedule::{Plugin, SimBuilder, Stage};

pub use grid::CellGrid;
pub use narrow::ContactIndex;
pub use neighbours::{CandidateChunk, NeighbourList};

/// Installs the broad phase and the narrow phase.
#[derive(Clone, Copy, Debug, Default)]
pub struct CollisionPlugin {
    /// Largest gap at which any contact law of the scene acts (cohesion beyond touch), m.
    pub interaction_range: f64,
}

impl Plugin for CollisionPlugin {
    fn name(&self) -> String {
        "collision".into()
    }

    fn build(&self, sim: &mut SimBuilder) {
        let grid = CellGrid {
            interaction_range: self.interaction_range,
            ..CellGrid::default()
        };
        sim.world.insert_resource(grid);
        sim.world.insert_resource(ContactIndex::default());
        sim.world.insert_resource(NeighbourList::default());
        sim.add_system(
            Stage::BroadPhase,
            "neighbour_list",
            neighbours::update_neighbour_list,
        );
        sim.add_system(
            Stage::NarrowPhase,
            "update_contact_entities",
            narrow::update_contacts,
        );
        // It takes the world to spawn and despawn contacts; it reads the grains only
        // through the snapshot, and no force total.
        sim.declare_motion_free(&narrow::update_contacts);
        sim.declare_frozen_totals_unread(&narrow::update_contacts);
    }
}
