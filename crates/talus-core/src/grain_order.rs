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

/// Held by a grain for a moment during a sort: adding it moves the grain to the end of
/// another table, removing it moves the grain back to the end of its own.
#[derive(Component)]
struct Resorting;

/// Puts the grains of every table in the order of [`RowsOfCells`] over all grains. A table
/// not already in order has its grains moved out, in the new order, to the table that
/// differs from it by a marker component, and back, in the same order: bevy has no other way
/// to permute a table's rows. (Leaving the marker on, one move a grain, would be faster, but a
/// grain spawned later goes to the unmarked table, and moving into a table that holds grains
/// would leave it out of order.) Each table keeps its allocation, so from the first sort on
/// the grains' components take twice their room. A stable sort: grains of one cell keep
/// their order, so the result is a function of the positions and the order before. Returns
/// the number of grains moved.
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
        world.insert_batch(table.iter().map(|&(_, e)| (e, Resorting)));
        for &(_, e) in &table {
            world.entity_mut(e).remove::<Resorting>();
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Each table's grains in the order of the rows of cells over all grains, checked from
    /// the definition: cells one largest diameter wide from the lowest corner, x fastest.
    fn assert_tables_in_rows(world: &mut World) {
        let mut q = world.query_filtered::<(&Position, &Radius), With<Grain>>();
        let grains: Vec<(DVec3, f64)> = q.iter(world).map(|(p, r)| (p.0, r.0)).collect();
        let cell = grains.iter().map(|g| 2.0 * g.1).fold(0.0, f64::max);
        let low = grains.iter().fold(DVec3::INFINITY, |low, g| low.min(g.0));
        let high = grains
            .iter()
            .fold(DVec3::NEG_INFINITY, |high, g| high.max(g.0));
        let cells = ((high - low) / cell).floor() + 1.0;
        let key = |p: DVec3| {
            let c = ((p - low) / cell).floor();
            (c.z * cells.y + c.y) * cells.x + c.x
        };
        for (positions, _) in q.contiguous_iter(world).unwrap() {
            let keys: Vec<f64> = positions.iter().map(|p| key(p.0)).collect();
            assert!(keys.windows(2).all(|k| k[0] <= k[1]), "{keys:?}");
        }
    }

    fn spawn(world: &mut World, count: u64, salt: u64, frozen: bool) {
        for i in 0..count {
            // Positions scattered by a multiplicative hash: any order but a sorted one.
            let h = (i + salt).wrapping_mul(0x9E37_79B9_7F4A_7C15);
            let p = DVec3::new(
                (h % 97) as f64 * 0.01,
                ((h >> 8) % 89) as f64 * 0.01,
                ((h >> 16) % 83) as f64 * 0.01,
            );
            let mut e = world.spawn((Grain, Position(p), Radius(0.004)));
            if frozen {
                e.insert(Frozen);
            }
        }
    }

    /// Two tables (moving and frozen grains), sorted, grains added to the moving table,
    /// sorted again: every table ends in rows of cells, every grain kept, and a sorted
    /// packing is left alone.
    #[test]
    fn every_table_ends_in_rows_of_cells() {
        let mut world = World::new();
        spawn(&mut world, 500, 0, false);
        spawn(&mut world, 200, 1000, true);
        let before: std::collections::BTreeSet<Entity> = world
            .query_filtered::<Entity, With<Grain>>()
            .iter(&world)
            .collect();
        assert_eq!(sort_grains(&mut world), 700);
        assert_tables_in_rows(&mut world);
        assert_eq!(sort_grains(&mut world), 0);
        spawn(&mut world, 300, 5000, false);
        assert_eq!(sort_grains(&mut world), 800, "the moving table only");
        assert_tables_in_rows(&mut world);
        let after: std::collections::BTreeSet<Entity> = world
            .query_filtered::<Entity, With<Grain>>()
            .iter(&world)
            .collect();
        assert_eq!(before.len(), 700);
        assert!(before.is_subset(&after) && after.len() == 1000);
    }
}
