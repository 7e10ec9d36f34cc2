//! The dense per-step snapshot of grains and walls that the hot loops read.
//!
//! Grain entities stay the source of truth; at the start of the broad phase their
//! state is copied, in table order, into flat arrays. Collision detection and contact
//! laws index those arrays, never the world, so the force loop needs neither hashing nor
//! entity look-ups. Between two steps that nothing observes the arrays hold the grains'
//! motion in place of their components, written back before anything looks
//! ([`crate::resources::DeferredKick::snapshot_holds_motion`]). (A subdomain's ghost
//! grains would be appended here.)

use bevy_ecs::prelude::*;
use glam::DVec3;
use rayon::prelude::*;
use smallvec::SmallVec;

use crate::components::*;
use crate::lanes::{F4, V4};
use crate::periodic::WrapRule;

/// Marker for "no dense index".
pub const NO_INDEX: u32 = u32::MAX;

/// A wall as the hot loops see it.
#[derive(Clone, Copy, Debug)]
pub struct WallState {
    /// The wall entity.
    pub entity: Entity,
    /// A point on the plane.
    pub point: DVec3,
    /// Unit outward normal.
    pub normal: DVec3,
    /// Prescribed velocity.
    pub velocity: DVec3,
    /// Material id.
    pub material: u16,
}

/// The state of one grain that the hot loops read together: position, radius, velocity
/// and inverse mass in 64 bytes, one cache line (the array is aligned to lines). A loop
/// that reaches a grain out of order (a contact's partner, a candidate pair's) then waits
/// for one line, not for one line or two in each of four arrays.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub struct GrainRecord {
    /// Centre position.
    pub position: DVec3,
    /// Radius.
    pub radius: f64,
    /// Velocity (the half-step velocity under velocity Verlet).
    pub velocity: DVec3,
    /// Inverse mass 1/m (0 for a frozen grain).
    pub inverse_mass: f64,
}

/// The snapshot's grain arrays, all of one length ([`GrainSnapshot::reader`]).
#[derive(Clone, Copy, Debug)]
pub struct GrainReader<'a> {
    records: &'a [GrainRecord],
    omega: &'a [DVec3],
}

impl GrainReader<'_> {
    /// The state of four grains (dense indices `i`), one per lane. Panics if an index is
    /// out of range (one test for the four, not one at each of their reads).
    #[inline(always)]
    pub fn gather4(&self, i: [usize; 4]) -> GrainLanes {
        let n = self.records.len();
        assert!(
            i[0].max(i[1]).max(i[2].max(i[3])) < n,
            "grain index out of the snapshot"
        );
        // SAFETY: every index is below `n`, the length of both arrays read (`reader` cut
        // them to it).
        let record = |k: usize| unsafe { self.records.get_unchecked(i[k]) };
        GrainLanes {
            position: V4::from_fn(|k| record(k).position),
            velocity: V4::from_fn(|k| record(k).velocity),
            omega: V4::from_fn(|k| unsafe { *self.omega.get_unchecked(i[k]) }),
            radius: F4::from_fn(|k| record(k).radius),
            inverse_mass: F4::from_fn(|k| record(k).inverse_mass),
        }
    }
}

/// The snapshot's state of four grains, one per lane ([`GrainReader::gather4`]).
#[derive(Clone, Copy, Debug)]
pub struct GrainLanes {
    /// Centre positions.
    pub position: V4,
    /// Velocities.
    pub velocity: V4,
    /// Angular velocities.
    pub omega: V4,
    /// Radii.
    pub radius: F4,
    /// Inverse masses.
    pub inverse_mass: F4,
}

/// Dense arrays of grain and wall state for the current step.
#[derive(Resource, Clone, Debug, Default)]
pub struct GrainSnapshot {
    /// Grain entities, in dense order.
    pub entity: Vec<Entity>,
    /// Positions, radii, velocities (half-step velocities under velocity Verlet) and
    /// inverse masses 1/m (0 for a frozen grain: the reduced mass of a pair is
    /// 1/(1/m_a + 1/m_b), one division instead of three), one cache line per grain.
    pub records: Vec<GrainRecord>,
    /// Angular velocities.
    pub omega: Vec<DVec3>,
    /// Material ids.
    pub material: Vec<u16>,
    /// Dense index of each grain, indexed by `Entity::index_u32()`; [`NO_INDEX`] elsewhere.
    pub dense_of: Vec<u32>,
    /// Walls.
    pub walls: Vec<WallState>,
    /// Largest grain radius.
    pub max_radius: f64,
    /// Identifies the dense order of grains and the list of walls: it changes (never to 0)
    /// whenever either changes, so dense indices taken at an earlier step stay valid while
    /// it is the same.
    pub layout: u32,
    /// The periodic box, when the scene has one: pair separations take its nearest image.
    /// Private so that it changes only with its precomputed rule ([`Self::set_periodic`]).
    periodic: Option<crate::periodic::PeriodicBox>,
    /// The nearest-image rule of `periodic` when it is not sheared (no periodic axis
    /// otherwise): [`Self::separation`] applies it to every candidate pair.
    image: crate::periodic::NearestImage,
    /// Grain positions at the last [`Self::mark_move_reference`] (empty: none).
    move_reference: Vec<DVec3>,
    /// The grains' displacements since the last mark, as of the last gather: see
    /// [`Self::move_bound_sq`].
    moves: Moves,
    /// The same for each block of [`MOVE_BLOCK`] consecutive grains (empty when no
    /// reference applies): see [`Self::block_moves`].
    block_moves: Vec<BlockMoves>,
    /// The blocks' moves as [`gather_snapshot`] merges them (scratch, kept for its
    /// allocation).
    block_scratch: Vec<Moves>,
    /// Whether this pass's first kick and drift of the held records
    /// ([`Self::kick_drift_held`]) also wrapped them and took their moves, which the broad
    /// phase then leaves as they are.
    moves_taken: bool,
    /// What each chunk of [`gather_snapshot`]'s copy found (scratch, kept for its
    /// allocation).
    chunk_scratch: Vec<ChunkMoves>,
}

impl GrainSnapshot {
    /// Number of grains.
    pub fn len(&self) -> usize {
        self.entity.len()
    }

    /// Whether there are no grains.
    pub fn is_empty(&self) -> bool {
        self.entity.is_empty()
    }

    /// Centre position of grain `i` (dense index).
    #[inline(always)]
    pub fn position(&self, i: usize) -> DVec3 {
        self.records[i].position
    }

    /// Radius of grain `i`.
    #[inline(always)]
    pub fn radius(&self, i: usize) -> f64 {
        self.records[i].radius
    }

    /// Velocity of grain `i`.
    #[inline(always)]
    pub fn velocity(&self, i: usize) -> DVec3 {
        self.records[i].velocity
    }

    /// Inverse mass of grain `i` (0 for a frozen grain).
    #[inline(always)]
    pub fn inverse_mass(&self, i: usize) -> f64 {
        self.records[i].inverse_mass
    }

    /// Dense index of a grain entity, if it is in the snapshot.
    #[inline]
    pub fn dense(&self, entity: Entity) -> Option<usize> {
        let i = *self.dense_of.get(entity.index_u32() as usize)?;
        (i != NO_INDEX && self.entity[i as usize] == entity).then_some(i as usize)
    }

    /// The periodic box, when the scene has one.
    #[inline]
    pub fn periodic(&self) -> Option<&crate::periodic::PeriodicBox> {
        self.periodic.as_ref()
    }

    /// Sets the periodic box (or none) and its precomputed nearest-image rule.
    pub fn set_periodic(&mut self, periodic: Option<crate::periodic::PeriodicBox>) {
        self.periodic = periodic;
        self.image = periodic.and_then(|b| b.nearest_image()).unwrap_or_default();
    }

    /// Records the grains' current positions as the reference of
    /// [`Self::move_bound_sq`] (the neighbour list does at each build).
    pub fn mark_move_reference(&mut self) {
        self.move_reference.clear();
        self.move_reference.par_extend(
            self.records
                .par_iter()
                .with_min_len(COPY_CHUNK)
                .map(|g| g.position),
        );
        self.moves = Moves::still();
        self.block_moves.clear();
        self.block_moves
            .resize(self.len().div_ceil(MOVE_BLOCK), BlockMoves::default());
    }

    /// D², m², for a distance D such that every grain's displacement Δ since the last
    /// [`Self::mark_move_reference`] (nearest image) lies within D of one common vector U,
    /// as of the last [`gather_snapshot`]: the separation of any two grains has then
    /// changed by at most |Δ_i − Δ_j| ≤ 2D. D is the smaller of the largest |Δ| (U = 0)
    /// and the half diagonal of the box that bounds every Δ (U its centre), so a packing
    /// that moves as a whole, or a flow whose displacements span a range away from zero
    /// (a chute's layers over a still base), counts only the spread of its moves. Found
    /// while the positions are copied, so the neighbour list's staleness test needs no
    /// pass over the grains of its own. Infinite when no reference applies (none marked,
    /// or grains added, removed or reordered since).
    #[inline]
    pub fn move_bound_sq(&self) -> f64 {
        if self.move_reference.is_empty() {
            f64::INFINITY
        } else {
            self.moves.bound_sq()
        }
    }

    /// The moves since the last [`Self::mark_move_reference`] of each block of
    /// [`MOVE_BLOCK`] consecutive grains in dense order (block `b` holds grains
    /// `b * MOVE_BLOCK..`), as of the last [`gather_snapshot`]; `None` when no reference
    /// applies. Grains near each other in dense order are near each other in space (the
    /// scene sorts them along a space-filling curve), so a block's moves span far less
    /// than the whole packing's in a shear flow: a pair of grains of two blocks has
    /// changed its separation by at most [`BlockMoves::pair_bound`] of the two.
    #[inline]
    pub fn block_moves(&self) -> Option<&[BlockMoves]> {
        (!self.move_reference.is_empty()
            && self.block_moves.len() == self.len().div_ceil(MOVE_BLOCK))
        .then_some(&self.block_moves[..])
    }

    /// Separation p_a − p_b of two positions, the nearest image in a periodic box.
    // Always inlined: it runs for every candidate pair and every grain's staleness check,
    // and a call costs as much as the arithmetic.
    #[inline(always)]
    pub fn separation(&self, a: DVec3, b: DVec3) -> DVec3 {
        nearest_separation(&self.periodic, &self.image, a - b)
    }

    /// Whether the periodic box is sheared (Lees–Edwards): then a pair's separation and
    /// relative velocity depend on the seam it crosses, which only the scalar
    /// [`Self::separation_and_image_velocity`] handles.
    #[inline]
    pub fn is_sheared(&self) -> bool {
        self.periodic.is_some_and(|b| b.shear.is_some())
    }

    /// The nearest-image rule of [`Self::separation`] in four lanes, for a box that is
    /// not sheared ([`Self::is_sheared`]): `image.apply(a − b)` is the separation of four
    /// pairs at once, bit for bit (the image velocity is then zero). Make it once before
    /// a loop.
    #[inline(always)]
    pub fn image_lanes(&self) -> crate::periodic::ImageLanes {
        debug_assert!(!self.is_sheared());
        self.image.lanes()
    }

    /// Separation p_a − p_b (nearest image) and the velocity of that image of b beyond
    /// b's own: nonzero only across a Lees–Edwards gradient seam. The pair's relative
    /// velocity is v_a − v_b − (the image velocity).
    #[inline]
    pub fn separation_and_image_velocity(&self, a: DVec3, b: DVec3) -> (DVec3, DVec3) {
        match &self.periodic {
            Some(box_) if box_.shear.is_some() => box_.min_image_with_velocity(a - b),
            _ => (self.image.apply(a - b), DVec3::ZERO),
        }
    }

    /// Asks the processor to bring grain `i`'s state (its record and its spin) into the
    /// cache, without waiting for it: a loop that will read grains in an order the
    /// hardware cannot guess (a contact's partners) calls this a few iterations ahead.
    /// Does nothing for an index out of range, and nothing off x86-64.
    #[inline(always)]
    pub fn prefetch(&self, i: usize) {
        if i < self.records.len() {
            prefetch_address(self.records.as_ptr().wrapping_add(i));
            prefetch_address(self.omega.as_ptr().wrapping_add(i));
        }
    }

    /// The grain arrays the lane forms of the hot loops read, checked once to be of one
    /// length: make it once before a loop that gathers four grains at a time
    /// ([`GrainReader::gather4`]).
    #[inline(always)]
    pub fn reader(&self) -> GrainReader<'_> {
        let n = self.records.len();
        GrainReader {
            records: &self.records[..n],
            omega: &self.omega[..n],
        }
    }

    /// Index of a wall entity in [`GrainSnapshot::walls`].
    pub fn wall_index(&self, entity: Entity) -> Option<usize> {
        self.walls.iter().position(|w| w.entity == entity)
    }
}

/// Grains per block of [`GrainSnapshot::block_moves`] (the neighbour list's chunks of grains
/// are these blocks).
pub const MOVE_BLOCK: usize = 256;

/// How far the grains of one block moved since the reference
/// ([`GrainSnapshot::block_moves`]): every displacement Δ of the block lies within
/// `largest` of zero and within `spread` of `centre`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BlockMoves {
    /// Centre of the box that bounds the block's displacements, m.
    pub centre: DVec3,
    /// Half the diagonal of that box, m.
    pub spread: f64,
    /// Largest |Δ| of the block, m.
    pub largest: f64,
}

impl BlockMoves {
    /// A bound on |Δ_i − Δ_j| for any grain i of this block and j of `other` (the same
    /// block or another), hence on how much their separation has changed since the
    /// reference: the smaller of |Δ_i| + |Δ_j| and, by the triangle inequality through
    /// the two centres, the two spreads plus the distance between the centres.
    #[inline]
    pub fn pair_bound(&self, other: &Self) -> f64 {
        let through_zero = self.largest + other.largest;
        let through_centres = self.spread + other.spread + (self.centre - other.centre).length();
        through_zero.min(through_centres)
    }
}

/// The grains' displacements since a reference: the largest length, and the box that
/// bounds them ([`GrainSnapshot::move_bound_sq`]).
#[derive(Clone, Copy, Debug)]
struct Moves {
    /// Largest |Δ|², m².
    largest_sq: f64,
    /// Componentwise least Δ, m (+∞ with no grain).
    low: DVec3,
    /// Componentwise greatest Δ, m (−∞ with no grain).
    high: DVec3,
}

impl Default for Moves {
    fn default() -> Self {
        Self::still()
    }
}

impl Moves {
    /// No displacement yet.
    fn still() -> Self {
        Self {
            largest_sq: 0.0,
            low: DVec3::splat(f64::INFINITY),
            high: DVec3::splat(f64::NEG_INFINITY),
        }
    }

    /// Adds one grain's displacement. A NaN displacement is left out, as `f64::max` and
    /// `f64::min` would leave it (the health check stops such a run), but the comparisons
    /// are single instructions: each of the seven running extremes is a chain through
    /// every grain of a block, and NaN-aware minima and maxima lengthen its every link.
    #[inline(always)]
    fn add(&mut self, d: DVec3) {
        let larger = |a: f64, b: f64| if b > a { b } else { a };
        let smaller = |a: f64, b: f64| if b < a { b } else { a };
        self.largest_sq = larger(self.largest_sq, d.length_squared());
        self.low = DVec3::new(
            smaller(self.low.x, d.x),
            smaller(self.low.y, d.y),
            smaller(self.low.z, d.z),
        );
        self.high = DVec3::new(
            larger(self.high.x, d.x),
            larger(self.high.y, d.y),
            larger(self.high.z, d.z),
        );
    }

    /// Both sets of displacements.
    fn merge(self, other: Self) -> Self {
        Self {
            largest_sq: self.largest_sq.max(other.largest_sq),
            low: self.low.min(other.low),
            high: self.high.max(other.high),
        }
    }

    /// D² of [`GrainSnapshot::move_bound_sq`]. With no grain the box is empty, its half
    /// diagonal infinite, and the bound the largest move, 0.
    fn bound_sq(&self) -> f64 {
        let half_diagonal_sq = (0.5 * (self.high - self.low)).length_squared();
        self.largest_sq.min(half_diagonal_sq)
    }

    /// The same moves as a [`BlockMoves`] (no move at all for no grain).
    fn block(&self) -> BlockMoves {
        if self.low.x > self.high.x {
            return BlockMoves::default();
        }
        BlockMoves {
            centre: 0.5 * (self.low + self.high),
            spread: (0.5 * (self.high - self.low)).length(),
            largest: self.largest_sq.sqrt(),
        }
    }
}

/// The nearest image of the difference `d` of two positions ([`GrainSnapshot::separation`]).
#[inline(always)]
fn nearest_separation(
    periodic: &Option<crate::periodic::PeriodicBox>,
    image: &crate::periodic::NearestImage,
    d: DVec3,
) -> DVec3 {
    match periodic {
        Some(box_) if box_.shear.is_some() => box_.min_image(d),
        _ => image.apply(d),
    }
}

/// Asks the processor to bring the cache line holding `address` into the cache, without
/// waiting. A hint only: nothing is read or written, and no address faults. Does nothing
/// off x86-64. Every prefetch of the hot loops goes through this.
#[inline(always)]
pub fn prefetch_address<T>(address: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch reads and writes nothing and does not fault, whatever the
    // address; the intrinsic is unsafe only for its target feature, which x86-64 has.
    unsafe {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        _mm_prefetch::<_MM_HINT_T0>(address.cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

/// Asks the processor to bring the cache line of `data[i]` into the cache, without
/// waiting: for a loop that will read or update items in an order the hardware cannot
/// guess. Does nothing for an index out of range.
#[inline(always)]
pub fn prefetch_item<T>(data: &[T], i: usize) {
    if let Some(item) = data.get(i) {
        prefetch_address(item);
    }
}

/// Asks for a few slices' cache lines a few at a time, spread over a loop's iterations
/// ([`Self::step`]): for data the loop after this one will read in an order the hardware
/// cannot guess. (Asking for all of it at once would overflow the processor's queue of
/// outstanding misses.)
pub struct LinePrefetcher {
    ranges: Vec<(*const i8, usize)>,
    range: usize,
    offset: usize,
}

// SAFETY: the pointers are only given to prefetch hints, which read nothing.
unsafe impl Send for LinePrefetcher {}

impl LinePrefetcher {
    /// A prefetcher over nothing yet.
    pub fn new() -> Self {
        Self {
            ranges: Vec::new(),
            range: 0,
            offset: 0,
        }
    }

    /// Adds a slice to ask for, after those added before.
    pub fn add<T>(&mut self, data: &[T]) {
        self.ranges
            .push((data.as_ptr().cast(), std::mem::size_of_val(data)));
    }

    /// Asks for the next `lines` cache lines (none once every slice is asked for).
    #[inline]
    pub fn step(&mut self, lines: usize) {
        for _ in 0..lines {
            let Some(&(start, len)) = self.ranges.get(self.range) else {
                return;
            };
            if self.offset >= len {
                self.range += 1;
                self.offset = 0;
                continue;
            }
            prefetch_address(start.wrapping_add(self.offset));
            self.offset += 64;
        }
    }
}

impl Default for LinePrefetcher {
    fn default() -> Self {
        Self::new()
    }
}

/// Grains per parallel work unit of the snapshot's copies.
const COPY_CHUNK: usize = 4096;

/// Copies one component's values into a snapshot array, in parallel chunks.
fn copy_column<T: Sync, U: Send>(dst: &mut [U], src: &[T], value: impl Fn(&T) -> U + Sync) {
    // Chunks, each a plain loop: rayon's per-item plumbing costs more than a copy.
    dst.par_chunks_mut(COPY_CHUNK)
        .zip(src.par_chunks(COPY_CHUNK))
        .for_each(|(d, x)| {
            for (d, x) in d.iter_mut().zip(x) {
                *d = value(x);
            }
        });
}

/// What one chunk of [`gather_snapshot`]'s copy found: its largest radius and the moves of
/// each block of grains (by index) it holds a part of (a chunk of `COPY_CHUNK` grains not
/// aligned on the blocks touches `COPY_CHUNK / MOVE_BLOCK + 1` of them; more spill to the
/// heap).
type ChunkMoves = (f64, SmallVec<[(usize, Moves); 20]>);

/// Four running sets of [`Moves`], one per lane of four grains' displacements.
struct MovesLanes {
    largest_sq: F4,
    low: V4,
    high: V4,
}

impl MovesLanes {
    /// No displacement yet.
    #[inline(always)]
    fn still() -> Self {
        Self {
            largest_sq: F4::zero(),
            low: V4::splat(DVec3::splat(f64::INFINITY)),
            high: V4::splat(DVec3::splat(f64::NEG_INFINITY)),
        }
    }

    /// Adds four displacements, one a lane, with [`Moves::add`]'s comparisons.
    #[inline(always)]
    fn add(&mut self, d: V4) {
        let larger = |a: F4, b: F4| b.gt(a).select(b, a);
        let smaller = |a: F4, b: F4| b.lt(a).select(b, a);
        self.largest_sq = larger(self.largest_sq, d.length_squared());
        self.low = V4 {
            x: smaller(self.low.x, d.x),
            y: smaller(self.low.y, d.y),
            z: smaller(self.low.z, d.z),
        };
        self.high = V4 {
            x: larger(self.high.x, d.x),
            y: larger(self.high.y, d.y),
            z: larger(self.high.z, d.z),
        };
    }

    /// The four lanes' moves merged into one set.
    #[inline(always)]
    fn merged(&self) -> Moves {
        let (largest, low, high) = (
            self.largest_sq.to_array(),
            self.low.to_array(),
            self.high.to_array(),
        );
        (0..4).fold(Moves::still(), |all, l| {
            all.merge(Moves {
                largest_sq: largest[l],
                low: low[l],
                high: high[l],
            })
        })
    }
}

/// A chunk of one table's grains whose moves since the reference are to be taken: the
/// grains `from..from + positions.len()` of the table that starts at dense index
/// `table_start`, `reference` the table's part of the reference positions.
struct MovedChunk<'a, T> {
    table_start: usize,
    from: usize,
    positions: &'a [T],
    reference: &'a [DVec3],
}

impl<T> MovedChunk<'_, T> {
    /// The moves of each block of grains (by dense index) this chunk holds a part of (a
    /// table need not start at a block's start), `position` reading an element's position.
    #[inline(always)]
    fn block_moves(
        &self,
        position: impl Fn(&T) -> DVec3,
        periodic_box: &Option<crate::periodic::PeriodicBox>,
        image: &crate::periodic::NearestImage,
    ) -> SmallVec<[(usize, Moves); 20]> {
        let (chunk_start, to) = (self.from, self.from + self.positions.len());
        let mut blocks = SmallVec::new();
        let mut from = chunk_start;
        while from < to {
            let block = (self.table_start + from) / MOVE_BLOCK;
            let end = ((block + 1) * MOVE_BLOCK - self.table_start).min(to);
            let positions = &self.positions[from - chunk_start..end - chunk_start];
            let reference = &self.reference[from..end];
            let mut moves = Moves::still();
            let mut tail = 0;
            if periodic_box.is_none_or(|b| b.shear.is_none()) {
                // Four grains at a time in AVX lanes (the nearest image of the unsheared
                // rule, bit for bit), each lane a running set of extremes, merged at the
                // end: the extremes of the same moves, whatever their grouping.
                let rule = image.lanes();
                let mut lanes = MovesLanes::still();
                for (p, q) in positions.chunks_exact(4).zip(reference.chunks_exact(4)) {
                    let p = V4::from_fn(|l| position(&p[l]));
                    let q = V4::new([q[0], q[1], q[2], q[3]]);
                    lanes.add(rule.apply(p - q));
                }
                moves = lanes.merged();
                tail = positions.len() / 4 * 4;
            }
            for (p, q) in positions[tail..].iter().zip(&reference[tail..]) {
                moves.add(nearest_separation(periodic_box, image, position(p) - *q));
            }
            blocks.push((block, moves));
            from = end;
        }
        blocks
    }
}

/// Copies grain and wall state into the snapshot, reusing its allocations, and wraps the
/// grains' positions into an unsheared periodic box as it copies them (the drift, just
/// before, may have carried grains across a face; [`crate::periodic::PeriodicBox::wrapper`]).
#[allow(clippy::type_complexity)]
pub fn gather_snapshot(
    mut snapshot: ResMut<GrainSnapshot>,
    mut grains: Query<
        (
            Entity,
            &mut Position,
            &Velocity,
            &AngularVelocity,
            &Radius,
            &Mass,
            &MaterialId,
            Has<Frozen>,
        ),
        With<Grain>,
    >,
    walls: Query<(Entity, &Wall)>,
    periodic: Option<Res<crate::periodic::PeriodicBox>>,
    deferred: Option<Res<crate::resources::DeferredKick>>,
) {
    let s = &mut *snapshot;
    s.set_periodic(periodic.map(|p| *p));
    let moves_taken = std::mem::take(&mut s.moves_taken);
    if deferred.is_some_and(|d| d.snapshot_holds_motion) {
        // The first kick and the drift worked on the records in place
        // ([`GrainSnapshot::kick_drift_held`]): nothing to copy, and nothing more to do
        // when they also wrapped them and took their moves.
        if !moves_taken {
            s.refresh_held_motion();
        }
        gather_walls(s, &walls, false);
        return;
    }
    let n: usize = grains
        .contiguous_iter_mut()
        .expect("grain query is dense")
        .map(|(e, ..)| e.len())
        .sum();
    let mut reordered = s.entity.len() != n;
    s.entity.resize(n, Entity::PLACEHOLDER);
    s.records.resize(n, GrainRecord::default());
    s.omega.resize(n, DVec3::ZERO);
    s.material.resize(n, 0);
    // Each table's slice of every array is filled in parallel (plain copies: the result
    // does not depend on the thread count).
    let mut k = 0;
    s.max_radius = 0.0;
    // The moves since the reference are taken in the copy pass when the reference has one
    // position per grain (a reordering found below voids it).
    let track_moves = s.move_reference.len() == n;
    // The blocks' moves are merged in the snapshot's scratch list (no allocation a step).
    let mut block_moves = std::mem::take(&mut s.block_scratch);
    let mut chunk_results = std::mem::take(&mut s.chunk_scratch);
    block_moves.clear();
    if track_moves {
        block_moves.resize(n.div_ceil(MOVE_BLOCK), Moves::still());
    }
    let (periodic_box, image) = (s.periodic, s.image);
    // An unsheared box is wrapped here, each grain as the copy reads its position (a pass
    // of its own read every position once more); a sheared one was wrapped after the
    // drift, with the velocities.
    let wrap_box = periodic_box.filter(|b| b.shear.is_none());
    let wrap = wrap_box.as_ref().map(|b| b.wrapper());
    for (e, mut p, v, w, r, m, mat, frozen) in
        grains.contiguous_iter_mut().expect("grain query is dense")
    {
        let p = p.bypass_change_detection();
        let table_start = k;
        let range = k..k + e.len();
        k += e.len();
        let (entity, records, omega, material) = (
            &mut s.entity[range.clone()],
            &mut s.records[range.clone()],
            &mut s.omega[range.clone()],
            &mut s.material[range.clone()],
        );
        let reference: &[DVec3] = if track_moves {
            &s.move_reference[range]
        } else {
            &[]
        };
        chunk_results.clear();
        let ((), entities_changed) = rayon::join(
            || {
                // Chunks, each a plain loop: rayon's per-item plumbing costs more than a
                // copy. The largest radius and the moves are taken in the same
                // pass (a second pass would read every record again for one number).
                // Kept between steps for its allocation; extended in chunk order.
                let chunks = records
                    .par_chunks_mut(COPY_CHUNK)
                    .zip(p.par_chunks_mut(COPY_CHUNK));
                chunk_results.par_extend(chunks.enumerate().map(|(c, (records, positions))| {
                    let from = c * COPY_CHUNK;
                    let to = from + records.len();
                    let sources = positions
                        .iter_mut()
                        .zip(&r[from..to])
                        .zip(v[from..to].iter().zip(&m[from..to]));
                    // A frozen grain resists like an infinite mass (a zero inverse):
                    // a contact's reduced mass is then the moving grain's own (as
                    // LAMMPS does for frozen atoms). `Frozen` is a table component, so
                    // a table's grains are all frozen or none is.
                    let inverse_mass = |m: &Mass| if frozen { 0.0 } else { 1.0 / m.0 };
                    for (record, ((p, r), (v, m))) in records.iter_mut().zip(sources) {
                        if let Some(wrap) = &wrap {
                            wrap(&mut p.0);
                        }
                        *record = GrainRecord {
                            position: p.0,
                            radius: r.0,
                            velocity: v.0,
                            inverse_mass: inverse_mass(m),
                        };
                    }
                    let largest_radius = r[from..to]
                        .iter()
                        .fold(0.0, |largest, r| f64::max(largest, r.0));
                    let blocks = if track_moves {
                        let moved = MovedChunk {
                            table_start,
                            from,
                            positions,
                            reference,
                        };
                        moved.block_moves(|p| p.0, &periodic_box, &image)
                    } else {
                        SmallVec::new()
                    };
                    (largest_radius, blocks)
                }));
            },
            || {
                copy_column(omega, w, |x| x.0);
                copy_column(material, mat, |x| x.0);
                // Unchanged entities (the common case) need no copy; compared in
                // parallel chunks, since on one thread the comparison of a large
                // packing's entities would keep the other threads waiting.
                entity
                    .par_chunks_mut(COPY_CHUNK)
                    .zip(e.par_chunks(COPY_CHUNK))
                    .map(|(kept, now)| {
                        let changed = kept != now;
                        if changed {
                            kept.copy_from_slice(now);
                        }
                        changed
                    })
                    .reduce(|| false, |a, b| a || b)
            },
        );
        reordered |= entities_changed;
        // Maxima and minima: the same on any number of threads.
        for (largest_radius, blocks) in chunk_results.drain(..) {
            s.max_radius = s.max_radius.max(largest_radius);
            for (block, moves) in blocks {
                block_moves[block] = block_moves[block].merge(moves);
            }
        }
    }
    s.finish_moves(block_moves, chunk_results);
    if !track_moves || reordered {
        s.move_reference.clear();
    }
    if reordered {
        let max_index = s.entity.iter().map(|e| e.index_u32()).max().unwrap_or(0) as usize;
        s.dense_of.clear();
        s.dense_of.resize(max_index + 1, NO_INDEX);
        for (i, e) in s.entity.iter().enumerate() {
            s.dense_of[e.index_u32() as usize] = i as u32;
        }
    }
    gather_walls(s, &walls, reordered);
}

/// Copies the walls into the snapshot, and changes its layout when they or the grains
/// (`grains_reordered`) changed.
fn gather_walls(s: &mut GrainSnapshot, walls: &Query<(Entity, &Wall)>, grains_reordered: bool) {
    let walls_changed = s.walls.len() != walls.iter().len()
        || s.walls
            .iter()
            .zip(walls.iter())
            .any(|(old, (e, _))| old.entity != e);
    s.walls.clear();
    s.walls.extend(walls.iter().map(|(entity, wall)| WallState {
        entity,
        point: wall.point,
        normal: wall.normal,
        velocity: wall.velocity,
        material: wall.material.0,
    }));
    if grains_reordered || walls_changed {
        s.layout = s.layout.wrapping_add(1).max(1);
    }
}

/// One table of moving grains for [`GrainSnapshot::kick_drift_held`]: their entities,
/// forces and masses.
pub(crate) type HeldTable<'a> = (&'a [Entity], &'a [Force], &'a [Mass]);

impl GrainSnapshot {
    /// The dense indices of one table's grains, `entities` in the table's order (a gather
    /// copies whole tables in order, so a table's grains are consecutive in the snapshot);
    /// empty for an empty table.
    pub(crate) fn table_range(&self, entities: &[Entity]) -> std::ops::Range<usize> {
        let Some(first) = entities.first() else {
            return 0..0;
        };
        let start = self.dense_of[first.index_u32() as usize] as usize;
        let range = start..start + entities.len();
        debug_assert_eq!(&self.entity[range.clone()], entities);
        range
    }

    /// The first kick and the drift of the moving grains when the snapshot holds their
    /// motion ([`crate::resources::DeferredKick::snapshot_holds_motion`]): `update` kicks
    /// and drifts a chunk of records in place, given their forces and masses, and returns
    /// the work of gravity over their drifts, summed grain by grain in order. The
    /// tables are those of the last gather, whose grains are consecutive in the snapshot.
    /// Returns the work of gravity, per table the partial sums of the chunks of `chunk`
    /// grains summed in order from `parallel_from` grains up, one sum below: the sums
    /// the kick of the grains' components takes.
    ///
    /// Each record is also wrapped into an unsheared periodic box (`periodic`, this
    /// pass's box) by `update` itself, with the rule it is given, right after its drift
    /// (while the record is in a register, not in a second loop over the chunk), and each
    /// chunk's moves since the reference are then taken: all the broad phase does to held
    /// records ([`Self::refresh_held_motion`]), done here while the chunk is in cache, which
    /// saves a pass over every record (one more read and write of 64 bytes a grain). The
    /// grains the kick leaves alone (the frozen ones) are wrapped and measured in chunks of
    /// their own. The broad phase then takes the moves as they are.
    pub(crate) fn kick_drift_held<'a>(
        &mut self,
        moving: impl Iterator<Item = HeldTable<'a>>,
        chunking: (usize, usize),
        periodic: Option<crate::periodic::PeriodicBox>,
        update: impl Fn(&mut [GrainRecord], &[Force], &[Mass], Option<&WrapRule>) -> f64 + Sync,
    ) -> f64 {
        let work = self.update_wrap_and_measure(moving, chunking, periodic, update);
        self.moves_taken = true;
        work
    }

    /// [`Self::kick_drift_held`]'s pass: `update` (which wraps) on the tables of `moving`,
    /// each chunk then measured, and the other grains wrapped and measured in chunks of
    /// their own; the moves stored.
    fn update_wrap_and_measure<'a>(
        &mut self,
        moving: impl Iterator<Item = HeldTable<'a>>,
        (chunk, parallel_from): (usize, usize),
        periodic: Option<crate::periodic::PeriodicBox>,
        update: impl Fn(&mut [GrainRecord], &[Force], &[Mass], Option<&WrapRule>) -> f64 + Sync,
    ) -> f64 {
        self.set_periodic(periodic);
        let n = self.records.len();
        let track_moves = self.move_reference.len() == n;
        let wrap_box = self.periodic.filter(|b| b.shear.is_none());
        let wrap = wrap_box.as_ref().map(|b| b.wrap_rule());
        let (periodic_box, image) = (self.periodic, self.image);
        // Both scratch lists are kept between steps for their allocations.
        let mut block_moves = std::mem::take(&mut self.block_scratch);
        let mut chunk_results = std::mem::take(&mut self.chunk_scratch);
        block_moves.clear();
        if track_moves {
            block_moves.resize(n.div_ceil(MOVE_BLOCK), Moves::still());
        }
        // Takes the moves of the blocks a piece of a table holds a part of (its grains
        // `from..` of the table at `table_start`).
        let reference = &self.move_reference[..];
        let measure = |table_start: usize, from: usize, records: &[GrainRecord]| {
            if track_moves {
                let moved = MovedChunk {
                    table_start,
                    from,
                    positions: records,
                    reference: &reference[table_start..],
                };
                moved.block_moves(|r| r.position, &periodic_box, &image)
            } else {
                SmallVec::new()
            }
        };
        // The kicked tables' ranges, each with its forces and masses, and the grains
        // between and after them, which are only wrapped and measured: one parallel loop
        // over the chunks of both, so that no thread waits while another wraps the grains
        // the kick leaves alone (the frozen base of a chute) on its own.
        // A piece: its grains, and for a kicked table its number, forces and masses.
        type Piece<'f> = (
            std::ops::Range<usize>,
            Option<(usize, &'f [Force], &'f [Mass])>,
        );
        let mut pieces: Vec<Piece> = Vec::new();
        for (k, (entities, forces, masses)) in moving.enumerate() {
            pieces.push((self.table_range(entities), Some((k, forces, masses))));
        }
        let kicked_tables = pieces.len();
        pieces.sort_by_key(|(range, _)| range.start);
        let mut at = 0;
        let mut left = Vec::new();
        for (range, _) in pieces.iter().chain(std::iter::once(&(n..n, None))) {
            if at < range.start {
                left.push((at..range.start, None));
            }
            at = at.max(range.end);
        }
        if wrap.is_some() || track_moves {
            pieces.extend(left);
            pieces.sort_by_key(|(range, _)| range.start);
        }
        // Each piece's records cut into chunks: (a kicked chunk's forces and masses, the
        // piece's start, the chunk's first grain in it, the chunk's records), and each
        // chunk's kicked table by number. A kicked table shorter than `parallel_from` is
        // one chunk.
        type Job<'r, 'f> = (
            Option<(&'f [Force], &'f [Mass])>,
            usize,
            usize,
            &'r mut [GrainRecord],
        );
        // Each piece is cut into at most one chunk more than its grains fill whole: sized
        // up front, so that the lists are not grown (and copied) step after step.
        let most_jobs = n.div_ceil(chunk.max(1)) + pieces.len();
        let mut jobs: Vec<Job> = Vec::with_capacity(most_jobs);
        let mut job_tables: Vec<Option<usize>> = Vec::with_capacity(most_jobs);
        let mut rest = &mut self.records[..];
        let mut at = 0;
        for (range, kicked) in pieces {
            let (_, tail) = rest.split_at_mut(range.start - at);
            let (records, tail) = tail.split_at_mut(range.len());
            (rest, at) = (tail, range.end);
            let size = match kicked {
                Some(_) if records.len() < parallel_from => records.len().max(1),
                _ => chunk,
            };
            for (c, records) in records.chunks_mut(size).enumerate() {
                let (from, to) = (c * size, c * size + records.len());
                let chunk_kicked = kicked.map(|(_, f, m)| (&f[from..to], &m[from..to]));
                jobs.push((chunk_kicked, range.start, from, records));
                job_tables.push(kicked.map(|(k, _, _)| k));
            }
        }
        let one_chunk = |(kicked, table_start, from, records): Job| {
            let work = match kicked {
                Some((f, m)) => update(records, f, m, wrap.as_ref()),
                None => {
                    if let Some(wrap) = &wrap {
                        for record in records.iter_mut() {
                            wrap.apply(&mut record.position);
                        }
                    }
                    0.0
                }
            };
            (work, measure(table_start, from, records))
        };
        // The chunks' results go to the kept scratch list (some 1.3 KB a chunk). One chunk
        // a job: rayon's adaptive split leaves each thread runs of several chunks that it
        // works through without letting the other take any, and at the end of the loop one
        // thread waited through up to five chunks of the other's (70–90 µs of a 32,000-grain
        // step on 2 threads, traced).
        chunk_results.clear();
        if n >= parallel_from {
            chunk_results.par_extend(jobs.into_par_iter().with_max_len(1).map(one_chunk));
        } else {
            chunk_results.extend(jobs.into_iter().map(one_chunk));
        }
        // The work of gravity table by table, in the order the tables came, each table's
        // chunks summed in order (a sum of one term is the term: it starts from -0.0).
        let mut work = 0.0;
        for table in 0..kicked_tables {
            work += chunk_results
                .iter()
                .zip(&job_tables)
                .filter(|&(_, &t)| t == Some(table))
                .map(|((w, _), _)| w)
                .sum::<f64>();
        }
        for (_, blocks) in chunk_results.drain(..) {
            for (block, moves) in blocks {
                block_moves[block] = block_moves[block].merge(moves);
            }
        }
        self.finish_moves(block_moves, chunk_results);
        work
    }

    /// The broad phase's pass when the snapshot holds the grains' motion: the grains are
    /// those of the last step and their records were kicked and drifted in place
    /// ([`Self::kick_drift_held`]), so only the wrap into an unsheared periodic box and the
    /// moves since the reference are left, taken as [`gather_snapshot`]'s copy takes them:
    /// for a pass whose kick did not take them (one with a zero time step).
    fn refresh_held_motion(&mut self) {
        let no_kick = |_: &mut [GrainRecord], _: &[Force], _: &[Mass], _: Option<&WrapRule>| 0.0;
        let chunking = (COPY_CHUNK, usize::MAX);
        self.update_wrap_and_measure(std::iter::empty(), chunking, self.periodic, no_kick);
    }

    /// Stores the moves of the blocks of grains found by a gather (and the whole
    /// packing's, merged from them), returning the scratch lists to the snapshot.
    fn finish_moves(&mut self, block_moves: Vec<Moves>, chunk_results: Vec<ChunkMoves>) {
        self.moves = block_moves
            .iter()
            .fold(Moves::still(), |all, block| all.merge(*block));
        self.block_moves.clear();
        self.block_moves
            .extend(block_moves.iter().map(Moves::block));
        self.block_scratch = block_moves;
        self.chunk_scratch = chunk_results;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periodic::PeriodicBox;
    use bevy_ecs::system::RunSystemOnce;

    fn spawn_grain(world: &mut World, position: DVec3) -> Entity {
        world
            .spawn((
                Grain,
                Position(position),
                Velocity(DVec3::ZERO),
                AngularVelocity(DVec3::ZERO),
                Radius(0.5),
                Mass(1.0),
                MaterialId(0),
            ))
            .id()
    }

    fn gather(world: &mut World) -> f64 {
        world.run_system_once(gather_snapshot).unwrap();
        world.resource::<GrainSnapshot>().move_bound_sq()
    }

    /// The bound is the smaller of the largest move and the half diagonal of the box of
    /// moves, each move the nearest-image distance from the marked position (a grain that
    /// crosses the periodic seam moved its short way); a change of the grains voids the
    /// mark.
    #[test]
    fn move_bound_takes_nearest_images_and_the_box_of_moves() {
        let mut world = World::new();
        world.insert_resource(GrainSnapshot::default());
        world.insert_resource(PeriodicBox {
            lo: DVec3::ZERO,
            hi: DVec3::new(10.0, 10.0, 10.0),
            axes: [true, false, false],
            shear: None,
        });
        let a = spawn_grain(&mut world, DVec3::new(9.9, 5.0, 5.0));
        let b = spawn_grain(&mut world, DVec3::new(3.0, 5.0, 5.0));
        assert_eq!(gather(&mut world), f64::INFINITY, "no mark yet");
        world.resource_mut::<GrainSnapshot>().mark_move_reference();
        assert_eq!(gather(&mut world), 0.0);
        // a crosses the seam at x = 10 (wrapped to 0.2: 0.3 along x, not 9.7); b moves 0.2
        // along z.
        world.get_mut::<Position>(a).unwrap().0 = DVec3::new(0.2, 5.0, 5.0);
        world.get_mut::<Position>(b).unwrap().0 = DVec3::new(3.0, 5.0, 5.2);
        // Displacements (0.3, 0, 0) (the short way across the seam, not 9.7 back) and
        // (0, 0, 0.2): the half diagonal of their bounding box, √(0.15² + 0.1²) ≈ 0.18, is
        // below the largest move, 0.3, and is the bound.
        let expected: f64 = 0.15f64.powi(2) + 0.1f64.powi(2);
        assert!((gather(&mut world) - expected).abs() < 1e-12 * expected);
        spawn_grain(&mut world, DVec3::new(7.0, 5.0, 5.0));
        assert_eq!(gather(&mut world), f64::INFINITY, "a grain was added");
    }

    /// The drift leaves a grain that crossed a face of an unsheared box outside it;
    /// `gather_snapshot` wraps it (the wrap's own rule) in the world and in the snapshot,
    /// and measures its move the short way across the seam. A non-periodic axis is left
    /// alone.
    #[test]
    fn gather_wraps_grains_carried_out_of_the_box() {
        let mut world = World::new();
        world.insert_resource(GrainSnapshot::default());
        let box_ = PeriodicBox {
            lo: DVec3::ZERO,
            hi: DVec3::new(10.0, 10.0, 10.0),
            axes: [true, true, false],
            shear: None,
        };
        world.insert_resource(box_);
        let a = spawn_grain(&mut world, DVec3::new(9.9, 0.1, 5.0));
        spawn_grain(&mut world, DVec3::new(5.0, 5.0, 5.0));
        gather(&mut world);
        world.resource_mut::<GrainSnapshot>().mark_move_reference();
        // Across x = 10 and y = 0 in one step, and out of the box along z (not periodic).
        let drifted = DVec3::new(10.2, -0.1, 12.0);
        world.get_mut::<Position>(a).unwrap().0 = drifted;
        let bound_sq = gather(&mut world);
        let wrapped = box_.wrap(drifted);
        assert_eq!(wrapped, DVec3::new(10.2 - 10.0, -0.1 + 10.0, 12.0));
        assert_eq!(world.get::<Position>(a).unwrap().0, wrapped);
        assert_eq!(world.resource::<GrainSnapshot>().position(0), wrapped);
        // The move: (0.3, −0.2, 7), the short way across both seams; the other grain stays,
        // so the bound is half the diagonal of the box of the two moves.
        let expected = (0.5 * DVec3::new(0.3, -0.2, 7.0)).length_squared();
        assert!(
            (bound_sq - expected).abs() < 1e-9,
            "{bound_sq} against {expected}"
        );
    }

    /// The first kick and drift of held records wraps them and takes their moves as the
    /// copy of the grains' components does: the same records and the same moves, block by
    /// block, with the kicked grains' table starting off a block's start, chunks smaller
    /// than a block and not aligned on them, grains drifting across the box's faces, and
    /// frozen grains (not kicked) before them.
    #[test]
    fn kick_drift_held_wraps_and_measures_as_the_copy_does() {
        let mut world = World::new();
        world.insert_resource(GrainSnapshot::default());
        let box_ = PeriodicBox {
            lo: DVec3::ZERO,
            hi: DVec3::new(10.0, 8.0, 50.0),
            axes: [true, true, false],
            shear: None,
        };
        world.insert_resource(box_);
        // A fixed pseudo-random sequence in [0, 1).
        let mut state = 12345_u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for k in 0..3000 {
            let p = DVec3::new(10.0 * next(), 8.0 * next(), 50.0 * next());
            let v = DVec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 4.0;
            let grain = spawn_grain(&mut world, p);
            world.get_mut::<Velocity>(grain).unwrap().0 = v;
            world.entity_mut(grain).insert(Force(DVec3::ZERO));
            if k < 300 {
                world.entity_mut(grain).insert(Frozen);
            }
        }
        gather(&mut world);
        world.resource_mut::<GrainSnapshot>().mark_move_reference();
        let mut held = world.resource::<GrainSnapshot>().clone();
        let dt = 0.1;
        // The frozen grains stand moved since the reference, some out of the box: the
        // kick leaves them alone, the wrap and the moves do not.
        let frozen_move = DVec3::new(0.3, 0.0, 0.0);
        for record in &mut held.records[..300] {
            record.position += frozen_move;
        }
        let drift =
            |records: &mut [GrainRecord], _: &[Force], _: &[Mass], wrap: Option<&WrapRule>| {
                for r in records.iter_mut() {
                    r.position += r.velocity * dt;
                    if let Some(wrap) = wrap {
                        wrap.apply(&mut r.position);
                    }
                }
                0.0
            };
        let mut moving =
            world.query_filtered::<(Entity, &Force, &Mass), (With<Grain>, Without<Frozen>)>();
        let moving = moving.query(&world);
        let tables: Vec<_> = moving.contiguous_iter().unwrap().collect();
        let kicked = held.table_range(tables[0].0);
        assert!(
            !kicked.start.is_multiple_of(MOVE_BLOCK),
            "the kicked table starts off a block"
        );
        held.kick_drift_held(tables.iter().copied(), (100, 500), Some(box_), drift);
        // The same motion in the components, copied by the broad phase.
        let mut grains = world.query::<(&mut Position, &Velocity, Has<Frozen>)>();
        for (mut p, v, frozen) in grains.iter_mut(&mut world) {
            p.0 += if frozen { frozen_move } else { v.0 * dt };
        }
        gather(&mut world);
        let copied = world.resource::<GrainSnapshot>();
        assert!(held.records == copied.records);
        let outside = |r: &GrainRecord| r.position.x >= 10.0 || r.position.y < 0.0;
        assert!(!held.records.iter().any(outside), "every grain wrapped");
        assert!(held.block_moves().unwrap() == copied.block_moves().unwrap());
        assert_eq!(held.move_bound_sq(), copied.move_bound_sq());
        assert!(held.move_bound_sq() > 0.0);
    }

    /// No grain: nothing moved (the empty box of moves gives no NaN).
    #[test]
    fn no_moves_bound_nothing() {
        assert_eq!(Moves::still().bound_sq(), 0.0);
    }

    /// Each block of grains bounds its own moves, and two blocks' bound on how far a pair
    /// of their grains closed holds for every such pair: a block carried along y with a
    /// small spread, another at rest, a part of a block moving along x.
    #[test]
    fn block_moves_bound_every_pair_of_their_grains() {
        let mut world = World::new();
        world.insert_resource(GrainSnapshot::default());
        // Two blocks and a part: grains on a line, 1 m apart.
        let n = 2 * MOVE_BLOCK + 7;
        let grains: Vec<Entity> = (0..n)
            .map(|k| spawn_grain(&mut world, DVec3::new(k as f64, 0.0, 0.0)))
            .collect();
        gather(&mut world);
        assert!(
            world.resource::<GrainSnapshot>().block_moves().is_none(),
            "no mark yet"
        );
        world.resource_mut::<GrainSnapshot>().mark_move_reference();
        // The first block drifts 0.3 m along y, each grain a little further along z; the
        // second stays; the last grains move 0.01 m along x.
        for (k, &e) in grains.iter().enumerate() {
            let d = match k / MOVE_BLOCK {
                0 => DVec3::new(0.0, 0.3, 1e-4 * k as f64),
                1 => DVec3::ZERO,
                _ => DVec3::new(0.01, 0.0, 0.0),
            };
            world.get_mut::<Position>(e).unwrap().0 += d;
        }
        let packing = gather(&mut world).sqrt();
        let s = world.resource::<GrainSnapshot>();
        let blocks = s.block_moves().expect("marked, same grains");
        assert_eq!(blocks.len(), 3);
        let spread = 0.5 * 1e-4 * (MOVE_BLOCK - 1) as f64;
        assert!((blocks[0].spread - spread).abs() < 1e-12, "{:?}", blocks[0]);
        assert_eq!(blocks[1], BlockMoves::default());
        assert!((blocks[2].largest - 0.01).abs() < 1e-12);
        // Within the drifting block only the spread counts, far below the drift.
        assert!(blocks[0].pair_bound(&blocks[0]) < 0.1 * 0.3);
        for i in 0..n {
            for j in i..n {
                let (bi, bj) = (&blocks[i / MOVE_BLOCK], &blocks[j / MOVE_BLOCK]);
                let bound = bi.pair_bound(bj);
                let change =
                    ((s.position(i) - s.position(j)).length() - (i as f64 - j as f64).abs()).abs();
                assert!(change <= bound + 1e-12, "pair {i}, {j}: {change} > {bound}");
                assert!(change <= 2.0 * packing + 1e-12);
            }
        }
    }

    /// Grains that move together count only the spread of their moves: two grains carried
    /// 2 m along y, one of them 0.1 m further, give D = 0.05 m (any pair's separation
    /// changed by at most 2D = 0.1 m, exactly the change here), not the 2.1 m largest move.
    #[test]
    fn a_common_drift_does_not_count_against_the_skin() {
        let mut world = World::new();
        world.insert_resource(GrainSnapshot::default());
        let a = spawn_grain(&mut world, DVec3::new(1.0, 0.0, 0.0));
        let b = spawn_grain(&mut world, DVec3::new(2.0, 0.0, 0.0));
        gather(&mut world);
        world.resource_mut::<GrainSnapshot>().mark_move_reference();
        world.get_mut::<Position>(a).unwrap().0 = DVec3::new(1.0, 2.0, 0.0);
        world.get_mut::<Position>(b).unwrap().0 = DVec3::new(2.0, 2.1, 0.0);
        let bound = gather(&mut world).sqrt();
        assert!((bound - 0.05).abs() < 1e-12, "D = {bound}");
        let s = world.resource::<GrainSnapshot>();
        let change = (s.position(1) - s.position(0)).length() - 1.0;
        assert!(change <= 2.0 * bound + 1e-12);
    }
}
