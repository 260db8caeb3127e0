//! `LabelConsensus`: owns the global label table and runs docs/METHOD.md §5 for each keyframe.

use std::collections::{BTreeMap, BTreeSet};

use crate::actions::{area, conf, Decisions, Evidence};
use crate::confidence::update_input_confidence;
use crate::config::ConsensusConfig;
use crate::consistent_map::{paint, PixelRules};
use crate::error::Result;
use crate::input::{
    input_confidences, rendered_completeness, validate_shapes, RenderedInput, SegmenterInput,
};
use crate::intersection::{touching_labels, Overlap};
use crate::label_table::GlobalLabelTable;
use crate::matching::Matching;
use crate::output::{ConsensusOutput, CounterPruneRegion, LabelAssignment, LabelTarget};

/// Confidence-based 2D label consensus with its global Label-Class table.
#[derive(Debug, Clone)]
pub struct LabelConsensus {
    config: ConsensusConfig,
    table: GlobalLabelTable,
}

impl LabelConsensus {
    /// Empty global table with `config.max_labels` as cap.
    pub fn new(config: ConsensusConfig) -> Result<Self> {
        config.validate()?;
        let table = GlobalLabelTable::new(config.max_labels);
        Ok(Self { config, table })
    }

    /// Resumes from a saved table (its own cap applies).
    pub fn with_table(config: ConsensusConfig, table: GlobalLabelTable) -> Result<Self> {
        config.validate()?;
        Ok(Self { config, table })
    }

    pub fn config(&self) -> &ConsensusConfig {
        &self.config
    }

    pub fn table(&self) -> &GlobalLabelTable {
        &self.table
    }

    pub fn into_table(self) -> GlobalLabelTable {
        self.table
    }

    /// Runs §5 on one keyframe. On error nothing changed: all checks precede the first update.
    pub fn process(
        &mut self,
        input: &SegmenterInput,
        rendered: &RenderedInput,
    ) -> Result<ConsensusOutput> {
        validate_shapes(input, rendered)?;
        let overlap = Overlap::count(input.label_map, rendered.label_map)
            .unsegmented_abstain(self.config.unsegmented_pixels_abstain);
        let non_zero =
            |m: &BTreeMap<u32, u32>| m.keys().copied().filter(|&l| l != 0).collect::<Vec<_>>();
        let (input_labels, rendered_labels) = (
            non_zero(&overlap.input_area),
            non_zero(&overlap.rendered_area),
        );
        let raw = input_confidences(input, input_labels.iter().copied())?;
        let completeness = if self.config.enable_confidence_update || self.config.absorb_fragments {
            rendered_completeness(rendered, rendered_labels.iter().copied())?
        } else {
            BTreeMap::new()
        };
        let conf_s = if self.config.enable_confidence_update {
            update_input_confidence(&overlap, &raw, &completeness)
        } else {
            raw
        };

        for &r in &rendered_labels {
            self.table.adopt(r);
        }
        // Every decision reads C_r as it was before this keyframe: order of labels cannot matter.
        let conf_r: BTreeMap<u32, f32> = rendered_labels
            .iter()
            .map(|&r| (r, self.table.confidence(r)))
            .collect();
        let touching = if self.config.enable_inside_split {
            touching_labels(input.label_map, input.width)
        } else {
            BTreeSet::new()
        };
        // Inside and Whole merges read completeness where it is given, and do not require it.
        let in_view = if completeness.is_empty() {
            rendered.completeness
        } else {
            &completeness
        };
        let matching = Matching::resolve(&overlap, in_view, &touching, &self.config);

        let evidence = Evidence {
            config: &self.config,
            completeness: in_view,
            matching: &matching,
            overlap: &overlap,
            conf_s: &conf_s,
            conf_r: &conf_r,
        };
        let d = Decisions::decide(&evidence, &mut self.table);

        self.update_table(input, &matching, &conf_s, &d);
        Ok(self.build_output(input, rendered, &matching, &overlap, &conf_s, d))
    }

    /// Full: C_r ← max(C_r, C_s); then part decay; then merged labels take C_s; absorbed labels
    /// retire; then classes.
    fn update_table(
        &mut self,
        input: &SegmenterInput,
        matching: &Matching,
        conf_s: &BTreeMap<u32, f32>,
        d: &Decisions,
    ) {
        for (&s, &r) in &matching.full {
            let c = self.table.confidence(r).max(conf(conf_s, s));
            self.table.set_confidence(r, c);
        }
        for &r in matching.full.values().chain(matching.majority.values()) {
            self.table.note_own_match(r);
        }
        for &r in &d.kept_fragments {
            self.table.note_fragment(r);
        }
        if self.config.enable_part_decay {
            for &r in &d.parts {
                self.table.decay(r, self.config.part_decay);
            }
        }
        for &(merged, c) in &d.merged {
            self.table.set_confidence(merged, c);
        }
        for &r in &d.absorbed {
            self.table.retire(r);
        }
        for (&s, (_, target)) in &d.targets {
            let class = input.classes.get(&s);
            let name = class.and_then(|c| c.class.as_deref());
            let score = class.map_or(0.0, |c| c.score);
            match target {
                LabelTarget::Label(t) => self.table.observe(*t, name, score),
                LabelTarget::RenderedParts(parts) => {
                    for &r in parts {
                        self.table.observe(r, name, score);
                    }
                }
                LabelTarget::Background => {}
            }
        }
    }

    fn build_output(
        &self,
        input: &SegmenterInput,
        rendered: &RenderedInput,
        matching: &Matching,
        overlap: &Overlap,
        conf_s: &BTreeMap<u32, f32>,
        mut d: Decisions,
    ) -> ConsensusOutput {
        let mut rules = PixelRules {
            unsegmented_abstain: self.config.unsegmented_pixels_abstain,
            ..PixelRules::default()
        };
        for (&s, (_, target)) in &d.targets {
            let rule = rules.input.entry(s).or_default();
            match target {
                LabelTarget::Label(t) => rule.label = *t,
                LabelTarget::Background => rule.label = 0,
                LabelTarget::RenderedParts(parts) => {
                    rule.take_parts = true;
                    rule.label = largest_part(parts, overlap);
                    for &r in parts {
                        rules.rendered.entry(r).or_default().part_of = Some(s);
                    }
                }
            }
        }
        for (&s, &i) in &d.input_regions {
            rules.input.entry(s).or_default().relabel = Some(i);
            d.relabels[i]
                .pixels
                .reserve(area(&overlap.input_area, s) as usize);
        }
        for (&r, &i) in &d.rendered_regions {
            rules.rendered.entry(r).or_default().relabel = Some(i);
            d.relabels[i]
                .pixels
                .reserve(area(&overlap.rendered_area, r) as usize);
        }
        let mut prune = Vec::new();
        if self.config.enable_counter_pruning {
            for (&s, &r) in &matching.full {
                rules.input.entry(s).or_default().full = Some((r, prune.len()));
                rules.rendered.entry(r).or_default().full = Some((s, prune.len()));
                let shared = u64::from(overlap.pairs.get(&(s, r)).copied().unwrap_or(0));
                let size = u64::from(area(&overlap.input_area, s))
                    + u64::from(area(&overlap.rendered_area, r))
                    - 2 * shared;
                prune.push(CounterPruneRegion {
                    label: r,
                    pixels: Vec::with_capacity(size as usize),
                });
            }
        }
        let consistent_label_map = paint(
            input.label_map,
            rendered.label_map,
            &rules,
            &mut d.relabels,
            &mut prune,
        );
        prune.retain(|region| !region.pixels.is_empty());
        for &(from, to) in &d.region_copies {
            let pixels = d.relabels[from].pixels.clone();
            d.relabels[to].pixels = pixels;
        }

        let assignments = d
            .targets
            .into_iter()
            .map(|(s, (relation, target))| LabelAssignment {
                input_label: s,
                relation,
                target,
                confidence: conf(conf_s, s),
            })
            .collect();
        ConsensusOutput {
            assignments,
            consistent_label_map,
            relabels: d.relabels,
            counter_pruning: prune,
            refused_allocations: d.refused,
        }
    }
}

/// The part with the largest rendered area (ties: smallest id); 0 without parts.
fn largest_part(parts: &[u32], overlap: &Overlap) -> u32 {
    parts
        .iter()
        .copied()
        .max_by_key(|&r| (area(&overlap.rendered_area, r), u32::MAX - r))
        .unwrap_or(0)
}
