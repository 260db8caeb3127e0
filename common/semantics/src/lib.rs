//! Label tables and confidence-based 2D label consensus (docs/METHOD.md §3–§5, GitHub issue 7).
//!
//! [`LabelConsensus::process`] takes one keyframe's segmenter output ([`SegmenterInput`]) and
//! the GS Voting render at the same pose ([`RenderedInput`]) and returns plain data
//! ([`ConsensusOutput`]): the mapping ℓs → ℓt, the consistent input label map, relabel
//! instructions for map Gaussians as pixel regions, and counter-pruning regions. The mapper
//! applies those through its per-pixel top-K record (of the same render) with
//! [`apply_relabels`] first, then [`select_counter_gaussians`], so Gaussians just moved to a
//! fresh label are not pruned as counters of their old one. No IPC here.
//!
//! # Decisions where docs/METHOD.md is open
//! - Relations only consider non-zero rendered labels; "New" means a < τ3 for all of them.
//! - Resolution order per input label: Full > Inside > Partial > Whole > New > Majority >
//!   other (Inside and Majority: docs/METHOD.md §5.5). A rendered
//!   label already used as a Full or Partial target is not also a Whole part (only possible at
//!   exact threshold boundaries). With thresholds ≤ 0.5, ties go to the largest I, then the
//!   smallest id.
//! - Every decision reads C_r as it was before the keyframe; updates are applied afterwards in
//!   this order: Full max(C_r, C_s), part decay, merged-label confidence, class observations.
//! - Partial, map wins (C_r > C̄s): all parts → ℓr, C_r unchanged. Otherwise parts with
//!   C_s > C_r get a fresh label (confidence C_s) and the relabel region is *all* pixels of that
//!   input part (from ℓr to ℓt); the other parts → ℓr.
//! - Whole, input wins (C_s > C̄r): the parts merge into the *largest* part's id (ties:
//!   smallest id) so most Gaussians keep their label; each other part is relabelled over *all*
//!   its rendered pixels; the merged label's confidence becomes C_s. Input loses: a pixel of ℓs
//!   takes its rendered label if that is one of the parts; where the map renders nothing it
//!   takes the largest part (the input's grouping extends the object into unmapped space, so
//!   new Gaussians there are labelled); where another label renders, 0.
//! - Part decay (δ, once per label per keyframe, floored at 0): every rendered part of a Whole
//!   match (either outcome) and every Partial target that lost at least one part to a fresh
//!   label.
//! - Input confidence update: Cov_r = 1 on rendered 0; C_s ← C_s · mean Cov_r over ℓs, computed
//!   from the intersection counts. Completeness is only required when the module is on.
//! - Fresh ids are handed out in increasing input-label order, starting at 1. Cap full: a New
//!   segment goes to 0 and a winning Partial part stays on ℓr; both are counted in
//!   `refused_allocations` (no error). Unknown rendered labels are adopted (confidence 0).
//! - Class table: every label an input segment maps to observes that segment's class and
//!   score (Whole-lost: each part); the best score keeps the class; input labels missing from
//!   the input table read as class `None`, score 0.0.
//! - Counter pruning: one region per Full match (symmetric difference, empty ones dropped);
//!   θ is applied by [`select_counter_gaussians`] (config: `counter_prune_scale`).
//! - Performance: intersections are counted in one pass, hashing once per run of equal
//!   (ℓs, ℓr) pairs along a row; a second pass paints the output. Both are O(W·H).
//! - `process` validates everything before it changes state: on error the table is untouched.

mod actions;
pub mod bench;
mod confidence;
mod config;
mod consensus;
mod consistent_map;
mod counter_pruning;
mod error;
mod input;
mod intersection;
mod label_table;
mod matching;
mod output;
mod relabel;
mod relation;

pub use confidence::update_input_confidence;
pub use config::ConsensusConfig;
pub use consensus::LabelConsensus;
pub use counter_pruning::{select_counter_gaussians, select_counter_gaussians_per_pixel};
pub use error::{Result, SemanticsError};
pub use input::{InputLabelClass, RenderedInput, SegmenterInput};
pub use intersection::Overlap;
pub use label_table::{GlobalLabel, GlobalLabelTable, LabelRecord};
pub use matching::Matching;
pub use output::{
    ConsensusOutput, CounterPruneRegion, LabelAssignment, LabelTarget, RelabelInstruction,
    RelabelScope,
};
pub use relabel::{apply_relabels, apply_relabels_centred, validate_regions};
pub use relation::{pair_relation, PairRelation, Relation};
