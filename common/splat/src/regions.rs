//! Where the top-K entries of one tile row's pixels go in the band store: each pixel keeps
//! min(n, K) entries, laid out in pixel order (an exclusive prefix sum over the row's 16
//! lanes), and some pixels need more than their list copied front to back.

use crate::row_log::LIST_CAP;
use crate::tiles::TILE_SIZE;

const T: usize = TILE_SIZE as usize;

/// The regions of one tile row's pixels, from their contribution counts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct RowRegions {
    /// Entries each pixel keeps: min(n, K).
    pub kept: [u32; T],
    /// Entries of the row's earlier pixels (where each pixel's region starts in the row's).
    pub before: [u32; T],
    /// Entries of the whole row.
    pub total: u32,
    /// Pixels whose top-K is chosen (or sorted) from a scratch list of their contributions.
    pub to_scratch: u32,
    /// Pixels whose list is longer than the scratch holds: replayed instead.
    pub skip: u32,
}

impl RowRegions {
    /// Regions for contribution counts `n` (lanes past the tile's edge count 0), top-K size
    /// `k` (≤ u16::MAX, so no sum wraps), sorted on request.
    #[inline(always)]
    pub fn new(n: &[u32; T], k: u32, sort: bool) -> Self {
        let kept: [u32; T] = std::array::from_fn(|x| n[x].min(k));
        // Log-step scan (4 shifted adds over the lanes), branch-free so it stays in vectors.
        let mut before: [u32; T] = std::array::from_fn(|x| if x == 0 { 0 } else { kept[x - 1] });
        let mut d = 1;
        while d < T {
            before = std::array::from_fn(|x| {
                if x >= d {
                    before[x] + before[x - d]
                } else {
                    before[x]
                }
            });
            d *= 2;
        }
        let (mut to_scratch, mut skip) = (0u32, 0u32);
        for (x, &n) in n.iter().enumerate() {
            let chosen = !top_k_is_whole_list(n as usize, k as usize, sort);
            to_scratch |= ((chosen & (n as usize <= LIST_CAP)) as u32) << x;
            skip |= ((chosen & (n as usize > LIST_CAP)) as u32) << x;
        }
        Self {
            total: before[T - 1] + kept[T - 1],
            kept,
            before,
            to_scratch,
            skip,
        }
    }
}

/// Whether a pixel's top-K is its whole list in front-to-back order (written straight from
/// the row log into the band store), rather than chosen or sorted from a scratch list.
#[inline(always)]
pub(crate) fn top_k_is_whole_list(n: usize, k: usize, sort: bool) -> bool {
    n <= k && (!sort || n <= 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_follow_each_other_and_flag_the_chosen_lists() {
        // k = 3: pixels with more than 3 keep 3, and choose them from a scratch list unless
        // their list is longer than the scratch (then skipped: replayed).
        let mut n = [0u32; T];
        n[..6].copy_from_slice(&[2, 0, 5, 3, LIST_CAP as u32 + 1, 1]);
        let r = RowRegions::new(&n, 3, false);
        assert_eq!(&r.kept[..6], &[2, 0, 3, 3, 3, 1]);
        assert_eq!(&r.before[..7], &[0, 2, 2, 5, 8, 11, 12]);
        assert!(r.before[6..].iter().all(|&b| b == 12));
        assert_eq!(r.total, 12);
        assert_eq!((r.to_scratch, r.skip), (0b000100, 0b010000));
        // Sorted: every list of two or more is chosen from the scratch.
        let r = RowRegions::new(&n, 3, true);
        assert_eq!((r.to_scratch, r.skip), (0b001101, 0b010000));
    }

    #[test]
    fn prefix_sums_match_a_running_total() {
        let n: [u32; T] = std::array::from_fn(|x| (x as u32 * 7 + 3) % 11);
        let r = RowRegions::new(&n, 6, false);
        let mut run = 0;
        for (x, (&before, &n)) in r.before.iter().zip(&n).enumerate() {
            assert_eq!(before, run, "lane {x}");
            run += n.min(6);
        }
        assert_eq!(r.total, run);
    }
}
