//! The narrow phase: exact overlap tests on the grid's neighbour stencil, and the
//! life cycle of contact entities (created when a pair starts touching, kept while it
//! touches, removed when it separates).

use bevy_ecs::prelude::*;
use rayon::prelude::*;
use smallvec::SmallVec;
use talus_contact::{
    Contact, ContactForce, ContactGeometry, ContactKind, systems::ContactLawTable,
};
use talus_core::snapshot::GrainSnapshot;

use crate::grid::CellGrid;
use crate::neighbours::{CHUNK, NeighbourList};

/// Body codes above this in a found pair are walls: `u32::MAX - wall index`.
const WALL_CODES: u32 = u32::MAX - 1024;

/// One live contact as seen from its first body.
#[derive(Clone, Copy, Debug)]
struct IndexEntry {
    partner: Entity,
    contact: Entity,
    /// The pass that last found the pair. An entry is dropped the pass after it was not
    /// found, so only the current and the previous pass are ever compared: a wrapping u32
    /// is exact.
    seen: u32,
}

/// Live contacts of each grain, by the grain's dense index in the snapshot: finding
/// whether a pair already has a contact is a scan of a handful of entries, no hashing,
/// and each chunk of grains owns its slice of the index, so the narrow phase's
/// bookkeeping runs in parallel over the same chunks as the overlap tests. Each contact
/// is entered under its first body only, so a grain holds about half its coordination
/// number; four entries fit inline (20 bytes each), more spill to the heap. When the
/// snapshot's grain order changes (grains added or removed, a component set changed) the
/// index is re-keyed by entity before the next pass.
#[derive(Resource, Default)]
pub struct ContactIndex {
    /// Live contacts of each grain, by dense index in the order of `entities`.
    per_grain: Vec<SmallVec<[IndexEntry; 4]>>,
    /// The grain entities in the dense order `per_grain` is keyed by.
    entities: Vec<Entity>,
    /// Contacts restored from a saved state before the snapshot knew their grains'
    /// dense indices: (first body, second body, contact), entered at the next pass.
    pending: Vec<(Entity, Entity, Entity)>,
    pass: u32,
    /// Pairs found touching this pass, per chunk of grains (dense indices; walls are
    /// encoded as `u32::MAX - wall index`).
    found: Vec<Vec<(u32, u32)>>,
    /// Per chunk of grains: the touching pairs that have no contact yet (scratch).
    new_pairs: Vec<Vec<(u32, u32)>>,
    /// Per chunk of grains: the contacts that ended this pass (scratch).
    ended: Vec<Vec<Entity>>,
}

impl ContactIndex {
    /// Number of live contacts.
    pub fn len(&self) -> usize {
        self.per_grain.iter().map(|v| v.len()).sum::<usize>() + self.pending.len()
    }

    /// Whether there is no live contact.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The contact entity of a pair, if they are in contact (in either order). A scan of
    /// the grain list: for inspection, not for hot loops.
    pub fn contact_between(&self, a: Entity, b: Entity) -> Option<Entity> {
        let find = |first: Entity, second: Entity| {
            let pending = self
                .pending
                .iter()
                .find(|&&(x, y, _)| x == first && y == second)
                .map(|&(_, _, c)| c);
            let k = self.entities.iter().position(|&e| e == first)?;
            self.per_grain[k]
                .iter()
                .find(|e| e.partner == second)
                .map(|e| e.contact)
                .or(pending)
        };
        find(a, b).or_else(|| find(b, a))
    }

    /// Enters an existing contact entity between grain `a` (the contact's first body) and
    /// body `b`: for contacts restored from a saved state. It is keyed by its grain's
    /// dense index at the next narrow phase.
    pub fn register(&mut self, a: Entity, b: Entity, contact: Entity) {
        self.pending.push((a, b, contact));
    }

    /// Keys the index by the snapshot's dense order (re-keying it by entity if the order
    /// changed) and enters the pending contacts. Adds to `orphans` the contacts whose first
    /// grain is no longer in the snapshot.
    fn key_by(&mut self, s: &GrainSnapshot, orphans: &mut Vec<Entity>) {
        if self.entities != s.entity {
            let mut old = std::mem::take(&mut self.per_grain);
            self.per_grain.resize_with(s.len(), SmallVec::new);
            for (k, &e) in self.entities.iter().enumerate() {
                match s.dense(e) {
                    Some(d) => self.per_grain[d] = std::mem::take(&mut old[k]),
                    None => orphans.extend(old[k].iter().map(|entry| entry.contact)),
                }
            }
            self.entities.clone_from(&s.entity);
        }
        // A restored contact counts as found at the previous pass, like a live one.
        let seen = self.pass;
        for (a, b, contact) in self.pending.drain(..) {
            match s.dense(a) {
                Some(d) => self.per_grain[d].push(IndexEntry {
                    partner: b,
                    contact,
                    seen,
                }),
                None => orphans.push(contact),
            }
        }
    }
}

/// Finds all touching grain–grain and grain–wall pairs among the neighbour list's
/// candidates, in parallel over fixed chunks.
pub fn find_touching_pairs(
    snapshot: Res<GrainSnapshot>,
    grid: Res<CellGrid>,
    list: Res<NeighbourList>,
    mut index: ResMut<ContactIndex>,
) {
    let s = &*snapshot;
    let n = s.len();
    let chunks = n.div_ceil(CHUNK);
    let range = grid.interaction_range;
    if index.found.len() < chunks {
        index.found.resize_with(chunks, Vec::new);
    }
    index.found[..chunks]
        .par_iter_mut()
        .zip(list.chunks[..chunks].par_iter())
        .enumerate()
        .for_each(|(chunk, (out, candidates))| {
            out.clear();
            let mut cursor = 0;
            for i in chunk * CHUNK..((chunk + 1) * CHUNK).min(n) {
                let p = s.position[i];
                let r = s.radius[i];
                // A frozen grain has an infinite mass in the snapshot. A contact between
                // two frozen grains, or a frozen grain and a wall, moves nothing, and its
                // reduced mass (hence a mass-scaled dashpot) would be infinite: none is made.
                let frozen = s.mass[i].is_infinite();
                while cursor < candidates.len() && candidates[cursor].0 as usize == i {
                    let j = candidates[cursor].1;
                    cursor += 1;
                    if frozen && s.mass[j as usize].is_infinite() {
                        continue;
                    }
                    let reach = r + s.radius[j as usize] + range;
                    if s.separation(p, s.position[j as usize]).length_squared() < reach * reach {
                        out.push((i as u32, j));
                    }
                }
                if frozen {
                    continue;
                }
                for (w, wall) in s.walls.iter().enumerate() {
                    if (p - wall.point).dot(wall.normal) < r + range {
                        out.push((i as u32, u32::MAX - w as u32));
                    }
                }
            }
        });
}

/// Creates contact entities for new pairs (with the law of their material pair) and
/// removes those whose pair no longer touches.
pub fn update_contacts(world: &mut World) {
    world.resource_scope(|world, mut index: Mut<ContactIndex>| {
        world.resource_scope(|world, table: Mut<ContactLawTable>| {
            world.resource_scope(|world, snapshot: Mut<GrainSnapshot>| {
                update_contacts_inner(world, &mut index, &table, &snapshot);
            });
        });
    });
}

fn update_contacts_inner(
    world: &mut World,
    index: &mut ContactIndex,
    table: &ContactLawTable,
    s: &GrainSnapshot,
) {
    let mut orphans = Vec::new();
    index.key_by(s, &mut orphans);
    index.pass = index.pass.wrapping_add(1);
    let pass = index.pass;
    let chunks = s.len().div_ceil(CHUNK);
    let ContactIndex {
        per_grain,
        found,
        new_pairs,
        ended,
        ..
    } = index;
    if new_pairs.len() < chunks {
        new_pairs.resize_with(chunks, Vec::new);
    }
    if ended.len() < chunks {
        ended.resize_with(chunks, Vec::new);
    }
    if found.len() < chunks {
        found.resize_with(chunks, Vec::new);
    }
    // Each chunk of grains owns its slice of the index: marking the pairs found again,
    // listing the new ones and dropping the ended ones run in parallel; only spawning and
    // despawning entities, which change the world's tables, are serial.
    let view: &World = world;
    per_grain
        .par_chunks_mut(CHUNK)
        .zip(found[..chunks].par_iter())
        .zip(new_pairs[..chunks].par_iter_mut())
        .zip(ended[..chunks].par_iter_mut())
        .enumerate()
        .for_each(|(chunk, (((entries, pairs), new), gone))| {
            let base = chunk * CHUNK;
            new.clear();
            gone.clear();
            for &(i, j) in pairs {
                let (b, mat_b) = body(s, j);
                if let Some(entry) = entries[i as usize - base]
                    .iter_mut()
                    .find(|e| e.partner == b)
                {
                    entry.seen = pass;
                } else if table.get(s.material[i as usize], mat_b).is_some() {
                    new.push((i, j));
                }
            }
            for list in entries.iter_mut() {
                list.retain(|e| {
                    if e.seen == pass {
                        return true;
                    }
                    // A pair that stopped touching keeps its contact for one more
                    // evaluation (with no force), so that the law books the work done in
                    // the step in which the contact ended; it goes at the next pass.
                    let acted = view
                        .get::<ContactGeometry>(e.contact)
                        .zip(view.get::<ContactForce>(e.contact))
                        .is_some_and(|(g, f)| f.is_active(g));
                    if !acted {
                        gone.push(e.contact);
                    }
                    acted
                });
            }
        });
    // New contacts are spawned in the order the pairs were found (chunk by chunk, grain
    // by grain, partner by partner): a fixed function of the state.
    for &(i, j) in new_pairs[..chunks].iter().flatten() {
        let (b, mat_b) = body(s, j);
        let kind = if j > WALL_CODES {
            ContactKind::GrainWall
        } else {
            ContactKind::GrainGrain
        };
        let slot = table
            .get(s.material[i as usize], mat_b)
            .expect("the parallel pass kept only interacting pairs");
        // The grain first in dense order is `a` (never the entity ids, which depend on
        // the history of spawns: a restored run must choose alike).
        let a = s.entity[i as usize];
        let contact = (slot.spawn)(
            world,
            Contact {
                a,
                b,
                kind,
                pair_slot: slot.pair_slot,
            },
        );
        per_grain[i as usize].push(IndexEntry {
            partner: b,
            contact,
            seen: pass,
        });
    }
    // Despawning moves the last contact of the table into the freed row, so the order of
    // removals sets the order in which forces are summed from then on. Remove in table
    // order (a fixed function of the state, not of entity ids or of the index's
    // layout), last row first so that no removal moves a contact still to be removed.
    orphans.retain(|&c| world.get_entity(c).is_ok());
    orphans.extend(ended[..chunks].iter().flatten().copied());
    orphans
        .sort_unstable_by_key(|&c| std::cmp::Reverse(world.entity(c).location().table_row.index()));
    for &c in orphans.iter() {
        world.despawn(c);
    }
}

/// The entity and material of a found pair's second body (grain index or wall code).
#[inline]
fn body(s: &GrainSnapshot, j: u32) -> (Entity, u16) {
    if j > WALL_CODES {
        let wall = &s.walls[(u32::MAX - j) as usize];
        (wall.entity, wall.material)
    } else {
        (s.entity[j as usize], s.material[j as usize])
    }
}
