//! The grains' order in memory: rows of cells, so that grains near in space stay near in
//! memory (the scene's sort as grains are read, and the re-sort a scene may ask for).
//!
//! Grains move, and a packing poured or mixed ends with its neighbours anywhere in the
//! tables; every loop that reaches a grain's partners then waits on memory. Like LAMMPS's
//! `atom_modify sort`, the grains can be put back in order of their cells between two
//! steps. The order changes no physics: contacts are entities keyed by their grains'
//! entities, and the snapshot, the contact index and the neighbour list follow the new
//! order at the next step (`tests/contact_history_reorder.rs`).

use bevy_ecs::prelude::*;
use glam::DVec3;

use crate::components::{Frozen, Grain, Position, Radius};

/// The order of rows of cubic cells one largest diameter wide over the box that bounds a
/// set of grains: x fastest, then y, then z (LAMMPS's `atom_modify sort` order).
///
/// Rows rather than a Z-order curve (`docs/architecture.md`, "Grain order"): a block of
/// consecutive grains is then one or two cells thin along z, the axis of gravity and of a
/// flow's shear, so the spread of its grains' moves, which bounds the narrow phase's pair
/// tests, is small; and a grain's partners are never more than two layers of cells away in
/// memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowsOfCells {
    low: DVec3,
    cell: f64,
    cells_x: u64,
    cells_y: u64,
}

impl RowsOfCells {
    /// The cells over `grains` (position, radius pairs); `None` for no grain or no positive
    /// radius, where there is nothing to order by.
    pub fn over(grains: impl Iterator<Item = (DVec3, f64)> + Clone) -> Option<Self> {
        let cell = grains
            .clone()
            .map(|(_, r)| 2.0 * r)
            .reduce(f64::max)
            .filter(|d| *d > 0.0)?;
        let (low, high) = grains.fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(low, high), (p, _)| (low.min(p), high.max(p)),
        );
        let mut rows = Self {
            low,
            cell,
            cells_x: 1,
            cells_y: 1,
        };
        let [top_x, top_y, _] = rows.cell_of(high);
        rows.cells_x = top_x.saturating_add(1);
        rows.cells_y = top_y.saturating_add(1);
        Some(rows)
    }

    fn cell_of(&self, p: DVec3) -> [u64; 3] {
        // `as` saturates (a NaN to 0), so no position makes a key panic.
        let c = ((p - self.low) / self.cell).floor();
        [c.x as u64, c.y as u64, c.z as u64]
    }

    /// The sort key of a grain at `p`: its cell's place in the rows. Saturating: a packing
    /// too sparse for 64 bits of cells (never a real one) is only sorted less well.
    pub fn key(&self, p: DVec3) -> u64 {
        let [x, y, z] = self.cell_of(p);
        z.saturating_mul(self.cells_y)
            .saturating_add(y)
            .saturating_mul(self.cells_x)
            .saturating_add(x)
    }
}

/// Held by the grains of a table every other time they are sorted: adding or removing it
/// moves a grain to the end of another table.
#[derive(Component)]
struct Resorted;

/// Puts the grains of every table in the order of [`RowsOfCells`] over all grains. A table
/// not already in order moves, grain by grain in the new order, to the table that differs
/// from it by a marker component (added if its grains lack it, removed if they hold it):
/// bevy has no other way to permute a table's rows, and one move a grain costs half of
/// a move out and back. Each table so moved keeps its allocation for the next sort, so the
/// grains' components then take twice their room. A stable sort: grains of one cell
/// keep their order, so the result is a function of the positions and the order before.
/// Returns the number of grains moved.
///
/// The grains' components must hold their state (the motion is not held in the snapshot:
/// [`Simulation::sort_grains`](crate::schedule::Simulation::sort_grains) writes it back
/// first). Per-grain histories kept in grain order (the Gear integrator's derivatives) are
/// permuted along.
pub fn sort_grains(world: &mut World) -> usize {
    let mut grains = world.query_filtered::<(Entity, &Position, &Radius), With<Grain>>();
    let Some(rows) = RowsOfCells::over(grains.iter(world).map(|(_, p, r)| (p.0, r.0))) else {
        return 0;
    };
    let mut tables: Vec<Vec<(u64, Entity)>> = Vec::new();
    for (entities, positions, _) in grains
        .contiguous_iter(world)
        .expect("the grain query is dense")
    {
        let keyed: Vec<(u64, Entity)> = entities
            .iter()
            .zip(positions)
            .map(|(e, p)| (rows.key(p.0), *e))
            .collect();
        if !keyed.is_sorted_by_key(|k| k.0) {
            tables.push(keyed);
        }
    }
    if tables.is_empty() {
        return 0;
    }
    let mut moving = world.query_filtered::<Entity, (With<Grain>, Without<Frozen>)>();
    let gear = world.contains_resource::<crate::gear::GearHistory>();
    let moving_before: Vec<Entity> = if gear {
        moving.iter(world).collect()
    } else {
        Vec::new()
    };
    let mut moved = 0;
    for mut table in tables {
        table.sort_by_key(|k| k.0);
        if world.entity(table[0].1).contains::<Resorted>() {
            for &(_, e) in &table {
                world.entity_mut(e).remove::<Resorted>();
            }
        } else {
            world.insert_batch(table.iter().map(|&(_, e)| (e, Resorted)));
        }
        moved += table.len();
    }
    if gear {
        let moving_after: Vec<Entity> = moving.iter(world).collect();
        world
            .resource_mut::<crate::gear::GearHistory>()
            .reorder(&moving_before, &moving_after);
    }
    moved
}
