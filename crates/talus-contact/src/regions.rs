//! A contact table's rows listed by the region of their key grain
//! ([`talus_core::regions`]): the rows a stage running region by region evaluates.
//!
//! Right after a table sort ([`crate::order`]) a region's rows are one run of the table;
//! between sorts, contacts made in recycled and appended rows sit outside it, so a region
//! holds a few runs. One pass over the contacts' keys finds the runs, a few hundred in a
//! table of 16,000 contacts 19 steps after a sort; they are what is listed, not the rows.

use std::ops::Range;

use talus_core::regions::GrainRegions;
use talus_core::snapshot::GrainSnapshot;

use crate::components::{Contact, ContactBodies, WALL_BODY_BASE};

/// A run of consecutive rows of a table, `[first, end)`.
pub type RowRun = [u32; 2];

/// The rows of one contact table by region, as runs of consecutive rows: region `r`'s runs,
/// in ascending order, are `runs[offsets[r]..offsets[r + 1]]`, and every row of the table
/// is in exactly one run.
#[derive(Clone, Debug, Default)]
pub struct RegionRuns {
    offsets: Vec<u32>,
    runs: Vec<RowRun>,
    /// The runs in table order with their regions, as the pass finds them (scratch, kept
    /// for its allocation).
    found: Vec<(u32, RowRun)>,
    /// The runs cut into pieces for [`Self::batch`] (scratch).
    pieces: Vec<RowRun>,
    /// Where each batch of [`Self::batch`] ends in `pieces`.
    batch_ends: Vec<u32>,
    /// For each region, the lowest region whose rows touch one of its grains (the region
    /// itself if no other's do).
    first_touching: Vec<u32>,
}

impl RegionRuns {
    /// Lists the rows of a table (its contacts and their bodies, row by row) by the region
    /// of each contact's key grain ([`key_grain`]) in snapshot `s`, and finds for each region
    /// the lowest region whose rows touch its grains ([`Self::first_touching`]), leaving out
    /// the grains of the `untracked` ranges of dense indices (frozen grains, which contacts
    /// from anywhere in the packing touch: their force sums read every row).
    pub fn build(
        &mut self,
        regions: &GrainRegions,
        s: &GrainSnapshot,
        contacts: &[Contact],
        bodies: &[ContactBodies],
        untracked: &[Range<u32>],
    ) {
        assert_eq!(contacts.len(), bodies.len(), "one body pair per contact");
        let n = u32::try_from(contacts.len()).expect("a contact table holds under 2^32 rows");
        // One pass finds the maximal runs of rows of one region (the region in a register:
        // a count per row in memory would chain every row's increment to the last's).
        self.found.clear();
        let count = regions.count();
        self.first_touching.clear();
        self.first_touching.extend(0..count as u32);
        let mut current = (0u32, 0u32);
        for (row, d) in bodies.iter().enumerate() {
            // The contact itself is read only when its cached bodies are out of date.
            let (key, other) = key_and_other_grain(s, &contacts[row], d);
            let region = regions.region_of(key) as u32;
            let other_region = regions.region_of(other);
            if other_region as u32 > region && !untracked.iter().any(|u| u.contains(&other)) {
                let first = &mut self.first_touching[other_region];
                *first = (*first).min(region);
            }
            if region != current.0 {
                if row as u32 > current.1 {
                    self.found.push((current.0, [current.1, row as u32]));
                }
                current = (region, row as u32);
            }
        }
        if n > current.1 {
            self.found.push((current.0, [current.1, n]));
        }
        // The runs by region, in table order within each (a counting sort of the runs).
        self.offsets.clear();
        self.offsets.resize(count + 1, 0);
        for &(region, _) in &self.found {
            self.offsets[region as usize + 1] += 1;
        }
        for r in 0..count {
            self.offsets[r + 1] += self.offsets[r];
        }
        self.runs.clear();
        self.runs.resize(self.found.len(), [0, 0]);
        for &(region, run) in &self.found {
            let at = &mut self.offsets[region as usize];
            self.runs[*at as usize] = run;
            *at += 1;
        }
        self.offsets.copy_within(0..count, 1);
        self.offsets[0] = 0;
    }

    /// How many regions the lists are for.
    pub fn count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// The runs of region `r`, ascending.
    pub fn region(&self, r: usize) -> &[RowRun] {
        &self.runs[self.offsets[r] as usize..self.offsets[r + 1] as usize]
    }

    /// Every run, region after region.
    pub fn all(&self) -> &[RowRun] {
        &self.runs
    }

    /// The lowest region whose rows touch a grain of region `r` (at most `r`: a row
    /// belongs to the region of its lower grain), its untracked grains left out.
    pub fn first_touching(&self, r: usize) -> usize {
        self.first_touching[r] as usize
    }

    /// Every run of rows that touches a grain of region `r` (the runs of regions
    /// [`Self::first_touching`]`(r)..=r`; untracked grains left out), from the last row to
    /// the first: the rows whose forces a grain of `r` sums, in the order the force sums
    /// take them.
    pub fn touching_runs_descending(&self, r: usize) -> Vec<RowRun> {
        let first = self.offsets[self.first_touching(r)] as usize;
        let end = self.offsets[r + 1] as usize;
        let mut runs = self.runs[first..end].to_vec();
        // Runs are disjoint: ordered by their first rows, they are ordered by every row.
        runs.sort_unstable_by_key(|&[first, _]| std::cmp::Reverse(first));
        runs
    }

    /// Cuts the runs, region after region, into batches of at most `max_rows` rows (a run
    /// longer than that in pieces), for parallel jobs; returns how many there are
    /// ([`Self::batch`] gives each).
    pub fn make_batches(&mut self, max_rows: usize) -> usize {
        let max_rows = max_rows.max(1) as u32;
        self.pieces.clear();
        self.batch_ends.clear();
        let mut rows = 0;
        for &[first, end] in &self.runs {
            let mut start = first;
            while start < end {
                let piece_end = end.min(start + max_rows);
                let len = piece_end - start;
                if rows + len > max_rows && rows > 0 {
                    self.batch_ends.push(self.pieces.len() as u32);
                    rows = 0;
                }
                self.pieces.push([start, piece_end]);
                rows += len;
                start = piece_end;
            }
        }
        if rows > 0 {
            self.batch_ends.push(self.pieces.len() as u32);
        }
        self.batch_ends.len()
    }

    /// Batch `k` of the last [`Self::make_batches`]: its runs, in order.
    pub fn batch(&self, k: usize) -> &[RowRun] {
        let start = if k == 0 { 0 } else { self.batch_ends[k - 1] };
        &self.pieces[start as usize..self.batch_ends[k] as usize]
    }
}

/// The dense index of a contact's key grain: the first of its two grains in dense order,
/// or its grain for a grain and a wall (the key the narrow phase's index files it under).
/// Read from the contact's cached bodies while they belong to the snapshot's layout, looked
/// up otherwise; `u32::MAX` if a body is missing from the snapshot.
#[inline]
pub fn key_grain(s: &GrainSnapshot, c: &Contact, cached: &ContactBodies) -> u32 {
    key_and_other_grain(s, c, cached).0
}

/// A contact's key grain ([`key_grain`]) and its other grain: the second of its two
/// grains in dense order, or the key again for a grain and a wall (and for a vacant row,
/// whose grains are one).
#[inline]
pub fn key_and_other_grain(s: &GrainSnapshot, c: &Contact, cached: &ContactBodies) -> (u32, u32) {
    let bodies = if cached.layout == s.layout {
        *cached
    } else {
        match ContactBodies::look_up(s, c) {
            Some(bodies) => bodies,
            None => return (u32::MAX, u32::MAX),
        }
    };
    // A wall's code is above every dense index: the smaller code is the grain.
    let key = bodies.a.min(bodies.b);
    let other = bodies.a.max(bodies.b);
    (key, if other >= WALL_BODY_BASE { key } else { other })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::components::ContactKind;
    use bevy_ecs::entity::Entity;

    #[test]
    fn every_row_is_listed_once_under_its_key_grains_region() {
        // The snapshot's layout (0) is the cached bodies': their indices are read as they are.
        let s = GrainSnapshot::default();
        let mut state = 12345u64;
        let mut draw = |n: u32| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) % u64::from(n)) as u32
        };
        let mut runs = RegionRuns::default();
        // The later tables reuse the first one's lists.
        // The last grains of the first table are untracked (as frozen grains are).
        for (contacts, grains, region_len, untracked) in [
            (500, 100, 16, 90..100),
            (37, 100, 1000, 0..0),
            (300, 50, 1, 0..0),
        ] {
            let regions = GrainRegions::new(grains, region_len);
            // Keys in ascending runs, as a table between sorts has them, some out of place.
            let bodies: Vec<ContactBodies> = (0..contacts)
                .map(|row| {
                    let a = if draw(8) == 0 {
                        draw(grains as u32)
                    } else {
                        (row * grains / contacts) as u32
                    };
                    let b = if draw(5) == 0 {
                        ContactBodies::wall_code(draw(3) as usize)
                    } else {
                        draw(grains as u32)
                    };
                    ContactBodies { a, b, layout: 0 }
                })
                .collect();
            let pairs = vec![
                Contact {
                    a: Entity::PLACEHOLDER,
                    b: Entity::PLACEHOLDER,
                    kind: ContactKind::GrainGrain,
                    pair_slot: 0,
                };
                contacts
            ];
            let last = regions.count() - 1;
            if !untracked.is_empty() {
                // With every grain tracked, the last region is touched from below.
                assert!(untracked.start as usize <= regions.range(last).start);
                runs.build(&regions, &s, &pairs, &bodies, &[]);
                assert!(runs.first_touching(last) < last);
            }
            let untracked = std::slice::from_ref(&untracked);
            runs.build(&regions, &s, &pairs, &bodies, untracked);
            assert_eq!(runs.count(), regions.count());
            if !untracked[0].is_empty() {
                // A region of untracked grains alone is touched by no other's rows.
                assert_eq!(runs.first_touching(last), last, "untracked grains left out");
            }
            let mut seen = vec![false; contacts];
            for r in 0..runs.count() {
                let list = runs.region(r);
                assert!(
                    list.windows(2).all(|w| w[0][1] < w[1][0]),
                    "region {r}: apart, ascending"
                );
                for &[first, end] in list {
                    assert!(first < end);
                    for row in first..end {
                        let d = bodies[row as usize];
                        let key = if d.wall_b().is_some() {
                            d.a
                        } else {
                            d.a.min(d.b)
                        };
                        assert_eq!(regions.region_of(key), r, "row {row}");
                        assert!(!std::mem::replace(&mut seen[row as usize], true));
                    }
                }
            }
            assert!(seen.iter().all(|&s| s), "every row listed");
            // The rows touching each region's grains, from the last row to the first.
            for r in 0..runs.count() {
                let touching = runs.touching_runs_descending(r);
                assert!(runs.first_touching(r) <= r);
                assert!(
                    touching.windows(2).all(|w| w[1][1] <= w[0][0]),
                    "region {r}: apart, descending"
                );
                let listed = |row: usize| {
                    touching
                        .iter()
                        .any(|&[first, end]| (first as usize..end as usize).contains(&row))
                };
                let grains = regions.range(r);
                for (row, d) in bodies.iter().enumerate() {
                    let tracked = |grain: u32| {
                        grains.contains(&(grain as usize)) && !untracked[0].contains(&grain)
                    };
                    let touches = tracked(d.a) || (d.wall_b().is_none() && tracked(d.b));
                    assert!(!touches || listed(row), "region {r}: row {row} left out");
                }
            }
            // Maximal: a run's neighbouring rows in the table belong to other regions.
            let region_of_row = |row: u32| {
                let d = bodies[row as usize];
                regions.region_of(if d.wall_b().is_some() {
                    d.a
                } else {
                    d.a.min(d.b)
                })
            };
            for &[first, end] in runs.all() {
                let r = region_of_row(first);
                assert!(first == 0 || region_of_row(first - 1) != r);
                assert!(end as usize == contacts || region_of_row(end) != r);
            }
            // Batches: every row once, in the runs' order, at most 16 rows a batch.
            let batches = runs.make_batches(16);
            let in_batches: Vec<u32> = (0..batches)
                .flat_map(|k| {
                    let batch = runs.batch(k);
                    let rows: u32 = batch.iter().map(|[f, e]| e - f).sum();
                    assert!((1..=16).contains(&rows), "batch {k}: {rows} rows");
                    batch.iter().flat_map(|&[f, e]| f..e).collect::<Vec<_>>()
                })
                .collect();
            let in_runs: Vec<u32> = runs.all().iter().flat_map(|&[f, e]| f..e).collect();
            assert_eq!(in_batches, in_runs);
        }
    }
}
