//! Top-K Gaussians per pixel by weight (the paper's G_topK): selection over a pixel's
//! contributions, and the per-tile-row storage of the result.

use half::f16;
use rayon::prelude::*;

/// Stored weights are the f16 of weight × 2^12: f16 halves the bytes the renderer stores per
/// contribution (a 640×480 top-K: 16 MB instead of 25; (b) renders 4–5 ms faster per three
/// frames on one thread), and the scale makes every weight it keeps (≥ MIN_ALPHA ·
/// MIN_TRANSMITTANCE ≈ 3.9e-7, < 1) a normal f16, so each is within a relative 2^-11 of the
/// f32 it was. The K are chosen on the f32s.
pub const WEIGHT_SCALE: f32 = 4096.0;
/// Largest weight the store holds (renderer weights are below 1; [`TopK::from_lists`] takes
/// up to this).
const MAX_STORED_WEIGHT: f32 = 15.0;
const _: () = assert!(
    crate::blend::MIN_ALPHA * crate::blend::MIN_TRANSMITTANCE * WEIGHT_SCALE
        >= f16::MIN_POSITIVE.to_f32_const()
        && MAX_STORED_WEIGHT * WEIGHT_SCALE <= f16::MAX.to_f32_const(),
    "every stored weight must be a normal f16 once scaled"
);

/// A weight as the top-K stores it.
#[inline(always)]
pub fn store_weight(w: f32) -> f16 {
    f16::from_f32(w * WEIGHT_SCALE)
}

/// A stored weight, back as f32.
#[inline(always)]
pub fn load_weight(h: f16) -> f32 {
    h.to_f32() * (1.0 / WEIGHT_SCALE)
}

/// The weight the top-K gives back for `w`.
pub fn stored_weight(w: f32) -> f32 {
    load_weight(store_weight(w))
}

/// Sort key: larger weight first, then the front-most Gaussian (smaller tile rank) on ties.
#[inline(always)]
pub fn topk_key(weight: f32, rank: u32) -> u64 {
    // Positive f32 bit patterns order like the values.
    ((weight.to_bits() as u64) << 32) | (!rank) as u64
}

#[inline(always)]
pub fn key_rank(key: u64) -> u32 {
    !(key as u32)
}

/// The `k` heaviest of a pixel's entries (id, weight), given front to back: heaviest first,
/// ties to the front one.
pub fn heaviest_first(entries: &[(u32, f32)], k: usize) -> Vec<(u32, f32)> {
    // Rank = front-to-back position.
    let mut keys: Vec<u64> = entries
        .iter()
        .enumerate()
        .map(|(i, e)| topk_key(e.1, i as u32))
        .collect();
    let k = k.min(keys.len());
    if keys.len() > k && k > 0 {
        keys.select_nth_unstable_by(k - 1, |a, b| b.cmp(a));
    }
    keys[..k].sort_unstable_by(|a, b| b.cmp(a));
    keys[..k]
        .iter()
        .map(|&key| entries[key_rank(key) as usize])
        .collect()
}

/// Where one tile row's visits are in its band's arrays.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RowSpan {
    /// First visit (index into the band's `ids` and `lanes`).
    pub visits: u32,
    /// Number of visits.
    pub len: u32,
    /// Where the first visit's weights start in the band's `weights`.
    pub weights: u32,
}

/// The top-K of one band of 16 image rows, stored as the renderer met it: per tile row, its
/// visits front to back (a Gaussian compositing onto some of the row's 16 pixels), each with
/// the weights of the pixels it reached. A pixel's top-K are the visits whose kept bit for
/// its lane is set. Writing a visit is one compress and vector store; per-pixel lists cost the
/// renderer a transpose and two stores per 16 visits and pixel, most of the top-K's price.
#[derive(Debug, Clone, Default)]
pub struct TopKBand {
    /// Per visit: the Gaussian's map id.
    pub ids: Vec<u32>,
    /// Per visit: bit x (x < 16) when pixel x of the row took a weight (stored in
    /// `weights`); bit 16 + x when that weight is among pixel x's K heaviest.
    pub lanes: Vec<u32>,
    /// The visits' weights α·T ([stored](store_weight) as f16), visit by visit, in lane
    /// order.
    pub weights: Vec<f16>,
}

/// Bits 0..16 of a visit's `lanes`: the pixels it reached.
pub const REACHED: u32 = 0xFFFF;
/// First bit of a visit's kept lanes.
pub const KEPT_SHIFT: u32 = 16;

/// Top-K Gaussians per pixel (the paper's G_topK): ids (map indices) and weights α·T, read
/// per pixel front to back ([`TopK::pixel`]) or heaviest first ([`TopK::pixel_sorted`]).
#[derive(Debug, Clone, Default)]
pub struct TopK {
    pub k: usize,
    pub width: u32,
    pub height: u32,
    /// Tiles per image row (tile rows of band b, tile tx, row y: `rows[(b·tiles_x + tx)·16 + y]`).
    pub tiles_x: u32,
    /// Per pixel (row-major): number of entries (≤ k).
    pub count: Vec<u16>,
    /// Per tile row, band by band, tile by tile, 16 rows each (past the image: empty).
    pub rows: Vec<RowSpan>,
    /// One entry per 16-row band (image rows 16·b .. 16·b + 15).
    pub bands: Vec<TopKBand>,
}

/// One pixel's top-K entries (Gaussian id, weight), front to back.
#[derive(Debug, Clone)]
pub struct PixelEntries<'a> {
    ids: &'a [u32],
    lanes: &'a [u32],
    weights: &'a [f16],
    /// Bit of the pixel's kept lane.
    kept: u32,
    /// The reached lanes before the pixel's (its weight's place in a visit).
    before: u32,
    v: usize,
    w: usize,
}

impl Iterator for PixelEntries<'_> {
    type Item = (u32, f32);

    #[inline]
    fn next(&mut self) -> Option<(u32, f32)> {
        while self.v < self.lanes.len() {
            let (l, v, w) = (self.lanes[self.v], self.v, self.w);
            self.v += 1;
            self.w += (l & REACHED).count_ones() as usize;
            if l & self.kept != 0 {
                let at = w + (l & self.before).count_ones() as usize;
                return Some((self.ids[v], load_weight(self.weights[at])));
            }
        }
        None
    }
}

const T: u32 = crate::tiles::TILE_SIZE;

impl TopK {
    /// Index into `rows` of the tile row holding pixel (x, y).
    fn row_index(&self, x: u32, y: u32) -> usize {
        (((y / T) * self.tiles_x + x / T) * T + y % T) as usize
    }

    /// Pixel (x, y)'s top-K (Gaussian id, weight α·T as [stored](stored_weight)), front to
    /// back.
    pub fn pixel(&self, x: u32, y: u32) -> PixelEntries<'_> {
        assert!(
            x < self.width && y < self.height,
            "pixel ({x}, {y}) outside {}x{}",
            self.width,
            self.height
        );
        let span = self.rows[self.row_index(x, y)];
        let band = &self.bands[(y / T) as usize];
        let (s, n) = (span.visits as usize, span.len as usize);
        let lane = x % T;
        PixelEntries {
            ids: &band.ids[s..s + n],
            lanes: &band.lanes[s..s + n],
            weights: &band.weights[span.weights as usize..],
            kept: 1 << (KEPT_SHIFT + lane),
            before: (1 << lane) - 1,
            v: 0,
            w: 0,
        }
    }

    /// The Gaussian ids kept in the top-K of any of the pixels `lanes` (bit x: pixel
    /// 16·`tile_x` + x) of image row `y`, front to back, each visit once: pixels of one
    /// tile row share its visits, so one scan serves them all, where [`TopK::pixel`] scans
    /// them once per pixel and decodes weights. An id the row's renderer met twice is
    /// yielded twice.
    pub fn ids_kept_in_tile_row(
        &self,
        y: u32,
        tile_x: u32,
        lanes: u32,
    ) -> impl Iterator<Item = u32> + '_ {
        assert!(
            y < self.height && tile_x < self.tiles_x,
            "tile row ({tile_x}, {y}) outside {}x{}",
            self.width,
            self.height
        );
        let span = self.rows[self.row_index(tile_x * T, y)];
        let band = &self.bands[(y / T) as usize];
        let (s, n) = (span.visits as usize, span.len as usize);
        let kept = (lanes & REACHED) << KEPT_SHIFT;
        band.ids[s..s + n]
            .iter()
            .zip(&band.lanes[s..s + n])
            .filter(move |&(_, &l)| l & kept != 0)
            .map(|(&id, _)| id)
    }

    /// Pixel (x, y)'s top-K heaviest first (ties: the front one first).
    pub fn pixel_sorted(&self, x: u32, y: u32) -> Vec<(u32, f32)> {
        let entries: Vec<(u32, f32)> = self.pixel(x, y).collect();
        heaviest_first(&entries, entries.len())
    }

    /// Number of pixels (row-major indices `0..pixel_count()`).
    pub fn pixel_count(&self) -> usize {
        self.count.len()
    }

    /// Row-major pixel `index`'s entries, front to back; none when out of range (indices
    /// come from messages, so they are not trusted).
    pub fn entries_at(&self, index: usize) -> impl Iterator<Item = (u32, f32)> + '_ {
        // An index in range means a width of at least 1.
        let w = self.width as usize;
        (index < self.count.len())
            .then(|| self.pixel((index % w) as u32, (index / w) as u32))
            .into_iter()
            .flatten()
    }

    /// Gaussian ids at row-major pixel `index`, front to back (none when out of range).
    pub fn gaussians_at(&self, index: usize) -> impl Iterator<Item = u32> + '_ {
        self.entries_at(index).map(|e| e.0)
    }

    /// Weight α·T of Gaussian `id` at row-major pixel `index`, if it is in that pixel's top-K.
    pub fn weight_of(&self, index: usize, id: u32) -> Option<f32> {
        self.entries_at(index).find(|e| e.0 == id).map(|e| e.1)
    }

    /// Total number of (id, weight) entries.
    pub fn entries(&self) -> usize {
        self.count.iter().map(|&c| c as usize).sum()
    }

    /// A top-K holding the given per-pixel lists (row-major, front to back), each kept whole
    /// (K = the longest): one visit per entry, weights (in (0, 15]) [stored](stored_weight).
    /// For tests and tools.
    pub fn from_lists(width: u32, height: u32, lists: &[Vec<(u32, f32)>]) -> Self {
        assert_eq!(
            lists.len(),
            width as usize * height as usize,
            "one list per pixel"
        );
        let tiles_x = width.div_ceil(T);
        let bands_n = height.div_ceil(T);
        let mut t = TopK {
            k: lists.iter().map(Vec::len).max().unwrap_or(0),
            width,
            height,
            tiles_x,
            count: lists.iter().map(|l| l.len() as u16).collect(),
            rows: Vec::with_capacity((bands_n * tiles_x * T) as usize),
            bands: Vec::with_capacity(bands_n as usize),
        };
        for b in 0..bands_n {
            let mut band = TopKBand::default();
            for tx in 0..tiles_x {
                for ly in 0..T {
                    let mut span = RowSpan {
                        visits: band.ids.len() as u32,
                        len: 0,
                        weights: band.weights.len() as u32,
                    };
                    let y = b * T + ly;
                    for lane in 0..T {
                        let x = tx * T + lane;
                        if x >= width || y >= height {
                            continue;
                        }
                        for &(id, w) in &lists[(y * width + x) as usize] {
                            assert!(
                                w > 0.0 && w <= MAX_STORED_WEIGHT,
                                "top-K weight {w} outside (0, {MAX_STORED_WEIGHT}]"
                            );
                            band.ids.push(id);
                            band.lanes.push((1 << lane) | (1 << (KEPT_SHIFT + lane)));
                            band.weights.push(store_weight(w));
                            span.len += 1;
                        }
                    }
                    t.rows.push(span);
                }
            }
            t.bands.push(band);
        }
        t
    }

    /// Per pixel (row-major), the summed weight α·T of every Gaussian the render met there
    /// (in the K heaviest or not) for which `counts(id)` holds. Walks each tile row's visits
    /// once, not once per pixel as [`TopK::pixel`] would.
    pub fn weight_where(&self, counts: impl Fn(u32) -> bool + Sync) -> Vec<f32> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut out = vec![0.0f32; w * h];
        if w == 0 {
            return out;
        }
        let rows_per_band = self.tiles_x as usize * T as usize;
        out.par_chunks_mut(T as usize * w)
            .zip(&self.bands)
            .enumerate()
            .for_each(|(b, (rows, band))| {
                for (r, span) in self.rows[b * rows_per_band..][..rows_per_band]
                    .iter()
                    .enumerate()
                {
                    let (tx, ly) = (r / T as usize, r % T as usize);
                    let (s, n) = (span.visits as usize, span.len as usize);
                    let mut at = span.weights as usize;
                    for (&id, &lanes) in band.ids[s..s + n].iter().zip(&band.lanes[s..s + n]) {
                        let mut reached = lanes & REACHED;
                        if !counts(id) {
                            at += reached.count_ones() as usize;
                            continue;
                        }
                        while reached != 0 {
                            let x = tx * T as usize + reached.trailing_zeros() as usize;
                            reached &= reached - 1;
                            if let Some(sum) = rows.get_mut(ly * w + x).filter(|_| x < w) {
                                *sum += load_weight(band.weights[at]);
                            }
                            at += 1;
                        }
                    }
                }
            });
        out
    }

    /// Renumbers ids after the map was compacted (`old_to_new` as `GaussianMap::remove_where`
    /// gives it); removed Gaussians (and ids past `old_to_new`) drop out of every list.
    pub fn remap(&mut self, old_to_new: &[Option<u32>]) {
        let rows_per_band = (self.tiles_x * T) as usize;
        for (r, span) in self.rows.iter().enumerate() {
            let (b, tx, ly) = (
                (r / rows_per_band) as u32,
                (r % rows_per_band) as u32 / T,
                r as u32 % T,
            );
            let band = &mut self.bands[b as usize];
            let (s, n) = (span.visits as usize, span.len as usize);
            for (id, lanes) in band.ids[s..s + n].iter_mut().zip(&mut band.lanes[s..s + n]) {
                if let Some(new) = old_to_new.get(*id as usize).copied().flatten() {
                    *id = new;
                    continue;
                }
                let mut kept = *lanes >> KEPT_SHIFT;
                *lanes &= REACHED;
                while kept != 0 {
                    let lane = kept.trailing_zeros();
                    kept &= kept - 1;
                    let p = ((b * T + ly) * self.width + tx * T + lane) as usize;
                    self.count[p] -= 1;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heaviest_first_orders_by_weight_then_front_first() {
        let entries = [(10, 0.1), (11, 0.45), (12, 0.1), (13, 0.2)];
        assert_eq!(
            heaviest_first(&entries, 3),
            vec![(11, 0.45), (13, 0.2), (10, 0.1)]
        );
        assert_eq!(heaviest_first(&entries, 9).len(), 4);
        assert!(heaviest_first(&entries, 0).is_empty());
        assert_eq!(key_rank(topk_key(0.45, 7)), 7);
    }

    /// A 20×3 top-K by hand: one band, two tiles. Tile row 0 of tile 0 has three visits:
    /// Gaussian 7 reaching pixels 0, 2 (weights 0.5, 0.25), Gaussian 8 reaching pixel 2
    /// (0.125, dropped from its top-K), Gaussian 9 reaching pixels 0, 1, 2 (0.0625, 0.1875,
    /// 0.375). (Sums of powers of two: f16 holds them exactly.)
    fn by_hand() -> TopK {
        let mut t = TopK::from_lists(20, 3, &vec![Vec::new(); 60]);
        t.k = 2;
        let band = &mut t.bands[0];
        band.ids = vec![7, 8, 9];
        band.lanes = vec![0b101 | (0b101 << 16), 0b100, 0b111 | (0b111 << 16)];
        band.weights = [0.5, 0.25, 0.125, 0.0625, 0.1875, 0.375]
            .map(store_weight)
            .to_vec();
        t.rows[0] = RowSpan {
            visits: 0,
            len: 3,
            weights: 0,
        };
        t.count[..3].copy_from_slice(&[2, 1, 2]);
        t
    }

    #[test]
    fn pixels_read_their_lanes_of_each_visit() {
        let t = by_hand();
        assert_eq!(t.pixel(0, 0).collect::<Vec<_>>(), [(7, 0.5), (9, 0.0625)]);
        assert_eq!(t.pixel(1, 0).collect::<Vec<_>>(), [(9, 0.1875)]);
        // Gaussian 8's weight is stored (it shifts 9's) but not in pixel 2's top-K.
        assert_eq!(t.pixel(2, 0).collect::<Vec<_>>(), [(7, 0.25), (9, 0.375)]);
        assert_eq!(t.pixel_sorted(2, 0), [(9, 0.375), (7, 0.25)]);
        assert_eq!(t.pixel(3, 0).count(), 0);
        assert_eq!(t.pixel(19, 2).count(), 0);
        assert_eq!(t.entries(), 5);
    }

    #[test]
    fn a_tile_row_yields_the_ids_kept_by_its_chosen_pixels() {
        let t = by_hand();
        let ids = |lanes| t.ids_kept_in_tile_row(0, 0, lanes).collect::<Vec<_>>();
        // Pixel 0 keeps 7 and 9, pixel 1 keeps 9, pixel 2 keeps 7 and 9: 8 only reached it.
        assert_eq!(ids(0b1), [7, 9]);
        assert_eq!(ids(0b10), [9]);
        assert_eq!(ids(0b111), [7, 9]);
        assert_eq!(ids(0b100), [7, 9]);
        assert_eq!(ids(0b1000), Vec::<u32>::new());
        // Against the per-pixel reading on a built top-K, tile by tile and row by row.
        let lists: Vec<Vec<(u32, f32)>> = (0..40u32 * 3)
            .map(|p| (0..p % 4).map(|k| ((p * 7 + k * 3) % 11, 0.5)).collect())
            .collect();
        let built = TopK::from_lists(40, 3, &lists);
        for y in 0..3 {
            for tile_x in 0..built.tiles_x {
                let lanes = 0b1011_0110_0101_1001;
                let mut got: Vec<u32> = built.ids_kept_in_tile_row(y, tile_x, lanes).collect();
                let mut want: Vec<u32> = (0..T)
                    .filter(|x| lanes & (1 << x) != 0 && tile_x * T + x < 40)
                    .flat_map(|x| built.pixel(tile_x * T + x, y).map(|e| e.0))
                    .collect();
                got.sort_unstable();
                got.dedup();
                want.sort_unstable();
                want.dedup();
                assert_eq!(got, want, "row {y}, tile {tile_x}");
            }
        }
    }

    #[test]
    fn weights_are_summed_over_every_gaussian_met_that_counts() {
        let t = by_hand();
        let all = t.weight_where(|_| true);
        assert_eq!(all.len(), 60);
        // Gaussian 8's 0.125 at pixel 2 counts though it is not in that pixel's top-K.
        assert_eq!(all[..4], [0.5625, 0.1875, 0.75, 0.0]);
        let without_9 = t.weight_where(|id| id != 9);
        assert_eq!(without_9[..3], [0.5, 0.0, 0.375]);
        assert!(all[3..].iter().all(|&w| w == 0.0));
    }

    #[test]
    fn remap_drops_removed_gaussians_and_renumbers() {
        let mut t = by_hand();
        // 7 removed; 9 → 4.
        let mut old_to_new = vec![None; 10];
        old_to_new[9] = Some(4);
        old_to_new[8] = Some(3);
        t.remap(&old_to_new);
        assert_eq!(t.pixel(0, 0).collect::<Vec<_>>(), [(4, 0.0625)]);
        assert_eq!(t.pixel(2, 0).collect::<Vec<_>>(), [(4, 0.375)]);
        assert_eq!(t.count[..3], [1, 1, 1]);
        assert_eq!(t.entries(), 3);
    }

    #[test]
    fn lists_round_trip_through_every_band_and_tile() {
        // 35×40 pixels: three tiles across (the last partial), three bands (the last partial).
        let (w, h) = (35u32, 40u32);
        let lists: Vec<Vec<(u32, f32)>> = (0..w * h)
            .map(|p| {
                (0..p % 5)
                    .map(|i| (p * 10 + i, 1.0 / (1 + i) as f32))
                    .collect()
            })
            .collect();
        let t = TopK::from_lists(w, h, &lists);
        assert_eq!((t.tiles_x, t.bands.len(), t.rows.len()), (3, 3, 3 * 3 * 16));
        assert_eq!(t.k, 4);
        for y in 0..h {
            for x in 0..w {
                let got: Vec<(u32, f32)> = t.pixel(x, y).collect();
                let want: Vec<(u32, f32)> = lists[(y * w + x) as usize]
                    .iter()
                    .map(|&(id, w)| (id, stored_weight(w)))
                    .collect();
                assert_eq!(got, want, "({x}, {y})");
            }
        }
        // Every band and tile (the partial ones too) sums into its own pixels.
        let odd = t.weight_where(|id| id % 2 == 1);
        for (p, list) in lists.iter().enumerate() {
            let want: f32 = list
                .iter()
                .filter(|e| e.0 % 2 == 1)
                .map(|e| stored_weight(e.1))
                .sum();
            assert_eq!(odd[p], want, "pixel {p}");
        }
    }

    #[test]
    fn stored_weights_are_within_2_pow_minus_11_over_the_renderers_range() {
        // From the smallest weight the renderer keeps up to 1, 64 steps per octave.
        let lo = crate::blend::MIN_ALPHA * crate::blend::MIN_TRANSMITTANCE;
        let mut w = lo;
        let mut worst = 0.0f64;
        while w < 1.0 {
            let rel = ((stored_weight(w) as f64 - w as f64) / w as f64).abs();
            worst = worst.max(rel);
            w *= 2f32.powf(1.0 / 64.0);
        }
        assert!(worst <= 2f64.powi(-11), "worst relative error {worst}");
        assert!(worst > 2f64.powi(-13), "f16 rounding should show: {worst}");
        // Powers of two are exact; the order of distinct f16s is kept.
        assert_eq!(stored_weight(0.5), 0.5);
        assert!(stored_weight(lo) > 0.0);
        assert!(stored_weight(0.3) < stored_weight(0.31));
    }

    #[test]
    fn remap_drops_removed_and_renumbers() {
        let mut t = TopK::from_lists(
            2,
            1,
            &[
                vec![(0, 0.5), (2, 0.25), (3, 0.125)],
                vec![(1, 0.5), (3, 0.375)],
            ],
        );
        // Gaussians 0 and 3 removed: 1 → 0, 2 → 1.
        t.remap(&[None, Some(0), Some(1), None]);
        assert_eq!(t.gaussians_at(0).collect::<Vec<_>>(), [1]);
        assert_eq!(t.gaussians_at(1).collect::<Vec<_>>(), [0]);
        assert_eq!(t.entries(), 2);
        assert_eq!(t.gaussians_at(2).count(), 0);
        assert_eq!(t.weight_of(0, 1), Some(0.25));
        assert_eq!(t.weight_of(1, 0), Some(0.5));
        assert_eq!(t.weight_of(1, 1), None);
    }

    #[test]
    fn lists_of_every_band_are_found_and_remapped() {
        // 3×40 pixels: three 16-row bands, the last one partial. Pixel p lists p % 7 ids,
        // weights in eighths (f16 holds them exactly).
        let lists: Vec<Vec<(u32, f32)>> = (0..120u32)
            .map(|p| (0..p % 7).map(|i| (p + i, (i + 1) as f32 / 8.0)).collect())
            .collect();
        let mut t = TopK::from_lists(3, 40, &lists);
        assert_eq!(t.pixel_count(), 120);
        assert_eq!(t.entries(), lists.iter().map(Vec::len).sum::<usize>());
        for (p, list) in lists.iter().enumerate() {
            let ids: Vec<u32> = list.iter().map(|e| e.0).collect();
            assert_eq!(t.gaussians_at(p).collect::<Vec<_>>(), ids, "pixel {p}");
        }
        assert_eq!(t.weight_of(104, 106), Some(0.375));
        // Odd ids removed, even ones halved.
        let old_to_new: Vec<Option<u32>> =
            (0..130u32).map(|i| (i % 2 == 0).then_some(i / 2)).collect();
        t.remap(&old_to_new);
        for (p, list) in lists.iter().enumerate() {
            let ids: Vec<u32> = list
                .iter()
                .filter(|e| e.0 % 2 == 0)
                .map(|e| e.0 / 2)
                .collect();
            assert_eq!(t.gaussians_at(p).collect::<Vec<_>>(), ids, "pixel {p}");
        }
        assert_eq!(t.weight_of(104, 53), Some(0.375));
    }
}
