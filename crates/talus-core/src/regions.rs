//! Regions of the dense grain index: contiguous ranges of grains that the stages of a step
//! can run over one at a time, each while its data is in cache (`docs/architecture.md` §11).
//!
//! The snapshot keeps the grains in rows of cells (x fastest, then y, then z), so a range
//! of the dense index is a slab across the slowest axis, and the partners of a region's
//! grains lie in it and in its neighbours once a region spans two cell layers. A contact
//! belongs to the region of its key, the first of its two grains in dense order (for a
//! grain and a wall, the grain), as the narrow phase's index keys it.

use std::ops::Range;

/// Grains per region when a stage asks for regions without a reason to size them
/// otherwise: about half of what the 32 MB L3 of the machines Talus is measured on holds
/// of a step's data (some 700 bytes a grain with its contacts), and more than two cell
/// layers of the 32,000-grain chute (800 grains a layer).
pub const REGION_GRAINS: usize = 16_384;

/// The dense index cut into regions of equal length, a power of two (the last region may be
/// shorter): region `r` holds grains `r * len .. (r + 1) * len`. A power of two, so that a
/// grain's region is a shift: the contacts' region pass takes one per contact.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GrainRegions {
    grains: u32,
    shift: u32,
    /// The last region's index, which keys past the last grain fall in.
    last: u32,
}

impl GrainRegions {
    /// `grains` grains cut into regions of `region_len` grains rounded up to a power of two
    /// (at most 2^31).
    pub fn new(grains: usize, region_len: usize) -> Self {
        let grains = u32::try_from(grains).expect("a snapshot holds fewer than 2^32 grains");
        let shift = region_len
            .clamp(1, 1 << 31)
            .next_power_of_two()
            .trailing_zeros();
        Self {
            grains,
            shift,
            last: grains.saturating_sub(1) >> shift,
        }
    }

    /// Grains per region (the last may hold fewer).
    pub fn region_len(&self) -> usize {
        1 << self.shift
    }

    /// How many regions there are: at least one, so that every key has a region even in
    /// an empty snapshot.
    pub fn count(&self) -> usize {
        self.last as usize + 1
    }

    /// The grains of region `r`.
    pub fn range(&self, r: usize) -> Range<usize> {
        let end = self.grains as usize;
        (r << self.shift).min(end)..((r + 1) << self.shift).min(end)
    }

    /// The region of the grain with dense index `dense`; an index past the last grain
    /// (a body not found in the snapshot) belongs to the last region.
    #[inline]
    pub fn region_of(&self, dense: u32) -> usize {
        (dense >> self.shift).min(self.last) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_cover_the_grains_once_in_order() {
        for (grains, len) in [(0, 4), (1, 4), (10, 3), (12, 4), (12, 1), (5, 100)] {
            let regions = GrainRegions::new(grains, len);
            assert!(regions.region_len() >= len && regions.region_len() < 2 * len);
            let mut next = 0;
            for r in 0..regions.count() {
                let range = regions.range(r);
                assert_eq!(range.start, next, "{grains} grains in regions of {len}");
                for i in range.clone() {
                    assert_eq!(regions.region_of(i as u32), r);
                }
                next = range.end;
            }
            assert_eq!(next, grains);
            assert_eq!(regions.region_of(grains as u32 + 7), regions.count() - 1);
        }
    }
}
