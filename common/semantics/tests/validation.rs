//! Bad inputs are errors (never panics) and leave the consensus state untouched.

mod common;

use std::collections::BTreeMap;

use common::{consensus_with, Scene};
use opengs_semantics::{
    ConsensusConfig, LabelConsensus, LabelTarget, RenderedInput, SegmenterInput, SemanticsError,
};

fn good_scene() -> Scene {
    let mut scene = Scene::new(4, 2);
    scene
        .input_span(0..4, 1, 0.5)
        .input_span(4..8, 2, 0.5)
        .rendered_span(0..4, 1);
    scene
}

#[test]
fn invalid_inputs_are_reported_and_change_nothing() {
    type Case = (&'static str, fn(&mut Scene), SemanticsError);
    let cases: [Case; 7] = [
        (
            "short input map",
            |s| {
                s.input.pop();
            },
            SemanticsError::LabelMapSize {
                which: "input",
                expected: 8,
                got: 7,
            },
        ),
        (
            "long rendered map",
            |s| s.rendered.push(0),
            SemanticsError::LabelMapSize {
                which: "rendered",
                expected: 8,
                got: 9,
            },
        ),
        (
            "zero width",
            |s| {
                s.width = 0;
            },
            SemanticsError::InvalidImageSize {
                width: 0,
                height: 2,
            },
        ),
        (
            "missing confidence",
            |s| {
                s.confidence.remove(&2);
            },
            SemanticsError::MissingConfidence(2),
        ),
        (
            "NaN confidence",
            |s| {
                s.confidence.insert(2, f32::NAN);
            },
            SemanticsError::InvalidConfidence {
                label: 2,
                value: f32::NAN,
            },
        ),
        (
            "completeness > 1",
            |s| {
                s.completeness(1, 1.5);
            },
            SemanticsError::InvalidCompleteness {
                label: 1,
                value: 1.5,
            },
        ),
        (
            "infinite score",
            |s| {
                s.class(1, Some("x"), f32::INFINITY);
            },
            SemanticsError::InvalidScore {
                label: 1,
                value: f32::INFINITY,
            },
        ),
    ];
    for (name, break_it, expected) in cases {
        let mut scene = good_scene();
        break_it(&mut scene);
        let mut consensus = consensus_with(&[0.5], ConsensusConfig::default());
        let before = consensus.table().clone();
        let err = scene.try_run(&mut consensus).expect_err(name);
        // NaN ≠ NaN: compare the message instead.
        assert_eq!(err.to_string(), expected.to_string(), "{name}");
        assert_eq!(consensus.table(), &before, "{name}");
    }
}

#[test]
fn missing_completeness_is_an_error() {
    let scene = good_scene();
    let empty = BTreeMap::new();
    let input = SegmenterInput {
        width: 4,
        height: 2,
        label_map: &scene.input,
        confidence: &scene.confidence,
        classes: &scene.classes,
    };
    let rendered = RenderedInput {
        label_map: &scene.rendered,
        completeness: &empty,
    };
    let mut consensus = consensus_with(&[0.5], ConsensusConfig::default());
    assert_eq!(
        consensus.process(&input, &rendered),
        Err(SemanticsError::MissingCompleteness(1))
    );
}

#[test]
fn invalid_configs_are_rejected() {
    let base = ConsensusConfig::default();
    let bad = [
        ConsensusConfig {
            tau_full: 1.2,
            ..base.clone()
        },
        ConsensusConfig {
            tau_min: 0.0,
            ..base.clone()
        },
        ConsensusConfig {
            tau_min: 0.9,
            ..base.clone()
        },
        ConsensusConfig {
            part_decay: -0.1,
            ..base.clone()
        },
        ConsensusConfig {
            max_labels: 0,
            ..base.clone()
        },
        ConsensusConfig {
            counter_prune_scale: f32::NAN,
            ..base.clone()
        },
    ];
    for config in bad {
        assert!(LabelConsensus::new(config.clone()).is_err(), "{config:?}");
    }
    assert!(LabelConsensus::new(base).is_ok());
}

#[test]
fn unknown_rendered_labels_are_adopted() {
    // Rendered 42 was never allocated here (e.g. consensus restarted): adopted with C_r = 0.
    let mut scene = Scene::new(4, 1);
    scene.input_span(0..4, 1, 0.6).rendered_span(0..4, 42);
    let mut consensus = LabelConsensus::new(ConsensusConfig::default()).expect("valid");
    let out = scene.run(&mut consensus);
    assert_eq!(out.target_of(1), Some(&LabelTarget::Label(42)));
    assert_eq!(consensus.table().confidence(42), 0.6);
    let mut next = Scene::new(4, 1);
    next.input_span(0..4, 1, 0.6);
    assert_eq!(
        next.run(&mut consensus).target_of(1),
        Some(&LabelTarget::Label(43))
    );
}

#[test]
fn full_table_keeps_winning_partial_part_on_map_label() {
    let config = ConsensusConfig {
        max_labels: 1,
        ..ConsensusConfig::default()
    };
    let mut consensus = consensus_with(&[0.2], config);
    let mut scene = Scene::new(4, 1);
    scene
        .rendered_span(0..4, 1)
        .input_span(0..2, 5, 0.9)
        .input_span(2..4, 6, 0.9);
    let out = scene.run(&mut consensus);
    assert_eq!(out.consistent_label_map, vec![1; 4]);
    assert!(out.relabels.is_empty());
    assert_eq!(out.refused_allocations, 2);
}

#[test]
fn empty_frames_are_fine() {
    let scene = Scene::new(3, 3);
    let mut consensus = LabelConsensus::new(ConsensusConfig::default()).expect("valid");
    let out = scene.run(&mut consensus);
    assert!(out.assignments.is_empty());
    assert_eq!(out.consistent_label_map, vec![0; 9]);
}
