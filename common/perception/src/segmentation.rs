//! Segmenter output: a per-pixel label map plus the input Label-Class table.

/// One entry of the input Label-Class table (docs/METHOD.md §6).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentInfo {
    /// Label id as painted in the label map (never 0).
    pub label: u32,
    /// Mask confidence in [0, 1] (predicted IoU for SAM, contrast for classic).
    pub confidence: f32,
    /// Class name when known; `None` for class-agnostic masks.
    pub class: Option<String>,
    /// Class score in [0, 1]; 0 when `class` is `None`.
    pub score: f32,
}

/// Instance segmentation of one frame; label ids are arbitrary per frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Segmentation {
    pub width: u32,
    pub height: u32,
    /// Row-major label per pixel, 0 = no segment.
    pub label_map: Vec<u32>,
    /// One entry per label present in `label_map`, sorted by label.
    pub labels: Vec<SegmentInfo>,
}

impl Segmentation {
    /// Table entry of `label`, if present.
    pub fn info(&self, label: u32) -> Option<&SegmentInfo> {
        self.labels
            .binary_search_by_key(&label, |s| s.label)
            .ok()
            .map(|i| &self.labels[i])
    }

    /// Pixel count per table entry, in `labels` order.
    pub fn pixel_counts(&self) -> Vec<usize> {
        let mut counts = vec![0usize; self.labels.len()];
        for &l in &self.label_map {
            if let Ok(i) = self.labels.binary_search_by_key(&l, |s| s.label) {
                counts[i] += 1;
            }
        }
        counts
    }
}
