//! Slow, obviously-correct twin of the automatic mask generation, for tests:
//! every decoder mask is first upsampled to the whole frame, then filtered
//! (predicted IoU, stability, size) and suppressed (box NMS) at full
//! resolution, as SAM's generator does on its full-size masks.

use super::amg::{box_iou, stability_score, AmgParams, MaskCandidate};
use super::bitmask::BitMask;

/// One decoder mask: which prompt and mask, its `side` × `side` low-res
/// logits (row-major) and its predicted IoU.
pub struct DecoderMask {
    pub prompt: usize,
    pub mask: usize,
    pub logits: Vec<f32>,
    pub predicted_iou: f32,
}

/// Full-frame logits of `logits` (a `side` × `side` grid over SAM's 1024
/// input): the frame fills the top-left resized-size / 1024 of the grid;
/// every pixel centre maps linearly into it, bilinear, borders clamped.
pub fn upsample_full(logits: &[f32], side: usize, width: usize, height: usize) -> Vec<f32> {
    let scale = 1024.0 / width.max(height) as f32;
    let extent =
        |n: usize| ((n as f32 * scale + 0.5) as usize).min(1024) as f32 * side as f32 / 1024.0;
    let (ex, ey) = (extent(width), extent(height));
    let (cols, rows) = (ex.ceil() as usize, ey.ceil() as usize);
    let at = |x: usize, y: usize| logits[y * side + x];
    let mut out = Vec::with_capacity(width * height);
    for y in 0..height {
        let sy = ((y as f32 + 0.5) * ey / height as f32 - 0.5).clamp(0.0, (rows - 1) as f32);
        let (y0, fy) = (sy.floor() as usize, sy - sy.floor());
        let y1 = (y0 + 1).min(rows - 1);
        for x in 0..width {
            let sx = ((x as f32 + 0.5) * ex / width as f32 - 0.5).clamp(0.0, (cols - 1) as f32);
            let (x0, fx) = (sx.floor() as usize, sx - sx.floor());
            let x1 = (x0 + 1).min(cols - 1);
            // Same lerp form as the fast path, so both round alike.
            let top = at(x0, y0) + (at(x1, y0) - at(x0, y0)) * fx;
            let bottom = at(x0, y1) + (at(x1, y1) - at(x0, y1)) * fx;
            out.push(top + (bottom - top) * fy);
        }
    }
    out
}

/// The kept masks, best first: (prompt, mask, full-resolution candidate).
/// With `best_only`, each prompt contributes at most its best passing mask.
pub fn generate(
    masks: &[DecoderMask],
    side: usize,
    width: usize,
    height: usize,
    params: &AmgParams,
    best_only: bool,
) -> Vec<(usize, usize, MaskCandidate)> {
    let mut order: Vec<&DecoderMask> = masks.iter().collect();
    if best_only {
        // A prompt's masks best first, so the first that passes is its one.
        order.sort_by(|a, b| {
            a.prompt
                .cmp(&b.prompt)
                .then(b.predicted_iou.total_cmp(&a.predicted_iou))
        });
    }
    let mut candidates: Vec<(usize, usize, MaskCandidate)> = Vec::new();
    for m in order {
        if best_only && candidates.iter().any(|c| c.0 == m.prompt) {
            continue;
        }
        if m.predicted_iou.is_nan() || m.predicted_iou < params.pred_iou_thresh {
            continue;
        }
        let full = upsample_full(&m.logits, side, width, height);
        let stability = stability_score(&full, params.stability_offset);
        if stability < params.stability_score_thresh {
            continue;
        }
        let mask = BitMask::from_fn(&full, width, |l| l > 0.0);
        if mask.area < params.min_mask_pixels.max(1) {
            continue;
        }
        candidates.push((
            m.prompt,
            m.mask,
            MaskCandidate {
                mask,
                predicted_iou: m.predicted_iou,
                stability,
            },
        ));
    }
    candidates.sort_by(|a, b| {
        b.2.predicted_iou
            .total_cmp(&a.2.predicted_iou)
            .then(b.2.stability.total_cmp(&a.2.stability))
    });
    let mut kept: Vec<(usize, usize, MaskCandidate)> = Vec::new();
    for c in candidates {
        if kept
            .iter()
            .all(|k| box_iou(k.2.mask.bbox, c.2.mask.bbox) <= params.nms_iou_thresh)
        {
            kept.push(c);
        }
    }
    kept
}
