//! Automatic mask generation after SAM's `SamAutomaticMaskGenerator`:
//! grid point prompts, predicted-IoU and stability filtering, mask NMS,
//! and painting the survivors into a label map.

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::bitmask::BitMask;
use crate::{SegmentInfo, Segmentation};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmgParams {
    /// Prompts on a `points_per_side`² grid (SAM default 32).
    pub points_per_side: u32,
    /// Drop masks whose predicted IoU is below this (SAM default 0.88).
    pub pred_iou_thresh: f32,
    /// Drop masks whose stability score is below this (SAM default 0.95).
    pub stability_score_thresh: f32,
    /// Logit offset of the stability score (SAM default 1.0).
    pub stability_offset: f32,
    /// Suppress a mask overlapping a better one by more than this IoU (0.7).
    pub nms_iou_thresh: f32,
    /// Drop masks smaller than this many pixels.
    pub min_mask_pixels: usize,
    /// Seeds the per-frame shuffle of label ids.
    pub seed: u64,
}

impl Default for AmgParams {
    fn default() -> Self {
        Self {
            points_per_side: 32,
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
/// mask barely changes with the threshold.
pub fn stability_score(logits: &[f32], offset: f32) -> f32 {
    let (mut tight, mut loose) = (0usize, 0usize);
    for &l in logits {
        tight += (l > offset) as usize;
        loose += (l > -offset) as usize;
    }
    if loose == 0 {
        0.0
    } else {
        tight as f32 / loose as f32
    }
}

/// Applies the IoU, stability and size filters to one decoder mask.
pub fn candidate(
    logits: &[f32],
    width: usize,
    predicted_iou: f32,
    params: &AmgParams,
) -> Option<MaskCandidate> {
    // NaN predictions fail this test too.
    if predicted_iou.is_nan() || predicted_iou < params.pred_iou_thresh {
        return None;
    }
    let stability = stability_score(logits, params.stability_offset);
    if stability < params.stability_score_thresh {
        return None;
    }
    let mask = BitMask::from_fn(logits, width, |l| l > 0.0);
    (mask.area >= params.min_mask_pixels.max(1)).then_some(MaskCandidate {
        mask,
        predicted_iou,
        stability,
    })
}

/// Greedy NMS by predicted IoU (then stability), on mask IoU.
pub fn non_max_suppression(
    mut candidates: Vec<MaskCandidate>,
    iou_thresh: f32,
) -> Vec<MaskCandidate> {
    candidates.sort_by(|a, b| {
        b.predicted_iou
            .total_cmp(&a.predicted_iou)
            .then(b.stability.total_cmp(&a.stability))
    });
    let mut kept: Vec<MaskCandidate> = Vec::new();
    for c in candidates {
        if kept.iter().all(|k| k.mask.iou(&c.mask) <= iou_thresh) {
            kept.push(c);
        }
    }
    kept
}

/// Paints masks largest first so smaller (nested, in front) masks stay
/// visible; labels are shuffled per frame; masks left with no visible pixel
/// are dropped. Confidence = predicted IoU; class-agnostic.
pub fn paint(mut masks: Vec<MaskCandidate>, width: u32, height: u32, seed: u64) -> Segmentation {
    masks.sort_by_key(|c| std::cmp::Reverse(c.mask.area));
    let n = width as usize * height as usize;
    let mut owner = vec![u32::MAX; n];
    for (m, c) in masks.iter().enumerate() {
        for (i, o) in owner.iter_mut().enumerate() {
            if c.mask.contains(i) {
                *o = m as u32;
            }
        }
    }
    let mut visible = vec![false; masks.len()];
    for &o in &owner {
        if o != u32::MAX {
            visible[o as usize] = true;
        }
    }
    let mut ids: Vec<u32> = (1..=masks.len() as u32).collect();
    ids.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
    let label_map = owner
        .iter()
        .map(|&o| if o == u32::MAX { 0 } else { ids[o as usize] })
        .collect();
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

    fn square_logits(
        w: usize,
        h: usize,
        x0: usize,
        y0: usize,
        side: usize,
        strength: f32,
    ) -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                if (x0..x0 + side).contains(&x) && (y0..y0 + side).contains(&y) {
                    strength
                } else {
                    -strength
                }
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
    fn filters_nms_and_painting() {
        let p = AmgParams {
            min_mask_pixels: 4,
            ..AmgParams::default()
        };
        let (w, h) = (20, 20);
        // Confident big square, a near-duplicate, a nested small one, an unstable one.
        let big = square_logits(w, h, 0, 0, 10, 5.0);
        let dup = square_logits(w, h, 0, 0, 9, 5.0);
        let small = square_logits(w, h, 2, 2, 3, 5.0);
        let unstable = square_logits(w, h, 12, 12, 5, 0.5);
        assert!(candidate(&unstable, w, 0.99, &p).is_none(), "stability 0");
        assert!(candidate(&big, w, 0.5, &p).is_none(), "low predicted IoU");
        assert!(candidate(&big, w, f32::NAN, &p).is_none(), "NaN IoU");
        let cands = vec![
            candidate(&big, w, 0.95, &p).expect("big"),
            candidate(&dup, w, 0.90, &p).expect("dup"),
            candidate(&small, w, 0.92, &p).expect("small"),
        ];
        let kept = non_max_suppression(cands, p.nms_iou_thresh);
        assert_eq!(kept.len(), 2, "duplicate suppressed (IoU 0.81)");
        let seg = paint(kept, w as u32, h as u32, 1);
        assert_eq!(seg.labels.len(), 2);
        let at = |x: usize, y: usize| seg.label_map[y * w + x];
        assert_ne!(at(3, 3), at(8, 8), "small mask painted over the big one");
        assert_ne!(at(8, 8), 0);
        assert_eq!(at(15, 15), 0, "outside every mask");
        let conf: Vec<f32> = seg.labels.iter().map(|s| s.confidence).collect();
        assert!(conf.contains(&0.95) && conf.contains(&0.92), "{conf:?}");
    }
}
