//! Mask ↔ box class assignment of the ensemble (docs/METHOD.md §6): every mask
//! label takes the class of the detection box it overlaps best, if that
//! pixel IoU is above 0.5; otherwise it stays class `None` with score 0.0.
//!
//! The ensemble models themselves (tagger, open-vocabulary detector) run in
//! `ensemble` (cargo feature `onnx`); this part needs no runtime.

use crate::Segmentation;

/// A mask needs more than this IoU with a box to take its class.
pub const CLASS_IOU_THRESHOLD: f32 = 0.5;

/// One detector box in original-image pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// `x0, y0, x1, y1` in continuous pixel coordinates (pixel `(x, y)`
    /// covers `[x, x+1) × [y, y+1)`): the box holds the pixels whose centre
    /// lies inside it.
    pub bbox: [f32; 4],
    pub class: String,
    /// Detection score in [0, 1].
    pub score: f32,
}

/// Class and score of one mask given its IoU with each detection: the
/// detection of highest IoU wins if that IoU is above
/// [`CLASS_IOU_THRESHOLD`], else `(None, 0.0)`. Ties go to the higher score.
pub fn assign_class(ious: &[f32], detections: &[Detection]) -> (Option<String>, f32) {
    let best = ious
        .iter()
        .zip(detections)
        .filter(|(iou, _)| iou.is_finite())
        .max_by(|(ia, da), (ib, db)| ia.total_cmp(ib).then(da.score.total_cmp(&db.score)));
    match best {
        Some((&iou, d)) if iou > CLASS_IOU_THRESHOLD => {
            (Some(d.class.clone()), d.score.clamp(0.0, 1.0))
        }
        _ => (None, 0.0),
    }
}

/// Pixel ranges `[x0, x1) × [y0, y1)` whose centres lie in `bbox`, clipped to the image.
pub fn box_pixels(bbox: [f32; 4], width: u32, height: u32) -> [usize; 4] {
    let edge = |v: f32, limit: u32| {
        if v.is_nan() {
            0
        } else {
            (v - 0.5).ceil().clamp(0.0, limit as f32) as usize
        }
    };
    let (x0, x1) = (edge(bbox[0], width), edge(bbox[2], width));
    let (y0, y1) = (edge(bbox[1], height), edge(bbox[3], height));
    [x0, y0, x1.max(x0), y1.max(y0)]
}

/// IoU of every label of `seg` (in `seg.labels` order) with every detection.
pub fn label_box_ious(seg: &Segmentation, detections: &[Detection]) -> Vec<Vec<f32>> {
    let areas = seg.pixel_counts();
    let width = seg.width as usize;
    let mut ious = vec![vec![0.0f32; detections.len()]; seg.labels.len()];
    let mut inside = vec![0usize; seg.labels.len()];
    for (d, det) in detections.iter().enumerate() {
        let [x0, y0, x1, y1] = box_pixels(det.bbox, seg.width, seg.height);
        let box_area = (x1 - x0) * (y1 - y0);
        inside.iter_mut().for_each(|n| *n = 0);
        for y in y0..y1 {
            for &l in &seg.label_map[y * width + x0..y * width + x1] {
                if let Ok(i) = seg.labels.binary_search_by_key(&l, |s| s.label) {
                    inside[i] += 1;
                }
            }
        }
        for (i, &n) in inside.iter().enumerate() {
            let union = areas[i] + box_area - n;
            ious[i][d] = if union == 0 {
                0.0
            } else {
                n as f32 / union as f32
            };
        }
    }
    ious
}

/// Sets class and score of every label of `seg` from the detections.
pub fn classify(seg: &mut Segmentation, detections: &[Detection]) {
    let ious = label_box_ious(seg, detections);
    for (info, ious) in seg.labels.iter_mut().zip(&ious) {
        let (class, score) = assign_class(ious, detections);
        info.class = class;
        info.score = score;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SegmentInfo;

    fn det(class: &str, score: f32, bbox: [f32; 4]) -> Detection {
        Detection {
            bbox,
            class: class.into(),
            score,
        }
    }

    #[test]
    fn highest_iou_above_half_wins() {
        let dets = [det("chair", 0.9, [0.0; 4]), det("table", 0.6, [0.0; 4])];
        assert_eq!(
            assign_class(&[0.501, 0.2], &dets),
            (Some("chair".into()), 0.9)
        );
        assert_eq!(assign_class(&[0.499, 0.2], &dets), (None, 0.0));
        assert_eq!(
            assign_class(&[0.5, 0.5], &dets),
            (None, 0.0),
            "0.5 is not above 0.5"
        );
        assert_eq!(
            assign_class(&[0.55, 0.8], &dets),
            (Some("table".into()), 0.6),
            "highest IoU, not highest score"
        );
        assert_eq!(assign_class(&[], &[]), (None, 0.0));
        assert_eq!(
            assign_class(&[f32::NAN, 0.7], &dets).0.as_deref(),
            Some("table")
        );
    }

    /// 20×20 frame; label 7 is the 10×10 square [0,10)², label 3 the rest.
    fn square_seg() -> Segmentation {
        let label_map = (0..400)
            .map(|i| if i % 20 < 10 && i / 20 < 10 { 7 } else { 3 })
            .collect();
        let info = |label| SegmentInfo {
            label,
            confidence: 1.0,
            class: None,
            score: 0.0,
        };
        Segmentation {
            width: 20,
            height: 20,
            label_map,
            labels: vec![info(3), info(7)],
        }
    }

    #[test]
    fn pixel_iou_just_above_and_just_below_half() {
        // The square (100 px) in a box [0,10)×[0,20) of 200 px: IoU exactly
        // 0.5, which is not above the threshold.
        let mut seg = square_seg();
        let exact_half = det("cup", 0.8, [0.0, 0.0, 10.0, 20.0]);
        classify(&mut seg, std::slice::from_ref(&exact_half));
        assert_eq!(seg.info(7).map(|s| s.class.clone()), Some(None));
        // Box [0,10)×[0,19) = 190 px: IoU 100/190 = 0.526 → "cup".
        let above = det("cup", 0.8, [0.0, 0.0, 10.0, 19.0]);
        let ious = label_box_ious(&seg, std::slice::from_ref(&above));
        assert!((ious[1][0] - 100.0 / 190.0).abs() < 1e-6, "{ious:?}");
        classify(&mut seg, std::slice::from_ref(&above));
        let square = seg.info(7).cloned().expect("label 7");
        assert_eq!((square.class.as_deref(), square.score), (Some("cup"), 0.8));
        // Box [0,11)×[0,19) = 209 px holds the square: IoU 100/209 = 0.478 → None.
        let below = det("cup", 0.8, [0.0, 0.0, 11.0, 19.0]);
        let ious = label_box_ious(&seg, std::slice::from_ref(&below));
        assert!((ious[1][0] - 100.0 / 209.0).abs() < 1e-6, "{ious:?}");
        classify(&mut seg, &[below]);
        let square = seg.info(7).cloned().expect("label 7");
        assert_eq!((square.class, square.score), (None, 0.0));
        // The background (300 px) overlaps that box by 109 px: IoU 109/400.
        let rest = seg.info(3).cloned().expect("label 3");
        assert_eq!((rest.class, rest.score), (None, 0.0));
    }

    #[test]
    fn box_pixels_use_centres_and_clip() {
        assert_eq!(box_pixels([0.4, 0.6, 2.5, 3.6], 10, 10), [0, 1, 2, 4]);
        assert_eq!(box_pixels([-5.0, -5.0, 50.0, 50.0], 10, 8), [0, 0, 10, 8]);
        assert_eq!(box_pixels([6.0, 6.0, 2.0, 2.0], 10, 10), [6, 6, 6, 6]);
        assert_eq!(box_pixels([f32::NAN, 0.0, 1.0, 1.0], 10, 10), [0, 0, 1, 1]);
    }
}
