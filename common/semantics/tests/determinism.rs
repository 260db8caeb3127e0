//! Same inputs → same outputs and same table, over a sequence of keyframes.

mod common;

use common::Scene;
use opengs_semantics::{ConsensusConfig, LabelConsensus};
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
