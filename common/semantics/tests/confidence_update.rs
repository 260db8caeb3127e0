//! Input confidence update (§5.2): C_s ← mean of Cov_r ⊙ I_s over the segment.

mod common;

use approx::assert_relative_eq;
use common::{conf, consensus_with, Scene};
use opengs_semantics::{ConsensusConfig, LabelTarget};

#[test]
fn updated_confidence_is_mean_of_completeness_times_confidence() {
    // (completeness of rendered 1, fraction of input over rendered 1, C_s, expected C_s)
    // Input 5 covers rows 0..20; rendered 1 covers rows 0..k, the rest renders 0 (Cov = 1).
    let cases = [
        (0.5, 20, 0.8, 0.4),
        (0.5, 10, 0.8, 0.6), // half at 0.5, half at 1
        (1.0, 20, 0.8, 0.8),
        (0.0, 20, 0.8, 0.0),
        (0.25, 4, 1.0, 0.85), // 0.2·0.25 + 0.8·1
    ];
    for (completeness, rows, cs, expected) in cases {
        let mut scene = Scene::new(20, 20);
        scene.input_rows(0..20, 5, cs).rendered_rows(0..rows, 1);
        scene.completeness(1, completeness);
        let mut consensus = consensus_with(&[0.5], ConsensusConfig::default());
        let out = scene.run(&mut consensus);
        assert_relative_eq!(out.assignments[0].confidence, expected, epsilon = 1e-6);
    }
}

/// Rendered 1 (a fully observed object, C_r = 0.7) fills the view but only half its Gaussians
/// are visible; the segmenter splits it into two parts with C_s = 0.9 each.
fn half_visible_scene() -> Scene {
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..20, 1).completeness(1, 0.5);
    scene.input_rows(0..10, 5, 0.9).input_rows(10..20, 6, 0.9);
    scene
}

#[test]
fn half_visible_object_cannot_overwrite_fully_observed_one() {
    let mut consensus = consensus_with(&[0.7], ConsensusConfig::default());
    let out = half_visible_scene().run(&mut consensus);
    // 0.9 · 0.5 = 0.45 each: C̄s = 0.45 < 0.7, so the map keeps the object whole.
    for a in &out.assignments {
        assert_relative_eq!(a.confidence, 0.45, epsilon = 1e-6);
        assert_eq!(a.target, LabelTarget::Label(1));
    }
    assert!(out.relabels.is_empty());
    assert_relative_eq!(conf(&consensus, 1), 0.7);
}

#[test]
fn without_update_the_half_visible_object_splits_the_map_label() {
    let config = ConsensusConfig {
        enable_confidence_update: false,
        ..ConsensusConfig::default()
    };
    let mut consensus = consensus_with(&[0.7], config);
    let out = half_visible_scene().run(&mut consensus);
    assert_eq!(out.target_of(5), Some(&LabelTarget::Label(2)));
    assert_eq!(out.target_of(6), Some(&LabelTarget::Label(3)));
    assert_eq!(out.relabels.len(), 2);
}

#[test]
fn half_visible_full_match_does_not_raise_map_confidence() {
    // Full match with completeness 0.5: C_s 0.9 → 0.45, so C_r = max(0.7, 0.45) stays 0.7.
    let mut scene = Scene::new(20, 20);
    scene.rendered_rows(0..10, 1).completeness(1, 0.5);
    scene.input_rows(0..10, 5, 0.9);
    let mut consensus = consensus_with(&[0.7], ConsensusConfig::default());
    scene.run(&mut consensus);
    assert_relative_eq!(conf(&consensus, 1), 0.7);
}
