//! Automatic mask generation after SAM's `SamAutomaticMaskGenerator`, at
//! CPU speed: every decoder mask is judged on the decoder's low-resolution
//! logits (predicted IoU first, then stability, then size), survivors keep
//! only the logits around their box, box NMS picks the kept ones, and only
//! those are upsampled to the frame and painted into a label map.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::bitmask::BitMask;
use super::preprocess::SAM_SIDE;
use crate::{SegmentInfo, Segmentation};

/// Side of the decoder's `low_res_masks` (SAM: 256 × 256 over the 1024 input).
pub const LOW_RES_SIDE: usize = 256;

/// Masks whose stability on the cells lies this close to the threshold are
/// re-scored on their full-resolution pixels (cell counts of a mask 20 cells
/// wide differ from the pixel counts by up to ~0.02).
pub const EXACT_STABILITY_MARGIN: f32 = 0.03;

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmgParams {
    /// Prompts on a `points_per_side`² grid (SAM's default 32, ours
    /// [`DEFAULT_POINTS_PER_SIDE`]).
    pub points_per_side: u32,
    /// Drop masks whose predicted IoU is below this (SAM default 0.88).
    pub pred_iou_thresh: f32,
    /// Drop masks whose stability score is below this (SAM default 0.95).
    pub stability_score_thresh: f32,
    /// Logit offset of the stability score (SAM default 1.0).
    pub stability_offset: f32,
    /// Suppress a mask whose box overlaps a better one's by more than this
    /// IoU (SAM's `box_nms_thresh`, 0.7).
    pub nms_iou_thresh: f32,
    /// Drop masks smaller than this many pixels.
    pub min_mask_pixels: usize,
    /// Seeds the per-frame shuffle of label ids.
    pub seed: u64,
}

pub use crate::model_paths::DEFAULT_POINTS_PER_SIDE;

impl Default for AmgParams {
    fn default() -> Self {
        Self {
            points_per_side: DEFAULT_POINTS_PER_SIDE,
            pred_iou_thresh: 0.88,
            stability_score_thresh: 0.95,
            stability_offset: 1.0,
            nms_iou_thresh: 0.7,
            min_mask_pixels: 100,
            seed: 0x5a3_5eed,
        }
    }
}

/// A mask that passed the filters, with its confidence.
#[derive(Debug, Clone)]
pub struct MaskCandidate {
    pub mask: BitMask,
    pub predicted_iou: f32,
    pub stability: f32,
}

/// Cell centres of an n × n grid over a `width` × `height` image (pixels).
pub fn point_grid(n: u32, width: usize, height: usize) -> Vec<[f32; 2]> {
    let n = n.max(1);
    let step = |extent: usize, i: u32| (i as f32 + 0.5) / n as f32 * extent as f32 - 0.5;
    (0..n)
        .flat_map(|j| (0..n).map(move |i| [step(width, i), step(height, j)]))
        .collect()
}

/// IoU between the mask thresholded at +offset and at −offset: high when the
/// mask barely changes with the threshold (whole-slice form, for the reference).
#[cfg(test)]
pub fn stability_score(logits: &[f32], offset: f32) -> f32 {
    let (tight, loose) = stability_counts(logits, offset);
    if loose == 0 {
        0.0
    } else {
        tight as f32 / loose as f32
    }
}

/// Logits above +offset and above −offset.
fn stability_counts(logits: &[f32], offset: f32) -> (usize, usize) {
    // u32 lanes let the compiler vectorise the compare-and-count.
    let (mut tight, mut loose) = (0u32, 0u32);
    for &l in logits {
        tight += (l > offset) as u32;
        loose += (l > -offset) as u32;
    }
    (tight as usize, loose as usize)
}

/// IoU of two inclusive boxes `[x0, y0, x1, y1]` in whole cells or pixels.
pub fn box_iou(a: [usize; 4], b: [usize; 4]) -> f32 {
    let area = |r: [usize; 4]| (r[2] + 1 - r[0]) * (r[3] + 1 - r[1]);
    let (x0, y0) = (a[0].max(b[0]), a[1].max(b[1]));
    let (x1, y1) = (a[2].min(b[2]), a[3].min(b[3]));
    let inter = if x0 <= x1 && y0 <= y1 {
        (x1 + 1 - x0) * (y1 + 1 - y0)
    } else {
        0
    };
    inter as f32 / (area(a) + area(b) - inter) as f32
}

/// Where a `width` × `height` frame lies in the decoder's low-resolution
/// logits: SAM scales the longest side to 1024 and pads bottom/right, so the
/// frame covers the top-left `extent` cells of the 256 × 256 grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LowResFrame {
    pub width: usize,
    pub height: usize,
    /// Cells holding the frame (the last one partly), ≤ the grid side.
    pub cols: usize,
    pub rows: usize,
    /// Row stride of the decoder's logits.
    pub stride: usize,
    /// The frame's exact extent in cells (x, y).
    extent: [f32; 2],
}

impl LowResFrame {
    /// The frame in a `side` × `side` grid over SAM's 1024 input.
    pub fn new(width: usize, height: usize, side: usize) -> Self {
        let scale = SAM_SIDE as f32 / width.max(height).max(1) as f32;
        // Resized size as the encoder input has it, then in cells.
        let resized = |n: usize| ((n as f32 * scale + 0.5) as usize).min(SAM_SIDE);
        let extent = |n: usize| resized(n) as f32 * side as f32 / SAM_SIDE as f32;
        let cells = |e: f32| (e.ceil() as usize).clamp(1, side);
        let extent = [extent(width), extent(height)];
        Self {
            width,
            height,
            cols: cells(extent[0]),
            rows: cells(extent[1]),
            stride: side,
            extent,
        }
    }

    /// Frame pixels per low-resolution cell (area).
    fn pixels_per_cell(&self) -> f32 {
        (self.width * self.height) as f32 / (self.extent[0] * self.extent[1])
    }

    /// Bilinear taps (pixel-centre mapping, borders clamped) of every frame
    /// column (`vertical` false) or row into the cells.
    fn taps(&self, vertical: bool) -> Vec<Tap> {
        let (n, extent, cells) = if vertical {
            (self.height, self.extent[1], self.rows)
        } else {
            (self.width, self.extent[0], self.cols)
        };
        (0..n)
            .map(|i| {
                let s = ((i as f32 + 0.5) * extent / n as f32 - 0.5).clamp(0.0, (cells - 1) as f32);
                let i0 = s.floor() as usize;
                Tap {
                    i0,
                    i1: (i0 + 1).min(cells - 1),
                    f: s - i0 as f32,
                }
            })
            .collect()
    }
}

/// One bilinear tap: cells `i0`, `i1` with weight `f` on `i1`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tap {
    i0: usize,
    i1: usize,
    f: f32,
}

/// A decoder mask that passed the cheap filters.
#[derive(Debug, Clone, PartialEq)]
pub struct Survivor {
    /// Which prompt and which of its masks (for callers and tests).
    pub prompt: usize,
    pub mask: usize,
    pub predicted_iou: f32,
    /// Stability score on the cells (on the pixels near the threshold).
    pub stability: f32,
    /// Cells with a positive logit, and their inclusive box.
    pub cells: usize,
    pub bbox: [usize; 4],
    /// The stored logits: the box of logits above −offset grown by one cell
    /// (all that upsampling reads), at `offset` in the arena.
    crop: [usize; 4],
    offset: usize,
}

/// Automatic mask generation on low-resolution logits; its buffers live
/// from frame to frame.
#[derive(Debug)]
pub struct MaskGenerator {
    frame: LowResFrame,
    columns: Vec<Tap>,
    rows: Vec<Tap>,
    survivors: Vec<Survivor>,
    arena: Vec<f32>,
    kept: Vec<usize>,
}

impl Default for MaskGenerator {
    fn default() -> Self {
        Self {
            frame: LowResFrame::new(0, 0, LOW_RES_SIDE),
            columns: Vec::new(),
            rows: Vec::new(),
            survivors: Vec::new(),
            arena: Vec::new(),
            kept: Vec::new(),
        }
    }
}

impl MaskGenerator {
    /// Starts a frame: forgets the last one's masks, keeps the buffers.
    pub fn begin(&mut self, frame: LowResFrame) {
        if frame != self.frame || self.columns.len() != frame.width {
            self.columns = frame.taps(false);
            self.rows = frame.taps(true);
            self.frame = frame;
        }
        self.survivors.clear();
        self.arena.clear();
        self.kept.clear();
    }

    pub fn frame(&self) -> &LowResFrame {
        &self.frame
    }

    /// Masks that passed the filters so far.
    pub fn survivors(&self) -> &[Survivor] {
        &self.survivors
    }

    /// Offers one decoder mask: `logits` holds at least the frame's rows of
    /// `stride` cells. Filters, cheapest first: predicted IoU, stability,
    /// size; a survivor keeps only the logits around its box. True if kept.
    /// Stability and size come from the cells; a mask within
    /// [`EXACT_STABILITY_MARGIN`] of the stability threshold, or of a size
    /// near the minimum, is re-scored on its full-resolution pixels.
    pub fn offer(
        &mut self,
        logits: &[f32],
        predicted_iou: f32,
        prompt: usize,
        mask: usize,
        params: &AmgParams,
    ) -> bool {
        let f = self.frame;
        // NaN predictions fail this test too.
        if predicted_iou.is_nan() || predicted_iou < params.pred_iou_thresh {
            return false;
        }
        if logits.len() < (f.rows - 1) * f.stride + f.cols {
            return false;
        }
        let offset = params.stability_offset;
        let row = |y: usize| &logits[y * f.stride..y * f.stride + f.cols];
        let (mut tight, mut loose) = (0, 0);
        for y in 0..f.rows {
            let (t, l) = stability_counts(row(y), offset);
            tight += t;
            loose += l;
        }
        let mut stability = if loose == 0 {
            0.0
        } else {
            tight as f32 / loose as f32
        };
        let thresh = params.stability_score_thresh;
        if stability < thresh - EXACT_STABILITY_MARGIN {
            return false;
        }
        // Boxes of the mask (logit > 0) and of its loose version (> −offset).
        let (mut cells, mut bbox) = (0, EMPTY_BOX);
        let mut loose_box = EMPTY_BOX;
        for y in 0..f.rows {
            let r = row(y);
            let Some(x0) = r.iter().position(|&l| l > -offset) else {
                continue;
            };
            let x1 = r.iter().rposition(|&l| l > -offset).unwrap_or(x0);
            loose_box = grow(loose_box, x0, x1, y);
            let inside = &r[x0..=x1];
            if let Some(p0) = inside.iter().position(|&l| l > 0.0) {
                let p1 = inside.iter().rposition(|&l| l > 0.0).unwrap_or(p0);
                bbox = grow(bbox, x0 + p0, x0 + p1, y);
                cells += inside[p0..=p1].iter().filter(|&&l| l > 0.0).count();
            }
        }
        if cells == 0 {
            return false;
        }
        let min_pixels = params.min_mask_pixels.max(1) as f32;
        let mut pixels = cells as f32 * f.pixels_per_cell();
        // The stored cells: both boxes grown by one, all any pixel reads.
        let crop = [
            loose_box[0].min(bbox[0]).saturating_sub(1),
            loose_box[1].min(bbox[1]).saturating_sub(1),
            (loose_box[2].max(bbox[2]) + 1).min(f.cols - 1),
            (loose_box[3].max(bbox[3]) + 1).min(f.rows - 1),
        ];
        let start = self.arena.len();
        for y in crop[1]..=crop[3] {
            self.arena
                .extend_from_slice(&logits[y * f.stride + crop[0]..=y * f.stride + crop[2]]);
        }
        let mut survivor = Survivor {
            prompt,
            mask,
            predicted_iou,
            stability,
            cells,
            bbox,
            crop,
            offset: start,
        };
        let near_size = pixels < 2.0 * min_pixels && pixels * 2.0 >= min_pixels;
        if stability < thresh + EXACT_STABILITY_MARGIN || near_size {
            let (mut tight, mut loose, mut positive) = (0usize, 0usize, 0usize);
            self.walk(&survivor, loose_box, |_, _, l| {
                tight += (l > offset) as usize;
                loose += (l > -offset) as usize;
                positive += (l > 0.0) as usize;
            });
            stability = if loose == 0 {
                0.0
            } else {
                tight as f32 / loose as f32
            };
            survivor.stability = stability;
            pixels = positive as f32;
        }
        if stability < thresh || pixels < min_pixels {
            self.arena.truncate(start);
            return false;
        }
        self.survivors.push(survivor);
        true
    }

    /// Offers the `ious.len()` masks of one prompt (`plane(c)` = mask c's
    /// logits): all of them, or with `best_only` (box prompts) only the one
    /// of highest predicted IoU that passes the filters.
    pub fn offer_prompt<'a>(
        &mut self,
        plane: impl Fn(usize) -> &'a [f32],
        ious: &[f32],
        prompt: usize,
        best_only: bool,
        params: &AmgParams,
    ) {
        if best_only {
            let mut order: Vec<usize> = (0..ious.len()).collect();
            order.sort_by(|&a, &b| ious[b].total_cmp(&ious[a]));
            order
                .into_iter()
                .find(|&c| self.offer(plane(c), ious[c], prompt, c, params));
        } else {
            for (c, &iou) in ious.iter().enumerate() {
                self.offer(plane(c), iou, prompt, c, params);
            }
        }
    }

    /// Greedy NMS of the survivors on their boxes, by predicted IoU then
    /// stability: indices into [`Self::survivors`], best first.
    pub fn suppress(&mut self, iou_thresh: f32) -> &[usize] {
        let s = &self.survivors;
        let mut order: Vec<usize> = (0..s.len()).collect();
        order.sort_by(|&a, &b| {
            s[b].predicted_iou
                .total_cmp(&s[a].predicted_iou)
                .then(s[b].stability.total_cmp(&s[a].stability))
        });
        self.kept.clear();
        for i in order {
            if self
                .kept
                .iter()
                .all(|&k| box_iou(s[k].bbox, s[i].bbox) <= iou_thresh)
            {
                self.kept.push(i);
            }
        }
        &self.kept
    }

    /// The kept survivors upsampled to the frame (bilinear, logit > 0),
    /// those still at least `min_pixels` large.
    pub fn upsample_kept(&self, min_pixels: usize) -> Vec<MaskCandidate> {
        self.kept
            .iter()
            .map(|&k| self.upsample(&self.survivors[k]))
            .filter(|c| c.mask.area >= min_pixels.max(1))
            .collect()
    }

    fn upsample(&self, s: &Survivor) -> MaskCandidate {
        let w = self.frame.width;
        let mut mask = BitMask::zeros(w * self.frame.height);
        self.walk(s, s.bbox, |x, y, l| {
            if l > 0.0 {
                mask.insert(x, y, w);
            }
        });
        MaskCandidate {
            mask,
            predicted_iou: s.predicted_iou,
            stability: s.stability,
        }
    }

    /// Calls `f(x, y, logit)` for the frame pixels that can see a cell of
    /// `cells` (inclusive box, inside `s.crop` grown by one): those whose
    /// left/top tap lies in the box grown by one cell to the left/top. All
    /// other pixels have their four neighbours outside the box, so their
    /// bilinear logit is no more than the largest logit outside it.
    fn walk(&self, s: &Survivor, cells: [usize; 4], mut f: impl FnMut(usize, usize, f32)) {
        let [cx0, cy0, cx1, _] = s.crop;
        let crop_w = cx1 + 1 - cx0;
        let range = |taps: &[Tap], lo: usize, hi: usize| {
            taps.partition_point(|t| t.i0 < lo)..taps.partition_point(|t| t.i0 <= hi)
        };
        let xs = range(&self.columns, cells[0].saturating_sub(1), cells[2]);
        let ys = range(&self.rows, cells[1].saturating_sub(1), cells[3]);
        let logits = &self.arena[s.offset..];
        for y in ys {
            let ty = self.rows[y];
            let r0 = &logits[(ty.i0 - cy0) * crop_w..];
            let r1 = &logits[(ty.i1 - cy0) * crop_w..];
            for x in xs.clone() {
                let tx = self.columns[x];
                let (a, b) = (tx.i0 - cx0, tx.i1 - cx0);
                let top = r0[a] + (r0[b] - r0[a]) * tx.f;
                let bottom = r1[a] + (r1[b] - r1[a]) * tx.f;
                f(x, y, top + (bottom - top) * ty.f);
            }
        }
    }
}

/// No cell yet: [x0, y0, x1, y1] with x0 > x1.
const EMPTY_BOX: [usize; 4] = [usize::MAX, usize::MAX, 0, 0];

/// `b` grown by cells x0..=x1 of row y (rows come in increasing order).
fn grow(b: [usize; 4], x0: usize, x1: usize, y: usize) -> [usize; 4] {
    [b[0].min(x0), b[1].min(y), b[2].max(x1), y]
}

/// Paints masks largest first so smaller (nested, in front) masks stay
/// visible; labels are shuffled per frame; masks left with no visible pixel
/// are dropped. Confidence = predicted IoU; class-agnostic.
pub fn paint(mut masks: Vec<MaskCandidate>, width: u32, height: u32, seed: u64) -> Segmentation {
    masks.sort_by_key(|c| std::cmp::Reverse(c.mask.area));
    let (w, n) = (width as usize, width as usize * height as usize);
    // Mask index + 1 per pixel (0 = none), turned into label ids in place.
    let mut label_map = vec![0u32; n];
    for (m, c) in masks.iter().enumerate() {
        if c.mask.area == 0 {
            continue;
        }
        let [x0, y0, x1, y1] = c.mask.bbox;
        for y in y0..=y1 {
            for x in x0..=x1 {
                if c.mask.contains(y * w + x) {
                    label_map[y * w + x] = m as u32 + 1;
                }
            }
        }
    }
    let mut visible = vec![false; masks.len()];
    for &o in &label_map {
        if o != 0 {
            visible[o as usize - 1] = true;
        }
    }
    let mut ids: Vec<u32> = (1..=masks.len() as u32).collect();
    ids.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    for o in label_map.iter_mut().filter(|o| **o != 0) {
        *o = ids[*o as usize - 1];
    }
    let mut labels: Vec<SegmentInfo> = masks
        .iter()
        .enumerate()
        .filter(|(m, _)| visible[*m])
        .map(|(m, c)| SegmentInfo {
            label: ids[m],
            confidence: c.predicted_iou.clamp(0.0, 1.0),
            class: None,
            score: 0.0,
        })
        .collect();
    labels.sort_unstable_by_key(|s| s.label);
    Segmentation {
        width,
        height,
        label_map,
        labels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sam::reference::{self, DecoderMask};

    const S: usize = LOW_RES_SIDE;

    /// S × S logits, `strength` inside the square [x0, x0+side)², −`strength` outside.
    fn square(x0: usize, y0: usize, side: usize, strength: f32) -> Vec<f32> {
        (0..S * S)
            .map(|i| {
                let (x, y) = (i % S, i / S);
                if (x0..x0 + side).contains(&x) && (y0..y0 + side).contains(&y) {
                    strength
                } else {
                    -strength
                }
            })
            .collect()
    }

    /// S × S logits `gain · (1 − r²)` of an ellipse (cells): stability
    /// (gain − 1) / (gain + 1) at any resolution.
    fn ellipse(cx: f32, cy: f32, rx: f32, ry: f32, gain: f32) -> Vec<f32> {
        (0..S * S)
            .map(|i| {
                let (x, y) = ((i % S) as f32, (i / S) as f32);
                gain * (1.0 - ((x - cx) / rx).powi(2) - ((y - cy) / ry).powi(2))
            })
            .collect()
    }

    #[test]
    fn grid_covers_image_centres() {
        let g = point_grid(2, 100, 50);
        assert_eq!(
            g,
            vec![[24.5, 12.0], [74.5, 12.0], [24.5, 37.0], [74.5, 37.0]]
        );
    }

    #[test]
    fn low_res_frame_follows_sam_resize_and_padding() {
        // 640×480 → 1024×768 → the top 192 of 256 rows, 2.5 × 2.5 pixels a cell.
        let f = LowResFrame::new(640, 480, S);
        assert_eq!(
            (f.cols, f.rows, f.stride, f.extent),
            (256, 192, 256, [256.0, 192.0])
        );
        assert_eq!(f.pixels_per_cell(), 6.25);
        // 641×480 → 1024×767 (766.8 rounded) → 191.75 rows of cells, 192 read.
        let f = LowResFrame::new(641, 480, S);
        assert_eq!((f.cols, f.rows, f.extent), (256, 192, [256.0, 191.75]));
        let f = LowResFrame::new(480, 640, S);
        assert_eq!((f.cols, f.rows), (192, 256));
        // Pixel centres map linearly, (x + 0.5) · 1.6 − 0.5 cells at 160 pixels wide ...
        let taps = LowResFrame::new(160, 120, S).taps(false);
        assert_eq!((taps[0].i0, taps[0].i1), (0, 1));
        assert!((taps[0].f - 0.3).abs() < 1e-5, "{:?}", taps[0]);
        assert_eq!((taps[159].i0, taps[159].i1), (254, 255));
        assert!((taps[159].f - 0.7).abs() < 1e-5, "{:?}", taps[159]);
        // ... and (x + 0.5) · 0.4 − 0.5 at 640, clamped at both borders.
        let taps = LowResFrame::new(640, 480, S).taps(false);
        assert_eq!((taps[0].i0, taps[0].i1, taps[0].f), (0, 1, 0.0));
        assert_eq!((taps[639].i0, taps[639].i1, taps[639].f), (255, 255, 0.0));
    }

    #[test]
    fn filters_nms_and_painting() {
        let p = AmgParams {
            min_mask_pixels: 4,
            ..AmgParams::default()
        };
        // A 256 × 256 frame: one pixel per cell, so upsampling copies cells.
        let (w, h) = (256, 256);
        let mut g = MaskGenerator::default();
        g.begin(LowResFrame::new(w, h, S));
        // Confident big square, a near-duplicate, a nested small one; rejects.
        let big = square(0, 0, 10, 5.0);
        assert!(
            !g.offer(&square(12, 12, 5, 0.5), 0.99, 0, 0, &p),
            "stability 0"
        );
        assert!(!g.offer(&big, 0.5, 0, 1, &p), "low predicted IoU");
        assert!(!g.offer(&big, f32::NAN, 0, 2, &p), "NaN IoU");
        assert!(
            !g.offer(&square(30, 30, 1, 5.0), 0.99, 0, 3, &p),
            "1 pixel < 4"
        );
        assert!(g.offer(&big, 0.95, 1, 0, &p));
        assert!(g.offer(&square(0, 0, 9, 5.0), 0.90, 2, 0, &p));
        assert!(g.offer(&square(2, 2, 3, 5.0), 0.92, 3, 0, &p));
        let s = g.survivors();
        assert_eq!(
            (s[0].cells, s[0].bbox, s[0].stability),
            (100, [0, 0, 9, 9], 1.0)
        );
        assert_eq!((s[2].cells, s[2].bbox), (9, [2, 2, 4, 4]));
        // Only the box grown by a cell is stored: 11 × 11 + 10 × 10 + 5 × 5.
        assert_eq!(g.arena.len(), 121 + 100 + 25);
        assert_eq!(box_iou([0, 0, 9, 9], [0, 0, 8, 8]), 0.81);
        assert_eq!(
            g.suppress(p.nms_iou_thresh),
            &[0, 2],
            "duplicate suppressed (box IoU 0.81)"
        );
        let kept = g.upsample_kept(p.min_mask_pixels);
        let areas: Vec<usize> = kept.iter().map(|c| c.mask.area).collect();
        assert_eq!(areas, vec![100, 9]);
        assert_eq!(kept[1].mask.bbox, [2, 2, 4, 4]);
        let seg = paint(kept, w as u32, h as u32, 1);
        assert_eq!(seg.labels.len(), 2);
        let at = |x: usize, y: usize| seg.label_map[y * w + x];
        assert_ne!(at(3, 3), at(8, 8), "small mask painted over the big one");
        assert_ne!(at(8, 8), 0);
        assert_eq!(at(15, 15), 0, "outside every mask");
        let conf: Vec<f32> = seg.labels.iter().map(|s| s.confidence).collect();
        assert!(conf.contains(&0.95) && conf.contains(&0.92), "{conf:?}");
        // The next frame starts empty but keeps the buffers.
        let capacity = g.arena.capacity();
        g.begin(LowResFrame::new(w, h, S));
        assert!(g.survivors().is_empty() && g.arena.is_empty());
        assert_eq!(g.arena.capacity(), capacity);
    }

    /// Decoder masks of a 640 × 480 frame (192 valid rows of cells): kept,
    /// duplicates, and masks each filter must drop.
    fn scene() -> Vec<DecoderMask> {
        let mut complement = ellipse(80.0, 70.0, 40.0, 30.0, 100.0);
        complement.iter_mut().for_each(|l| *l = -*l);
        let mut padding_only = vec![-5.0; S * S];
        padding_only[200 * S..].fill(5.0);
        let m = |prompt, mask, logits, predicted_iou| DecoderMask {
            prompt,
            mask,
            logits,
            predicted_iou,
        };
        vec![
            m(0, 0, ellipse(80.0, 70.0, 40.0, 30.0, 100.0), 0.95),
            m(0, 1, ellipse(80.0, 70.0, 38.0, 28.0, 100.0), 0.90),
            m(0, 2, ellipse(80.0, 70.0, 60.0, 50.0, 100.0), 0.80),
            m(1, 0, ellipse(85.0, 75.0, 12.0, 9.0, 100.0), 0.93),
            m(1, 1, ellipse(180.0, 60.0, 20.0, 20.0, 8.0), 0.97),
            m(1, 2, ellipse(180.0, 60.0, 20.0, 20.0, 100.0), f32::NAN),
            m(2, 0, ellipse(190.0, 140.0, 25.0, 18.0, 100.0), 0.91),
            m(2, 1, ellipse(30.0, 160.0, 1.2, 1.2, 100.0), 0.99),
            m(3, 0, ellipse(191.0, 141.0, 24.0, 18.0, 100.0), 0.89),
            m(4, 0, complement, 0.905),
            m(5, 0, ellipse(250.0, 185.0, 15.0, 12.0, 100.0), 0.96),
            m(5, 1, padding_only, 0.99),
            // 8 × 6 cells: 8 of its 149 cells sit on the r = 1 band, so the
            // cells say 0.946; its pixels (as SAM scores it) say ≥ 0.97.
            m(6, 0, ellipse(140.0, 30.0, 8.0, 6.0, 100.0), 0.92),
        ]
    }

    fn fast(
        masks: &[DecoderMask],
        w: usize,
        h: usize,
        p: &AmgParams,
        best_only: bool,
    ) -> (Vec<(usize, usize)>, Vec<MaskCandidate>, Vec<f32>) {
        let mut g = MaskGenerator::default();
        g.begin(LowResFrame::new(w, h, S));
        let mut prompts: Vec<usize> = masks.iter().map(|m| m.prompt).collect();
        prompts.dedup();
        for prompt in prompts {
            let of: Vec<&DecoderMask> = masks.iter().filter(|m| m.prompt == prompt).collect();
            let ious: Vec<f32> = of.iter().map(|m| m.predicted_iou).collect();
            g.offer_prompt(|c| &of[c].logits, &ious, prompt, best_only, p);
        }
        let kept = g.suppress(p.nms_iou_thresh).to_vec();
        let s = g.survivors();

        let ids = kept.iter().map(|&k| (s[k].prompt, s[k].mask)).collect();
        let stability = kept.iter().map(|&k| s[k].stability).collect();
        (ids, g.upsample_kept(p.min_mask_pixels), stability)
    }

    #[test]
    fn low_res_path_keeps_the_full_resolution_reference_set() {
        let p = AmgParams::default();
        let masks = scene();
        let (w, h) = (640, 480);
        let (ids, kept, stability) = fast(&masks, w, h, &p, false);
        // By predicted IoU; the lower duplicates, the 0.80 mask, the unstable
        // one (0.78), the NaN, the 31-pixel speck and the mask living in the
        // padding rows are gone.
        assert_eq!(ids, vec![(5, 0), (0, 0), (1, 0), (6, 0), (2, 0), (4, 0)]);
        let twin = reference::generate(&masks, S, w, h, &p, false);
        let twin_ids: Vec<(usize, usize)> = twin.iter().map(|k| (k.0, k.1)).collect();
        assert_eq!(ids, twin_ids);
        assert_eq!(kept.len(), twin.len());
        for ((fast, twin), stability) in kept.iter().zip(&twin).zip(&stability) {
            // Same pixels: the crop and tap ranges lose nothing.
            assert_eq!(fast.mask, twin.2.mask);
            // Gain 100: (100 − 1) / (100 + 1) = 0.980 in the continuum
            // (the complement of an ellipse: 0.998, its band is small next to it).
            let full = twin.2.stability;
            assert!((0.97..1.0).contains(&full), "{full}");
            if *stability < p.stability_score_thresh + EXACT_STABILITY_MARGIN {
                assert_eq!(*stability, full, "re-scored on the pixels");
            } else {
                assert!((stability - full).abs() < 0.02, "{stability} vs {full}");
            }
        }
        // The small ellipse was re-scored; on its cells alone it would have failed.
        let mut g = MaskGenerator::default();
        g.begin(LowResFrame::new(w, h, S));
        let (tight, loose) = stability_counts(&masks[12].logits[..192 * S], p.stability_offset);
        assert_eq!((tight, loose), (141, 149), "0.946 on the cells");
        assert!(g.offer(&masks[12].logits, 0.92, 6, 0, &p));
        assert!(g.survivors()[0].stability > p.stability_score_thresh);
        // The mask crossing the bottom-right corner ends at the frame.
        assert_eq!(kept[0].mask.bbox[2..], [639, 479]);
        let paint_of = |m: Vec<MaskCandidate>| paint(m, w as u32, h as u32, 7).label_map;
        let twin_masks: Vec<MaskCandidate> = twin.into_iter().map(|k| k.2).collect();
        assert_eq!(paint_of(kept), paint_of(twin_masks));
    }

    #[test]
    fn box_prompts_keep_the_best_passing_mask_of_each_prompt() {
        let p = AmgParams::default();
        let masks = scene();
        let (w, h) = (640, 480);
        let (ids, kept, _) = fast(&masks, w, h, &p, true);
        // Prompt 1's 0.97 mask is unstable and its NaN one never passes, so
        // its 0.93 mask speaks for it; prompt 0 gives only its 0.95 mask.
        assert_eq!(ids, vec![(5, 0), (0, 0), (1, 0), (6, 0), (2, 0), (4, 0)]);
        let twin = reference::generate(&masks, S, w, h, &p, true);
        let twin_ids: Vec<(usize, usize)> = twin.iter().map(|k| (k.0, k.1)).collect();
        assert_eq!(ids, twin_ids);
        for (fast, twin) in kept.iter().zip(&twin) {
            assert_eq!(fast.mask, twin.2.mask);
        }
    }
}
