//! Stable counting sorts whose passes run on every thread, each thread over a range of
//! the keys: the grid's grains by cell, a contact table's rows by first grain.
//!
//! A serial counting sort is two passes over the items (count, then place) with a prefix
//! sum between them, and it was serial work of the step that the other threads waited
//! behind (the grid's sort at every neighbour-list build, the contact tables' at every
//! table sort). Here each thread owns a range of keys: it counts and places only the
//! items whose keys fall in it, reading every item's key but writing only its own slots.
//! The result is the serial sort's, whatever the number of threads: a key's items keep
//! their index order, and every key's slots follow from the counts alone. It needs no
//! memory beyond the serial sort's: each thread's counts are its keys' own entries, and
//! its items fill one run of the order.

use rayon::prelude::*;

/// Below this many items a sort runs serially: the parallel passes' fixed cost exceeds
/// what a second thread saves.
const PARALLEL_FROM: usize = 8192;

/// Sorts the items `0..len` by key (`key_of(i) < key_count`), stably: on return
/// `order[start[k]..start[k + 1]]` are the items of key `k` in increasing index order,
/// for every `k < key_count` (`start` gets `key_count + 1` entries; `order` must hold
/// `len`). The same result on any number of threads.
pub fn counting_sort(
    len: usize,
    key_count: usize,
    key_of: impl Fn(usize) -> usize + Sync,
    start: &mut Vec<u32>,
    order: &mut [u32],
) {
    assert_eq!(order.len(), len, "the order holds one entry per item");
    start.clear();
    start.resize(key_count + 1, 0);
    let threads = rayon::current_num_threads();
    if threads < 2 || len < PARALLEL_FROM || key_count < 2 {
        let total = count_range(len, &key_of, 0..key_count, &mut start[1..]);
        debug_assert_eq!(total as usize, len);
        place_range(len, &key_of, 0..key_count, &mut start[1..], order, 0);
        return;
    }
    // Each part's keys: cut where the items at equal steps of the index have their keys,
    // so that parts of items laid out in key order (grains in cell order, a sorted
    // table's rows) hold about as many items each. Any cut gives the same result.
    let mut cuts: Vec<usize> = (1..threads).map(|p| key_of(p * len / threads)).collect();
    cuts.sort_unstable();
    let bounds: Vec<usize> = std::iter::once(0)
        .chain(cuts)
        .chain(std::iter::once(key_count))
        .collect();
    let ranges: Vec<std::ops::Range<usize>> = bounds.windows(2).map(|w| w[0]..w[1]).collect();
    // Part p owns `start[k + 1]` for its keys k: disjoint slices of `start[1..]`.
    let mut slices: Vec<&mut [u32]> = Vec::with_capacity(ranges.len());
    let mut rest = &mut start[1..];
    for range in &ranges {
        let (mine, others) = rest.split_at_mut(range.len());
        slices.push(mine);
        rest = others;
    }
    let totals: Vec<u32> = slices
        .par_iter_mut()
        .zip(ranges.par_iter())
        .map(|(counts, range)| count_range(len, &key_of, range.clone(), counts))
        .collect();
    // The keys are in order, so each part's items fill one run of the order.
    let mut runs: Vec<(u32, &mut [u32])> = Vec::with_capacity(totals.len());
    let (mut rest, mut offset) = (order, 0);
    for &total in &totals {
        let (run, others) = rest.split_at_mut(total as usize);
        runs.push((offset, run));
        (rest, offset) = (others, offset + total);
    }
    slices
        .into_par_iter()
        .zip(ranges.into_par_iter())
        .zip(runs.into_par_iter())
        .for_each(|((begins, range), (offset, run))| {
            begins.iter_mut().for_each(|b| *b += offset);
            place_range(len, &key_of, range, begins, run, offset);
        });
}

/// Counts the items of each key of `keys` and turns the counts into each key's first
/// slot relative to the range's first (`begins[k - keys.start]`); returns the range's
/// item count.
fn count_range(
    len: usize,
    key_of: &impl Fn(usize) -> usize,
    keys: std::ops::Range<usize>,
    begins: &mut [u32],
) -> u32 {
    for i in 0..len {
        let k = key_of(i).wrapping_sub(keys.start);
        if k < begins.len() {
            begins[k] += 1;
        }
    }
    let mut sum = 0;
    for slot in begins.iter_mut() {
        let count = *slot;
        *slot = sum;
        sum += count;
    }
    sum
}

/// Places the items of the keys of `keys` at their keys' next slots, in index order,
/// moving each slot on: a key's entry in `begins` ends at its items' end, which is the
/// next key's first slot (where `start` wants it). `run` is the order's entries from slot
/// `offset` on, which hold the range's items.
fn place_range(
    len: usize,
    key_of: &impl Fn(usize) -> usize,
    keys: std::ops::Range<usize>,
    begins: &mut [u32],
    run: &mut [u32],
    offset: u32,
) {
    for i in 0..len {
        let k = key_of(i).wrapping_sub(keys.start);
        if k < begins.len() {
            let slot = &mut begins[k];
            run[(*slot - offset) as usize] = i as u32;
            *slot += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The serial counting sort, written plainly.
    fn reference(keys: &[usize], key_count: usize) -> (Vec<u32>, Vec<u32>) {
        let mut start = vec![0u32; key_count + 1];
        for &k in keys {
            start[k + 1] += 1;
        }
        for k in 0..key_count {
            start[k + 1] += start[k];
        }
        let mut cursor = start.clone();
        let mut order = vec![0u32; keys.len()];
        for (i, &k) in keys.iter().enumerate() {
            order[cursor[k] as usize] = i as u32;
            cursor[k] += 1;
        }
        (start, order)
    }

    /// Keys in no order, nearly sorted, all one key, and with empty key ranges: the same
    /// starts and order as the plain serial sort on one to four threads, above and below
    /// the parallel threshold.
    #[test]
    fn sorts_as_the_serial_counting_sort_on_any_number_of_threads() {
        let mut state = 7_u64;
        let mut next = move |n: usize| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as usize) % n
        };
        for len in [0, 1, 100, PARALLEL_FROM + 1, 40_000] {
            let key_count = 5000;
            let random: Vec<usize> = (0..len).map(|_| next(key_count)).collect();
            let nearly: Vec<usize> = (0..len)
                .map(|i| (i * key_count / len.max(1) + next(7)).min(key_count - 1))
                .collect();
            let one = vec![3; len];
            let ends: Vec<usize> = (0..len)
                .map(|i| if i % 2 == 0 { 0 } else { key_count - 1 })
                .collect();
            for keys in [random, nearly, one, ends] {
                let expected = reference(&keys, key_count);
                for threads in 1..=4 {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    let (mut start, mut order) = (Vec::new(), vec![u32::MAX; len]);
                    pool.install(|| {
                        counting_sort(len, key_count, |i| keys[i], &mut start, &mut order)
                    });
                    assert_eq!((start, order), expected, "{len} items, {threads} threads");
                }
            }
        }
    }
}
