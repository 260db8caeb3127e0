//! Label areas |ℓ| and intersections I(ℓs, ℓr) from one pass over the pixels.

use std::collections::{BTreeMap, BTreeSet};

// FxHash: the keys are labels from our own pipeline, so SipHash's flood resistance buys nothing.
use rustc_hash::FxHashMap;

/// Pixel counts of both label maps and of every co-occurring (input, rendered) pair, 0 included.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overlap {
    /// |ℓs| per input label.
    pub input_area: BTreeMap<u32, u32>,
    /// |ℓr| per rendered label.
    pub rendered_area: BTreeMap<u32, u32>,
    /// I(ℓs, ℓr) per pair with at least one shared pixel, sorted by (ℓs, ℓr).
    pub pairs: BTreeMap<(u32, u32), u32>,
    /// Whether b leaves out the pixels of ℓr where the input has no label
    /// ([`Overlap::unsegmented_abstain`]).
    pub unsegmented_abstain: bool,
}

impl Overlap {
    /// Counts in one pass; equal-length slices are the caller's job (checked by the consensus).
    pub fn count(input: &[u32], rendered: &[u32]) -> Self {
        let mut runs: FxHashMap<(u32, u32), u32> = FxHashMap::default();
        let mut pixels = input.iter().zip(rendered);
        let Some((&s0, &r0)) = pixels.next() else {
            return Self::default();
        };
        // Segment maps are piecewise constant: hashing once per run, not per pixel, keeps this fast.
        let (mut current, mut run) = ((s0, r0), 1u32);
        for (&s, &r) in pixels {
            if (s, r) == current {
                run += 1;
            } else {
                *runs.entry(current).or_insert(0) += run;
                current = (s, r);
                run = 1;
            }
        }
        *runs.entry(current).or_insert(0) += run;

        let mut overlap = Self::default();
        for (&(s, r), &n) in &runs {
            *overlap.input_area.entry(s).or_insert(0) += n;
            *overlap.rendered_area.entry(r).or_insert(0) += n;
            overlap.pairs.insert((s, r), n);
        }
        overlap
    }

    /// b counts only the pixels of ℓr where the input has a label: where the segmenter says
    /// nothing (no depth, no mask), a rendered label is no evidence against a segment
    /// (docs/METHOD.md §5.5).
    pub fn unsegmented_abstain(mut self, on: bool) -> Self {
        self.unsegmented_abstain = on;
        self
    }

    /// |ℓr| as b's denominator: without the pixels where the input is 0 when those abstain.
    pub fn rendered_segmented_area(&self, r: u32) -> u32 {
        let area = self.rendered_area.get(&r).copied().unwrap_or(0);
        match self.unsegmented_abstain {
            true => area.saturating_sub(self.pairs.get(&(0, r)).copied().unwrap_or(0)),
            false => area,
        }
    }

    /// a = I/|ℓs| and b = I/|ℓr| of a pair (0 when either area is 0); |ℓr| without the
    /// unsegmented pixels when those abstain.
    pub fn ratios(&self, s: u32, r: u32) -> (f64, f64) {
        let i = f64::from(self.pairs.get(&(s, r)).copied().unwrap_or(0));
        let area = |a: Option<&u32>| a.copied().map_or(0.0, f64::from);
        let (ns, nr) = (
            area(self.input_area.get(&s)),
            f64::from(self.rendered_segmented_area(r)),
        );
        let div = |x: f64, n: f64| if n > 0.0 { x / n } else { 0.0 };
        (div(i, ns), div(i, nr))
    }
}

/// Non-zero labels of a row-major label map that meet across a 4-neighbour edge, as
/// (smaller, larger) pairs.
pub fn touching_labels(label_map: &[u32], width: usize) -> BTreeSet<(u32, u32)> {
    let mut pairs = BTreeSet::new();
    if width == 0 {
        return pairs;
    }
    let mut meet = |a: u32, b: u32| {
        if a != b && a != 0 && b != 0 {
            pairs.insert((a.min(b), a.max(b)));
        }
    };
    for (y, row) in label_map.chunks_exact(width).enumerate() {
        for x in 1..width {
            meet(row[x - 1], row[x]);
        }
        if y > 0 {
            let above = &label_map[(y - 1) * width..y * width];
            for (&a, &b) in above.iter().zip(row) {
                meet(a, b);
            }
        }
    }
    pairs
}
