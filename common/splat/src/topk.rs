//! Top-K Gaussians per pixel by weight (the paper's G_topK): selection over a pixel's
//! contributions, and compact per-band storage of the result.

/// Sort key: larger weight first, then the front-most Gaussian (smaller tile rank) on ties.
#[inline(always)]
pub fn topk_key(weight: f32, rank: u32) -> u64 {
    // Positive f32 bit patterns order like the values.
    ((weight.to_bits() as u64) << 32) | (!rank) as u64
}

#[inline(always)]
pub fn key_weight(key: u64) -> f32 {
    f32::from_bits((key >> 32) as u32)
}

#[inline(always)]
pub fn key_rank(key: u64) -> u32 {
    !(key as u32)
}

/// The `k` largest keys: sorted descending (heaviest first) if `sort`, else front to back.
pub fn select_top_k(keys: &mut [u64], k: usize, sort: bool) -> &[u64] {
    let k = k.min(keys.len());
    if sort {
        if keys.len() > k {
            keys.select_nth_unstable_by(k - 1, |a, b| b.cmp(a));
        }
        keys[..k].sort_unstable_by(|a, b| b.cmp(a));
    } else if keys.len() > k {
        keys.select_nth_unstable_by(k - 1, |a, b| b.cmp(a));
        // Back to front-to-back order: larger rank bits (!rank) first.
        keys[..k].sort_unstable_by_key(|&key| std::cmp::Reverse(key as u32));
    }
    &keys[..k]
}

/// For each of the first `n` weights (front to back), its position when ordered by weight
/// desc, ties to the front one (lanes past `n` get garbage). O(n·N) compares, but
/// branch-free with the N positions in vector lanes (one broadcast weight per step, no
/// horizontal sums): for the few dozen contributions a pixel has, far cheaper than a sort.
#[inline(always)]
pub fn weight_positions<const N: usize>(ws: &[f32; N], n: usize, pos: &mut [u32; N]) {
    // u32 lane indices keep the tie test as wide as the weight compares.
    let lane: [u32; N] = std::array::from_fn(|l| l as u32);
    let mut r = [0u32; N];
    for (j, &wj) in ws.iter().enumerate().take(n) {
        let ju = j as u32;
        for i in 0..N {
            // j outranks i: heavier, or as heavy and in front.
            let outranks = (wj > ws[i]) | ((wj == ws[i]) & (ju < lane[i]));
            r[i] += outranks as u32;
        }
    }
    *pos = r;
}

/// Top-K lists of one band of 16 image rows.
#[derive(Debug, Clone, Default)]
pub struct TopKBand {
    pub ids: Vec<u32>,
    pub weights: Vec<f32>,
}

/// Top-K Gaussians per pixel: ids (map indices) and weights α·T; heaviest first when the
/// request asked for sorting, else front to back.
#[derive(Debug, Clone, Default)]
pub struct TopK {
    pub k: usize,
    pub width: u32,
    pub height: u32,
    /// Per pixel (row-major): start of its entries in its band's arrays.
    pub start: Vec<u32>,
    /// Per pixel: number of entries (≤ k).
    pub count: Vec<u16>,
    /// One entry per 16-row band (image rows 16·b .. 16·b + 15).
    pub bands: Vec<TopKBand>,
}

impl TopK {
    /// (Gaussian ids, weights) of pixel (x, y).
    pub fn pixel(&self, x: u32, y: u32) -> (&[u32], &[f32]) {
        let p = (y * self.width + x) as usize;
        let band = &self.bands[(y / crate::tiles::TILE_SIZE) as usize];
        let s = self.start[p] as usize;
        let n = self.count[p] as usize;
        (&band.ids[s..s + n], &band.weights[s..s + n])
    }

    /// Total number of stored (id, weight) entries.
    pub fn entries(&self) -> usize {
        self.bands.iter().map(|b| b.ids.len()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_match_sorting() {
        let mut ws = [-1.0f32; 16];
        let vals = [0.1f32, 0.45, 0.1, 0.2, 0.3, 0.45];
        ws[..6].copy_from_slice(&vals);
        let mut pos = [0u32; 16];
        weight_positions(&ws, 6, &mut pos);
        assert_eq!(&pos[..6], &[4, 0, 5, 3, 2, 1]);
    }

    #[test]
    fn keys_order_by_weight_then_front_first() {
        let mut keys = vec![
            topk_key(0.1, 0),
            topk_key(0.45, 1),
            topk_key(0.1, 2),
            topk_key(0.2, 3),
        ];
        let top: Vec<(u32, f32)> = select_top_k(&mut keys.clone(), 3, true)
            .iter()
            .map(|&k| (key_rank(k), key_weight(k)))
            .collect();
        assert_eq!(top, vec![(1, 0.45), (3, 0.2), (0, 0.1)]);
        let set: Vec<u32> = select_top_k(&mut keys, 3, false)
            .iter()
            .map(|&k| key_rank(k))
            .collect();
        assert_eq!(set, vec![0, 1, 3]);
    }
}
