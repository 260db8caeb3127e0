//! Relations between an input label ℓs and a rendered label ℓr (docs/METHOD.md §5 table).

use serde::{Deserialize, Serialize};

use crate::config::ConsensusConfig;

/// Relation of one (ℓs, ℓr) pair from a = I/|ℓs| and b = I/|ℓr|.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum PairRelation {
    /// a ≥ τ1 and b ≥ τ1: same object in both maps.
    Full,
    /// a ≥ τ2 and τ3 ≤ b < τ1: the input segment is a part of the rendered label.
    Partial,
    /// b ≥ τ2 and τ3 ≤ a < τ1: the rendered label is a part of the input segment.
    Whole,
}

/// Outcome class of one input label after the whole keyframe is resolved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Relation {
    Full,
    /// a ≥ τ2 inside a rendered label that another input label Full-matches: a separate object
    /// the map absorbed into that label (departure from the paper, docs/METHOD.md §5).
    Inside,
    Partial,
    Whole,
    /// a < τ3 for every non-zero ℓr: the segment covers unmapped space.
    New,
    /// No relation of the table, but ℓs and ℓr are each other's largest partner and share over
    /// half of both (departure, docs/METHOD.md §5.5): ℓs takes ℓr, nothing else changes.
    Majority,
    /// Anything else: the segment's pixels become background 0.
    Other,
}

/// The pair relation of the §5 table; Full is tested first (priority), then Partial, then Whole.
pub fn pair_relation(a: f64, b: f64, config: &ConsensusConfig) -> Option<PairRelation> {
    let (t1, t2, t3) = (config.tau_full, config.tau_part, config.tau_min);
    if a >= t1 && b >= t1 {
        Some(PairRelation::Full)
    } else if a >= t2 && t3 <= b && b < t1 {
        Some(PairRelation::Partial)
    } else if b >= t2 && t3 <= a && a < t1 {
        Some(PairRelation::Whole)
    } else {
        None
    }
}
