//! Thresholds and ablation switches of the label consensus (docs/METHOD.md §5).

use serde::{Deserialize, Serialize};

use crate::error::{Result, SemanticsError};

/// Consensus configuration; every threshold of docs/METHOD.md §5 is here, none is a literal in
/// code.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ConsensusConfig {
    /// τ1: Full match needs a ≥ τ1 and b ≥ τ1.
    pub tau_full: f64,
    /// τ2: the containing side of a Partial / Whole match needs ≥ τ2.
    pub tau_part: f64,
    /// τ3: the smallest overlap that still counts (Partial / Whole lower bound, New upper bound).
    pub tau_min: f64,
    /// δ: confidence lost by a map label each time it is identified as a part (§5.1).
    pub part_decay: f32,
    /// Cap on global labels per run (paper: 2000); see `GlobalLabelTable` for the full behaviour.
    pub max_labels: usize,
    /// θ in metres: counter Gaussians with a larger largest scale are pruned (§5.3).
    pub counter_prune_scale: f32,
    /// Ablation switch: segmentation counter pruning (§5.3).
    pub enable_counter_pruning: bool,
    /// Ablation switch: input confidence update from completeness (§5.2).
    pub enable_confidence_update: bool,
    /// Ablation switch: part label decay (§5.1).
    pub enable_part_decay: bool,
    /// Switch of the Inside relation (a departure from the paper, §5.5): off, an object absorbed
    /// into a larger map label stays there.
    pub enable_inside_split: bool,
    /// A departure from the paper (§5.5): for Full and Inside, a = I/|ℓs| counts only the pixels
    /// of ℓs where the map renders a label, and a segment with under τ3 of its pixels mapped
    /// is New. Off, an object half over unmapped space is "other" and its unlabelled
    /// Gaussians never get a label.
    pub unmapped_pixels_abstain: bool,
    /// A departure from the paper (§5.5), the mirror of the one above: b = I/|ℓr| counts only
    /// the pixels of ℓr where the segmenter gave a label, and counter pruning skips the
    /// others. Off, a wall whose map label also renders where the frame has no depth (beyond
    /// the sensor's range) is never a Whole part of the segment of the wall, and stays in
    /// two labels.
    pub unsegmented_pixels_abstain: bool,
    /// A departure from the paper (§5.5): a segment with no relation of the table that shares
    /// over half of its mapped pixels with a map label ℓr, and over half of ℓr's pixels, or
    /// that has τ2 of its mapped pixels in ℓr and covers τ3 of it, takes ℓr (Majority). Off,
    /// it is "other" and its new Gaussians stay unlabelled.
    pub majority_match: bool,
    /// A departure from the paper (§5.5): a map label lying wholly inside (b ≥ τ2) a segment
    /// that Full- or Majority-matches another label, too small for a Whole part (a < τ3), is
    /// decayed as a part and, when C_s beats its C_r, all its Gaussians take that label.
    /// Off, such fragments of a surface keep their own label for good.
    pub absorb_fragments: bool,
    /// Completeness (§5.2) a fragment needs to be absorbed: most of the label is in view, so
    /// a large label seen as a sliver inside a segment is not mistaken for a fragment.
    pub absorb_min_completeness: f32,
    /// Keyframes in a row a label must be a fragment before it is absorbed (and at least as
    /// many as it had a Full or Majority match of its own); such a match in between starts the
    /// count again.
    pub absorb_after_views: u32,
    /// A departure from the paper (§5.5): a Whole merge won by the input moves every Gaussian
    /// of a part that is mostly in view (completeness ≥ `absorb_min_completeness`), hidden
    /// ones too. Off, only those the view meets move, and the rest come back as the part's
    /// label from the next side seen (a sofa in three labels after two merges).
    pub merge_whole_labels: bool,
    /// A departure from the paper (§5.5): of the Partial parts that beat ℓr, one that holds
    /// over half of ℓr's rendered pixels keeps ℓr instead of taking a fresh label. Off, a
    /// table seen whole but for a sliver takes a fresh label over the pixels of this view,
    /// and its hidden side stays on the old one.
    pub partial_majority_keeps: bool,
    /// A departure from the paper (§5.5): a segment mostly over unlabelled Gaussians (under
    /// half of its pixels render a label), all of whose labelled pixels lie in labels that
    /// other segments of the view hold, each of which it covers under τ3, is Inside: an
    /// object beside a held surface that the map left unlabelled. Off, such an object (a box
    /// on a table, once sent to "other") stays unlabelled for good: too few of its pixels
    /// are mapped for Inside's τ2, and the table's fringe on it is over τ3 for New. Its
    /// fresh label goes back to the held label where the mapper finds it on that label's
    /// surface ([`crate::RelabelScope::Rejoin`]): a piece of floor, not a box on a table.
    pub split_unlabelled_objects: bool,
}

impl Default for ConsensusConfig {
    fn default() -> Self {
        Self {
            tau_full: 0.85,
            tau_part: 0.9,
            tau_min: 0.1,
            part_decay: 0.06,
            max_labels: 2000,
            counter_prune_scale: 0.10,
            enable_counter_pruning: true,
            enable_confidence_update: true,
            enable_part_decay: true,
            enable_inside_split: true,
            unmapped_pixels_abstain: true,
            unsegmented_pixels_abstain: true,
            majority_match: true,
            absorb_fragments: true,
            absorb_min_completeness: 0.5,
            absorb_after_views: 3,
            merge_whole_labels: true,
            partial_majority_keeps: true,
            split_unlabelled_objects: true,
        }
    }
}

impl ConsensusConfig {
    /// Checks ranges: thresholds in (0, 1], τ3 < τ1 and τ3 < τ2, δ ≥ 0, θ > 0, cap ≥ 1.
    pub fn validate(&self) -> Result<()> {
        let in_unit = |x: f64| x.is_finite() && x > 0.0 && x <= 1.0;
        if !in_unit(self.tau_full) || !in_unit(self.tau_part) || !in_unit(self.tau_min) {
            return Err(SemanticsError::InvalidConfig(format!(
                "thresholds must lie in (0, 1]: τ1={}, τ2={}, τ3={}",
                self.tau_full, self.tau_part, self.tau_min
            )));
        }
        if self.tau_min >= self.tau_full || self.tau_min >= self.tau_part {
            return Err(SemanticsError::InvalidConfig(format!(
                "τ3={} must be below τ1={} and τ2={}",
                self.tau_min, self.tau_full, self.tau_part
            )));
        }
        if !self.part_decay.is_finite() || self.part_decay < 0.0 {
            return Err(SemanticsError::InvalidConfig(format!(
                "part decay δ={} must be finite and ≥ 0",
                self.part_decay
            )));
        }
        if !self.counter_prune_scale.is_finite() || self.counter_prune_scale <= 0.0 {
            return Err(SemanticsError::InvalidConfig(format!(
                "counter prune scale θ={} must be finite and > 0",
                self.counter_prune_scale
            )));
        }
        if !(0.0..=1.0).contains(&self.absorb_min_completeness) {
            return Err(SemanticsError::InvalidConfig(format!(
                "absorb_min_completeness={} must lie in [0, 1]",
                self.absorb_min_completeness
            )));
        }
        if self.max_labels == 0 {
            return Err(SemanticsError::InvalidConfig(
                "max_labels must be ≥ 1".into(),
            ));
        }
        Ok(())
    }
}
