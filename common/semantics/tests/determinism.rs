//! Same inputs → same outputs and same table, over a sequence of keyframes.

mod common;

use common::Scene;
use opengs_semantics::{ConsensusConfig, GlobalLabelTable, LabelConsensus, Relation};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Random blocky maps (8×8 blocks) so every relation shows up somewhere.
fn random_scene(rng: &mut ChaCha8Rng, rendered_labels: u32) -> Scene {
    let (w, h) = (64, 48);
    let mut scene = Scene::new(w, h);
    for by in 0..h / 8 {
        for bx in 0..w / 8 {
            let s = rng.gen_range(0..12u32);
            let r = rng.gen_range(0..=rendered_labels);
            for y in by * 8..by * 8 + 8 {
                for x in bx * 8..bx * 8 + 8 {
                    scene.input[y * w + x] = s;
                    scene.rendered[y * w + x] = r;
                }
            }
        }
    }
    for s in 1..12 {
        scene.confidence.insert(s, rng.gen_range(0.0..1.0));
        scene.class(
            s,
            Some(["a", "b", "c"][s as usize % 3]),
            rng.gen_range(0.0..1.0),
        );
    }
    for r in 1..=rendered_labels {
        scene.completeness(r, rng.gen_range(0.2..1.0));
    }
    scene
}

#[test]
fn repeated_runs_are_identical() {
    let run = || {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut consensus = LabelConsensus::new(ConsensusConfig::default()).expect("valid");
        let mut outputs = Vec::new();
        for frame in 0..10 {
            let scene = random_scene(&mut rng, frame.min(8));
            outputs.push(scene.run(&mut consensus));
        }
        (outputs, consensus.into_table())
    };
    let (a, table_a) = run();
    let (b, table_b) = run();
    assert_eq!(a, b);
    assert_eq!(table_a, table_b);
    // Every non-zero consistent label is a known global label.
    for out in &a {
        for &l in out.consistent_label_map.iter().filter(|&&l| l != 0) {
            assert!(table_a.get(l).is_some(), "label {l} unknown");
        }
    }
}

#[test]
fn a_table_saved_and_loaded_answers_a_keyframe_again_with_the_same_ids() {
    // A consensus killed between sending an answer and saving it answers that keyframe again
    // after its restart, from the table saved before it: the mapper can only skip the repeat
    // when it carries the same labels.
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut consensus = LabelConsensus::new(ConsensusConfig::default()).expect("valid");
    for frame in 0..6 {
        random_scene(&mut rng, frame.min(8)).run(&mut consensus);
    }
    // What `save` writes and `load` reads.
    let saved = serde_json::to_string_pretty(consensus.table()).expect("serialises");
    let saved_len = consensus.table().len();
    let mut next = random_scene(&mut rng, 8);
    // Two segments over unmapped space: New, each gets a fresh label.
    for y in 0..48 {
        for x in 48..64 {
            next.input[y * 64 + x] = if y < 24 { 20 } else { 21 };
            next.rendered[y * 64 + x] = 0;
        }
    }
    next.confidence.insert(20, 0.9);
    next.confidence.insert(21, 0.8);
    let first = next.run(&mut consensus);
    assert_eq!(
        first
            .assignments
            .iter()
            .filter(|a| a.relation == Relation::New)
            .count(),
        2
    );
    assert!(consensus.table().len() >= saved_len + 2);
    let loaded: GlobalLabelTable = serde_json::from_str(&saved).expect("parses");
    let mut restarted =
        LabelConsensus::with_table(ConsensusConfig::default(), loaded).expect("valid");
    assert_eq!(next.run(&mut restarted), first);
    assert_eq!(restarted.into_table(), consensus.into_table());
}
