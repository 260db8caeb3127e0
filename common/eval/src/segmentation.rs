//! Instance segmentation scores over a whole sequence (docs/METHOD.md §9): one global one-to-one
//! matching of predicted labels to ground-truth instances, so a label that changes id between
//! views is penalised.
//!
//! Pixels whose ground truth is 0 (no instance) are ignored; predicted label 0 means "no
//! label" and never matches an instance. IoU of (ℓ, g) = I / (|ℓ| + |g| − I) with |ℓ| counted
//! over scored pixels only. The matching maximises the summed IoU (Hungarian algorithm);
//! mIoU is the mean over ground-truth instances (unmatched ones count 0), accuracy the
//! fraction of scored pixels whose predicted label is matched to their instance.

use std::collections::{BTreeMap, HashMap};

use pathfinding::prelude::{kuhn_munkres, Matrix};
use serde::{Deserialize, Serialize};

/// Pixel counts accumulated over frames: (predicted, ground truth) pairs and areas.
#[derive(Debug, Clone, Default)]
pub struct LabelConfusion {
    pairs: HashMap<(u32, u32), u64>,
    predicted: HashMap<u32, u64>,
    truth: BTreeMap<u32, u64>,
    frames: usize,
}

/// One ground-truth instance after the matching.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InstanceScore {
    pub instance: u32,
    /// Scored pixels of the instance over all frames.
    pub pixels: u64,
    /// Predicted label matched to it (None: no label left to match).
    pub label: Option<u32>,
    pub iou: f64,
    /// Share of the instance's pixels carrying its most frequent predicted label (0 included):
    /// 1.0 means one dominant label.
    pub dominant_share: f64,
    /// That most frequent predicted label.
    pub dominant_label: u32,
}

/// Scores of a sequence, in percent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SegmentationScore {
    pub miou: f64,
    pub acc: f64,
    pub frames: usize,
    pub predicted_labels: usize,
    pub instances: Vec<InstanceScore>,
}

impl LabelConfusion {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one frame. `predicted` and `truth` are row-major maps of the same size.
    pub fn add_frame(&mut self, predicted: &[u32], truth: &[u32]) -> Result<(), String> {
        if predicted.len() != truth.len() {
            return Err(format!(
                "predicted label map has {} pixels, ground truth {}",
                predicted.len(),
                truth.len()
            ));
        }
        // Runs of equal pairs along a row are common: count them before hashing.
        let mut run: Option<((u32, u32), u64)> = None;
        for (&p, &g) in predicted.iter().zip(truth) {
            if g == 0 {
                continue;
            }
            match &mut run {
                Some((key, n)) if *key == (p, g) => *n += 1,
                _ => {
                    if let Some((key, n)) = run.take() {
                        self.add(key, n);
                    }
                    run = Some(((p, g), 1));
                }
            }
        }
        if let Some((key, n)) = run {
            self.add(key, n);
        }
        self.frames += 1;
        Ok(())
    }

    fn add(&mut self, (p, g): (u32, u32), n: u64) {
        *self.pairs.entry((p, g)).or_insert(0) += n;
        *self.predicted.entry(p).or_insert(0) += n;
        *self.truth.entry(g).or_insert(0) += n;
    }

    pub fn frames(&self) -> usize {
        self.frames
    }

    fn iou(&self, p: u32, g: u32) -> f64 {
        let i = self.pairs.get(&(p, g)).copied().unwrap_or(0) as f64;
        let union = self.predicted.get(&p).copied().unwrap_or(0) as f64
            + self.truth.get(&g).copied().unwrap_or(0) as f64
            - i;
        if union > 0.0 {
            i / union
        } else {
            0.0
        }
    }

    /// Global one-to-one matching and the resulting scores (None when nothing was scored).
    pub fn score(&self) -> Option<SegmentationScore> {
        if self.truth.is_empty() {
            return None;
        }
        let instances: Vec<u32> = self.truth.keys().copied().collect();
        let mut labels: Vec<u32> = self.predicted.keys().copied().filter(|&p| p != 0).collect();
        labels.sort_unstable();
        // kuhn_munkres needs rows ≤ columns: pad with "no label" columns.
        let columns = labels.len().max(instances.len());
        const SCALE: f64 = 1e9;
        let mut weights = Matrix::new(instances.len(), columns, 0i64);
        for (r, &g) in instances.iter().enumerate() {
            for (c, &p) in labels.iter().enumerate() {
                weights[(r, c)] = (self.iou(p, g) * SCALE).round() as i64;
            }
        }
        let (_, assignment) = kuhn_munkres(&weights);
        let mut scores = Vec::with_capacity(instances.len());
        let (mut iou_sum, mut correct) = (0.0, 0u64);
        for (r, &g) in instances.iter().enumerate() {
            let label = labels.get(assignment[r]).copied();
            let iou = label.map_or(0.0, |p| self.iou(p, g));
            if let Some(p) = label {
                correct += self.pairs.get(&(p, g)).copied().unwrap_or(0);
            }
            let pixels = self.truth[&g];
            let (dominant_label, dominant) = self
                .pairs
                .iter()
                .filter(|((_, gg), _)| *gg == g)
                .map(|(&(p, _), &n)| (p, n))
                .max_by_key(|&(p, n)| (n, std::cmp::Reverse(p)))
                .unwrap_or((0, 0));
            iou_sum += iou;
            scores.push(InstanceScore {
                instance: g,
                pixels,
                label,
                iou,
                dominant_share: dominant as f64 / pixels as f64,
                dominant_label,
            });
        }
        let total: u64 = self.truth.values().sum();
        Some(SegmentationScore {
            miou: 100.0 * iou_sum / instances.len() as f64,
            acc: 100.0 * correct as f64 / total as f64,
            frames: self.frames,
            predicted_labels: labels.len(),
            instances: scores,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn consistent_labels_score_perfectly() {
        let mut c = LabelConfusion::new();
        c.add_frame(&[7, 7, 9, 9, 0], &[1, 1, 2, 2, 0]).unwrap();
        c.add_frame(&[9, 7, 7, 0], &[2, 1, 1, 0]).unwrap();
        let s = c.score().unwrap();
        assert_relative_eq!(s.miou, 100.0);
        assert_relative_eq!(s.acc, 100.0);
        assert_eq!(s.instances[0].label, Some(7));
        assert_eq!(s.instances[1].label, Some(9));
    }

    #[test]
    fn a_label_that_changes_id_between_views_is_penalised() {
        // Frame 1 calls instance 1 "5", frame 2 calls it "6": one of them cannot match.
        let mut c = LabelConfusion::new();
        c.add_frame(&[5, 5, 5, 5], &[1, 1, 1, 1]).unwrap();
        c.add_frame(&[6, 6, 6, 6], &[1, 1, 1, 1]).unwrap();
        let s = c.score().unwrap();
        // Matched 5: I = 4, |5| = 4, |g| = 8 → IoU 0.5; acc 4 / 8.
        assert_relative_eq!(s.miou, 50.0);
        assert_relative_eq!(s.acc, 50.0);
        assert_relative_eq!(s.instances[0].dominant_share, 0.5);
    }

    #[test]
    fn matching_is_one_to_one_and_maximises_total_iou() {
        // Label 3 overlaps both instances; the best total gives 3 → instance 2, 4 → instance 1.
        let pred = [3, 3, 3, 4, 3, 3, 3, 3];
        let truth = [1, 1, 1, 1, 2, 2, 2, 2];
        let mut c = LabelConfusion::new();
        c.add_frame(&pred, &truth).unwrap();
        let s = c.score().unwrap();
        // IoU(3,1) = 3/8, IoU(3,2) = 4/7, IoU(4,1) = 1/4, IoU(4,2) = 0.
        // 3→2 + 4→1 = 4/7 + 1/4 = 0.821 > 3→1 + 4→2 = 0.375.
        assert_eq!(s.instances[0].label, Some(4));
        assert_eq!(s.instances[1].label, Some(3));
        assert_relative_eq!(s.miou, 100.0 * (0.25 + 4.0 / 7.0) / 2.0, epsilon = 1e-9);
        assert_relative_eq!(s.acc, 100.0 * 5.0 / 8.0);
    }

    #[test]
    fn unlabelled_pixels_and_missing_predictions() {
        let mut c = LabelConfusion::new();
        // Instance 2 is never predicted (0 = no label): IoU 0; ground truth 0 ignored.
        c.add_frame(&[1, 0, 0, 8], &[1, 2, 2, 0]).unwrap();
        let s = c.score().unwrap();
        assert_relative_eq!(s.miou, 50.0);
        assert_relative_eq!(s.acc, 100.0 / 3.0, epsilon = 1e-9);
        assert_eq!(s.instances[1].label, None);
        assert!(c.add_frame(&[1], &[1, 2]).is_err());
        assert!(LabelConfusion::new().score().is_none());
    }
}
