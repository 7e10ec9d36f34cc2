//! The allocator of the `talus` binary: the system's, with large blocks asked to be backed
//! by huge pages.
//!
//! A 512,000-grain run keeps about 350 MB of arrays that its hot loops read in no order
//! a 4 KiB page's translation stays cached for: every first touch of a page beyond the
//! translation cache's reach costs a page-table walk. Linux backs memory with 2 MiB pages
//! (transparent huge pages) everywhere, only on request (`madvise`), or never; most
//! distributions ship "only on request", and glibc asks only when told by an environment
//! variable (`GLIBC_TUNABLES=glibc.malloc.hugetlb=1`). This allocator asks for every
//! block of [`HUGE_PAGE_FROM`] bytes or more; where the kernel gives huge pages always or
//! never, the request changes nothing. It changes no result: only where memory lies.

use std::alloc::{GlobalAlloc, Layout, System};

/// The system allocator, with blocks of at least [`HUGE_PAGE_FROM`] bytes advised to be
/// backed by transparent huge pages. Install it with `#[global_allocator]` in a binary.
pub struct HugePageAllocator;

/// The smallest block advised to huge pages: two of them, so that a block holds at least
/// one whole huge page (the advice covers whole pages only).
pub const HUGE_PAGE_FROM: usize = 2 * HUGE_PAGE;

/// The size of a transparent huge page on x86-64 and most other Linux targets.
const HUGE_PAGE: usize = 2 * 1024 * 1024;

/// Advises the kernel to back the block `[block, block + size)` with huge pages where it
/// can (whole, aligned 2 MiB extents). Best effort: the advice may be refused (no such
/// support, a kernel that never gives them) and nothing depends on it.
///
/// The advice covers every page the block touches, not only the huge pages inside it:
/// advice on part of a mapping splits it into mappings of different kinds, and the kernel
/// then refuses to move the block as a whole when it grows (`mremap` fails with `EFAULT`),
/// so glibc's `realloc` copies it into a new mapping instead. The old and the new block
/// were then resident together: when the 512,000-grain chute's contact table passed 2^18
/// rows, 18 MB on top of the run's peak. The pages past the block's ends that the advice
/// covers belong to this process (the block's own mapping, or its neighbours on the heap);
/// the advice changes how they are backed, not what they hold.
fn advise_huge_pages(block: *mut u8, size: usize) {
    #[cfg(target_os = "linux")]
    if !block.is_null() && size >= HUGE_PAGE_FROM {
        // SAFETY: `sysconf` reads a system constant.
        let page = usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) })
            .ok()
            .filter(|&p| p.is_power_of_two())
            .unwrap_or(4096);
        let start = block as usize / page * page;
        let end = (block as usize + size).next_multiple_of(page);
        // SAFETY: the range covers a block the system allocator just handed out and the
        // rest of the pages it lies on, all mapped in this process; the advice changes how
        // the pages are backed, not what they hold.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (block, size);
}

// SAFETY: every call is forwarded to the system allocator with its own arguments; the
// advice afterwards neither moves nor changes the block.
unsafe impl GlobalAlloc for HugePageAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc`, forwarded.
        let block = unsafe { System.alloc(layout) };
        advise_huge_pages(block, layout.size());
        block
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc_zeroed`, forwarded.
        let block = unsafe { System.alloc_zeroed(layout) };
        advise_huge_pages(block, layout.size());
        block
    }

    unsafe fn dealloc(&self, block: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract for `dealloc`, forwarded.
        unsafe { System.dealloc(block, layout) }
    }

    unsafe fn realloc(&self, block: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract for `realloc`, forwarded.
        let moved = unsafe { System.realloc(block, layout, new_size) };
        advise_huge_pages(moved, new_size);
        moved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blocks above and below the threshold, grown and zeroed through the allocator, hold
    /// what was written to them: the advice moves nothing.
    #[test]
    fn advised_blocks_keep_their_contents_through_growth() {
        let allocator = HugePageAllocator;
        for size in [4096, HUGE_PAGE_FROM - 1, HUGE_PAGE_FROM + 12_345] {
            let layout = Layout::from_size_align(size, 64).unwrap();
            // SAFETY: a non-zero size and a valid alignment; every byte read was written
            // (or zeroed by `alloc_zeroed`), and each block is freed with its own layout.
            unsafe {
                let zeroed = allocator.alloc_zeroed(layout);
                assert!(!zeroed.is_null());
                assert!((0..size).step_by(4093).all(|k| *zeroed.add(k) == 0));
                allocator.dealloc(zeroed, layout);

                let block = allocator.alloc(layout);
                assert!(!block.is_null());
                for k in (0..size).step_by(4093) {
                    *block.add(k) = (k % 251) as u8;
                }
                let grown_size = 3 * size + HUGE_PAGE;
                let grown = allocator.realloc(block, layout, grown_size);
                assert!(!grown.is_null());
                assert!(
                    (0..size)
                        .step_by(4093)
                        .all(|k| *grown.add(k) == (k % 251) as u8)
                );
                *grown.add(grown_size - 1) = 7;
                assert_eq!(*grown.add(grown_size - 1), 7);
                allocator.dealloc(grown, Layout::from_size_align(grown_size, 64).unwrap());
            }
        }
    }

    /// The mapping (`/proc/self/maps` line) that holds address `at`: its start and end.
    #[cfg(target_os = "linux")]
    fn mapping_of(at: usize) -> Option<(usize, usize)> {
        let maps = std::fs::read_to_string("/proc/self/maps").ok()?;
        maps.lines().find_map(|line| {
            let range = line.split_whitespace().next()?;
            let (start, end) = range.split_once('-')?;
            let start = usize::from_str_radix(start, 16).ok()?;
            let end = usize::from_str_radix(end, 16).ok()?;
            (start <= at && at < end).then_some((start, end))
        })
    }

    /// The advice leaves a large block in one mapping, before and after it grows: advice on
    /// part of it would split its mapping, and the kernel would then refuse to grow it in
    /// place (glibc copying it instead, the old and new block resident together).
    #[cfg(target_os = "linux")]
    #[test]
    fn a_large_block_stays_one_mapping_through_growth() {
        let allocator = HugePageAllocator;
        let size = 3 * HUGE_PAGE_FROM + 12_345;
        let layout = Layout::from_size_align(size, 64).unwrap();
        // SAFETY: a non-zero size and a valid alignment; the blocks are only written and
        // freed with their own layouts.
        unsafe {
            let block = allocator.alloc(layout);
            assert!(!block.is_null());
            let one = |block: *mut u8, size: usize| {
                let (first, last) = (block as usize, block as usize + size - 1);
                mapping_of(first).is_some_and(|(start, end)| start <= first && last < end)
            };
            assert!(
                one(block, size),
                "the advised block spans more than one mapping"
            );
            let grown_size = 2 * size;
            let grown = allocator.realloc(block, layout, grown_size);
            assert!(!grown.is_null());
            assert!(
                one(grown, grown_size),
                "the grown block spans more than one mapping"
            );
            allocator.dealloc(grown, Layout::from_size_align(grown_size, 64).unwrap());
        }
    }
}
