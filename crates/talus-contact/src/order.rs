//! Keeping each law's contact table in the order of its grains, so that the force loop
//! and the force sums read the snapshot's grains in nearly sequential order.
//!
//! Contacts are born in grain order, but every despawn refills its row of the table with
//! the table's last contact, so within a hundred steps the table is in no order and each
//! contact's reads of its two grains miss the cache once the grains outgrow it. bevy_ecs
//! cannot move a table's rows; this module moves their *contents* instead: the rows of
//! one law's table (all of its components, none left behind) are permuted among the same
//! entities, so that after a sort the contact in row r is the r-th in the order of its
//! bodies' dense indices. A contact entity therefore stands for another pair after a sort;
//! whoever keys contacts by pair (the narrow phase's index) re-points its entries, and
//! nothing keeps a contact's entity across steps otherwise. The pair, its geometry, force
//! and history move together, bit for bit.

use bevy_ecs::prelude::*;
use talus_core::snapshot::GrainSnapshot;

use crate::components::*;
use crate::law::ContactLaw;

/// Sorts one law's contact table by its contacts' bodies; returns how many rows changed
/// contents (0 when the table was already in order).
pub type ContactTableSort = fn(&mut World, &GrainSnapshot) -> usize;

/// The table sorts of the installed laws, one per law that has contacts, in installation
/// order, each with its law's Rust type name ([`crate::install_law`] adds them).
#[derive(Resource, Clone, Debug, Default)]
pub struct ContactTableSorts(pub Vec<(&'static str, ContactTableSort)>);

/// How many components a contact of a law carries: [`Contact`], [`ContactGeometry`],
/// [`ContactForce`], [`ContactBodies`] and the law's [`LawState`]. A table whose contacts
/// carry anything more is not sorted, since its extra column would not move with them.
const CONTACT_COMPONENTS: usize = 5;

/// Sorts law `L`'s contact table so that row order is the order of (first body's dense
/// index, second body's dense index or wall code), and brings every contact's
/// [`ContactBodies`] up to the snapshot's layout. A sort is a fixed function of the set of
/// contacts and the grains' order, so the order after it (and the order in which forces
/// are summed) does not depend on the history of spawns and despawns or on the number of
/// threads. Returns the number of rows whose contents moved. Leaves the table as it is
/// if any contact's body is missing from the snapshot or if the law's contacts carry a
/// component besides their five.
pub fn sort_law_contacts<L: ContactLaw>(world: &mut World, s: &GrainSnapshot) -> usize {
    let Some(state_id) = world.component_id::<LawState<L::History>>() else {
        return 0;
    };
    let whole_rows = world
        .archetypes()
        .iter()
        .filter(|a| a.contains(state_id))
        .all(|a| a.component_count() == CONTACT_COMPONENTS);
    if !whole_rows {
        return 0;
    }
    let mut query = world.query::<(
        &mut Contact,
        &mut LawState<L::History>,
        &mut ContactGeometry,
        &mut ContactForce,
        &mut ContactBodies,
    )>();
    let mut moved = 0;
    for (mut c, mut h, mut g, mut f, mut b) in query
        .query_mut(world)
        .contiguous_iter_mut()
        .expect("contact query is dense")
    {
        moved += sort_rows(
            s,
            c.bypass_change_detection(),
            h.bypass_change_detection(),
            g.bypass_change_detection(),
            f.bypass_change_detection(),
            b.bypass_change_detection(),
        );
    }
    moved
}

/// Sorts one table's rows (its five columns) by body indices; see [`sort_law_contacts`].
fn sort_rows<H: Send + Sync + 'static>(
    s: &GrainSnapshot,
    contacts: &mut [Contact],
    histories: &mut [LawState<H>],
    geometries: &mut [ContactGeometry],
    forces: &mut [ContactForce],
    bodies: &mut [ContactBodies],
) -> usize {
    // Contacts made since the last force evaluation, or before a change of the grains'
    // order, still have to be looked up.
    for (c, b) in contacts.iter().zip(bodies.iter_mut()) {
        if b.layout != s.layout {
            match ContactBodies::look_up(s, c) {
                Some(fresh) => *b = fresh,
                None => return 0,
            }
        }
        if b.a as usize >= s.len() {
            return 0;
        }
    }
    let key = |b: &ContactBodies| (u64::from(b.a) << 32) | u64::from(b.b);
    if bodies.is_sorted_by_key(key) {
        return 0;
    }
    // Row r receives the contents of row order[r]: a counting sort by first body (two
    // sequential passes, no comparison), then each first body's few contacts by second
    // body. Stable, so two rows with one key (no valid table has any) keep their order.
    let mut start = vec![0u32; s.len() + 1];
    for b in bodies.iter() {
        start[b.a as usize + 1] += 1;
    }
    for k in 1..start.len() {
        start[k] += start[k - 1];
    }
    let mut order = vec![0u32; bodies.len()];
    for (row, b) in bodies.iter().enumerate() {
        let slot = &mut start[b.a as usize];
        order[*slot as usize] = row as u32;
        *slot += 1;
    }
    // Now start[a] is where grain a's group ends, and the next one begins.
    let mut begin = 0;
    for &end in &start[..s.len()] {
        let group = &mut order[begin..end as usize];
        if group.len() > 1 {
            group.sort_by_key(|&row| bodies[row as usize].b);
        }
        begin = end as usize;
    }
    drop(start);
    let moved = order
        .iter()
        .enumerate()
        .filter(|&(row, &from)| row != from as usize)
        .count();
    // The columns are independent: one job each.
    let order = &order;
    rayon::scope(|jobs| {
        jobs.spawn(move |_| permute(order, contacts));
        jobs.spawn(move |_| permute(order, histories));
        jobs.spawn(move |_| permute(order, geometries));
        jobs.spawn(move |_| permute(order, forces));
        jobs.spawn(move |_| permute(order, bodies));
    });
    moved
}

/// Permutes `rows` in place so that `rows[r]` becomes the old `rows[order[r]]`, following
/// each cycle of the permutation with swaps: no copy of the column, a bit per row to mark
/// the rows done.
fn permute<T>(order: &[u32], rows: &mut [T]) {
    debug_assert_eq!(order.len(), rows.len());
    let mut done = vec![0u64; rows.len().div_ceil(64)];
    for start in 0..rows.len() {
        if order[start] as usize == start || done[start / 64] & (1 << (start % 64)) != 0 {
            continue;
        }
        let mut row = start;
        loop {
            done[row / 64] |= 1 << (row % 64);
            let from = order[row] as usize;
            if from == start {
                break;
            }
            // `row` takes `from`'s contents; `start`'s travel on to `from`.
            rows.swap(row, from);
            row = from;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::permute;

    #[test]
    fn permute_gives_each_row_the_contents_the_order_names() {
        // A permutation with a fixed point, a 2-cycle and a 4-cycle.
        let order = [0u32, 2, 1, 6, 3, 4, 5];
        let old: Vec<u32> = (100..107).collect();
        let mut rows = old.clone();
        permute(&order, &mut rows);
        for (r, &from) in order.iter().enumerate() {
            assert_eq!(rows[r], old[from as usize], "row {r}");
        }
        // Applying the inverse restores the table.
        let mut inverse = vec![0u32; order.len()];
        for (r, &from) in order.iter().enumerate() {
            inverse[from as usize] = r as u32;
        }
        permute(&inverse, &mut rows);
        assert_eq!(rows, old);
    }
}
