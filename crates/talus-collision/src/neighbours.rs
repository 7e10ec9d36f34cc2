//! Verlet neighbour lists with a skin: candidate pairs within reach + skin are found on
//! the cell grid only when the grains have moved, about their common drift, more than half
//! the skin since the last build; every other step tests just those candidates. Exact: a
//! pair that comes within reach must have been within reach + skin at the last build,
//! since its separation has changed by at most twice that bound.
//!
//! A build tests the grains of the 27 cells around each grain four at a time, in lanes,
//! and keeps each chunk's pairs sorted by their gap, so that the narrow phase's pairs of a
//! step are a prefix of the list.

use bevy_ecs::prelude::*;
use rayon::prelude::*;
use smallvec::SmallVec;
use talus_core::lanes::{F4, V4};
use talus_core::periodic::{ImageLanes, LeesEdwards, NearestImage, PeriodicBox};
use talus_core::snapshot::{GrainReader, GrainSnapshot};

use crate::grid::CellGrid;

/// Grains per parallel work unit; fixed so that results do not depend on the thread count.
pub const CHUNK: usize = 256;

/// Skin as a fraction of the largest diameter (LAMMPS's chute benchmark: 0.1 of d).
pub const SKIN_FRACTION: f64 = 0.1;

/// The candidate pairs (i, j), j > i, of the grains i of one chunk of [`CHUNK`] grains, in
/// increasing order of their gap at the build (then of i, then of j): the pairs that may
/// be within reach at a step are a prefix of the list, which the narrow phase tests four
/// at a time without looking at grain boundaries.
#[derive(Default, Clone, Debug)]
pub struct CandidateChunk {
    /// Each pair's first grain, as its offset in the chunk (dense index − first index of
    /// the chunk).
    pub(crate) local: Vec<u8>,
    /// Each pair's second grain (dense index j > i).
    pub(crate) partner: Vec<u32>,
    /// Each pair's gap at the build (distance less the reach of the pair), in units of
    /// [`GAP_UNITS`] per skin, rounded down, 0 for pairs already within reach: a pair
    /// cannot be within reach while twice the bound D on the moves since the build
    /// ([`GrainSnapshot::move_bound_sq`]) is below its gap. Increasing.
    pub(crate) gap: Vec<u16>,
    /// The blocks of moves ([`GrainSnapshot::block_moves`]; a chunk is one) of the
    /// partners, without repeats, in increasing order: the blocks whose moves, with the
    /// chunk's own, bound how far this chunk's pairs can have closed.
    pub(crate) partner_blocks: SmallVec<[u32; 16]>,
}

// A chunk's grains are told apart by a byte.
const _: () = assert!(CHUNK <= 256);
// A chunk of the list is a block of the snapshot's moves.
const _: () = assert!(CHUNK == talus_core::snapshot::MOVE_BLOCK);

impl CandidateChunk {
    /// Number of candidate pairs.
    pub fn len(&self) -> usize {
        self.partner.len()
    }

    /// Whether the chunk has no candidate pair.
    pub fn is_empty(&self) -> bool {
        self.partner.is_empty()
    }

    /// How many pairs, from the first, have a gap at most `threshold`
    /// ([`NeighbourList::gap_threshold`]): the only ones that may be within reach.
    #[inline]
    pub fn within_threshold(&self, threshold: u16) -> usize {
        self.gap.partition_point(|&gap| gap <= threshold)
    }

    /// Fills the chunk from pair keys ([`pair_key`]), in increasing order of their gaps
    /// (a stable radix sort on the gap's two bytes: pairs of the same gap stay in the
    /// order they were found, which is a fixed function of the grains' state).
    fn fill(&mut self, keys: &mut Vec<u64>, scratch: &mut Vec<u64>) {
        for byte in [40, 48] {
            let mut start = [0usize; 257];
            for &k in keys.iter() {
                start[(k >> byte) as usize & 0xFF] += 1;
            }
            let mut sum = 0;
            for slot in start.iter_mut() {
                let count = *slot;
                *slot = sum;
                sum += count;
            }
            scratch.clear();
            scratch.resize(keys.len(), 0);
            for &k in keys.iter() {
                let bucket = &mut start[(k >> byte) as usize & 0xFF];
                scratch[*bucket] = k;
                *bucket += 1;
            }
            std::mem::swap(keys, scratch);
        }
        self.local.clear();
        self.partner.clear();
        self.gap.clear();
        reserve_with_headroom(&mut self.local, keys.len());
        reserve_with_headroom(&mut self.partner, keys.len());
        reserve_with_headroom(&mut self.gap, keys.len());
        self.local.extend(keys.iter().map(|&k| (k >> 32) as u8));
        self.partner.extend(keys.iter().map(|&k| k as u32));
        self.gap.extend(keys.iter().map(|&k| (k >> 40) as u16));
        // The blocks are entered one at a time in their sorted place, not gathered one per
        // pair and then sorted and deduplicated: a list one entry per pair (some 1,000 a
        // chunk) outgrew the inline room and kept its heap block from build to build, 8 MB
        // at 512,000 grains for a list that holds a few dozen blocks. A pair costs a binary
        // search among those, none when its block is the last one entered.
        self.partner_blocks.clear();
        let mut last = u32::MAX;
        for &j in &self.partner {
            let block = j / CHUNK as u32;
            if block == last {
                continue;
            }
            last = block;
            if let Err(at) = self.partner_blocks.binary_search(&block) {
                self.partner_blocks.insert(at, block);
            }
        }
    }
}

/// Makes room for `needed` items in an empty `list`, with an eighth more when it must
/// grow, instead of `Vec`'s growth, which at least doubles it: each chunk's lists are
/// kept from build to build, and as a long run's chunks outgrow their first builds one
/// after another, doubling left them holding up to twice what they need (512,000-grain
/// chute: the heap's blocks of 1 to 8 KB, where these lists are, grew from 24.3 to 28.6 MB
/// in 100 steps; with the eighth, 25.9 to 27.3 MB).
fn reserve_with_headroom<T>(list: &mut Vec<T>, needed: usize) {
    if list.capacity() < needed {
        list.reserve_exact(needed + needed / 8);
    }
}

/// A candidate pair as one sortable number: gap, then first grain's offset in its chunk,
/// then partner.
#[inline]
fn pair_key(gap: u16, local: usize, partner: u32) -> u64 {
    (u64::from(gap) << 40) | ((local as u64) << 32) | u64::from(partner)
}

/// Gap quanta per skin in [`CandidateChunk::gap`].
pub const GAP_UNITS: f64 = 65_535.0;

/// Candidate pairs of the last build and what they were built from.
#[derive(Resource, Default)]
pub struct NeighbourList {
    /// Skin beyond the reach, m (set at each build from the largest radius).
    pub skin: f64,
    /// Candidate partners, per chunk of [`CHUNK`] grains.
    pub chunks: Vec<CandidateChunk>,
    /// The snapshot layout ([`GrainSnapshot::layout`]) of the last build (0: none).
    layout: u32,
    /// Number of builds so far.
    pub builds: u64,
    /// Lees–Edwards image offset at the last build, m (0 without shear).
    offset: f64,
    /// Twice the bound D on the whole packing's moves since the build, m, as found by the
    /// last staleness check: how much any pair's distance can have shrunk, less the change
    /// of the Lees–Edwards offset.
    packing_closing: f64,
    /// The change of the Lees–Edwards offset since the build, m (0 without shear).
    shift: f64,
}

impl NeighbourList {
    /// Forces a rebuild at the next broad phase (the result must not change: the list is
    /// only a superset of the touching pairs).
    pub fn invalidate(&mut self) {
        self.layout = 0;
    }

    /// Whether the list must be rebuilt: first use, a changed set or order of grains or
    /// walls (the snapshot's layout), or grains that moved, about their common drift, more
    /// than half the skin ([`GrainSnapshot::move_bound_sq`]). When it need not, sets
    /// [`Self::packing_closing`] and [`Self::shift`] for this step.
    fn stale(&mut self, s: &GrainSnapshot) -> bool {
        if self.layout != s.layout {
            return true;
        }
        // Across a Lees–Edwards seam a pair's separation also changes with the image
        // offset: exact as long as 2D + |change of Δ| stays within the skin (D the bound on
        // the grains' moves).
        let mut shift = 0.0;
        if let Some(b) = s.periodic()
            && let Some(shear) = &b.shear
        {
            let lf = b.length()[shear.flow];
            shift = (shear.offset - self.offset).abs();
            if shift > 0.5 * lf {
                shift = lf - shift;
            }
        }
        let half = 0.5 * (self.skin - shift);
        if half <= 0.0 {
            return true;
        }
        // Found while the snapshot was gathered (against the positions marked at the
        // last build); infinite when the grains changed since.
        let bound_sq = s.move_bound_sq();
        if bound_sq > half * half {
            return true;
        }
        self.packing_closing = 2.0 * bound_sq.sqrt();
        self.shift = shift;
        false
    }

    /// The gap quantum below which a candidate pair closing by at most `closing` may be
    /// within reach. One quantum of margin covers the rounding of the gaps.
    fn quanta(&self, closing: f64) -> u16 {
        if self.skin > 0.0 {
            ((closing / self.skin * GAP_UNITS).ceil() + 1.0).min(GAP_UNITS) as u16
        } else {
            u16::MAX
        }
    }

    /// The gap quantum below which a candidate pair of chunk `chunk` may be within reach
    /// this step, `s` the step's snapshot: pairs whose [`CandidateChunk::gap`] is larger
    /// are not, and need no distance test. A chunk's pairs can have closed by at most the
    /// largest bound of its block's moves with its own and its partners' blocks
    /// ([`BlockMoves::pair_bound`](talus_core::snapshot::BlockMoves::pair_bound)), never more than the packing's bound, which also
    /// holds. Computed by the narrow phase chunk by chunk, in its parallel pass.
    pub fn gap_threshold(&self, chunk: usize, s: &GrainSnapshot) -> u16 {
        let blocks = s.block_moves().filter(|b| b.len() == self.chunks.len());
        let (Some(blocks), Some(candidates)) = (blocks, self.chunks.get(chunk)) else {
            return self.quanta(self.packing_closing + self.shift);
        };
        let own = &blocks[chunk];
        let mut closing = own.pair_bound(own);
        for &b in &candidates.partner_blocks {
            if closing >= self.packing_closing {
                break;
            }
            closing = closing.max(own.pair_bound(&blocks[b as usize]));
        }
        self.quanta(closing.min(self.packing_closing) + self.shift)
    }
}

/// The gap of a candidate pair at distance² `dist_sq` and reach `reach` (without the skin),
/// in quanta of the skin, rounded down.
#[inline]
fn gap_quanta(dist_sq: f64, reach: f64, skin: f64) -> u16 {
    let gap = dist_sq.sqrt() - reach;
    if gap > 0.0 && skin > 0.0 {
        (gap / skin * GAP_UNITS).floor().min(GAP_UNITS) as u16
    } else {
        0
    }
}

/// Broad phase: rebuilds the cell grid and the candidate pairs when the list is stale.
pub fn update_neighbour_list(
    mut snapshot: ResMut<GrainSnapshot>,
    mut grid: ResMut<CellGrid>,
    mut list: ResMut<NeighbourList>,
) {
    let s = &*snapshot;
    if !list.bypass_change_detection().stale(s) {
        return;
    }
    let skin = SKIN_FRACTION * 2.0 * s.max_radius;
    list.skin = skin;
    let range = grid.interaction_range;
    grid.rebuild_with_margin(s, skin);
    let grid = &*grid;
    let n = s.len();
    let chunks = n.div_ceil(CHUNK);
    let list = &mut *list;
    if list.chunks.len() < chunks {
        list.chunks.resize_with(chunks, CandidateChunk::default);
    }
    list.chunks.truncate(chunks);
    // One chunk a job (some 100 µs each at 32,000 grains): with rayon's adaptive split,
    // a thread runs a run of chunks it took without letting go of any, and the other
    // thread could wait through several of them at the end.
    list.chunks
        .par_iter_mut()
        .enumerate()
        .with_max_len(1)
        .for_each(|(chunk, out)| {
            let (mut keys, mut scratch): (Vec<u64>, Vec<u64>) = (Vec::new(), Vec::new());
            let mut pairs: Vec<(u32, u16)> = Vec::new();
            let mut after: Vec<u32> = Vec::new();
            let base = chunk * CHUNK;
            // (Only used where the box is not sheared.)
            let image = NearestImage::default().lanes();
            let image = if s.is_sheared() {
                image
            } else {
                s.image_lanes()
            };
            let reader = s.reader();
            for i in base..(base + CHUNK).min(n) {
                let p = s.position(i);
                let c = grid.coords(p);
                if let Some(b) = s.periodic()
                    && let Some(shear) = &b.shear
                {
                    pairs.clear();
                    sheared_candidates(s, grid, b, shear, i, c, range, skin, &mut pairs);
                    keys.extend(pairs.iter().map(|&(j, gap)| pair_key(gap, i - base, j)));
                    continue;
                }
                let [xs, ys, zs] = [0, 1, 2].map(|a| grid.neighbour_cells(c, a));
                // Cells next to each other along x are next to each other in the grid's
                // sorted grains: each row of the stencil is one or two runs of grains.
                // The grains after i in those runs (without a branch per grain, which
                // half of them would mispredict) are then tested four at a time.
                let (runs, run_count) = x_runs(xs.cells());
                let mut spans = [(0usize, 0usize); 18];
                let mut span_count = 0;
                let mut total = 0;
                for &cz in zs.cells() {
                    for &cy in ys.cells() {
                        let row = grid.index([0, cy, cz]);
                        for &(first, last) in &runs[..run_count] {
                            let span = grid.cells_span(row + first, row + last);
                            total += span.1 - span.0;
                            spans[span_count] = span;
                            span_count += 1;
                        }
                    }
                }
                after.resize(total.max(after.len()), 0);
                let mut count = 0;
                for &(start, end) in &spans[..span_count] {
                    for &j in &grid.sorted[start..end] {
                        after[count] = j;
                        count += usize::from(j as usize > i);
                    }
                }
                candidates_after(
                    s,
                    &reader,
                    &image,
                    i,
                    &after[..count],
                    range,
                    skin,
                    |j, gap| {
                        keys.push(pair_key(gap, i - base, j));
                    },
                );
            }
            out.fill(&mut keys, &mut scratch);
        });
    list.layout = s.layout;
    list.offset = s
        .periodic()
        .and_then(|b| b.shear)
        .map_or(0.0, |shear| shear.offset);
    list.builds += 1;
    list.packing_closing = 0.0;
    list.shift = 0.0;
    snapshot.bypass_change_detection().mark_move_reference();
}

/// The runs of consecutive cells among a stencil's cells along one axis (sorted, or
/// wrapped around a periodic axis: `[n − 1, 0, 1]`), as (first, last) pairs, and how
/// many there are (one or two).
#[inline]
fn x_runs(cells: &[usize]) -> ([(usize, usize); 3], usize) {
    let mut runs = [(cells[0], cells[0]); 3];
    let mut k = 0;
    for &c in &cells[1..] {
        if runs[k].1 + 1 == c {
            runs[k].1 = c;
        } else {
            k += 1;
            runs[k] = (c, c);
        }
    }
    (runs, k + 1)
}

/// The grains among `after` (dense indices, each above `i`) within reach + skin of grain
/// `i`, each handed to `found` with its gap quanta; four at a time, in a box without a
/// sheared seam. The same test, bit for bit, as one pair at a time.
#[inline]
#[allow(clippy::too_many_arguments)]
fn candidates_after(
    s: &GrainSnapshot,
    grains: &GrainReader,
    image: &ImageLanes,
    i: usize,
    after: &[u32],
    range: f64,
    skin: f64,
    mut found: impl FnMut(u32, u16),
) {
    let (p, r) = (V4::splat(s.position(i)), F4::splat(s.radius(i)));
    let (range4, skin4) = (F4::splat(range), F4::splat(skin));
    let mut test = |j: [u32; 4], live: u32| {
        let b = grains.gather4(j.map(|j| j as usize));
        let reach = r + b.radius + range4;
        let dist_sq = image.apply(p - b.position).length_squared();
        let limit = reach + skin4;
        let mut near = dist_sq.lt(limit * limit).bits() & live;
        if near == 0 {
            return;
        }
        let (dist_sq, reach) = (dist_sq.to_array(), reach.to_array());
        while near != 0 {
            let l = near.trailing_zeros() as usize;
            found(j[l], gap_quanta(dist_sq[l], reach[l], skin));
            near &= near - 1;
        }
    };
    let batches = after.chunks_exact(4);
    let rest = batches.remainder();
    for batch in batches {
        test(batch.try_into().expect("four grains"), 0xF);
    }
    if !rest.is_empty() {
        // The last grains, with the first of them repeated in the lanes left over.
        test(
            std::array::from_fn(|l| rest[l.min(rest.len() - 1)]),
            (1 << rest.len()) - 1,
        );
    }
}

/// Candidate partners j > i of grain `i` (in cell `c`) in a Lees–Edwards box, with their
/// gaps: the plain stencil along the third axis and the gradient axis, and along the flow
/// axis the cells of [`CellGrid::sheared_flow_cells`], which follow the shifted seam.
#[allow(clippy::too_many_arguments)]
fn sheared_candidates(
    s: &GrainSnapshot,
    grid: &CellGrid,
    b: &PeriodicBox,
    shear: &LeesEdwards,
    i: usize,
    c: [usize; 3],
    range: f64,
    skin: f64,
    out: &mut Vec<(u32, u16)>,
) {
    let (g, f) = (shear.gradient, shear.flow);
    let third = 3 - g - f;
    let p = s.position(i);
    let r = s.radius(i);
    let gs = grid.neighbour_cells(c, g);
    let ts = grid.neighbour_cells(c, third);
    for &cg in gs.cells() {
        let fs = grid.sheared_flow_cells(b, shear, p, c, cg);
        for &ct in ts.cells() {
            for &cf in fs.cells() {
                let mut cell = [0; 3];
                cell[g] = cg;
                cell[f] = cf;
                cell[third] = ct;
                for &j in grid.cell_grains(grid.index(cell)) {
                    if (j as usize) <= i {
                        continue;
                    }
                    let reach = r + s.radius(j as usize) + range;
                    let dist_sq = s.separation(p, s.position(j as usize)).length_squared();
                    if dist_sq < (reach + skin) * (reach + skin) {
                        out.push((j, gap_quanta(dist_sq, reach, skin)));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pair keys of chunk 0 whose partners come in runs of the same block, the runs in no
    /// order and some blocks met twice: `pairs` pairs over `blocks` blocks.
    fn keys_over_blocks(pairs: usize, blocks: u32) -> Vec<u64> {
        (0..pairs)
            .map(|p| {
                let block = (p as u32 / 7 * 37 + 11) % blocks + 1;
                let partner = block * CHUNK as u32 + p as u32 % CHUNK as u32;
                pair_key((p % 5) as u16, p % CHUNK, partner)
            })
            .collect()
    }

    #[test]
    fn partner_blocks_are_the_partners_blocks_sorted_once_each() {
        let mut chunk = CandidateChunk::default();
        let mut keys = keys_over_blocks(1_000, 40);
        chunk.fill(&mut keys, &mut Vec::new());
        let mut expected: Vec<u32> = chunk.partner.iter().map(|&j| j / CHUNK as u32).collect();
        expected.sort_unstable();
        expected.dedup();
        assert_eq!(chunk.partner_blocks.as_slice(), expected.as_slice());
        assert_eq!(expected.len(), 40);
    }

    #[test]
    fn a_chunk_of_many_pairs_over_few_blocks_keeps_its_blocks_inline() {
        // The list of blocks is a chunk's for as long as the run lasts: gathering one entry
        // per pair before deduplicating moved it to the heap for good (8 MB at 512,000
        // grains), though a chunk's partners lie in a few dozen blocks.
        let mut chunk = CandidateChunk::default();
        let mut keys = keys_over_blocks(1_000, 12);
        chunk.fill(&mut keys, &mut Vec::new());
        assert_eq!(chunk.partner_blocks.len(), 12);
        assert!(!chunk.partner_blocks.spilled());
    }
}
