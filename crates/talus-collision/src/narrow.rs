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

/// Live contacts of each grain, keyed by the grain entity's index: finding whether a
/// pair already has a contact is a scan of a handful of entries, no hashing. Each contact
/// is entered under its first body only, so a grain holds about half its coordination
/// number; four entries fit inline (20 bytes each), more spill to the heap.
#[derive(Resource, Default)]
pub struct ContactIndex {
    per_grain: Vec<SmallVec<[IndexEntry; 4]>>,
    pass: u32,
    /// Pairs found touching this pass, per chunk of grains (dense indices; walls are
    /// encoded as `u32::MAX - wall index`).
    found: Vec<Vec<(u32, u32)>>,
    /// Contacts that ended this pass (scratch).
    ended: Vec<Entity>,
}

impl ContactIndex {
    /// Number of live contacts.
    pub fn len(&self) -> usize {
        self.per_grain.iter().map(|v| v.len()).sum()
    }

    /// Whether there is no live contact.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The contact entity of a pair, if they are in contact (in either order).
    pub fn contact_between(&self, a: Entity, b: Entity) -> Option<Entity> {
        let find = |first: Entity, second: Entity| {
            self.per_grain
                .get(first.index_u32() as usize)?
                .iter()
                .find(|e| e.partner == second)
                .map(|e| e.contact)
        };
        find(a, b).or_else(|| find(b, a))
    }

    /// Enters an existing contact entity between grain `a` (the contact's first body) and
    /// body `b`: for contacts restored from a saved state.
    pub fn register(&mut self, a: Entity, b: Entity, contact: Entity) {
        let k = a.index_u32() as usize;
        if self.per_grain.len() <= k {
            self.per_grain.resize_with(k + 1, SmallVec::new);
        }
        self.per_grain[k].push(IndexEntry {
            partner: b,
            contact,
            seen: self.pass,
        });
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
    index.pass = index.pass.wrapping_add(1);
    let pass = index.pass;
    let ContactIndex {
        per_grain,
        found,
        ended,
        ..
    } = index;
    let max_entity = s.entity.iter().map(|e| e.index_u32()).max().unwrap_or(0) as usize;
    if per_grain.len() <= max_entity {
        per_grain.resize_with(max_entity + 1, SmallVec::new);
    }
    let chunks = s.len().div_ceil(CHUNK);
    for list in &found[..chunks] {
        for &(i, j) in list {
            let ea = s.entity[i as usize];
            let (a, b, kind, mat_b) = if j > u32::MAX - 1024 {
                let wall = &s.walls[(u32::MAX - j) as usize];
                (ea, wall.entity, ContactKind::GrainWall, wall.material)
            } else {
                // The grain first in dense order is `a` (never the entity ids, which
                // depend on the history of spawns: a restored run must choose alike).
                (
                    ea,
                    s.entity[j as usize],
                    ContactKind::GrainGrain,
                    s.material[j as usize],
                )
            };
            let entries = &mut per_grain[a.index_u32() as usize];
            if let Some(entry) = entries.iter_mut().find(|e| e.partner == b) {
                entry.seen = pass;
                continue;
            }
            let Some(slot) = table.get(s.material[i as usize], mat_b) else {
                continue; // this material pair does not interact
            };
            let contact = (slot.spawn)(
                world,
                Contact {
                    a,
                    b,
                    kind,
                    pair_slot: slot.pair_slot,
                },
            );
            per_grain[a.index_u32() as usize].push(IndexEntry {
                partner: b,
                contact,
                seen: pass,
            });
        }
    }
    ended.clear();
    for entries in per_grain.iter_mut() {
        entries.retain(|e| {
            if e.seen == pass {
                return true;
            }
            // A pair that stopped touching keeps its contact for one more evaluation
            // (with no force), so that the law books the work done in the step in
            // which the contact ended; it goes at the next pass.
            let acted = world
                .get::<ContactGeometry>(e.contact)
                .zip(world.get::<ContactForce>(e.contact))
                .is_some_and(|(g, f)| f.is_active(g));
            if !acted {
                ended.push(e.contact);
            }
            acted
        });
    }
    // Despawning moves the last contact of the table into the freed row, so the order of
    // removals sets the order in which forces are summed from then on. Remove in table
    // order (a fixed function of the state, not of entity ids or of the index's
    // layout), last row first so that no removal moves a contact still to be removed.
    ended
        .sort_unstable_by_key(|&c| std::cmp::Reverse(world.entity(c).location().table_row.index()));
    for &c in ended.iter() {
        world.despawn(c);
    }
}
