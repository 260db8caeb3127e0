//! GS Voting sums of one tile (docs/METHOD.md §3), kept per tile row: every Gaussian gives all the
//! pixels of a row visit one label, so a row keeps a short table of the labels it met and,
//! per label, a 16-lane vector of summed weights (0 where a pixel never took that label). A
//! visit is one table lookup and one vector add; the winner per pixel is a few vector
//! compares at the end of the tile. Rows meeting more labels than the table holds are marked
//! and their pixels voted exactly by the caller (from their log columns, or a replay). Most tiles
//! meet one label (77 % in the benchmark scene): until a second one comes, nothing is
//! summed at all, since the silhouette is that label's sum.

use crate::tiles::TILE_SIZE;

const T: usize = TILE_SIZE as usize;

/// Labels a tile row can track (rows at object borders meet a few).
pub(crate) const ROW_LABELS: usize = 8;
const _: () = assert!(ROW_LABELS == 8, "label_hits compares 8 labels");

pub(crate) struct RowVotes {
    /// `[row][slot]`: the labels met on the row, in order of first contribution.
    label: [[u32; ROW_LABELS]; T],
    used: [usize; T],
    /// `[row][slot][pixel]`: summed weight of the slot's label at the pixel.
    sum: [[[f32; T]; ROW_LABELS]; T],
    /// Bit y: row y met more than ROW_LABELS labels.
    overflow: u32,
    /// The one real label every Gaussian of the tile so far carried, while voting waits.
    uniform: Option<u32>,
    /// Whether visits are voted one by one (a second label, or label 0, came).
    per_visit: bool,
}

impl RowVotes {
    pub fn new() -> Self {
        Self {
            label: [[0; ROW_LABELS]; T],
            used: [0; T],
            sum: [[[0.0; T]; ROW_LABELS]; T],
            overflow: 0,
            uniform: None,
            per_visit: false,
        }
    }

    /// Forgets the last tile (sums are reset as their slot is taken).
    #[inline(always)]
    pub fn clear(&mut self) {
        self.used = [0; T];
        self.overflow = 0;
        self.uniform = None;
        self.per_visit = false;
    }

    /// Called for each Gaussian of the tile, in list order, before it composites: whether its
    /// visits must be [added](RowVotes::add) one by one. While every Gaussian so far carries
    /// one real label L, each pixel's sum for L is its silhouette so far (the same adds of the
    /// same weights, in the same order), so nothing is voted per visit; the first Gaussian of
    /// another label (or label 0) starts every row's table with L and its silhouette.
    #[inline(always)]
    pub fn per_visit(&mut self, label: u32, silhouette: &[[f32; T]; T]) -> bool {
        if self.per_visit || self.uniform == Some(label) {
            return self.per_visit;
        }
        match self.uniform {
            None if label != 0 => {
                self.uniform = Some(label);
                return false;
            }
            Some(l) => {
                for (y, s) in silhouette.iter().enumerate() {
                    if s.iter().any(|&v| v > 0.0) {
                        self.label[y][0] = l;
                        self.sum[y][0] = *s;
                        self.used[y] = 1;
                    }
                }
            }
            None => {}
        }
        self.per_visit = true;
        true
    }

    /// While no visit was voted one by one: the label every contributing Gaussian of the tile
    /// carried (pixels that took anything vote it), or 0 for a tile that met none.
    #[inline(always)]
    pub fn uniform(&self) -> Option<u32> {
        (!self.per_visit).then_some(self.uniform.unwrap_or(0))
    }

    /// Adds a visit of a Gaussian with real label `label` (≠ 0) to row `y`: weights `w`,
    /// 0 where a pixel took nothing. Sums add in front-to-back order, as the reference vote
    /// does (0 + w == w and s + 0 == s exactly, so the lanes that took nothing change nothing).
    #[inline(always)]
    pub fn add(&mut self, y: usize, label: u32, w: &[f32; T]) {
        let used = self.used[y];
        let hits = label_hits(&self.label[y], label) & ((1u32 << used) - 1);
        let slot = if hits != 0 {
            hits.trailing_zeros() as usize
        } else {
            used
        };
        if slot < used {
            for (s, &wi) in self.sum[y][slot].iter_mut().zip(w) {
                *s += wi;
            }
        } else if used < ROW_LABELS {
            self.label[y][used] = label;
            self.sum[y][used] = *w;
            self.used[y] = used + 1;
        } else {
            self.overflow |= 1 << y;
        }
    }

    /// Whether row `y` met more labels than it could track (vote its pixels another way).
    #[inline(always)]
    pub fn overflowed(&self, y: usize) -> bool {
        (self.overflow >> y) & 1 != 0
    }

    /// The voted label of each pixel of row `y`: the largest sum, ties to the smaller label;
    /// 0 where no real label contributed (weights are positive, so a sum > 0 means taken).
    #[inline(always)]
    pub fn winners(&self, y: usize) -> [u32; T] {
        let (mut best_l, mut best_s) = ([0u32; T], [0.0f32; T]);
        for slot in 0..self.used[y] {
            let (l, sum) = (self.label[y][slot], &self.sum[y][slot]);
            for x in 0..T {
                let s = sum[x];
                let wins = (s > 0.0)
                    & ((best_l[x] == 0) | (s > best_s[x]) | ((s == best_s[x]) & (l < best_l[x])));
                best_l[x] = if wins { l } else { best_l[x] };
                best_s[x] = if wins { s } else { best_s[x] };
            }
        }
        best_l
    }
}

/// Bit s set where `labels[s] == label`: two SSE2 compares on x86_64 (baseline there), a
/// loop elsewhere.
#[inline(always)]
fn label_hits(labels: &[u32; ROW_LABELS], label: u32) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        // SAFETY: SSE2 is part of the x86_64 baseline; the loads read the 8 labels.
        unsafe {
            let l = _mm_set1_epi32(label as i32);
            let a = _mm_loadu_si128(labels.as_ptr().cast());
            let b = _mm_loadu_si128(labels.as_ptr().add(4).cast());
            let ma = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(a, l))) as u32;
            let mb = _mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(b, l))) as u32;
            ma | (mb << 4)
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut hits = 0u32;
        for (s, &l) in labels.iter().enumerate() {
            hits |= ((l == label) as u32) << s;
        }
        hits
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::voting::vote;

    #[test]
    fn winners_match_the_reference_vote() {
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        let mut rnd = move || rng.gen::<u32>();
        let mut v = RowVotes::new();
        let mut sums = Vec::new();
        for case in 0..500 {
            v.clear();
            let labels = 1 + rnd() % 11;
            let visits = 1 + rnd() as usize % 40;
            let mut per_pixel: Vec<Vec<(u32, f32)>> = vec![Vec::new(); T];
            let mut met = std::collections::BTreeSet::new();
            for _ in 0..visits {
                // Labels 0..labels (0 = none); weights on a coarse grid so sums tie.
                let label = rnd() % (labels + 1);
                let mut w = [0.0f32; T];
                for (x, wx) in w.iter_mut().enumerate() {
                    if rnd() % 2 == 0 {
                        *wx = (1 + rnd() % 4) as f32 / 8.0;
                        per_pixel[x].push((label, *wx));
                    }
                }
                if label != 0 {
                    met.insert(label);
                    v.add(3, label, &w);
                }
            }
            assert_eq!(v.overflowed(3), met.len() > ROW_LABELS, "case {case}");
            if v.overflowed(3) {
                continue;
            }
            let got = v.winners(3);
            for x in 0..T {
                let want = vote(per_pixel[x].iter().copied(), &mut sums);
                assert_eq!(got[x], want, "case {case} pixel {x}");
            }
        }
    }

    #[test]
    fn a_ninth_label_overflows_the_row() {
        let mut v = RowVotes::new();
        let w = [0.5f32; T];
        for l in 1..=ROW_LABELS as u32 {
            v.add(0, l, &w);
        }
        assert!(!v.overflowed(0));
        v.add(0, 100, &w);
        assert!(v.overflowed(0));
        assert!(!v.overflowed(1));
    }
}
