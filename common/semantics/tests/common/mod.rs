//! Hand-built label maps for the consensus tests.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::ops::Range;

use opengs_semantics::{
    ConsensusConfig, ConsensusOutput, GlobalLabelTable, InputLabelClass, LabelConsensus,
    RenderedInput, SegmenterInput,
};

/// Input + rendered maps of one keyframe, with per-label confidence / completeness.
#[derive(Debug, Clone)]
pub struct Scene {
    pub width: usize,
    pub height: usize,
    pub input: Vec<u32>,
    pub rendered: Vec<u32>,
    pub confidence: BTreeMap<u32, f32>,
    pub classes: BTreeMap<u32, InputLabelClass>,
    pub completeness: BTreeMap<u32, f32>,
}

impl Scene {
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            input: vec![0; width * height],
            rendered: vec![0; width * height],
            confidence: BTreeMap::new(),
            classes: BTreeMap::new(),
            completeness: BTreeMap::new(),
        }
    }

    /// Input label `label` with confidence `conf` on pixel indices `span` (row-major).
    pub fn input_span(&mut self, span: Range<usize>, label: u32, conf: f32) -> &mut Self {
        self.input[span].fill(label);
        self.confidence.insert(label, conf);
        self
    }

    /// Input label on whole rows `rows`.
    pub fn input_rows(&mut self, rows: Range<usize>, label: u32, conf: f32) -> &mut Self {
        let w = self.width;
        self.input_span(rows.start * w..rows.end * w, label, conf)
    }

    pub fn rendered_span(&mut self, span: Range<usize>, label: u32) -> &mut Self {
        self.rendered[span].fill(label);
        self
    }

    pub fn rendered_rows(&mut self, rows: Range<usize>, label: u32) -> &mut Self {
        let w = self.width;
        self.rendered_span(rows.start * w..rows.end * w, label)
    }

    pub fn class(&mut self, label: u32, class: Option<&str>, score: f32) -> &mut Self {
        self.classes.insert(
            label,
            InputLabelClass {
                class: class.map(str::to_owned),
                score,
            },
        );
        self
    }

    pub fn completeness(&mut self, label: u32, value: f32) -> &mut Self {
        self.completeness.insert(label, value);
        self
    }

    /// Runs one keyframe; rendered labels without explicit completeness get 1.0.
    pub fn run(&self, consensus: &mut LabelConsensus) -> ConsensusOutput {
        self.try_run(consensus).expect("valid scene")
    }

    pub fn try_run(
        &self,
        consensus: &mut LabelConsensus,
    ) -> opengs_semantics::Result<ConsensusOutput> {
        let mut completeness = self.completeness.clone();
        for &r in self.rendered.iter().filter(|&&r| r != 0) {
            completeness.entry(r).or_insert(1.0);
        }
        let input = SegmenterInput {
            width: self.width,
            height: self.height,
            label_map: &self.input,
            confidence: &self.confidence,
            classes: &self.classes,
        };
        let rendered = RenderedInput {
            label_map: &self.rendered,
            completeness: &completeness,
        };
        consensus.process(&input, &rendered)
    }

    /// Pixel indices of whole rows `rows`.
    pub fn rows(&self, rows: Range<usize>) -> Vec<u32> {
        (rows.start * self.width..rows.end * self.width)
            .map(|p| p as u32)
            .collect()
    }
}

/// Consensus whose table already holds labels 1..=n with these map confidences.
pub fn consensus_with(confidences: &[f32], config: ConsensusConfig) -> LabelConsensus {
    let mut table = GlobalLabelTable::new(config.max_labels);
    for &c in confidences {
        table.allocate(None, 0.0, c).expect("room in table");
    }
    LabelConsensus::with_table(config, table).expect("valid config")
}

/// Map confidence C_r of `label`.
pub fn conf(consensus: &LabelConsensus, label: u32) -> f32 {
    consensus.table().confidence(label)
}
