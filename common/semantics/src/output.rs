//! Plain-data result of one keyframe's consensus, ready to be sent to the mapper.

use serde::{Deserialize, Serialize};

use crate::relation::Relation;

/// Where the pixels of one input label go in the consistent input label map.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum LabelTarget {
    /// Every pixel of ℓs takes global label ℓt.
    Label(u32),
    /// Every pixel of ℓs becomes background 0.
    Background,
    /// Whole match lost by the input: a pixel takes its rendered label if that label is one of
    /// these parts, else 0.
    RenderedParts(Vec<u32>),
}

/// ℓs → ℓt for one input label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LabelAssignment {
    pub input_label: u32,
    pub relation: Relation,
    pub target: LabelTarget,
    /// C_s after the input confidence update (§5.2), the value the matching used.
    pub confidence: f32,
}

/// Map Gaussians labelled `from` in the top-K lists of `pixels` get label `to` (docs/METHOD.md §4).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RelabelInstruction {
    pub from: u32,
    pub to: u32,
    /// Row-major pixel indices, increasing.
    pub pixels: Vec<u32>,
    /// Which Gaussians labelled `from` change.
    #[serde(default)]
    pub scope: RelabelScope,
}

/// Which Gaussians labelled `from` a relabel instruction changes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum RelabelScope {
    /// Those in the top-K lists of the instruction's pixels (§4).
    #[default]
    Pixels,
    /// Every one in the map: the label as a whole is absorbed (§5.5), hidden Gaussians too.
    /// The mapper applies it only where the label lies on the surface of `to`.
    Label,
    /// Every one in the map, wherever it lies: a Whole merge of a label mostly in view
    /// (§5.5), whose parts need not share a surface (a chair's seat and back).
    Merged,
    /// Every one in the map, after the consistent label map labelled the unlabelled ones: a
    /// fresh label just split off `to` (the unlabelled-object split, §5.5) goes back where it
    /// lies on the surface of `to`. The mapper applies it; [`crate::apply_relabels`] skips it.
    Rejoin,
}

/// Symmetric difference of a Full match's masks: look for Gaussians labelled `label` there (§5.3).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CounterPruneRegion {
    pub label: u32,
    /// Row-major pixel indices, increasing.
    pub pixels: Vec<u32>,
}

/// Everything one keyframe's consensus produces.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct ConsensusOutput {
    /// One entry per non-zero input label present in the map, sorted by input label.
    pub assignments: Vec<LabelAssignment>,
    /// Row-major W×H map of global labels (0 = background).
    pub consistent_label_map: Vec<u32>,
    /// Relabel instructions, to be applied in order.
    pub relabels: Vec<RelabelInstruction>,
    /// Counter-pruning regions (empty when the module is switched off).
    pub counter_pruning: Vec<CounterPruneRegion>,
    /// Fresh labels that the full label table refused (New → 0, Partial part kept on ℓr).
    pub refused_allocations: u32,
}

impl ConsensusOutput {
    /// One line for a debug log: each input label's C_s, relation and target (with the target's
    /// map confidence from `confidence_of`), then the relabels, so a label's history can be
    /// followed keyframe by keyframe.
    pub fn describe(&self, confidence_of: impl Fn(u32) -> f32) -> String {
        let label = |t: u32| format!("{t} (C {:.2})", confidence_of(t));
        let mut parts: Vec<String> = self
            .assignments
            .iter()
            .map(|a| {
                let target = match &a.target {
                    LabelTarget::Label(t) => label(*t),
                    LabelTarget::Background => "0".to_string(),
                    LabelTarget::RenderedParts(p) => {
                        let p: Vec<String> = p.iter().map(|&t| label(t)).collect();
                        format!("its parts {}", p.join(", "))
                    }
                };
                format!(
                    "{} (C_s {:.2}) {:?} → {target}",
                    a.input_label, a.confidence, a.relation
                )
            })
            .collect();
        parts.extend(self.relabels.iter().map(|r| match r.scope {
            RelabelScope::Pixels => {
                format!("relabel {} → {} ({} px)", r.from, r.to, r.pixels.len())
            }
            RelabelScope::Label => format!("absorb {} → {} (whole label)", r.from, r.to),
            RelabelScope::Merged => format!("merge {} → {} (whole label)", r.from, r.to),
            RelabelScope::Rejoin => format!("rejoin {} → {} if on its surface", r.from, r.to),
        }));
        parts.join("; ")
    }

    /// Target of input label `input_label`, if it was present.
    pub fn target_of(&self, input_label: u32) -> Option<&LabelTarget> {
        self.assignments
            .binary_search_by_key(&input_label, |a| a.input_label)
            .ok()
            .map(|i| &self.assignments[i].target)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn describe_names_each_decision_and_relabel_with_confidences() {
        let out = ConsensusOutput {
            assignments: vec![
                LabelAssignment {
                    input_label: 3,
                    relation: Relation::Whole,
                    target: LabelTarget::RenderedParts(vec![4, 9]),
                    confidence: 0.41,
                },
                LabelAssignment {
                    input_label: 5,
                    relation: Relation::New,
                    target: LabelTarget::Label(12),
                    confidence: 1.0,
                },
            ],
            relabels: vec![RelabelInstruction {
                from: 4,
                to: 9,
                pixels: vec![1, 2, 3],
                scope: RelabelScope::Pixels,
            }],
            ..ConsensusOutput::default()
        };
        let confidence = |label: u32| if label == 12 { 1.0 } else { 0.53 };
        assert_eq!(
            out.describe(confidence),
            "3 (C_s 0.41) Whole → its parts 4 (C 0.53), 9 (C 0.53); \
             5 (C_s 1.00) New → 12 (C 1.00); relabel 4 → 9 (3 px)"
        );
    }
}
