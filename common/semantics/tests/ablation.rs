//! Each ablation switch changes exactly its own behaviour.

mod common;

use common::{consensus_with, Scene};
use opengs_semantics::{ConsensusConfig, ConsensusOutput, GlobalLabelTable};

/// A scene exercising every module: a Full match with a symmetric difference (counter
/// pruning), a Partial split (decay), a Whole loss (decay) and completeness < 1 (update).
fn scene() -> Scene {
    let mut scene = Scene::new(20, 20);
    // Full: rendered 1 on pixels 0..85, input 10 on 0..90 (a = 0.94, b = 1); difference 85..90.
    scene.rendered_span(0..85, 1).input_span(0..90, 10, 0.9);
    // Partial split: rendered 2 rows 5..13; parts 11 (0.9) and 12 (0.3).
    scene.rendered_rows(5..13, 2);
    scene.input_rows(5..9, 11, 0.9).input_rows(9..13, 12, 0.3);
    // Whole lost: input 13 rows 13..20 (C 0.2), rendered 3 rows 13..16 and 4 rows 16..19.
    scene.input_rows(13..20, 13, 0.2);
    scene.rendered_rows(13..16, 3).rendered_rows(16..19, 4);
    scene.completeness(1, 0.9).completeness(2, 0.95);
    scene
}

fn run(config: ConsensusConfig) -> (ConsensusOutput, GlobalLabelTable) {
    let mut consensus = consensus_with(&[0.5, 0.5, 0.5, 0.5], config);
    let out = scene().run(&mut consensus);
    (out, consensus.into_table())
}

fn confidences(table: &GlobalLabelTable) -> Vec<(u32, f32)> {
    table.iter().map(|(id, l)| (id, l.confidence)).collect()
}

#[test]
fn baseline_exercises_every_module() {
    let (out, table) = run(ConsensusConfig::default());
    assert!(!out.counter_pruning.is_empty());
    assert!(table.iter().any(|(_, l)| l.part_decays > 0));
    assert!(out
        .assignments
        .iter()
        .any(|a| a.confidence < 0.9 && a.input_label == 10));
}

#[test]
fn counter_pruning_switch_only_empties_prune_regions() {
    let (base, base_table) = run(ConsensusConfig::default());
    let (off, off_table) = run(ConsensusConfig {
        enable_counter_pruning: false,
        ..ConsensusConfig::default()
    });
    assert!(off.counter_pruning.is_empty());
    assert_eq!(
        ConsensusOutput {
            counter_pruning: Vec::new(),
            ..base
        },
        off
    );
    assert_eq!(base_table, off_table);
}

#[test]
fn part_decay_switch_only_changes_decayed_confidences() {
    let (base, base_table) = run(ConsensusConfig::default());
    let (off, off_table) = run(ConsensusConfig {
        enable_part_decay: false,
        ..ConsensusConfig::default()
    });
    assert_eq!(base, off);
    let delta = ConsensusConfig::default().part_decay;
    for ((id, on), (_, off)) in confidences(&base_table)
        .into_iter()
        .zip(confidences(&off_table))
    {
        let decays = base_table.get(id).map_or(0, |l| l.part_decays);
        let expected = if decays > 0 { off - delta } else { off };
        approx::assert_relative_eq!(on, expected, epsilon = 1e-6);
    }
    assert!(off_table.iter().all(|(_, l)| l.part_decays == 0));
}

#[test]
fn confidence_update_switch_only_changes_confidences() {
    let (base, base_table) = run(ConsensusConfig::default());
    let (off, off_table) = run(ConsensusConfig {
        enable_confidence_update: false,
        ..ConsensusConfig::default()
    });
    // Same decisions and pixels; only the reported C_s (and C_r of the Full match) move.
    assert_eq!(base.consistent_label_map, off.consistent_label_map);
    assert_eq!(base.relabels, off.relabels);
    assert_eq!(base.counter_pruning, off.counter_pruning);
    let targets = |o: &ConsensusOutput| {
        o.assignments
            .iter()
            .map(|a| a.target.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(targets(&base), targets(&off));
    let conf_of = |o: &ConsensusOutput, l: u32| {
        o.assignments
            .iter()
            .find(|a| a.input_label == l)
            .map(|a| a.confidence)
    };
    // Input 10: 85 px over rendered 1 (Cov 0.9) + 5 px over 0: 0.9·(85·0.9 + 5)/90.
    approx::assert_relative_eq!(
        conf_of(&base, 10).unwrap_or(0.0),
        0.9 * (85.0 * 0.9 + 5.0) / 90.0,
        epsilon = 1e-6
    );
    assert_eq!(conf_of(&off, 10), Some(0.9));
    assert_ne!(confidences(&base_table), confidences(&off_table));
}

#[test]
fn without_confidence_update_and_absorption_completeness_is_not_required() {
    // Fragment absorption reads completeness too (is the fragment mostly in view?).
    let config = ConsensusConfig {
        enable_confidence_update: false,
        absorb_fragments: false,
        ..ConsensusConfig::default()
    };
    let mut consensus = consensus_with(&[0.5], config);
    let mut scene = Scene::new(4, 1);
    scene.input_span(0..4, 1, 0.5).rendered_span(0..4, 1);
    let empty = std::collections::BTreeMap::new();
    let input = opengs_semantics::SegmenterInput {
        width: 4,
        height: 1,
        label_map: &scene.input,
        confidence: &scene.confidence,
        classes: &scene.classes,
    };
    let rendered = opengs_semantics::RenderedInput {
        label_map: &scene.rendered,
        completeness: &empty,
    };
    assert!(consensus.process(&input, &rendered).is_ok());
}
