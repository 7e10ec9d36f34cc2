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
use rayon::prelude::*;
use talus_core::counting::counting_sort;
use talus_core::snapshot::{GrainSnapshot, prefetch_item};

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

/// Grains whose groups of contacts one job of a sort orders by second body.
const GROUP_GRAINS: usize = 4096;

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
    if bodies.par_windows(2).all(|w| key(&w[0]) <= key(&w[1])) {
        return 0;
    }
    // Row r receives the contents of row order[r]: a counting sort by first body (two
    // sequential passes, no comparison, each thread over a range of grains), then each
    // first body's few contacts by second body. Stable, so two rows with one key (no
    // valid table has any) keep their order.
    let mut start = Vec::new();
    let mut order = vec![0u32; bodies.len()];
    let first_bodies = &*bodies;
    counting_sort(
        bodies.len(),
        s.len(),
        |row| first_bodies[row].a as usize,
        &mut start,
        &mut order,
    );
    // Grain a's group is order[start[a]..start[a + 1]]: the groups of each chunk of
    // grains are sorted by one job.
    let mut pieces: Vec<(usize, &mut [u32])> = Vec::with_capacity(s.len().div_ceil(GROUP_GRAINS));
    let mut rest = &mut order[..];
    for first in (0..s.len()).step_by(GROUP_GRAINS) {
        let end = (first + GROUP_GRAINS).min(s.len());
        let (piece, others) = rest.split_at_mut((start[end] - start[first]) as usize);
        pieces.push((first, piece));
        rest = others;
    }
    let (starts, rows) = (&start, &*bodies);
    pieces.into_par_iter().for_each(|(first, piece)| {
        let base = starts[first];
        let end = (first + GROUP_GRAINS).min(starts.len() - 1);
        for a in first..end {
            let group = &mut piece[(starts[a] - base) as usize..(starts[a + 1] - base) as usize];
            if group.len() > 1 {
                group.sort_by_key(|&row| rows[row as usize].b);
            }
        }
    });
    drop(start);
    let moved = order
        .par_iter()
        .enumerate()
        .filter(|&(row, &from)| row != from as usize)
        .count();
    let jobs = if rayon::current_num_threads() >= PER_COLUMN_FROM_THREADS {
        PermuteJobs::PerColumn
    } else {
        PermuteJobs::Two
    };
    permute_table(
        &order, jobs, contacts, histories, geometries, forces, bodies,
    );
    moved
}

/// How a table's permutation is split into parallel jobs. Either gives the same table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PermuteJobs {
    /// Two jobs of about equal bytes a row, each walking the permutation once for its
    /// columns, so that a step of a cycle asks for a row of every column at once: for
    /// fewer threads than columns, where more walks would queue behind each other.
    Two,
    /// One job per column, five walks of the permutation, each waiting on its own rows:
    /// for at least one thread per column ([`PER_COLUMN_FROM_THREADS`]).
    PerColumn,
}

/// Threads from which a table's permutation runs one job per column. Each walk of the
/// permutation costs about as much whatever the columns it moves (it waits on the rows it
/// reaches), so five walks beat two only when they all run at once. Session 57, on a
/// 16-core machine, the table sorts' time a step (a probe, 3 runs each): on 16 threads
/// 518–575 µs per column against 633–852 in two jobs at 512,000 grains, 50–54 against 58–64
/// at 32,000; on 4 threads 765–814 against 628–678 at 512,000 grains.
const PER_COLUMN_FROM_THREADS: usize = 5;

/// Permutes a law table's five columns so that row `r` takes the old row `order[r]`.
fn permute_table<H: Send + Sync + 'static>(
    order: &[u32],
    jobs: PermuteJobs,
    contacts: &mut [Contact],
    histories: &mut [LawState<H>],
    geometries: &mut [ContactGeometry],
    forces: &mut [ContactForce],
    bodies: &mut [ContactBodies],
) {
    match jobs {
        PermuteJobs::Two => {
            rayon::join(
                || permute(order, (contacts, (histories, bodies))),
                || permute(order, (geometries, forces)),
            );
        }
        PermuteJobs::PerColumn => {
            rayon::join(
                || rayon::join(|| permute(order, forces), || permute(order, geometries)),
                || {
                    rayon::join(
                        || permute(order, histories),
                        || rayon::join(|| permute(order, contacts), || permute(order, bodies)),
                    )
                },
            );
        }
    }
}

/// Columns of a table permuted together: a row is asked for ahead and swapped in every
/// column at once.
trait Columns {
    /// Asks for row `row` of every column ahead of its swap, without waiting.
    fn ask(&self, row: usize);
    /// Swaps rows `row` and `from` of every column.
    fn swap(&mut self, row: usize, from: usize);
}

impl<T> Columns for &mut [T] {
    fn ask(&self, row: usize) {
        prefetch_item(self, row);
    }
    fn swap(&mut self, row: usize, from: usize) {
        <[T]>::swap(self, row, from);
    }
}

impl<A: Columns, B: Columns> Columns for (A, B) {
    fn ask(&self, row: usize) {
        self.0.ask(row);
        self.1.ask(row);
    }
    fn swap(&mut self, row: usize, from: usize) {
        self.0.swap(row, from);
        self.1.swap(row, from);
    }
}

/// Permutes `rows` in place so that row `r` of every column takes the old row
/// `order[r]`, following each cycle of the permutation with swaps: no copy of a column
/// (a gather into scratch columns was faster but raised the peak memory of a
/// 512,000-grain run by 25 bytes a grain), a bit per row to mark the rows done. Between
/// two sorts about a third of the rows changed pairs, so the cycles are few and long and
/// jump across the table; the row [`AHEAD`] places further along the cycle is asked for
/// ahead (`order` is small and cached, so walking it ahead is cheap).
fn permute(order: &[u32], mut rows: impl Columns) {
    /// How many rows along a cycle are asked for ahead of the swap.
    const AHEAD: usize = 8;
    let mut done = vec![0u64; order.len().div_ceil(64)];
    for start in 0..order.len() {
        if order[start] as usize == start || done[start / 64] & (1 << (start % 64)) != 0 {
            continue;
        }
        // `ahead` walks the cycle AHEAD rows in front of `row` and stops at its start.
        let mut ahead = start;
        for _ in 0..AHEAD {
            ahead = order[ahead] as usize;
            if ahead == start {
                break;
            }
            rows.ask(ahead);
        }
        let mut row = start;
        loop {
            done[row / 64] |= 1 << (row % 64);
            let from = order[row] as usize;
            if from == start {
                break;
            }
            if ahead != start {
                ahead = order[ahead] as usize;
                rows.ask(ahead);
            }
            // `row` takes `from`'s contents; `start`'s travel on to `from`.
            rows.swap(row, from);
            row = from;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permute_gives_each_row_the_contents_the_order_names() {
        // A permutation with a fixed point, a 2-cycle and a 4-cycle.
        let order = [0u32, 2, 1, 6, 3, 4, 5];
        let old: Vec<u32> = (100..107).collect();
        let mut rows = old.clone();
        permute(&order, rows.as_mut_slice());
        for (r, &from) in order.iter().enumerate() {
            assert_eq!(rows[r], old[from as usize], "row {r}");
        }
        // Applying the inverse restores the table.
        let mut inverse = vec![0u32; order.len()];
        for (r, &from) in order.iter().enumerate() {
            inverse[from as usize] = r as u32;
        }
        permute(&inverse, rows.as_mut_slice());
        assert_eq!(rows, old);
    }

    #[test]
    fn permute_moves_the_rows_of_every_column_alike() {
        // One long cycle through a table of 100 rows, longer than the look-ahead.
        let order: Vec<u32> = (0..100).map(|r| (r * 37 + 11) % 100).collect();
        let old_a: Vec<u32> = (0..100).collect();
        let old_b: Vec<[f64; 3]> = (0..100).map(|r| [f64::from(r); 3]).collect();
        let old_c: Vec<u8> = (0..100).map(|r| r as u8).collect();
        let (mut a, mut b, mut c) = (old_a.clone(), old_b.clone(), old_c.clone());
        permute(
            &order,
            (a.as_mut_slice(), (b.as_mut_slice(), c.as_mut_slice())),
        );
        for (r, &from) in order.iter().enumerate() {
            let from = from as usize;
            assert_eq!(
                (a[r], b[r], c[r]),
                (old_a[from], old_b[from], old_c[from]),
                "row {r}"
            );
        }
    }

    #[test]
    fn a_table_permuted_per_column_on_many_threads_equals_the_two_job_permutation() {
        let n = 5_000usize;
        let order: Vec<u32> = (0..n as u32).map(|r| (r * 2_017 + 11) % n as u32).collect();
        let table = || {
            let contacts: Vec<Contact> = (0..n)
                .map(|r| Contact::vacant(Entity::from_raw_u32(r as u32 + 1).unwrap()))
                .collect();
            let histories: Vec<LawState<[f64; 3]>> = (0..n)
                .map(|r| LawState([r as f64, 1.0, -(r as f64)]))
                .collect();
            let geometries: Vec<ContactGeometry> = (0..n)
                .map(|r| ContactGeometry {
                    normal: glam::DVec3::new(r as f64, 0.5, 0.25),
                    overlap: r as f64 * 1e-3,
                })
                .collect();
            let forces: Vec<ContactForce> = (0..n)
                .map(|r| ContactForce {
                    force: glam::DVec3::splat(r as f64),
                    torque_a: glam::DVec3::X * r as f64,
                    torque_b: glam::DVec3::Y * r as f64,
                })
                .collect();
            let bodies: Vec<ContactBodies> = (0..n as u32)
                .map(|r| ContactBodies {
                    a: r,
                    b: r + 1,
                    layout: 7,
                })
                .collect();
            (contacts, histories, geometries, forces, bodies)
        };
        let permuted = |jobs: PermuteJobs, threads: usize| {
            let (mut c, mut h, mut g, mut f, mut b) = table();
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool")
                .install(|| permute_table(&order, jobs, &mut c, &mut h, &mut g, &mut f, &mut b));
            (c, h.into_iter().map(|s| s.0).collect::<Vec<_>>(), g, f, b)
        };
        let two = permuted(PermuteJobs::Two, 2);
        let per_column = permuted(PermuteJobs::PerColumn, 4);
        assert_eq!(two, per_column);
        // And it is the permutation `order` names.
        let (c, h, g, f, b) = table();
        let r = 1_234;
        let from = order[r] as usize;
        assert_eq!(
            (two.0[r], two.1[r], two.2[r], two.3[r], two.4[r]),
            (c[from], h[from].0, g[from], f[from], b[from])
        );
    }
}
