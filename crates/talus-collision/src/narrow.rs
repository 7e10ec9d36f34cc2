//! The narrow phase: exact overlap tests on the neighbour list's candidate pairs, and
//! the life cycle of contact entities (created when a pair starts touching, or handed
//! over from a contact of the same law that ended in the same pass; kept while it
//! touches or carried a force at its last evaluation; removed when neither holds).
//!
//! The candidate pairs of a chunk of grains come in increasing order of their gap at the
//! neighbour list's build, so those that may be within reach are a prefix of the list,
//! tested four at a time in lanes with no regard for which grain they belong to. A pair
//! that has a live contact is not tested: a bit per candidate pair, set while it has one,
//! masks it out (four such pairs in a row are not even read), so a touching pair without
//! a bit is new (only a grain and a wall, outside the list, are looked up in the grain's
//! contacts). Which contacts may end is not found by testing every live contact again:
//! the force loops list those that carried no force ([`IdleContacts`]), and only those
//! are tested.

use bevy_ecs::archetype::ArchetypeId;
use bevy_ecs::prelude::*;
use rayon::prelude::*;
use smallvec::SmallVec;
use talus_contact::regions::key_grain;
use talus_contact::{
    Contact, ContactBodies, ContactForce, ContactGeometry, ContactKind, ContactTableSorts,
    IdleContacts,
    systems::{ContactLawTable, LawSlot, RecycleContacts},
};
use talus_core::lanes::F4;
use talus_core::regions::{GrainRegions, REGION_GRAINS};
use talus_core::resources::Clock;
use talus_core::snapshot::{GrainSnapshot, prefetch_item};

use crate::grid::CellGrid;
use crate::neighbours::{CHUNK, CandidateChunk, NeighbourList};

/// The live contacts entered under one grain. Two fit inline (16 bytes each, 40 bytes
/// with the length). The narrow phase's pair tests do not read these lists (the live bits
/// of [`ContactIndex`] stand for them), so a grain with more, whose list is on the heap,
/// costs a cache miss only where a contact starts, ends or moves in its table; a third
/// inline entry would cost 8 bytes a grain.
type GrainContacts = SmallVec<[IndexEntry; 2]>;

/// The slot of a contact whose pair is not among the neighbour list's candidates (a grain
/// and a wall).
const NO_SLOT: u32 = u32::MAX;

/// One live contact as seen from its first body.
#[derive(Clone, Copy, Debug)]
struct IndexEntry {
    /// The second body: its dense index, or its wall code ([`ContactBodies::wall_code`]).
    partner: u32,
    /// The contact entity's bits ([`Entity::to_bits`]) in two halves: an `Entity` is
    /// aligned to 8 bytes, which would leave four bytes of padding.
    contact: [u32; 2],
    /// The pair's place in its chunk of the neighbour list ([`CandidateChunk`]), whose
    /// live bit ([`ContactIndex::live`]) the entry holds set; [`NO_SLOT`] if none.
    slot: u32,
}

impl IndexEntry {
    #[inline]
    fn new(partner: u32, contact: Entity, slot: u32) -> Self {
        let mut entry = Self {
            partner,
            contact: [0; 2],
            slot,
        };
        entry.set_contact(contact);
        entry
    }

    /// Points the entry at another contact entity of the same pair.
    #[inline]
    fn set_contact(&mut self, contact: Entity) {
        let bits = contact.to_bits();
        self.contact = [bits as u32, (bits >> 32) as u32];
    }

    /// The contact entity.
    #[inline]
    fn contact(&self) -> Entity {
        Entity::from_bits(u64::from(self.contact[0]) | (u64::from(self.contact[1]) << 32))
    }
}

/// Live contacts of each grain, by the grain's dense index in the snapshot: finding
/// whether a pair already has a contact is a scan of a handful of entries, no hashing and
/// no entity look-up, and each chunk of grains owns its slice of the index, so the narrow
/// phase runs in parallel over the same chunks as the neighbour list. Each contact is
/// entered under the body first in dense order only (the neighbour list's candidates of
/// a grain are the partners after it), so a grain holds about half its coordination
/// number; two entries fit inline, more spill to the heap. When the
/// snapshot's order of grains or walls changes (grains added or removed, a component set
/// changed) the index is re-keyed, from each contact's bodies, before the next pass.
#[derive(Resource, Default)]
pub struct ContactIndex {
    /// Live contacts of each grain, by its dense index in the snapshot of `layout`.
    per_grain: Vec<GrainContacts>,
    /// The snapshot layout ([`GrainSnapshot::layout`]) the index is keyed by (0: none).
    /// No copy of that layout's entity order is kept (8 bytes a grain): re-keying reads
    /// each contact's bodies from its [`Contact`] component.
    layout: u32,
    /// Contacts restored from a saved state before the snapshot knew their bodies' dense
    /// indices: (first body, second body, contact), entered at the next pass.
    pending: Vec<(Entity, Entity, Entity)>,
    /// Per chunk of grains, one bit per candidate pair of the neighbour list's chunk, set
    /// while the pair has a live contact (whose entry holds the pair's slot). The narrow
    /// phase neither tests nor looks up those pairs: the force loop evaluates their
    /// contacts, and which of them end is decided from the contacts that carried no force
    /// ([`IdleContacts`]). In the 32,000-grain chute about one pair in five of the tested
    /// prefixes has a contact (16,000 of 76,000 a step).
    live: Vec<Vec<u64>>,
    /// The neighbour-list build ([`NeighbourList::builds`]) whose pairs the slots and
    /// live bits refer to; `None` when they must be derived again (the index re-keyed,
    /// contacts entered from a saved state).
    live_build: Option<u64>,
    /// Per chunk of grains: the touching pairs that have no contact yet (scratch).
    new_pairs: Vec<Vec<NewPair>>,
    /// Per chunk of grains: the same, listed bare, as (key, partner, slot) (scratch;
    /// [`narrow_chunk`] says when).
    bare_pairs: Vec<Vec<(u32, u32, u32)>>,
    /// Spawn every new contact and despawn every ended one, instead of handing ended
    /// contacts to new pairs of their law (off by default; the results differ only by
    /// the order in which contact forces are summed, for comparisons).
    pub never_recycle: bool,
    /// Hand ended contacts to new pairs in table order alone, whatever their regions of
    /// grains (off by default; as before the handout by region; the results differ only by
    /// the order in which contact forces are summed, for comparisons).
    pub handout_in_table_order: bool,
    /// Despawn the ended contacts that no new pair takes, instead of keeping their rows
    /// vacant for their regions' next new contacts (off by default; the results differ only
    /// by the order in which contact forces are summed, for comparisons).
    pub despawn_unused: bool,
    /// Hand ended contacts to new pairs in one job over every region, instead of a job
    /// per region (off by default; the results are the same bit for bit, for the test that
    /// says so).
    pub handout_in_one_job: bool,
    /// The vacant rows of the contact tables ([`Contact::is_vacant`]), by archetype, region
    /// of their grain and row: where a new contact goes first. Rows stay put between sorts
    /// (nothing else despawns a contact), so the list is kept as the narrow phase changes
    /// it, and found again from the tables after anything that moves rows.
    vacant: Vec<VacantRow>,
    /// Whether `vacant` lists the tables' vacant rows as they are; when not, the next pass
    /// finds them again.
    vacant_known: bool,
    /// Grains (dense indices in `layout`) whose contact list, on the heap, lost a contact
    /// and then held no more than fit inline: brought back inline at the next sort
    /// ([`bring_short_lists_inline`]). A grain may be listed twice, or hold more again by
    /// then.
    shrunk: Vec<u32>,
    /// A pass's ended contacts and vacant rows in handout order, and the list they are
    /// merged into: kept from pass to pass, like the lists below, for their allocations.
    /// A 512,000-grain chute ends some 4,000 contacts a step and holds some 8,000 vacant
    /// rows; lists of that size made afresh at each step came from new pages of memory,
    /// some 300 page faults a step (about 2 µs each on a virtual machine).
    ended_scratch: (Vec<EndedRow>, Vec<EndedRow>),
    /// The lists of rows a pass hands each law's recycling ([`Reusable::reuses`]), kept
    /// from pass to pass for their allocations.
    reuse_lists: Vec<Vec<Reuse>>,
}

/// A vacant row of a contact table: its archetype, the region of its grain, its row and
/// its entity.
type VacantRow = (ArchetypeId, u32, usize, Entity);

/// A touching pair with no contact yet, as the parallel pass ([`narrow_chunk`]) found it,
/// with the contact it is to get: the serial handout then reads no grain's entity or
/// material, which lie all over the packing (a quarter of its time on the 32,000-grain
/// chute, with the reads asked for ahead).
#[derive(Clone, Copy, Debug)]
struct NewPair {
    /// The grain first in dense order (the pair's key in the index).
    key: u32,
    /// The other body: a grain's dense index or a wall code.
    partner: u32,
    /// The pair's place among its chunk's candidates ([`NO_SLOT`] if none).
    slot: u32,
    /// The pair's entry in [`ContactLawTable::slots`].
    law: u32,
    /// The pair the contact joins.
    contact: Contact,
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

    /// How many grains' contact lists are on the heap, and how many of those hold more
    /// contacts than fit inline: after a contact-table sort the two are equal (a list
    /// that shrank back returns inline there). For memory checks.
    pub fn lists_on_heap(&self) -> (usize, usize) {
        let on_heap = self.per_grain.iter().filter(|l| l.spilled());
        let longer = on_heap.clone().filter(|l| l.len() > l.inline_size());
        (on_heap.count(), longer.count())
    }

    /// The contact entity of a pair, if they are in contact (in either order), with the
    /// bodies' dense indices taken from `s`, the snapshot the index was last keyed by
    /// (`None` if it was keyed by another layout). For inspection, not for hot loops.
    pub fn contact_between(&self, s: &GrainSnapshot, a: Entity, b: Entity) -> Option<Entity> {
        if let Some(&(_, _, c)) = self
            .pending
            .iter()
            .find(|&&(x, y, _)| (x, y) == (a, b) || (x, y) == (b, a))
        {
            return Some(c);
        }
        if s.layout != self.layout {
            return None;
        }
        let code = |body: Entity| {
            s.dense(body)
                .map(|d| d as u32)
                .or_else(|| s.wall_index(body).map(ContactBodies::wall_code))
        };
        // A pair of a grain and a wall is held under the grain, whichever way it is asked.
        let (a, b) = if s.dense(a).is_none() { (b, a) } else { (a, b) };
        let (key, partner) = first_in_order(s.dense(a)? as u32, code(b)?);
        self.per_grain[key as usize]
            .iter()
            .find(|e| e.partner == partner)
            .map(|e| e.contact())
    }

    /// Enters an existing contact entity between grain `a` (the contact's first body) and
    /// body `b`: for contacts restored from a saved state. It is keyed by its bodies'
    /// dense indices at the next narrow phase.
    pub fn register(&mut self, a: Entity, b: Entity, contact: Entity) {
        self.pending.push((a, b, contact));
        self.vacant_known = false;
    }

    /// Keys the index by the snapshot's order of grains and walls (re-keying it from each
    /// contact's bodies if the order changed) and enters the pending contacts. Adds to `orphans` the
    /// contacts one of whose bodies is no longer in the snapshot.
    fn key_by(&mut self, world: &World, s: &GrainSnapshot, orphans: &mut Vec<Entity>) {
        if self.layout != s.layout {
            // Each contact's own bodies give its place in the new order.
            let new_codes = |contact: Entity| -> Option<(u32, u32)> {
                let b = ContactBodies::look_up(s, world.get::<Contact>(contact)?)?;
                Some(first_in_order(b.a, b.b))
            };
            let mut rekeyed: Vec<GrainContacts> = Vec::new();
            rekeyed.resize_with(s.len(), SmallVec::new);
            for entry in self.per_grain.iter().flatten() {
                match new_codes(entry.contact()) {
                    Some((key, partner)) => {
                        rekeyed[key as usize].push(IndexEntry::new(
                            partner,
                            entry.contact(),
                            NO_SLOT,
                        ));
                    }
                    None => orphans.push(entry.contact()),
                }
            }
            self.per_grain = rekeyed;
            // Fresh lists hold what they need; the listed grains were of the old order.
            self.shrunk.clear();
            self.layout = s.layout;
            self.live_build = None;
            // The vacant rows' regions follow their grains' new places.
            self.vacant_known = false;
        }
        if !self.pending.is_empty() {
            self.live_build = None;
        }
        for (a, b, contact) in std::mem::take(&mut self.pending) {
            let partner = s
                .dense(b)
                .map(|d| d as u32)
                .or_else(|| s.wall_index(b).map(ContactBodies::wall_code));
            match (s.dense(a), partner) {
                (Some(d), Some(partner)) => {
                    let (key, partner) = first_in_order(d as u32, partner);
                    self.per_grain[key as usize].push(IndexEntry::new(partner, contact, NO_SLOT));
                }
                _ => orphans.push(contact),
            }
        }
    }
}

/// The key and partner code under which the index holds a pair of a grain (dense index
/// `grain`) and a body (partner code `other`): a pair of grains under the one first in
/// dense order (the neighbour list's candidates are (i, j) with i < j, whichever body is
/// the contact's `a`), a grain and a wall under the grain.
#[inline]
fn first_in_order(grain: u32, other: u32) -> (u32, u32) {
    if ContactBodies::wall_of(other).is_none() && other < grain {
        (other, grain)
    } else {
        (grain, other)
    }
}

/// The narrow phase: tests the neighbour list's candidate pairs (and each grain against
/// each wall) for touch, creates contact entities for new touching pairs (with the law
/// of their material pair) and removes those whose pair no longer touches.
pub fn update_contacts(world: &mut World) {
    // The resources the pass reads beside the world are moved out for its duration, each
    // leaving its empty default, and moved back: `World::resource_scope` takes a resource's
    // component off its entity and puts it back, moving the entity between archetypes
    // twice, and four such scopes cost 7–8 µs a step, serial (32,000-grain chute).
    let mut index = std::mem::take(&mut *world.resource_mut::<ContactIndex>());
    let table = std::mem::take(&mut *world.resource_mut::<ContactLawTable>());
    let snapshot = std::mem::take(&mut *world.resource_mut::<GrainSnapshot>());
    let list = std::mem::take(&mut *world.resource_mut::<NeighbourList>());
    let range = world.resource::<CellGrid>().interaction_range;
    update_contacts_inner(world, &mut index, &table, &snapshot, &list, range);
    *world.resource_mut::<ContactIndex>() = index;
    *world.resource_mut::<ContactLawTable>() = table;
    *world.resource_mut::<GrainSnapshot>() = snapshot;
    *world.resource_mut::<NeighbourList>() = list;
}

fn update_contacts_inner(
    world: &mut World,
    index: &mut ContactIndex,
    table: &ContactLawTable,
    s: &GrainSnapshot,
    list: &NeighbourList,
    range: f64,
) {
    let mut orphans = Vec::new();
    // Contacts restored from a saved state, or an index re-keyed to a new order of
    // grains, were not all seen by the last force pass: check every contact this time.
    let idle = std::mem::take(&mut *world.resource_mut::<IdleContacts>());
    let check_all = !index.pending.is_empty()
        || index.layout != s.layout
        || !idle.evaluated
        || idle.layout != s.layout;
    index.key_by(world, s, &mut orphans);
    let n = s.len();
    let chunks = n.div_ceil(CHUNK);
    let recycle = !index.never_recycle;
    let ContactIndex {
        per_grain,
        new_pairs,
        bare_pairs,
        live,
        live_build,
        shrunk,
        ..
    } = index;
    if new_pairs.len() < chunks {
        new_pairs.resize_with(chunks, Vec::new);
    }
    if bare_pairs.len() < chunks {
        bare_pairs.resize_with(chunks, Vec::new);
    }
    if *live_build != Some(list.builds) || live.len() < chunks {
        // A new list (or a re-keyed index): each contact's pair is found among its
        // chunk's candidates once, here, and its bit set.
        live.resize_with(chunks, Vec::new);
        per_grain
            .par_chunks_mut(CHUNK)
            .zip(list.chunks[..chunks].par_iter())
            .zip(live[..chunks].par_iter_mut())
            // Small jobs, so that no thread is left with a run of chunks alone at the end
            // (as the list's build, `update_neighbour_list`).
            .with_max_len(2)
            .for_each(|((entries, candidates), bits)| mark_live(entries, candidates, bits));
        *live_build = Some(list.builds);
    }
    // Each chunk of grains owns its slice of the index: the overlap tests and the listing
    // of new pairs run in parallel; only spawning and despawning entities, which change
    // the world's tables, are serial.
    let per_grain_view: &[GrainContacts] = per_grain;
    per_grain_view
        .par_chunks(CHUNK)
        .zip(list.chunks[..chunks].par_iter())
        .zip(new_pairs[..chunks].par_iter_mut())
        .zip(bare_pairs[..chunks].par_iter_mut())
        .zip(live[..chunks].par_iter())
        .enumerate()
        // Chunks differ in cost (dense and dilute regions, the frozen base): small jobs,
        // which idle threads steal, even the threads' shares out.
        .with_max_len(2)
        .for_each(|(chunk, ((((entries, candidates), new), bare), live))| {
            let pass_state = PassState {
                s,
                table,
                range,
                gap_threshold: list.gap_threshold(chunk, s),
            };
            // While this chunk is tested, the next chunk's contact lists and grains are
            // asked for, a few lines per batch of pairs: a chunk's pairs read them in no
            // order the hardware can follow, and a large packing's do not fit in cache.
            let mut ahead = talus_core::snapshot::LinePrefetcher::new();
            let next = (chunk + 1) * CHUNK..((chunk + 2) * CHUNK).min(n);
            if !next.is_empty() {
                // The gaps first: the search for the chunk's tested prefix reads them
                // in a chain of dependent loads.
                ahead.add(&list.chunks[chunk + 1].gap);
                ahead.add(&s.records[next]);
            }
            narrow_chunk(
                &pass_state,
                chunk * CHUNK,
                entries,
                candidates,
                live,
                (new, bare),
                &mut ahead,
            );
        });
    // In table order alone, every grain is in one region.
    let region_len = if index.handout_in_table_order {
        usize::MAX
    } else {
        REGION_GRAINS
    };
    let regions = GrainRegions::new(n, region_len);
    let ended_region = |key: u32| {
        if key == NO_KEY {
            u32::MAX
        } else {
            regions.region_of(key) as u32
        }
    };
    // A contact ends when its bodies neither touch now nor carried a force at its last
    // evaluation (one that did is kept for one more evaluation, so that its law books the
    // work of the step in which it ended). Those that did not are few, and the force
    // loops listed them.
    // Each with its key grain, whose region the contact's row stands in; those the
    // threads ended with their rows found.
    let mut ended: Vec<(Entity, u32)> = Vec::new();
    let mut ended_rows: Vec<(Vec<EndedRow>, Vec<u32>)> = Vec::new();
    let view: &World = world;
    if check_all {
        for (key, entries) in per_grain.iter_mut().enumerate() {
            let spilled = entries.spilled();
            entries.retain(|e| {
                let keep = touching(s, range, key, e.partner) || {
                    view.get::<ContactGeometry>(e.contact())
                        .zip(view.get::<ContactForce>(e.contact()))
                        .is_some_and(|(g, f)| f.is_active(g))
                };
                if !keep {
                    ended.push((e.contact(), key as u32));
                    set_live(live, key, e.slot, false);
                }
                keep
            });
            if spilled && entries.len() <= entries.inline_size() {
                shrunk.push(key as u32);
            }
        }
    } else {
        // Each thread ends the contacts keyed in its share of whole chunks of grains, whose
        // contact lists and live bits it alone holds, and finds their rows: a serial
        // stretch of the step otherwise, latency-bound (the pairs' grains, lists and
        // entities are all over the packing), in which the other threads wait. Which
        // thread ends a contact changes nothing: the rows are sorted below.
        let parts = rayon::current_num_threads().clamp(1, chunks.max(1));
        let part_chunks = chunks.div_ceil(parts).max(1);
        let pairs = &idle.pairs[..];
        per_grain[..n]
            .par_chunks_mut(part_chunks * CHUNK)
            .zip(live[..chunks].par_chunks_mut(part_chunks))
            .enumerate()
            .map(|(part, (lists, live))| {
                let first = part * part_chunks * CHUNK;
                end_idle_contacts(s, range, pairs, first, lists, live, view, &ended_region)
            })
            .collect_into_vec(&mut ended_rows);
    }
    for (_, keys) in &ended_rows {
        shrunk.extend_from_slice(keys);
    }
    // The list is read; its allocation goes back for the next force pass to fill.
    let mut pairs = idle.pairs;
    pairs.clear();
    world.resource_mut::<IdleContacts>().pairs = pairs;
    // A new pair takes over a contact of its law that ended in this pass, when there is
    // one: its components are overwritten in place (`LawSlot::recycle`), which costs a
    // fraction of a despawn and a spawn (each moves a row of five columns and their change
    // ticks, and updates the entity and archetype lists) and keeps the table's length.
    // Both are serial, as they change the world's tables. A new pair takes an ended
    // contact of its own region of grains (`talus_core::regions`) first, so that a table
    // sorted by key stays so by region until its next sort (handed out in table order
    // alone, a quarter of the 512,000-grain chute's contacts sat outside their region ten
    // steps after a sort); the pairs left take the contacts left. Ended contacts are handed
    // out by region, then in table order, new pairs taken in the order they were found
    // (chunk by chunk, grain by grain, partner by partner, walls last): a fixed function of
    // the state, not of entity ids, so a resumed run makes the same choices.
    orphans.retain(|&c| world.get_entity(c).is_ok());
    // The rows of ended contacts that no new pair takes stay in their tables, vacant, for
    // the next new contacts of their regions: a despawn would move the table's last
    // contact into the freed row, out of its region's rows.
    let keep_vacant = recycle && !index.despawn_unused;
    if keep_vacant && !index.vacant_known {
        index.vacant = find_vacant_rows(world, s, &regions);
        index.vacant_known = true;
    }
    let ended = orphans
        .iter()
        .map(|&c| (c, NO_KEY))
        .chain(ended)
        .map(|(c, key)| (c, ended_region(key), key));
    let (mut ended_at, mut merged) = std::mem::take(&mut index.ended_scratch);
    ended_at.clear();
    ended_at.extend(
        ended
            .map(|(c, region, key)| ended_row(world, c, region, key))
            .chain(ended_rows.into_iter().flat_map(|(rows, _)| rows)),
    );
    ended_at.sort_unstable_by_key(handout_order);
    // The vacant rows join them, in the same order.
    if keep_vacant {
        join_vacant_rows(&mut ended_at, &mut merged, &index.vacant);
        index.vacant.clear();
    }
    let mut reuse_lists = std::mem::take(&mut index.reuse_lists);
    let mut reusable: SmallVec<[Reusable; 2]> = SmallVec::new();
    if recycle {
        for (k, &(archetype, region, _, _, _)) in ended_at.iter().enumerate() {
            let group = match reusable.last_mut() {
                Some(group) if group.archetype == archetype => group,
                _ => {
                    reusable.push(Reusable {
                        archetype,
                        by_region: Vec::new(),
                        spare: 0,
                        reuses: reuse_lists.pop().unwrap_or_default(),
                        recycle: table.by_archetype(archetype).map(|slot| slot.recycle),
                    });
                    reusable.last_mut().expect("just pushed")
                }
            };
            match group.by_region.last_mut() {
                Some(run) if run.region == region => run.end = k + 1,
                _ => group.by_region.push(RegionEnded {
                    region,
                    next: k,
                    end: k + 1,
                }),
            }
        }
    }
    let ContactIndex {
        per_grain,
        new_pairs,
        bare_pairs,
        live,
        ..
    } = index;
    let mut reused = vec![false; ended_at.len()];
    let mut to_spawn: Vec<(NewPair, &LawSlot)> = Vec::new();
    let mut unplaced: Vec<(NewPair, &LawSlot)> = Vec::new();
    // A new contact knows its bodies' places in this step's snapshot, which the force loop
    // reads next: its first evaluation goes through the law's lane form like any other.
    let bodies_of = |i: u32, j: u32| ContactBodies {
        a: i,
        b: j,
        layout: s.layout,
    };
    // Each region's pairs take the ended contacts of their own region, the regions in
    // parallel: a region's pairs, contact lists, live bits and ended contacts are its own
    // (a job holds whole regions when they are whole chunks of grains, else all of them).
    // What each took is then entered region after region, which is the pairs' order, so the
    // handout is the one a single loop over the pairs makes. Each pair waits on its key's
    // contact list and its chunk's live bits: a serial loop over a step's few hundred new
    // pairs was some 2 % of the 32,000-grain chute's step on 2 threads.
    let job_chunks = if !index.handout_in_one_job && regions.region_len().is_multiple_of(CHUNK) {
        regions.region_len() / CHUNK
    } else {
        chunks
    };
    let (reusable_view, ended_view) = (&reusable, &ended_at);
    let mut parts: Vec<RegionHandout> = Vec::new();
    per_grain[..n]
        .par_chunks_mut(job_chunks * CHUNK)
        .zip(live[..chunks].par_chunks_mut(job_chunks))
        .zip(new_pairs[..chunks].par_chunks(job_chunks))
        .zip(bare_pairs[..chunks].par_chunks(job_chunks))
        .enumerate()
        .map(|(job, (((lists, live), made), bare))| {
            let first = job * job_chunks * CHUNK;
            hand_out_region(
                s,
                table,
                &regions,
                reusable_view,
                ended_view,
                first,
                lists,
                live,
                made,
                bare,
            )
        })
        .collect_into_vec(&mut parts);
    // Gives ended contact `k` of `group` to a new pair; returns the contact.
    let mut take = |group: &mut Reusable, k: usize, new: &NewPair| {
        let (_, _, row, contact, _) = ended_at[k];
        reused[k] = true;
        group
            .reuses
            .push((contact, row, new.contact, bodies_of(new.key, new.partner)));
        contact
    };
    for part in parts {
        for (group, at, k, new) in part.handed {
            let group = &mut reusable[group];
            group.by_region[at].next = k + 1;
            take(group, k, &new);
        }
        to_spawn.extend(part.no_law_group);
        unplaced.extend(part.unplaced);
    }
    // The pairs whose region had no ended contact left take those of other regions, in
    // order, and are spawned when none is left.
    for (new, law) in unplaced {
        let group = reusable.iter_mut().find(|g| g.archetype == law.archetype);
        let Some(group) = group else {
            to_spawn.push((new, law));
            continue;
        };
        while group
            .by_region
            .get(group.spare)
            .is_some_and(|run| run.next == run.end)
        {
            group.spare += 1;
        }
        match group.by_region.get_mut(group.spare) {
            Some(run) => {
                let k = run.next;
                run.next += 1;
                let contact = take(group, k, &new);
                enter_pair(per_grain, live, new.key as usize, &new, contact);
            }
            None => to_spawn.push((new, law)),
        }
    }
    for (made, bare) in new_pairs[..chunks]
        .iter_mut()
        .zip(&mut bare_pairs[..chunks])
    {
        made.clear();
        bare.clear();
    }
    // The ended contacts no pair took become vacant rows of their regions (in the same call
    // that writes the handed-out ones); those whose grain is not known (a body is gone)
    // are despawned, as are all of them when rows are not kept.
    let mut removals: Vec<(usize, Entity)> = Vec::new();
    for (k, &(archetype, region, row, c, key)) in ended_at.iter().enumerate() {
        if reused[k] {
            continue;
        }
        if key == VACANT_KEY {
            index.vacant.push((archetype, region, row, c));
            continue;
        }
        let group = reusable
            .iter_mut()
            .find(|g| g.archetype == archetype && g.recycle.is_some());
        match group {
            Some(group) if keep_vacant && key != NO_KEY => {
                let last = vacant_key(&regions, region as usize);
                let bodies = ContactBodies {
                    a: last,
                    b: last,
                    layout: s.layout,
                };
                let grain = s.entity[last as usize];
                group.reuses.push((c, row, Contact::vacant(grain), bodies));
                index.vacant.push((archetype, region, row, c));
            }
            _ => removals.push((row, c)),
        }
    }
    for group in &reusable {
        if let Some(recycle) = group.recycle
            && !group.reuses.is_empty()
        {
            recycle(world, &group.reuses);
        }
    }
    for group in reusable {
        let mut reuses = group.reuses;
        reuses.clear();
        reuse_lists.push(reuses);
    }
    index.reuse_lists = reuse_lists;
    index.ended_scratch = (ended_at, merged);
    // The ended contacts not kept go before any spawn, so that new contacts take their
    // freed rows and entity slots instead of growing the table and the entity list (both
    // double their capacity when full). Despawning moves the last contact of the table
    // into the freed row, so the order of removals sets the order in which forces are
    // summed from then on: last row first, so that no removal moves a contact still to be
    // removed.
    removals.sort_unstable_by_key(|&(row, _)| std::cmp::Reverse(row));
    for &(_, c) in &removals {
        world.despawn(c);
    }
    if !removals.is_empty() {
        // A despawn may have moved a vacant row.
        index.vacant_known = false;
    }
    let ContactIndex {
        per_grain, live, ..
    } = index;
    for (new, law) in to_spawn {
        let contact = (law.spawn)(world, new.contact, bodies_of(new.key, new.partner));
        enter_pair(per_grain, live, new.key as usize, &new, contact);
    }
    if world
        .resource::<Clock>()
        .step
        .is_multiple_of(CONTACT_SORT_INTERVAL)
    {
        if keep_vacant {
            fit_vacant_rows(world, index, table, s, &regions);
        }
        sort_contacts(world, index, s);
        bring_short_lists_inline(&mut index.per_grain, &mut index.shrunk);
    }
}

/// Moves back inline each contact list of the grains in `shrunk` that is on the heap and
/// holds no more than fits inline, then empties `shrunk`. A list spills to the heap when
/// its grain keys a third contact, and removing entries never gives the heap block back:
/// without this, the lists on the heap only ever grew in number (512,000-grain chute:
/// 11,000 grains with three or more contacts at any step, but 36,000 lists on the heap
/// after 100 steps and 69,000 after 400, 64 bytes each plus the allocator's header). Done
/// at the sorts, every [`CONTACT_SORT_INTERVAL`] steps, so that a grain whose count goes
/// back and forth between two and three does not free and allocate at every step; for the
/// grains whose lists shrank since the last sort only (a pass over every list cost 0.17 %
/// of the 512,000-grain step). Moves entries, in their order: changes no result.
fn bring_short_lists_inline(per_grain: &mut [GrainContacts], shrunk: &mut Vec<u32>) {
    for &key in shrunk.iter() {
        if let Some(list) = per_grain.get_mut(key as usize)
            && list.spilled()
            && list.len() <= list.inline_size()
        {
            list.shrink_to_fit();
        }
    }
    shrunk.clear();
}

/// An ended contact or a vacant row in the narrow phase's handout: its archetype, the
/// region of its key grain, its row, its entity and its key grain ([`NO_KEY`] if not
/// known, [`VACANT_KEY`] for a row already vacant).
type EndedRow = (ArchetypeId, u32, usize, Entity, u32);

/// The order of the handout's list: by archetype, region, then row (two entries are never of
/// one row).
#[inline]
fn handout_order(&(archetype, region, row, _, _): &EndedRow) -> (ArchetypeId, u32, usize) {
    (archetype, region, row)
}

/// A row a law's recycling writes: the contact's entity and table row, the contact it is
/// to hold and its bodies ([`talus_contact::systems::RecycleContacts`]).
type Reuse = (Entity, usize, Contact, ContactBodies);

/// Adds the `vacant` rows to the ended contacts' rows `ended` (each list in
/// [`handout_order`]), as [`VACANT_KEY`] entries, keeping that order;
/// `spare` is the list it merges them in (its contents are lost). The order is the one a
/// stable sort of `ended` followed by `vacant` gives (two rows are never the same), found
/// in one pass; a `vacant` out of order (not made by the narrow phase) is sorted with them.
fn join_vacant_rows(ended: &mut Vec<EndedRow>, spare: &mut Vec<EndedRow>, vacant: &[VacantRow]) {
    let as_ended =
        |&(archetype, region, row, c): &VacantRow| (archetype, region, row, c, VACANT_KEY);
    if !vacant.is_sorted_by_key(|v| handout_order(&as_ended(v))) {
        ended.extend(vacant.iter().map(as_ended));
        ended.sort_by_key(handout_order);
        return;
    }
    spare.clear();
    spare.reserve(ended.len() + vacant.len());
    let (mut e, mut v) = (0, 0);
    while e < ended.len() && v < vacant.len() {
        let next = as_ended(&vacant[v]);
        if handout_order(&next) < handout_order(&ended[e]) {
            spare.push(next);
            v += 1;
        } else {
            spare.push(ended[e]);
            e += 1;
        }
    }
    spare.extend_from_slice(&ended[e..]);
    spare.extend(vacant[v..].iter().map(as_ended));
    std::mem::swap(ended, spare);
}

/// The handout's entry for an ended contact: its row found from its entity.
#[inline]
fn ended_row(world: &World, contact: Entity, region: u32, key: u32) -> EndedRow {
    let at = world.entity(contact).location();
    (at.archetype_id, region, at.table_row.index(), contact, key)
}

/// What one job of the narrow phase's handout did ([`hand_out_region`]), in the order of
/// its pairs.
struct RegionHandout<'a> {
    /// The pairs that took an ended contact of their region: the group ([`Reusable`]) and
    /// its run of the region, the contact's place in the pass's ended list, and the pair.
    handed: Vec<(usize, usize, usize, NewPair)>,
    /// The pairs whose law has no ended contact in the pass (spawned).
    no_law_group: Vec<(NewPair, &'a LawSlot)>,
    /// The pairs whose region had no ended contact of their law left.
    unplaced: Vec<(NewPair, &'a LawSlot)>,
}

/// One job of the narrow phase's handout: the new pairs of the chunks of grains from grain
/// `first` (their lists `made` and `bare`, whose contact lists and live bits are `lists` and
/// `live`), each given the next ended contact of its law and its key's region, in order.
/// Enters each handed-out pair in its key's contact list and sets its live bit; the
/// groups' lists are the caller's to fill from what it returns.
#[allow(clippy::too_many_arguments)]
fn hand_out_region<'a>(
    s: &GrainSnapshot,
    table: &'a ContactLawTable,
    regions: &GrainRegions,
    reusable: &[Reusable],
    ended_at: &[EndedRow],
    first: usize,
    lists: &mut [GrainContacts],
    live: &mut [Vec<u64>],
    made: &[Vec<NewPair>],
    bare: &[Vec<(u32, u32, u32)>],
) -> RegionHandout<'a> {
    let mut out = RegionHandout {
        handed: Vec::new(),
        no_law_group: Vec::new(),
        unplaced: Vec::new(),
    };
    // The next ended contact of each group's runs, as this job takes them.
    let mut next: SmallVec<[Vec<usize>; 2]> = reusable
        .iter()
        .map(|g| g.by_region.iter().map(|run| run.next).collect())
        .collect();
    // Chunk after chunk, each chunk's pairs in its one non-empty list; a bare pair gets
    // its contact here.
    let listed = made.iter().zip(bare).flat_map(|(made, bare)| {
        let bare = bare.iter().map(|&(key, partner, slot)| {
            new_pair(s, table, key as usize, partner, slot)
                .expect("the parallel pass kept only interacting pairs")
        });
        made.iter().copied().chain(bare)
    });
    // A pair's key grain is anywhere in the job's grains: the pair a few ahead asks for its
    // contact list, on which the loop otherwise waits pair after pair.
    let mut ahead = made
        .iter()
        .zip(bare)
        .flat_map(|(made, bare)| {
            let bare = bare.iter().map(|&(key, _, _)| key);
            made.iter().map(|pair| pair.key).chain(bare)
        })
        .skip(LISTS_AHEAD);
    for new in listed {
        if let Some(ahead) = ahead.next() {
            prefetch_item(lists, ahead as usize - first);
        }
        let law = table.slots[new.law as usize]
            .as_ref()
            .expect("the parallel pass kept only interacting pairs");
        let Some(g) = reusable.iter().position(|g| g.archetype == law.archetype) else {
            out.no_law_group.push((new, law));
            continue;
        };
        let runs = &reusable[g].by_region;
        let region = regions.region_of(new.key) as u32;
        let own = runs
            .binary_search_by_key(&region, |run| run.region)
            .ok()
            .filter(|&at| next[g][at] < runs[at].end);
        match own {
            Some(at) => {
                let k = next[g][at];
                next[g][at] += 1;
                let (_, _, _, contact, _) = ended_at[k];
                enter_pair(lists, live, new.key as usize - first, &new, contact);
                out.handed.push((g, at, k, new));
            }
            None => out.unplaced.push((new, law)),
        }
    }
    out
}

/// Enters new pair `new`, given `contact`, in its key's contact list, `lists[local]`, and
/// sets its live bit (`lists` and `live` start at the same chunk of grains).
#[inline]
fn enter_pair(
    lists: &mut [GrainContacts],
    live: &mut [Vec<u64>],
    local: usize,
    new: &NewPair,
    contact: Entity,
) {
    lists[local].push(IndexEntry::new(new.partner, contact, new.slot));
    set_live(live, local, new.slot, true);
}

/// The key of a row that was vacant before the pass.
const VACANT_KEY: u32 = u32::MAX - 1;

/// The grain a vacant row of `region` is given ([`Contact::vacant`]): the region's last, so
/// that a sort puts the region's vacant rows together at the end of its rows (before the
/// last grain's few contacts). Spread among the region's contacts they would leave a
/// vacant lane in many of the force loop's groups of four (measured 5–7 % of the 32,000-grain
/// chute's step with a vacant row per 16 contacts).
fn vacant_key(regions: &GrainRegions, region: usize) -> u32 {
    (regions.range(region).end - 1) as u32
}

/// The vacant rows of every contact table, by archetype, region of their grain and row.
fn find_vacant_rows(
    world: &mut World,
    s: &GrainSnapshot,
    regions: &GrainRegions,
) -> Vec<VacantRow> {
    scan_contact_tables(world, s, regions, false).0
}

/// One pass over every contact table: its vacant rows (as [`find_vacant_rows`]) and, if
/// `count`, its other contacts by region of their key grain, per archetype.
#[allow(clippy::type_complexity)]
fn scan_contact_tables(
    world: &mut World,
    s: &GrainSnapshot,
    regions: &GrainRegions,
    count: bool,
) -> (Vec<VacantRow>, Vec<(ArchetypeId, Vec<usize>)>) {
    let mut vacant = Vec::new();
    let mut counts = Vec::new();
    let mut contacts = world.query::<(Entity, &Contact, &ContactBodies)>();
    let contacts = contacts.query(world);
    for (entities, c, b) in contacts.contiguous_iter().expect("contact query is dense") {
        let Some(&first) = entities.first() else {
            continue;
        };
        let archetype = world.entity(first).location().archetype_id;
        let mut per_region = vec![0usize; if count { regions.count() } else { 0 }];
        for (row, (c, b)) in c.iter().zip(b).enumerate() {
            let key = key_grain(s, c, b);
            let region = if key == u32::MAX {
                u32::MAX
            } else {
                regions.region_of(key) as u32
            };
            if c.is_vacant() {
                vacant.push((archetype, region, row, entities[row]));
            } else if count && key != u32::MAX {
                per_region[region as usize] += 1;
            }
        }
        if count {
            counts.push((archetype, per_region));
        }
    }
    vacant.sort_unstable_by_key(|&(archetype, region, row, _)| (archetype, region, row));
    (vacant, counts)
}

/// The vacant rows a region is given at a sort: one per this many of its contacts, and
/// [`VACANT_ROWS_MIN`] at the least; [`VACANT_ROWS_TAKEN`] times that for a region left
/// with less than half of it. Between two sorts the contacts a region makes, less those it
/// ends, take its vacant rows; once they are gone its new contacts land in other regions'
/// rows. A share large enough everywhere for the regions that take most (one row per 16
/// contacts) cost the 32,000-grain chute's step 3 % for the rows the others leave unused
/// (`docs/architecture.md` §6 has the measurements).
const CONTACTS_PER_VACANT_ROW: usize = 128;
/// See [`CONTACTS_PER_VACANT_ROW`].
const VACANT_ROWS_MIN: usize = 8;
/// See [`CONTACTS_PER_VACANT_ROW`].
const VACANT_ROWS_TAKEN: usize = 8;
/// A region keeps up to this many times its share of vacant rows through a sort (the
/// rows of contacts it ended), so that a region whose contacts come and go in turn does
/// not have rows despawned at one sort and spawned at the next.
const VACANT_ROWS_KEPT: usize = 2;

/// Before a sort: gives each region of each law's table its share of vacant rows
/// ([`CONTACTS_PER_VACANT_ROW`]): a region short of it gets new vacant rows; one with more
/// than [`VACANT_ROWS_KEPT`] times it has the rest despawned, so that a packing whose
/// contacts grow fewer does not keep the rows of its past. The sort that follows puts every
/// row, old or new, in its region's place.
fn fit_vacant_rows(
    world: &mut World,
    index: &mut ContactIndex,
    table: &ContactLawTable,
    s: &GrainSnapshot,
    regions: &GrainRegions,
) {
    if s.is_empty() {
        return;
    }
    // Contacts of each law's archetype, by region, and the vacant rows as they are.
    let (vacant, counts) = scan_contact_tables(world, s, regions, true);
    index.vacant = vacant;
    index.vacant_known = true;
    let mut removals: Vec<(usize, Entity)> = Vec::new();
    let mut spawns: Vec<(&LawSlot, u32)> = Vec::new();
    for (archetype, per_region) in &counts {
        let Some(slot) = table.by_archetype(*archetype) else {
            continue;
        };
        // This archetype's vacant rows, by region (the list is by archetype, region, row).
        let first = index.vacant.partition_point(|v| v.0 < *archetype);
        let end = index.vacant.partition_point(|v| v.0 <= *archetype);
        let mut vacant = index.vacant[first..end].iter().peekable();
        for (region, &contacts) in per_region.iter().enumerate() {
            let mut held = Vec::new();
            while let Some(v) = vacant.next_if(|v| v.1 as usize <= region) {
                if v.1 as usize == region {
                    held.push(v);
                } else {
                    removals.push((v.2, v.3));
                }
            }
            // A region that used up most of its vacant rows since the last sort is given
            // more: a fixed function of the table, so that a resumed run fits alike.
            let floor = VACANT_ROWS_MIN.max(contacts / CONTACTS_PER_VACANT_ROW);
            let share = if held.len() < floor / 2 {
                VACANT_ROWS_TAKEN * floor
            } else {
                floor
            };
            // The region's last rows go.
            removals.extend(
                held.iter()
                    .skip(VACANT_ROWS_KEPT * share)
                    .map(|v| (v.2, v.3)),
            );
            let missing = share.saturating_sub(held.len());
            if missing > 0 && !regions.range(region).is_empty() {
                let key = vacant_key(regions, region);
                spawns.extend((0..missing).map(|_| (slot, key)));
            }
        }
        // Rows of regions past the last (a body not found) go too.
        removals.extend(vacant.map(|v| (v.2, v.3)));
    }
    if removals.is_empty() && spawns.is_empty() {
        return;
    }
    removals.sort_unstable_by_key(|&(row, _)| std::cmp::Reverse(row));
    for &(_, c) in &removals {
        world.despawn(c);
    }
    for (slot, key) in spawns {
        let bodies = ContactBodies {
            a: key,
            b: key,
            layout: s.layout,
        };
        (slot.spawn)(world, Contact::vacant(s.entity[key as usize]), bodies);
    }
    index.vacant_known = false;
}

/// The contacts of one archetype that ended in a pass, as ranges of the pass's ended list
/// (sorted by archetype, region, then row), and the new pairs given to them.
struct Reusable {
    archetype: ArchetypeId,
    /// The group's ended contacts by region of their key grain, regions ascending.
    by_region: Vec<RegionEnded>,
    /// The first entry of `by_region` that may have an ended contact left for a pair of
    /// another region.
    spare: usize,
    /// The ended contacts handed out, with their table rows, their new pairs and the
    /// pairs' bodies.
    reuses: Vec<Reuse>,
    /// The recycling function of the archetype's law (`None` for a table no law spawns,
    /// whose ended contacts are despawned).
    recycle: Option<RecycleContacts>,
}

/// The ended contacts of one archetype and region, as a range of the pass's ended list.
struct RegionEnded {
    /// The region of their key grains (`u32::MAX`: not known, for a contact that lost a
    /// body).
    region: u32,
    /// The next one to hand out.
    next: usize,
    /// One past the last.
    end: usize,
}

/// The key of an ended contact whose key grain is not known (it lost a body).
const NO_KEY: u32 = u32::MAX;

/// Steps between two sorts of the contact tables ([`sort_contacts`]). Despawns scramble a
/// table a little at every step; a sort of a table that is nearly in order moves few rows.
/// A fixed step count, not a measure of disorder, so that a run resumed from a saved state
/// sorts at the same steps as the run that was never interrupted.
pub const CONTACT_SORT_INTERVAL: u64 = 20;

/// Sorts every law's contact table into the order of its contacts' bodies
/// ([`talus_contact::order`]) and re-points the index's entries at the entities that now
/// hold their pairs. Called by the narrow phase every [`CONTACT_SORT_INTERVAL`] steps;
/// public so that tests can sort at any step. Sorts nothing unless the index is keyed by
/// `s`'s layout with no contact pending (as after a narrow phase on `s`). Returns how many
/// contacts changed rows.
pub fn sort_contacts(world: &mut World, index: &mut ContactIndex, s: &GrainSnapshot) -> usize {
    if index.layout != s.layout || !index.pending.is_empty() {
        return 0;
    }
    let sorts = world.resource::<ContactTableSorts>().0.clone();
    let mut moved = 0;
    for (_, sort) in sorts {
        moved += sort(world, s);
    }
    if moved == 0 {
        return 0;
    }
    // The vacant rows moved with the rest.
    index.vacant_known = false;
    // A sorted law's every contact has its bodies in `s`'s layout; an unsorted law's
    // contacts did not move, and any whose bodies are of another layout is skipped.
    let mut contacts = world.query::<(Entity, &ContactBodies)>();
    let contacts = contacts.query(world);
    let per_grain = &mut index.per_grain;
    let key_of = |bodies: &ContactBodies| first_in_order(bodies.a, bodies.b).0;
    for (entities, bodies) in contacts.contiguous_iter().expect("contact query is dense") {
        let in_order = bodies.par_iter().all(|b| b.layout == s.layout)
            && bodies
                .par_windows(2)
                .all(|w| key_of(&w[0]) <= key_of(&w[1]));
        if in_order {
            // A table in the order of its contacts' keys (as a sort leaves it): each
            // range of grains' lists is re-pointed, in parallel, from the rows whose
            // keys fall in the range, found by bisection.
            per_grain
                .par_chunks_mut(REPOINT_GRAINS)
                .enumerate()
                .for_each(|(part, lists)| {
                    let first = part * REPOINT_GRAINS;
                    let rows = bodies.partition_point(|b| (key_of(b) as usize) < first)
                        ..bodies.partition_point(|b| (key_of(b) as usize) < first + lists.len());
                    for (&contact, b) in entities[rows.clone()].iter().zip(&bodies[rows]) {
                        repoint(lists, first, b, contact);
                    }
                });
        } else {
            for (&contact, b) in entities.iter().zip(bodies) {
                if b.layout == s.layout {
                    repoint(per_grain, 0, b, contact);
                }
            }
        }
    }
    moved
}

/// Grains whose contact lists one job of [`sort_contacts`] re-points.
const REPOINT_GRAINS: usize = 16 * CHUNK;

/// Points the entry of the pair of `bodies` (a contact in `s`'s layout) in `lists` (the
/// contact lists of the grains from `first`) at `contact`, the entity that now holds it.
#[inline]
fn repoint(lists: &mut [GrainContacts], first: usize, bodies: &ContactBodies, contact: Entity) {
    let (key, partner) = first_in_order(bodies.a, bodies.b);
    if let Some(entry) = lists
        .get_mut((key as usize).wrapping_sub(first))
        .and_then(|list| list.iter_mut().find(|e| e.partner == partner))
    {
        entry.set_contact(contact);
    }
}

/// Finds each contact of a chunk of grains among the chunk's candidate pairs: sets the
/// pair's live bit and enters its slot in the contact's entry (a contact whose pair is not
/// a candidate gets [`NO_SLOT`]).
fn mark_live(entries: &mut [GrainContacts], candidates: &CandidateChunk, live: &mut Vec<u64>) {
    live.clear();
    live.resize(candidates.len().div_ceil(64), 0);
    for entry in entries.iter_mut().flatten() {
        entry.slot = NO_SLOT;
    }
    let pairs = candidates.local.iter().zip(&candidates.partner);
    for (slot, (&local, &partner)) in pairs.enumerate() {
        if let Some(entry) = entries[local as usize]
            .iter_mut()
            .find(|e| e.partner == partner)
        {
            entry.slot = slot as u32;
            live[slot / 64] |= 1 << (slot % 64);
        }
    }
}

/// Sets or clears the live bit of the candidate pair at `slot` of grain `key`'s chunk
/// (nothing for [`NO_SLOT`]).
#[inline]
fn set_live(live: &mut [Vec<u64>], key: usize, slot: u32, on: bool) {
    if slot == NO_SLOT {
        return;
    }
    let (word, bit) = (slot as usize / 64, slot % 64);
    let bits = &mut live[key / CHUNK][word];
    if on {
        *bits |= 1 << bit;
    } else {
        *bits &= !(1 << bit);
    }
}

/// Ends the contacts of `pairs` (idle ones: they carried no force at their last
/// evaluation) whose grains no longer touch, for the key grains `first..` of `lists` (their
/// contact lists, `first` a multiple of [`CHUNK`]) and `live` (their chunks' live bits);
/// the other pairs are another call's. Returns each ended contact's row, as the handout
/// lists it, and the key grains whose lists, on the heap, came to fit inline
/// ([`ContactIndex::shrunk`]).
#[allow(clippy::too_many_arguments)]
fn end_idle_contacts(
    s: &GrainSnapshot,
    range: f64,
    pairs: &[[u32; 2]],
    first: usize,
    lists: &mut [GrainContacts],
    live: &mut [Vec<u64>],
    world: &World,
    region_of: &impl Fn(u32) -> u32,
) -> (Vec<EndedRow>, Vec<u32>) {
    let len = lists.len();
    let keyed_here = move |&[a, b]: &[u32; 2]| {
        let (key, partner) = first_in_order(a, b);
        let local = (key as usize).wrapping_sub(first);
        (local < len).then_some((key, partner, local))
    };
    let mut ended = Vec::new();
    let mut ended_contacts: Vec<(Entity, u32)> = Vec::new();
    let mut shrunk = Vec::new();
    // The pairs' grains and contact lists are all over the packing: each pair asks for
    // those of the pair a few ahead.
    let mut ahead = pairs.iter().filter_map(keyed_here).skip(LISTS_AHEAD);
    for (key, partner, local) in pairs.iter().filter_map(keyed_here) {
        if let Some((key, partner, local)) = ahead.next() {
            prefetch_item(lists, local);
            prefetch_item(&s.records, key as usize);
            prefetch_item(&s.records, partner as usize);
        }
        if touching(s, range, key as usize, partner) {
            continue;
        }
        let entries = &mut lists[local];
        if let Some(k) = entries.iter().position(|e| e.partner == partner) {
            let entry = entries.remove(k);
            set_live(live, local, entry.slot, false);
            ended_contacts.push((entry.contact(), key));
            if entries.spilled() && entries.len() <= entries.inline_size() {
                shrunk.push(key);
            }
        }
    }
    // The ended contacts' rows, in a loop of their own: each lookup waits on the entity's
    // record, but none waits on another, so the core has several in flight (inside the loop
    // above each waited behind its pair's test and list search).
    ended.extend(
        ended_contacts
            .iter()
            .map(|&(contact, key)| ended_row(world, contact, region_of(key), key)),
    );
    (ended, shrunk)
}

/// What every chunk of the narrow phase's parallel pass reads.
struct PassState<'a> {
    s: &'a GrainSnapshot,
    table: &'a ContactLawTable,
    range: f64,
    gap_threshold: u16,
}

/// Whether grain `key` touches body `partner` (a grain after it in dense order, or a wall
/// code) within the interaction range: the test of the pass ([`narrow_chunk`]), one pair
/// at a time, with the same bits.
#[inline]
fn touching(s: &GrainSnapshot, range: f64, key: usize, partner: u32) -> bool {
    let (p, r) = (s.position(key), s.radius(key));
    match ContactBodies::wall_of(partner) {
        Some(w) => {
            let wall = &s.walls[w];
            (p - wall.point).dot(wall.normal) < r + range
        }
        None => {
            let j = partner as usize;
            let reach = r + s.radius(j) + range;
            s.separation(p, s.position(j)).length_squared() < reach * reach
        }
    }
}

/// How many pairs ahead the serial loops over ended and new contacts ask for the grains'
/// contact lists (and records).
const LISTS_AHEAD: usize = 8;

/// The new pair of grain `i` (dense index) and `partner` (a dense index or a wall code)
/// with its contact and law, or `None` if no law joins their materials.
fn new_pair(
    s: &GrainSnapshot,
    table: &ContactLawTable,
    i: usize,
    partner: u32,
    slot: u32,
) -> Option<NewPair> {
    let (b, material_b, kind) = match ContactBodies::wall_of(partner) {
        Some(w) => {
            let wall = &s.walls[w];
            (wall.entity, wall.material, ContactKind::GrainWall)
        }
        None => {
            let j = partner as usize;
            (s.entity[j], s.material[j], ContactKind::GrainGrain)
        }
    };
    let (law, slot_of_law) = table.slot_of(s.material[i], material_b)?;
    // The grain first in dense order is `a` (never the entity ids, which depend on the
    // history of spawns: a restored run must choose alike).
    let contact = Contact {
        a: s.entity[i],
        b,
        kind,
        pair_slot: slot_of_law.pair_slot,
    };
    Some(NewPair {
        key: i as u32,
        partner,
        slot,
        law,
        contact,
    })
}

/// How many pairs ahead [`narrow_chunk`] asks for the partners' positions and radii.
const PARTNERS_AHEAD: usize = 32;

/// The narrow phase on one chunk of grains (first grain `base`): tests the candidate
/// pairs that may be within reach (a prefix of the chunk's pairs, which come in
/// increasing order of their gap at the build) and have no live contact (their bits in
/// `live` clear) four at a time, and each grain against each wall, and lists in `new`
/// the touching pairs that have no contact yet, ordered by grain, then partner (walls
/// last), whatever the order of the tests. Not inlined, so that profiles show it.
///
/// The pairs go to the first of `lists` with their contacts ([`NewPair`]), so that the
/// serial handout reads no grain's entity or material; a chunk none of whose candidate
/// pairs has a contact (every chunk in a run's first narrow phase, which finds every
/// contact new) lists them bare in the second, 12 bytes a pair instead of 40, and the
/// handout makes their contacts: those lists hold every contact of the packing at once,
/// and their memory stays with the process (the 512,000-grain chute's peak resident set
/// 747 bytes a grain with every pair made here, 727–728 with these bare).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn narrow_chunk(
    state: &PassState,
    base: usize,
    entries: &[GrainContacts],
    candidates: &CandidateChunk,
    live: &[u64],
    lists: (&mut Vec<NewPair>, &mut Vec<(u32, u32, u32)>),
    ahead: &mut talus_core::snapshot::LinePrefetcher,
) {
    let PassState {
        s,
        table,
        range,
        gap_threshold,
    } = *state;
    let (new, bare) = lists;
    new.clear();
    bare.clear();
    let listed_bare = live.iter().all(|&bits| bits == 0);
    // A contact between two frozen grains (zero inverse mass in the snapshot), or a
    // frozen grain and a wall, moves nothing, and its reduced mass (hence a mass-scaled
    // dashpot) would be infinite: none is made.
    let frozen = |i: usize| s.inverse_mass(i) == 0.0;
    // A touching candidate pair reaches here only without a live bit, so it has no
    // contact (the bits are exact: `tests/neighbour_rebuild.rs`); a grain and a wall
    // (no slot) are looked up in the grain's contacts. The partner's material and entity
    // are looked up only for a pair with no contact: they are arrays of their own, which
    // a large packing's partners would each miss in cache.
    let mut touch = |i: usize, partner: u32, slot: u32| {
        let known = |partner| entries[i - base].iter().any(|e| e.partner == partner);
        debug_assert!(
            slot == NO_SLOT || !known(partner),
            "a live pair without its bit"
        );
        if slot != NO_SLOT || !known(partner) {
            // Listed bare first in any case: the contacts are made below, in a loop that
            // asks ahead for the grains' entities and materials.
            bare.push((i as u32, partner, slot));
        }
    };
    let tested = candidates.within_threshold(gap_threshold);
    let (local, partner) = (&candidates.local[..tested], &candidates.partner[..tested]);
    // Four pairs at a time where the separation is the plain nearest image (the same bits
    // as one at a time); across a sheared seam, one at a time.
    let image = (!s.is_sheared()).then(|| s.image_lanes());
    let grains = s.reader();
    let range4 = F4::splat(range);
    // One loop over groups of four pairs, the last padded with its first pair repeated
    // in the lanes left over: the test is written once, inlined in the loop.
    for first in (0..tested).step_by(4) {
        ahead.step(2);
        // A chunk's pairs reach grains all over the packing, beyond a core's own cache at
        // any size worth timing (the records of 32,000 grains are 2 MB): ask for the
        // records of the pairs a few batches ahead.
        for &j in partner.iter().skip(first + PARTNERS_AHEAD).take(4) {
            prefetch_item(&s.records, j as usize);
        }
        // The lanes to look at: pairs that are neither padding nor with a contact (their
        // live bits, four from a multiple of four, so within a word). Four pairs that all
        // have contacts are not even read.
        let padding = 0xF_u32 << (tested - first).min(4) & 0xF;
        let live_four = (live[first / 64] >> (first % 64)) as u32 & 0xF;
        let wanted = 0xF & !(padding | live_four);
        if wanted == 0 {
            continue;
        }
        let pair = |l: usize| (first + l).min(tested - 1);
        let i: [usize; 4] = std::array::from_fn(|l| base + local[pair(l)] as usize);
        let j: [u32; 4] = std::array::from_fn(|l| partner[pair(l)]);
        let mut within = if let Some(image) = &image {
            let (a, b) = (grains.gather4(i), grains.gather4(j.map(|j| j as usize)));
            let reach = a.radius + b.radius + range4;
            image
                .apply(a.position - b.position)
                .length_squared()
                .lt(reach * reach)
                .bits()
        } else {
            (0..4)
                .map(|l| u32::from(touching(s, range, i[l], j[l])) << l)
                .sum()
        };
        within &= wanted;
        while within != 0 {
            let l = within.trailing_zeros() as usize;
            within &= within - 1;
            let (i, j) = (i[l], j[l]);
            if !(frozen(i) && frozen(j as usize)) {
                touch(i, j, (first + l) as u32);
            }
        }
    }
    if !s.walls.is_empty() {
        for i in base..base + entries.len() {
            if frozen(i) {
                continue;
            }
            for w in 0..s.walls.len() {
                let code = ContactBodies::wall_code(w);
                if touching(s, range, i, code) {
                    touch(i, code, NO_SLOT);
                }
            }
        }
    }
    // By grain, then partner (wall codes after every grain's index), as one pass over
    // the grains in index order would list them: where and when the list was built never
    // shows in the order contacts are made (and forces summed).
    bare.sort_unstable();
    if listed_bare {
        // Only the pairs some law joins.
        bare.retain(|&(i, partner, slot)| new_pair(s, table, i as usize, partner, slot).is_some());
        return;
    }
    // The pairs' grains lie all over the chunk's reach, their entities and materials in
    // arrays of their own: all are asked for before the first is read (a chunk of a
    // flowing packing lists a few pairs a step), so that their misses overlap.
    for &(i, j, _) in bare.iter() {
        prefetch_item(&s.entity, i as usize);
        prefetch_item(&s.material, i as usize);
        if ContactBodies::wall_of(j).is_none() {
            prefetch_item(&s.entity, j as usize);
            prefetch_item(&s.material, j as usize);
        }
    }
    new.extend(
        bare.iter()
            .filter_map(|&(i, partner, slot)| new_pair(s, table, i as usize, partner, slot)),
    );
    bare.clear();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vacant rows join the ended contacts' rows in the order a stable sort of the two
    /// lists one after the other gives (the handout's order before the lists were kept
    /// from pass to pass), whether the vacant rows come in order (merged) or not (sorted),
    /// and the spare list's contents do not matter.
    #[test]
    fn vacant_rows_join_ended_rows_as_a_stable_sort_orders_them() {
        let mut world = World::new();
        let entities: Vec<Entity> = (0..90).map(|_| world.spawn_empty().id()).collect();
        let archetype = |row: usize| {
            if row < 45 {
                ArchetypeId::EMPTY
            } else {
                ArchetypeId::new(3)
            }
        };
        // Rows 0..90 of two tables' regions, every third ended and every third vacant, so
        // that the two lists interleave; the ended ones as the threads list them (in no
        // order), then sorted as the narrow phase sorts them.
        let mut ended: Vec<EndedRow> = (0..90)
            .rev()
            .filter(|row| row % 3 == 0)
            .map(|row| {
                (
                    archetype(row),
                    (row / 7) as u32,
                    row,
                    entities[row],
                    row as u32,
                )
            })
            .collect();
        ended.sort_unstable_by_key(|&(archetype, region, row, _, _)| (archetype, region, row));
        let vacant: Vec<VacantRow> = (0..90)
            .filter(|row| row % 3 == 1)
            .map(|row| (archetype(row), (row / 7) as u32, row, entities[row]))
            .collect();
        let stable_sort_of_both = |vacant: &[VacantRow]| {
            let mut both = ended.clone();
            both.extend(
                vacant
                    .iter()
                    .map(|&(a, region, row, c)| (a, region, row, c, VACANT_KEY)),
            );
            both.sort_by_key(|&(archetype, region, row, _, _)| (archetype, region, row));
            both
        };
        let expected = stable_sort_of_both(&vacant);
        assert_eq!(expected.len(), 60);
        let mut joined = ended.clone();
        let mut spare = vec![ended[3]; 5];
        join_vacant_rows(&mut joined, &mut spare, &vacant);
        assert_eq!(joined, expected);
        // Vacant rows out of order.
        let mut shuffled = vacant.clone();
        shuffled.reverse();
        shuffled.swap(0, 7);
        let mut joined = ended.clone();
        join_vacant_rows(&mut joined, &mut spare, &shuffled);
        assert_eq!(joined, stable_sort_of_both(&shuffled));
        // No vacant rows, or no ended ones.
        let mut joined = ended.clone();
        join_vacant_rows(&mut joined, &mut spare, &[]);
        assert_eq!(joined, ended);
        let mut joined = Vec::new();
        join_vacant_rows(&mut joined, &mut spare, &vacant);
        let vacant_alone: Vec<EndedRow> = vacant
            .iter()
            .map(|&(a, region, row, c)| (a, region, row, c, VACANT_KEY))
            .collect();
        assert_eq!(joined, vacant_alone);
    }

    /// The listed grains' lists that spilled to the heap and shrank back to what fits
    /// inline are moved back inline with their entries in order; longer lists, lists never
    /// spilled and grains not listed are left as they are, and the list is emptied.
    #[test]
    fn short_lists_come_back_inline_with_their_entries_in_order() {
        let entry = |partner| IndexEntry::new(partner, Entity::PLACEHOLDER, partner + 100);
        let spilled_then_shrunk = |keep: u32| {
            let mut list: GrainContacts = (0..5).map(entry).collect();
            list.retain(|e| e.partner < keep);
            list
        };
        let mut lists: Vec<GrainContacts> = vec![
            spilled_then_shrunk(0),
            spilled_then_shrunk(2),
            spilled_then_shrunk(3),
            (0..1).map(entry).collect(),
            spilled_then_shrunk(1),
        ];
        assert!(
            lists
                .iter()
                .enumerate()
                .all(|(k, l)| l.spilled() == (k != 3))
        );
        let before: Vec<Vec<(u32, u32)>> = lists
            .iter()
            .map(|l| l.iter().map(|e| (e.partner, e.slot)).collect())
            .collect();
        let mut shrunk = vec![0, 1, 2, 3, 1, 17];
        bring_short_lists_inline(&mut lists, &mut shrunk);
        assert!(shrunk.is_empty());
        let spilled: Vec<bool> = lists.iter().map(|l| l.spilled()).collect();
        assert_eq!(spilled, [false, false, true, false, true]);
        let after: Vec<Vec<(u32, u32)>> = lists
            .iter()
            .map(|l| l.iter().map(|e| (e.partner, e.slot)).collect())
            .collect();
        assert_eq!(before, after);
    }
}
